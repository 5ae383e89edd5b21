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
    assert agents and len(lines) == 1 + len(agents)
    for (env_id, algo), line in zip(agents, lines[1:], strict=True):
        assert line.startswith(f"{env_short_name(env_id)}/{algo} ")
        meta = zoo.load(env_id, algo).metadata
        assert f"{100 * meta['success_rate']:.0f} %" in line


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
