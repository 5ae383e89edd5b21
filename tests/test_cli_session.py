"""The typical session of ``rehabbot --help`` on the install it names: each command run as
on a core install (``pip install rehabbot``; tests/core_install.py hides every module the
extras bring) either works (``list``) or stops at once, before any work, with one line naming
the ``pip install "rehabbot[EXTRA]"`` its comment in the session says."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest
from core_install import hidden_names, imported, messages, run_core, run_python_core

from rehabbot.cli import TYPICAL_SESSION
from rehabbot.envs.registration import ENV_SPECS, required_extra

SESSION_LINE = re.compile(r"^  (rehabbot .*?)\s+# (.*)$")


def session() -> list[tuple[list[str], set[str]]]:
    """The session's commands (argv after ``rehabbot``) and the extras their comments name
    (none for "the core install")."""
    commands = []
    for line in TYPICAL_SESSION.splitlines():
        match = SESSION_LINE.match(line)
        if match:
            argv = shlex.split(match.group(1))[1:]
            commands.append((argv, set(re.findall(r"\[(\w+)\]", match.group(2)))))
    return commands


def _hint_extras(line: str) -> set[str]:
    match = re.search(r'pip install "rehabbot\[([\w,]+)\]"', line)
    assert match, line
    return set(match.group(1).split(","))


def test_the_session_is_the_one_of_the_help() -> None:
    names = [argv[0] for argv, _extras in session()]
    assert names == ["list", "train", "evaluate", "plot", "render"]


def test_the_core_simulation_hides_the_extras_and_keeps_the_core() -> None:
    import importlib.util

    hidden = set(hidden_names()["modules"])
    for module in ("stable_baselines3", "torch", "yaml", "sbx", "jax", "matplotlib", "imageio",
                   "ray", "myo_sim", "warp", "rsl_rl", "mujoco.mjx"):
        if importlib.util.find_spec(module) is not None:  # installed here: hidden there
            assert module in hidden, module
    assert not {"mujoco", "gymnasium", "numpy", "rehabbot"} & hidden


@pytest.fixture(scope="module")
def session_folder(tmp_path_factory) -> Path:
    """A folder holding what the session's commands read: a tiny SAC run of
    Stable-Baselines3 at runs/rehab-reach-v2/sac/seed0 (trained with every extra here)."""
    pytest.importorskip("stable_baselines3")
    from rehabbot.rl.training import train_run

    folder = tmp_path_factory.mktemp("session")
    train_run("rehab-reach-v2", "sac", 0, 200, folder / "runs",
              hyperparams={"learning_starts": 100, "batch_size": 16,
                           "policy_kwargs": "dict(net_arch=[8, 8])"},
              env_kwargs={"max_episode_steps": 50}, eval_freq=0, checkpoint_freq=0,
              progress_bar=False, backend="sb3")
    return folder


def _files(folder: Path) -> set[Path]:
    return {path for path in folder.rglob("*")}


@pytest.mark.parametrize("argv, extras", [
    pytest.param(argv, extras, id=argv[0]) for argv, extras in session()])
def test_each_session_command_works_or_names_its_extra_on_a_core_install(
        session_folder: Path, argv: list[str], extras: set[str]) -> None:
    before = _files(session_folder)
    done = run_core(argv, session_folder)
    lines = messages(done.stderr)
    assert imported(done.stderr) == [], "the command did work before it checked its extra"
    assert _files(session_folder) == before  # nothing written
    if not extras:
        assert done.returncode == 0, done.stderr
        return
    assert done.returncode == 1, done.stderr
    assert len(lines) == 1 and lines[0].startswith("rehabbot: error: "), lines
    assert _hint_extras(lines[0]) == extras


@pytest.mark.parametrize("argv, extras", [
    (["train", "rehab-reach-v2", "--algo", "tqc", "--backend", "sb3"], {"train"}),
    (["train", "rehab-reach-v2", "--algo", "sac", "--backend", "sbx"], {"train", "jax"}),
    (["train", "rehab-reach-v2", "--algo", "ppo", "--backend", "rsl_rl"], {"gpu"}),
    (["sweep", "sweeps/example.yaml"], {"train", "sweep"}),
    (["sweep", "sweeps/example.yaml", "--dry-run"], {"train"}),
    (["demo", "--out", "demo"], {"train", "plot", "video"}),
    (["demo", "--out", "demo", "--no-video"], {"train", "plot"}),
    (["render", "expert", "--env", "rehab-reach-v2", "--out", "expert.gif"], {"video"}),
    (["render", "expert", "--env", "rehab-reach-v2", "--out", "expert.mp4"], {"video"}),
    (["snapshot", "upper_right", "--out", "front.png"], {"video"}),
])
def test_every_other_command_names_its_extras_before_any_work(tmp_path: Path, argv: list[str],
                                                              extras: set[str]) -> None:
    argv = [str(Path(__file__).resolve().parents[1] / arg) if arg.startswith("sweeps/")
            else arg for arg in argv]
    done = run_core(argv, tmp_path)
    lines = messages(done.stderr)
    assert done.returncode == 1 and len(lines) == 1, done.stderr
    assert _hint_extras(lines[0]) == extras
    assert imported(done.stderr) == []
    assert list(tmp_path.iterdir()) == []


def test_list_on_a_core_install_marks_the_ids_that_need_an_extra(tmp_path: Path) -> None:
    done = run_core(["list"], tmp_path)
    assert done.returncode == 0 and messages(done.stderr) == []
    assert imported(done.stderr) == []  # read from the registry: MuJoCo not even imported
    rows = {line.split()[0]: line.split()[4] for line in done.stdout.splitlines()
            if line.startswith("rehabbot/")}
    assert set(rows) == set(ENV_SPECS)
    for env_id, needs in rows.items():
        extra = required_extra(env_id)
        assert needs == (f"[{extra}]" if extra else "-"), env_id
    assert '[myo]: 3 ids need pip install "rehabbot[myo]" (not installed here)' in done.stdout


@pytest.mark.slow
def test_every_id_builds_on_a_core_install_unless_list_marks_it(tmp_path: Path) -> None:
    source = """
