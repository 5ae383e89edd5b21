"""``rehabbot zoo list`` and ``rehabbot zoo show``: every shipped agent, one line each; one
agent's metadata as JSON; a bad name is one line and exit code 2."""

from __future__ import annotations

import json

import pytest

from rehabbot.cli import main
from rehabbot.envs.registration import env_short_name
from rehabbot.rl import zoo


def test_zoo_list_has_one_line_per_shipped_agent(capsys) -> None:
    assert main(["zoo", "list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    agents = zoo.available()
    assert agents and len(lines) == 2 + len(agents)  # a header, the agents, a legend
    held_out = zoo.held_out_figures()
    for (env_id, algo), line in zip(agents, lines[1:-1], strict=True):
        name = f"{env_short_name(env_id)}/{algo}"
        assert line.startswith(f"{name} ")
        meta = zoo.load(env_id, algo).metadata
        figures = held_out.get(name)
        if figures and figures.get("weights_sha256") == meta["weights_sha256"]:
            finished, of = figures["bodies"]
            assert f"{finished}/{of} ({100 * finished / of:.0f} %)" in line
    assert lines[-1].startswith("patients: ")


def test_zoo_list_shows_held_out_figures_only_for_the_weights_measured(
        capsys, tmp_path, monkeypatch) -> None:
    shipped = zoo.zoo_path("rehab-knee-v2", "sac")
    root = tmp_path / "zoo"
    (root / "rehab-knee-v2").mkdir(parents=True)
    (root / "rehab-knee-v2" / "sac.npz").write_bytes(shipped.read_bytes())
    (root / "rehab-knee-v2" / "td3.npz").write_bytes(
        zoo.zoo_path("rehab-knee-v2", "td3").read_bytes())
    sha = zoo.load("rehab-knee-v2", "sac").metadata["weights_sha256"]
    monkeypatch.setenv("REHABBOT_ZOO_DIR", str(root))
    (root / zoo.HELD_OUT_FILE).write_text(json.dumps({"agents": {
        "rehab-knee-v2/sac": {"bodies": [37, 40], "conditions": [90, 120],
                              "weights_sha256": sha},
        "rehab-knee-v2/td3": {"bodies": [40, 40], "conditions": [120, 120],
                              "weights_sha256": "0" * 64}}}))
    assert main(["zoo", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    sac = next(line for line in lines if line.startswith("rehab-knee-v2/sac "))
    td3 = next(line for line in lines if line.startswith("rehab-knee-v2/td3 "))
    assert "37/40 (92 %)" in sac and "90/120 (75 %)" in sac
    assert "40/40" not in td3 and td3.split()[-2:] == ["-", "-"]  # other weights: no figure


def test_zoo_show_prints_the_agents_metadata(capsys) -> None:
    env_id, algo = zoo.available()[0]
    assert main(["zoo", "show", f"zoo:{env_short_name(env_id)}/{algo}"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["env_id"] == env_id and shown["algo"] == algo
    assert shown["weights_sha256"] == zoo.load(env_id, algo).metadata["weights_sha256"]


@pytest.mark.parametrize(("name", "words"), [("knee", "is not ENV/ALGO"),
                                             ("rehab-knee-v9/sac", "has no agent"),
                                             ("../sac", "not a zoo name"),
                                             ("../../etc/sac", "is not a rehabbot id"),
                                             ("evilmod:rehabbot/rehab-knee-v2/sac",
                                              "is not a rehabbot id")])
def test_a_bad_agent_name_is_one_line(capsys, name: str, words: str) -> None:
    assert main(["zoo", "show", name]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and err.startswith("rehabbot: error: ")


def test_a_damaged_held_out_file_is_named(capsys, tmp_path, monkeypatch) -> None:
    root = tmp_path / "zoo"
    (root / "rehab-knee-v2").mkdir(parents=True)
    (root / "rehab-knee-v2" / "sac.npz").write_bytes(
        zoo.zoo_path("rehab-knee-v2", "sac").read_bytes())
    monkeypatch.setenv("REHABBOT_ZOO_DIR", str(root))
    (root / zoo.HELD_OUT_FILE).write_text("{not json")
    assert main(["zoo", "list"]) != 0
    assert zoo.HELD_OUT_FILE in capsys.readouterr().err
