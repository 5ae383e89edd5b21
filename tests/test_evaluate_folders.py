"""Where ``rehabbot evaluate`` writes and what ``rehabbot plot`` draws of it: a default folder of
its own per comparison, ``--overwrite`` leaving no empty label folder, nothing removed or written
through a link, never into a live run's folder; a failing policy named, with a truthful exit
code; every number bounded and a user's ``--out`` never built out of missing folders."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import rehabbot  # noqa: F401
from rehabbot.analysis.evaluation import evaluate_policies
from rehabbot.cli import main
from rehabbot.common.files import FolderLock
from rehabbot.rl.policies import PolicyError

ENV = "rehab-reach-v1"
SHORT = ["--episodes", "1", "--env-kwargs", '{"max_episode_steps": 30}']
REPO = Path(__file__).resolve().parent.parent


def evaluate(*args: str) -> int:
    return main(["evaluate", *args, *SHORT])


# ------------------------------------------------------------------ one default folder each
def test_evaluations_of_other_policies_never_meet_in_a_default_folder(tmp_path, capsys,
                                                                      monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert evaluate("zoo:rehab-reach-v1/ppo", "expert") == 0  # as `rehabbot zoo --help` says
    out = capsys.readouterr().out
    assert evaluate("expert", "random", "--env", ENV) == 0, capsys.readouterr().err
    first = tmp_path / "runs" / "evaluation" / ENV / "zoo-ppo+expert"
    assert f"evaluation folder: {Path('runs/evaluation') / ENV / 'zoo-ppo+expert'}" in out
    assert out.rstrip().endswith(f"rehabbot plot runs/evaluation/{ENV}/zoo-ppo+expert")
    second = tmp_path / "runs" / "evaluation" / ENV / "expert+random"
    for folder, labels in ((first, {"zoo-ppo", "expert"}), (second, {"expert", "random"})):
        assert {p.parent.name for p in folder.glob("*/evaluation.json")} == labels
        assert (folder / "comparison.md").is_file()


def test_a_default_folder_is_named_after_the_policies_compared(tmp_path) -> None:
    from rehabbot.analysis.evaluation_folders import comparison_name, default_out_dir

    run = tmp_path / "runs" / "rehab-reach-v1" / "sac" / "seed0"
    run.mkdir(parents=True)
    (run / "manifest.json").write_text(json.dumps({"env_id": "rehabbot/rehab-reach-v1"}))
    (run / "model.zip").write_bytes(b"")
    model = str(run / "model.zip")
    env_id = "rehabbot/rehab-reach-v1"
    assert default_out_dir([model], env_id, ["sac-seed0"]) == run / "evaluation"
    assert default_out_dir([model, "expert"], env_id, ["sac-seed0", "expert"]) == (
        tmp_path / "runs" / "rehab-reach-v1" / "evaluation" / "sac-seed0+expert")
    # another env than the run's: not inside the run's env folder
    assert default_out_dir([model, "expert"], "rehabbot/rehab-reach-spastic-v1",
                           ["sac-seed0", "expert"]) == (
        Path("runs/evaluation/rehab-reach-spastic-v1/sac-seed0+expert"))
    assert default_out_dir(["expert", "aan"], env_id, ["expert", "aan"]) == (
        Path("runs/evaluation/rehab-reach-v1/expert+aan"))
    long = [f"policy-{k}-" + "x" * 30 for k in range(6)]
    assert len(comparison_name(long)) <= 120
    assert comparison_name(long) != comparison_name([*long[:5], "other"])


def test_overwrite_leaves_no_empty_label_folder(tmp_path, capsys) -> None:
    out = tmp_path / "ev"
    assert evaluate("expert", "aan", "--env", ENV, "--out", str(out)) == 0
    assert evaluate("random", "--env", ENV, "--out", str(out)) == 2
    assert "already holds an evaluation" in capsys.readouterr().err
    (out / "aan" / "notes.txt").write_text("mine")  # not the evaluation's: kept
    assert evaluate("random", "--env", ENV, "--out", str(out), "--overwrite") == 0
    assert sorted(p.name for p in out.iterdir()) == ["aan", "random"]
    assert [p.name for p in (out / "aan").iterdir()] == ["notes.txt"]
    assert sorted(p.name for p in (out / "random").iterdir()) == ["evaluation.json",
                                                                   "trace.npz"]


# ------------------------------------------------------------------ never through a link
def _outside(tmp_path: Path) -> tuple[Path, dict[str, bytes]]:
    """A folder outside the evaluation's that holds a label folder's files."""
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    files = {"evaluation.json": b'{"mine": 1}\n', "trace.npz": b"not ours",
             "patients.md": b"| mine |\n"}
    for name, data in files.items():
        (outside / name).write_bytes(data)
    return outside, files


@pytest.mark.parametrize("link_name, policy", [("expert", "expert"), ("other", "random")])
def test_a_linked_label_folder_is_refused_and_nothing_outside_is_touched(
        tmp_path, capsys, link_name, policy) -> None:
    outside, files = _outside(tmp_path)
    out = tmp_path / "ev"
    out.mkdir()
    (out / link_name).symlink_to(outside, target_is_directory=True)
    for extra in (["--overwrite"], []):
        assert evaluate(policy, "--env", ENV, "--out", str(out), *extra) == 1
        err = capsys.readouterr().err
        assert f"refusing {out / link_name}" in err and "symbolic link" in err
        assert {p.name: p.read_bytes() for p in outside.iterdir()} == files
    assert not (out / policy).exists() or policy == link_name


def test_the_library_never_writes_through_a_linked_folder(tmp_path) -> None:
    from rehabbot.analysis.evaluation import save_report
    from rehabbot.common.errors import OutputError

    outside, files = _outside(tmp_path)
    link = tmp_path / "expert"
    link.symlink_to(outside, target_is_directory=True)
    report, trace = evaluate_policies(["expert"], ENV, episodes=1,
                                      env_kwargs={"max_episode_steps": 5})[0]
    with pytest.raises(OutputError, match="symbolic link"):
        save_report(report, trace, link)
    assert {p.name: p.read_bytes() for p in outside.iterdir()} == files


# ------------------------------------------------------------------ never into a live run
def test_a_live_run_folder_is_refused_naming_it(tmp_path, capsys) -> None:
    run = tmp_path / "runs" / ENV / "sac" / "seed0"
    run.mkdir(parents=True)
    (run / "manifest.json").write_text("{}")
    lock = FolderLock(run, ".lock").acquire("run folder")  # as `rehabbot train` holds it
    try:
        (run / "evaluation").mkdir()
        for out in (run, run / "evaluation", run / "evaluation" / "expert+random"):
            assert evaluate("expert", "--env", ENV, "--out", str(out)) == 1
            err = capsys.readouterr().err
            assert f"run folder {run} is being written by another process (pid " in err
            assert not (run / "expert").exists() and not list((run / "evaluation").iterdir())
    finally:
        lock.release()
    assert evaluate("expert", "--env", ENV, "--out", str(run / "evaluation")) == 0


# ------------------------------------------------------------------ a failing policy is named
POLICIES = '''
import sys
import numpy as np

class Quit:
    def __init__(self, env):
        pass
    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        sys.exit(0)

class NotANumber:
    label = "nan-policy"
    def __init__(self, env):
        self.shape = env.action_space.shape
    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.full(self.shape, np.nan), state

class Bare:
    def __init__(self, env):
        self.shape = env.action_space.shape
    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.zeros(self.shape)

class Wide:
    def __init__(self, env):
        pass
    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.zeros(99), state

class Broken:
    def __init__(self, env):
        pass
    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        raise KeyError("gripper")
'''


@pytest.mark.slow
@pytest.mark.parametrize("attr, label, needle", [
    ("Quit", "Quit", "its predict() called exit(0)"),
    ("NotANumber", "nan-policy", "returned a non-finite action"),
    ("Bare", "Bare", "not a pair (action, state)"),
    ("Wide", "Wide", "returned an action of shape (99,)"),
    ("Broken", "Broken", "its predict() raised KeyError: 'gripper'"),
])
def test_a_failing_policy_fails_the_command_naming_it(tmp_path, attr, label, needle) -> None:
    (tmp_path / "mypolicies.py").write_text(POLICIES)
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-m", "rehabbot", "evaluate", f"mypolicies:{attr}",
                           "--env", ENV, *SHORT, "--out", "ev"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert f"policy '{label}' (mypolicies:{attr})" in done.stderr and needle in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "ev").exists() or not list((tmp_path / "ev").rglob("*.json"))


def test_the_library_names_a_failing_policy_object() -> None:
    class Bare:
        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return np.zeros(6)

    with pytest.raises(PolicyError, match=r"policy 'Bare': predict\(\) returned a float64 "
                                          r"array of shape \(6,\), not a pair"):
        evaluate_policies([Bare()], ENV, episodes=1, env_kwargs={"max_episode_steps": 5})


def test_a_policy_that_exits_while_it_loads_is_named(tmp_path, monkeypatch, capsys) -> None:
    (tmp_path / "exits_on_import.py").write_text("import sys\nsys.exit(0)\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    assert evaluate("exits_on_import:Policy", "--env", ENV, "--out", "ev") == 1
    err = capsys.readouterr().err
    assert "policy 'exits_on_import:Policy': loading it called exit(0)" in err


# ------------------------------------------------------------------ bounded numbers, --out
def evaluate_parser():
    import argparse

    from rehabbot.cli.evaluate import add_evaluate_parser

    parser = argparse.ArgumentParser(prog="rehabbot")
    add_evaluate_parser(parser.add_subparsers(dest="command", required=True))
    return parser


@pytest.mark.parametrize("option, value", [("--episodes", "0"), ("--episodes", "1e26"),
                                           ("--episodes", "100000000"), ("--seed", "-1"),
                                           ("--seed", "1e12"), ("--seed", "1000000000000"),
                                           ("--seed", "2.5")])
def test_every_number_evaluate_takes_is_bounded(option, value, capsys) -> None:
    parser = evaluate_parser()  # parsed only: an unbounded count would run for ever
    with pytest.raises(SystemExit) as stop:
        parser.parse_args(["evaluate", "expert", "--env", ENV, option, value])
    assert stop.value.code == 2
    assert repr(value) in capsys.readouterr().err
    args = parser.parse_args(["evaluate", "expert", option, {"--episodes": "100000",
                                                              "--seed": "2147483647"}[option]])
    assert getattr(args, option[2:]) in (100_000, 2**31 - 1)


def test_a_user_out_needs_an_existing_parent(tmp_path, capsys) -> None:
    missing = tmp_path / "no" / "such" / "ev"
    assert evaluate("expert", "--env", ENV, "--out", str(missing)) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()
    assert evaluate("expert", "--env", ENV, "--out", str(tmp_path / "ev")) == 0  # last part


# ------------------------------------------------------------------ plot: matplotlib first
def test_plot_checks_matplotlib_before_evaluating_anything(tmp_path, monkeypatch,
                                                           capsys) -> None:
    run = tmp_path / "runs" / ENV / "sac" / "seed0"
    run.mkdir(parents=True)
    (run / "manifest.json").write_text(json.dumps({"env_id": f"rehabbot/{ENV}", "algo": "sac",
                                                   "seed": 0}))
    (run / "model.zip").write_bytes(b"PK\x05\x06" + b"\x00" * 18)
    calls: list[Path] = []
    fake = types.ModuleType("rehabbot.analysis.evaluation")
    fake.ensure_trace = lambda run_dir: calls.append(run_dir)  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "rehabbot.analysis.evaluation", fake)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # not installed
    assert main(["plot", str(tmp_path / "runs")]) == 1
    assert 'pip install "rehabbot[plot]"' in capsys.readouterr().err
    assert calls == []