import json, gymnasium as gym, rehabbot
from rehabbot.envs.registration import ENV_SPECS
result = {}
for env_id in ENV_SPECS:
    try:
        gym.make(env_id).close()
        result[env_id] = None
    except Exception as err:
        result[env_id] = str(err)
print("RESULT " + json.dumps(result))
"""
    done = run_python_core(source, tmp_path)
    assert done.returncode == 0, done.stderr
    line = next(line for line in done.stdout.splitlines() if line.startswith("RESULT "))
    for env_id, error in json.loads(line.removeprefix("RESULT ")).items():
        extra = required_extra(env_id)
        if extra is None:
            assert error is None, (env_id, error)
        else:
            assert error is not None and f'pip install "rehabbot[{extra}]"' in error, env_id


@pytest.mark.slow
def test_list_spaces_on_a_core_install_builds_what_it_can(tmp_path: Path) -> None:
    done = run_core(["list", "--spaces"], tmp_path)
    assert done.returncode == 0, done.stderr
    rows = [line for line in done.stdout.splitlines() if line.startswith("rehabbot/")]
    assert len(rows) == len(ENV_SPECS)
    for row in rows:
        env_id = row.split()[0]
        if required_extra(env_id):
            assert f"needs [{required_extra(env_id)}]" in row
        else:
            assert "Box(" in row
    total = len(ENV_SPECS)
    assert any(f"id {total}/{total}" in line for line in messages(done.stderr))  # progress


def _getting_started_table() -> dict[str, set[str]]:
    """docs/getting-started.md's table: command -> the extras of its first clause."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "getting-started.md").read_text()
    table = {}
    for line in text.splitlines():
        match = re.match(r"^\| `rehabbot (\w+)` \| (.*) \|$", line)
        if match:
            first = re.split(r";| for ", match.group(2))[0]
            table[match.group(1)] = {extra for group in re.findall(r"\[([\w,]+)\]", first)
                                     for extra in group.split(",")}
    return table


@pytest.mark.parametrize("argv", [
    ["list"], ["train", "rehab-reach-v2", "--algo", "sac"],
    ["snapshot", "upper_right", "--out", "front.png"], ["demo", "--out", "demo"],
    ["sweep", "sweeps/example.yaml"]], ids=lambda argv: argv[0])
def test_getting_started_names_the_extras_the_commands_ask_for(tmp_path: Path,
                                                                argv: list[str]) -> None:
    documented = _getting_started_table()[argv[0]]
    argv = [str(Path(__file__).resolve().parents[1] / arg) if arg.startswith("sweeps/")
            else arg for arg in argv]
    done = run_core(argv, tmp_path)
    if not documented:
        assert done.returncode == 0, done.stderr
        return
    assert done.returncode == 1 and _hint_extras(messages(done.stderr)[0]) == documented
