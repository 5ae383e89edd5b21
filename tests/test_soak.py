"""The random-action soak (``benchmarks/performance/soak.py``): a short clean run of every cell, its
reproducibility, the detectors (with deliberately faulty envs), the JSON report, bad arguments
and interrupts."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from benchmarks.performance.soak import END_REASONS, SoakReport, main, run_soak
from rehabbot.envs.control import CONTROL_MODES
from rehabbot.envs.registration import ENV_SPECS

N_CELLS = len(ENV_SPECS) * len(CONTROL_MODES)  # every id x 4 modes
SHORT_STEPS = N_CELLS * 200  # 200 steps per cell
FAULT_EVERY = 100  # the faulty envs misbehave on every 100th step call


@pytest.fixture(scope="module")
def short_soak() -> SoakReport:
    return run_soak(SHORT_STEPS, seed=0)


def _counts(report: SoakReport) -> dict[str, tuple]:
    return {cell.name: (cell.steps, cell.episodes, cell.ends, cell.reset_seeds,
                        cell.action_seeds) for cell in report.cells}


@pytest.mark.slow
def test_short_soak_of_every_cell_is_clean(short_soak: SoakReport) -> None:
    report = short_soak
    cells = {(cell.env_id, cell.control_mode) for cell in report.cells}
    assert cells == {(env_id, mode) for env_id in ENV_SPECS for mode in CONTROL_MODES}
    assert len(report.cells) == N_CELLS
    assert report.complete and report.interrupted_by is None
    assert report.steps == SHORT_STEPS
    for cell in report.cells:
        assert cell.status == "complete", cell.name
        assert cell.steps == cell.steps_planned == SHORT_STEPS // N_CELLS, cell.name
        assert cell.exceptions == 0, (cell.name, cell.exception_examples)
        assert cell.non_finite == 0, (cell.name, cell.non_finite_example)
        assert cell.obs_outside == 0, (cell.name, cell.obs_outside_example)
        assert cell.episodes >= 1
        assert set(cell.ends) <= set(END_REASONS), cell.ends
        assert sum(cell.ends.values()) == cell.episodes, (cell.name, cell.ends)
        assert len(cell.reset_seeds) == len(cell.action_seeds) == 1
        for value in (cell.rss_warmup_mib, cell.rss_end_mib, cell.rss_growth_mib,
                      cell.rss_growth_mib_per_million_steps, cell.steps_per_s):
            assert value is not None and math.isfinite(value), cell.name
    assert report.exit_code() == 0
    assert sum(report.ends().values()) == report.episodes
    (process,) = report.processes
    assert process.pid == os.getpid() and process.cells == N_CELLS
    assert process.steps_since_baseline == SHORT_STEPS - report.cells[0].warmup_steps
    assert process.growth_mib is not None and math.isfinite(process.growth_mib)


@pytest.mark.slow
def test_same_seed_gives_the_same_counts(short_soak: SoakReport) -> None:
    # A subset of the cells, with the same share each: the same episodes, whatever the filter.
    share = SHORT_STEPS // N_CELLS
    again = run_soak(2 * share, env_ids=["rehabbot/rehab-knee-v0", "rehab-reach-v0"],
                     control_modes=["torque"], seed=0)
    first = _counts(short_soak)
    assert len(again.cells) == 2
    assert _counts(again) == {name: first[name] for name in _counts(again)}
    other_seed = run_soak(share, env_ids=["rehab-knee-v0"], control_modes=["torque"], seed=1)
    (name, counts), = _counts(other_seed).items()
    assert counts[1:] != first[name][1:]  # other episodes and seeds


@pytest.mark.slow
def test_workers_give_the_same_counts_as_one_process() -> None:
    kwargs = {"total_steps": 600, "env_ids": ["rehab-hip-v0"],
              "control_modes": ["joint_delta", "torque"], "seed": 3}
    serial = run_soak(**kwargs)
    parallel = run_soak(**kwargs, workers=2)
    assert _counts(parallel) == _counts(serial)
    assert parallel.complete and parallel.exit_code() == 0
    assert {cell.pid for cell in parallel.cells} <= {p.pid for p in parallel.processes}
    assert os.getpid() not in {p.pid for p in parallel.processes}
    for process in parallel.processes:
        assert process.growth_mib is not None and math.isfinite(process.growth_mib)


# --------------------------------------------------------------------------- faulty envs


class FaultyEnv(gym.Wrapper):
    """Misbehaves on every ``FAULT_EVERY``-th step call (or once at ``at``), by ``fault``."""

    def __init__(self, env: gym.Env, fault: str, at: int | None = None) -> None:
        super().__init__(env)
        self.fault = fault
        self.at = at
        self.calls = 0

    def step(self, action):
        self.calls += 1
        due = self.calls == self.at if self.at is not None else self.calls % FAULT_EVERY == 0
        if due and self.fault == "raise":
            raise RuntimeError(f"deliberate failure at call {self.calls}")
        if due and self.fault == "interrupt":
            raise KeyboardInterrupt
        if due and self.fault == "sigterm":
            os.kill(os.getpid(), signal.SIGTERM)
        obs, reward, terminated, truncated, info = self.env.step(action)
        if due and self.fault == "nan_obs":
            obs = obs.copy()
            obs[3] = np.nan
        elif due and self.fault == "outside":
            obs = obs.copy()
            obs[9] = self.observation_space.high[9] + 1.0
        elif due and self.fault == "nan_info":
            reward = math.inf
            info = {**info, "interaction_force_n": math.nan,
                    "nested": {"torque": np.array([0.0, -np.inf])}}
        return obs, reward, terminated, truncated, info


FAULT_BY_MODE = {"joint_delta": "nan_obs", "joint_velocity": "outside",
                 "joint_position": "raise", "torque": "nan_info"}


def faulty_env(env_id: str, mode: str) -> gym.Env:
    return FaultyEnv(gym.make(env_id, control_mode=mode), FAULT_BY_MODE[mode])


def test_detectors_count_each_fault_and_the_run_goes_on() -> None:
    steps = 4 * 3 * FAULT_EVERY
    report = run_soak(steps, env_ids=["rehab-reach-v0"], seed=0, make_env=faulty_env)
    cells = {cell.control_mode: cell for cell in report.cells}
    assert report.complete and report.steps == steps
    assert all(cell.status == "complete" and cell.steps == 3 * FAULT_EVERY
               for cell in report.cells)

    nan_obs = cells["joint_delta"]
    assert nan_obs.non_finite == 3 and nan_obs.non_finite_by_field == {"obs": 3}
    assert nan_obs.non_finite_example["fields"] == {"obs": [3]}
    assert nan_obs.non_finite_example["step"] == FAULT_EVERY - 1
    assert len(nan_obs.non_finite_example["action"]) == 6
    assert nan_obs.obs_outside == 3  # NaN is outside the space too
    assert nan_obs.exceptions == 0

    outside = cells["joint_velocity"]
    assert outside.obs_outside == 3 and outside.non_finite == 0
    assert outside.obs_outside_example["indices"] == [9]
    assert outside.obs_outside_example["values"][0] > outside.obs_outside_example["high"][0]
    assert outside.obs_outside_example["step"] == FAULT_EVERY - 1

    raising = cells["joint_position"]
    # Each new env raises on its 100th step call: after 99 steps, then every 99 steps.
    assert raising.exceptions == 3 and raising.exceptions_by_type == {"RuntimeError": 3}
    first = raising.exception_examples[0]
    assert first["type"] == "RuntimeError" and "deliberate failure" in first["message"]
    assert first["source"] == "step" and first["step"] == FAULT_EVERY - 1
    assert len(first["action"]) == 6 and all(math.isfinite(a) for a in first["action"])
    assert [e["env"] for e in raising.exception_examples] == [0, 1, 2]
    assert len(raising.action_seeds) == len(set(raising.action_seeds)) == 4  # rebuilt 3 times
    assert raising.ends["exception"] == 3
    assert sum(raising.ends.values()) == raising.episodes
    assert raising.non_finite == raising.obs_outside == 0

    nan_info = cells["torque"]
    assert nan_info.non_finite_by_field == {"reward": 3, "info.interaction_force_n": 3,
                                            "info.nested.torque": 3}
    assert nan_info.non_finite_example["fields"]["info.nested.torque"] == [1]
    assert nan_info.obs_outside == 0

    assert report.exit_code() == 1


def test_main_exits_1_on_problems_and_prints_the_table(tmp_path: Path, capsys) -> None:
    out = tmp_path / "faulty.json"
    code = main(["--steps", "400", "--env", "rehab-reach-v0", "--quiet", "--out", str(out)],
                make_env=faulty_env)
    assert code == 1
    printed = re.sub(" +", " ", capsys.readouterr().out)  # the table's padding out
    assert "seed 0" in printed and "mujoco" in printed
    assert printed.count("| rehab-reach-v0 |") == 4 and "| **total** |" in printed
    assert "FOUND PROBLEMS" in printed and "RuntimeError" in printed
    data = json.loads(out.read_text())
    assert data["complete"] is True and data["exceptions"] == 1
    assert data["non_finite"] == 1 + 3 and data["obs_outside"] == 2
    # NaN reaches the JSON as a string, keeping it strict JSON.
    json.loads(out.read_text(), parse_constant=lambda name: pytest.fail(f"bare {name}"))


# --------------------------------------------------------------------------- report and CLI


def test_json_report_is_complete_and_written_atomically(tmp_path: Path, capsys,
                                                       monkeypatch) -> None:
    out = tmp_path / "sub" / "soak.json"
    argv = ["--steps", "40", "--env", "rehab-hip-v0", "--mode", "joint_delta", "--mode",
            "torque", "--seed", "7", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    data = json.loads(out.read_text())
    assert data["complete"] is True and data["interrupted_by"] is None
    assert data["seed"] == 7 and data["total_steps"] == data["steps"] == 40
    assert data["env_ids"] == ["rehabbot/rehab-hip-v0"]
    assert data["control_modes"] == ["joint_delta", "torque"]
    assert [cell["steps"] for cell in data["cells"]] == [20, 20]
    assert all(cell["reset_seeds"] and cell["action_seeds"] for cell in data["cells"])
    assert data["versions"]["mujoco"] and data["versions"]["rehabbot"]
    assert "--seed 7" in data["command"]
    assert os.listdir(out.parent) == ["soak.json"]  # no temporary file left
    assert f"wrote {out}" in capsys.readouterr().out

    # A failure while writing leaves the previous report whole and no temporary file.
    previous = out.read_text()

    def failing_fsync(_fd: int) -> None:
        raise OSError("disk full")

    with monkeypatch.context() as patch:
        patch.setattr(os, "fsync", failing_fsync)
        assert main(argv) == 1
    assert out.read_text() == previous
    assert os.listdir(out.parent) == ["soak.json"]
    assert "disk full" in capsys.readouterr().err


@pytest.mark.parametrize(("argv", "named"), [
    (["--steps", "15"], "15"),
    (["--steps", "1", "--env", "rehab-hip-v0", "--mode", "torque", "--mode", "joint_delta"],
     "1"),
    (["--steps", "many"], "many"),
    (["--env", "rehab-elbow-v0"], "rehab-elbow-v0"),
    (["--env", "rehab-hip-v0", "--env", "rehabbot/nope-v0"], "rehabbot/nope-v0"),
    (["--mode", "impedance"], "impedance"),
    (["--workers", "0"], "--workers 0"),
    (["--seed", "-3"], "-3"),
])
def test_bad_arguments_exit_2_with_one_line(argv: list[str], named: str, capsys) -> None:
    assert main([*argv, "--quiet"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert named in lines[0] and "error" in lines[0]
    assert "| **total** |" not in captured.out


def test_keyboard_interrupt_saves_a_partial_report(tmp_path: Path, capsys) -> None:
    def interrupting_env(env_id: str, mode: str) -> gym.Env:
        at = 150 if mode == "joint_velocity" else None
        return FaultyEnv(gym.make(env_id, control_mode=mode), "interrupt" if at else "none",
                         at=at)

    out = tmp_path / "partial.json"
    code = main(["--steps", "1200", "--env", "rehab-reach-v0", "--quiet", "--out", str(out)],
                make_env=interrupting_env)
    assert code == 130
    data = json.loads(out.read_text())
    assert data["complete"] is False and data["interrupted_by"] == "KeyboardInterrupt"
    statuses = {cell["control_mode"]: (cell["status"], cell["steps"]) for cell in data["cells"]}
    assert statuses == {"joint_delta": ("complete", 300), "joint_position": ("complete", 300),
                        "joint_velocity": ("interrupted", 149), "torque": ("not_run", 0)}
    assert data["steps"] == 300 + 300 + 149 and data["total_steps"] == 1200
    for cell in data["cells"]:
        assert sum(cell["ends"].values()) == cell["episodes"]
    assert os.listdir(tmp_path) == ["partial.json"]
    assert "INTERRUPTED by KeyboardInterrupt after 749 of 1200 steps" in capsys.readouterr().out


def test_sigterm_stops_the_run_with_exit_143(tmp_path: Path) -> None:
    def terminating_env(env_id: str, mode: str) -> gym.Env:
        return FaultyEnv(gym.make(env_id, control_mode=mode), "sigterm", at=100)

    out = tmp_path / "term.json"
    previous = signal.getsignal(signal.SIGTERM)
    code = main(["--steps", "2000", "--env", "rehab-reach-v0", "--mode", "joint_delta",
                 "--mode", "torque", "--quiet", "--out", str(out)], make_env=terminating_env)
    assert code == 143
    assert signal.getsignal(signal.SIGTERM) is previous  # the handler is put back
    data = json.loads(out.read_text())
    assert data["complete"] is False and data["interrupted_by"] == "SIGTERM"
    first, second = data["cells"]
    assert first["status"] == "interrupted" and 100 <= first["steps"] < 1000
    assert second["status"] == "not_run" and second["steps"] == 0
    assert data["steps"] == first["steps"]


@pytest.mark.slow
def test_the_script_runs_from_the_repository_root(tmp_path) -> None:
    out = tmp_path / "soak.json"
    result = subprocess.run([sys.executable, "benchmarks/performance/soak.py", "--steps", "40",
                             "--env", "rehab-knee-v0", "--mode", "joint_delta", "--out", str(out),
                             "--quiet"], capture_output=True, text=True, timeout=300,
                            cwd=Path(__file__).resolve().parents[1])
    assert result.returncode == 0, result.stderr
    assert json.loads(out.read_text())["steps"] == 40
