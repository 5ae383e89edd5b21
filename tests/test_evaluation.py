"""``rehabbot evaluate`` / ``rehabbot render`` / ``rehabbot list`` / ``rehabbot bench``, the
policy loader, and the paper's Listings 2 and 3."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401
from rehabbot.analysis.evaluation import SUMMARY_METRICS, ensure_trace, evaluate
from rehabbot.analysis.traces import TRACE_KEYS
from rehabbot.cli import main
from rehabbot.rl.policies import PolicyError, detect_algo, load_policy
from rehabbot.sim.physics import RULES
from rehabbot.sim.robots import ur5e as ur

ENV = "rehab-reach-v0"
FULL_ID = "rehabbot/rehab-reach-v0"
REPO = Path(__file__).resolve().parent.parent
KINEMATIC_KEYS = ("peak_joint_speed_rad_s", "rms_joint_acceleration_rad_s2",
                  "peak_joint_acceleration_rad_s2", "peak_joint_jerk_rad_s3", "sparc", "ldlj",
                  "normalized_jerk", "peak_torque_per_joint_nm", "peak_torque_nm")


@pytest.fixture(scope="module")
def expert_report() -> tuple[dict, dict]:
    return evaluate("expert", ENV, episodes=2, seed=0)


@pytest.fixture(scope="module")
def sac_model(tmp_path_factory) -> Path:
    """A tiny SAC model saved by SB3 (300 steps: it acts, it is not trained)."""
    from stable_baselines3 import SAC

    folder = tmp_path_factory.mktemp("sac")
    model = SAC("MlpPolicy", gym.make(FULL_ID), learning_starts=100, buffer_size=1000, seed=0,
                policy_kwargs={"net_arch": [16, 16]})
    model.learn(300)
    model.save(folder / "model")
    return folder / "model.zip"


# --------------------------------------------------------------------------- the report


def test_expert_report_has_every_metric_and_finishes(expert_report) -> None:
    report, _trace = expert_report
    summary = report["summary"]
    for key, _label, _unit in SUMMARY_METRICS:
        assert key in summary, key
    assert summary["success_rate"] == 1.0
    assert set(summary["safety_terminations"]) == set(RULES)
    assert sum(summary["safety_terminations"].values()) == 0
    for episode in report["per_episode"]:
        # The expert finishes a reaching exercise in 300-450 decisions (benchmarks/expert...).
        assert episode["success"] and 300 <= episode["steps_to_finish"] <= 450
        assert episode["steps_to_finish"] == episode["length"]
        assert episode["targets_reached"] == episode["num_targets"] == 6
        for key in KINEMATIC_KEYS:
            assert episode[key] is not None, key
        # Torques stay within the UR5e limits; the cuff force under ISO/TS 15066's 140 N.
        assert np.all(np.array(episode["peak_torque_per_joint_nm"]) <= ur.TORQUE_LIMIT_NM)
        assert 0.0 < episode["peak_cuff_force_n"] < 140.0
        # The expert moves at most pi/400 rad per 20 ms decision: <= 0.393 rad/s, plus the
        # servo's transient overshoot.
        assert 0.2 < episode["peak_joint_speed_rad_s"] < 0.6
        assert episode["sparc"] < -1.0 and episode["ldlj"] < -5.0
    assert report["episode_seeds"] == [0, 1]
    assert report["versions"]["mujoco"] is not None
    json.dumps(report)  # JSON-ready


def test_trace_is_consistent_with_the_report(expert_report) -> None:
    report, trace = expert_report
    assert set(trace) == set(TRACE_KEYS)
    steps = report["per_episode"][0]["length"]
    for key in ("time_s", "robot_qpos_rad", "robot_torque_nm", "tool_pos_m", "target_index",
                "patient_qpos_rad", "interaction_force_n"):
        assert len(trace[key]) == steps + 1, key
    assert trace["target_tool_pos_m"].shape == (6, 3)
    assert trace["target_robot_rad"].shape == (6, 6)
    # The episode ends within tolerance of the last target, in joint space and near it in
    # task space.
    final_error = trace["robot_qpos_rad"][-1] - trace["target_robot_rad"][-1]
    assert np.max(np.abs(final_error)) < 0.05
    assert np.linalg.norm(trace["tool_pos_m"][-1] - trace["target_tool_pos_m"][-1]) < 0.05
    assert np.all(np.diff(trace["target_index"]) >= 0)
    assert float(trace["dt_s"]) == pytest.approx(0.02)
    assert np.max(trace["interaction_force_n"]) == pytest.approx(
        report["per_episode"][0]["peak_cuff_force_n"])


def test_random_policy_is_seeded_and_fails() -> None:
    first, _ = evaluate("random", ENV, episodes=1, seed=3)
    second, _ = evaluate("random", ENV, episodes=1, seed=3)
    other, _ = evaluate("random", ENV, episodes=1, seed=4)
    assert first["per_episode"] == second["per_episode"]
    assert first["per_episode"][0]["return"] != other["per_episode"][0]["return"]
    assert first["summary"]["success_rate"] == 0.0


# --------------------------------------------------------------------------- models


def test_model_is_detected_loaded_and_checked(sac_model: Path) -> None:
    assert detect_algo(sac_model) == "sac"
    env = gym.make(FULL_ID)
    policy = load_policy(sac_model, env)
    obs, _ = env.reset(seed=0)
    action = policy.act(obs)
    assert action.shape == (6,) and env.action_space.contains(action)
    # SB3 style: the path without .zip works too.
    assert load_policy(str(sac_model)[:-4], env).algo == "sac"
    # A model of other spaces is refused with both spaces named.
    other = gym.make("rehabbot/rehab-hip-v0")
    with pytest.raises(PolicyError, match="observation space"):
        load_policy(sac_model, other)


def test_model_of_another_env_is_refused_by_the_cli(tmp_path: Path, capsys) -> None:
    from stable_baselines3 import PPO

    PPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64).save(tmp_path / "pendulum")
    out = tmp_path / "out"
    code = main(["evaluate", str(tmp_path / "pendulum.zip"), "--env", ENV, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1
    assert "does not fit rehabbot/rehab-reach-v0" in err and len(err.strip().splitlines()) == 1
    assert not any(p.is_file() for p in out.rglob("*"))


@pytest.mark.parametrize("content", [b"", b"not a zip", b"PK\x03\x04garbage"])
def test_corrupt_model_gives_one_line_error(tmp_path: Path, capsys, content: bytes) -> None:
    bad = tmp_path / "model.zip"
    bad.write_bytes(content)
    out = tmp_path / "out"
    code = main(["evaluate", str(bad), "--env", ENV, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1
    assert str(bad) in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not any(p.is_file() for p in out.rglob("*"))


def test_missing_model_unknown_env_and_unwritable_out(tmp_path: Path, capsys) -> None:
    assert main(["evaluate", str(tmp_path / "nope.zip"), "--env", ENV,
                 "--out", str(tmp_path / "o")]) == 1
    assert "not found" in capsys.readouterr().err
    assert main(["evaluate", "expert", "--env", "rehab-bogus-v9"]) == 2
    err = capsys.readouterr().err
    assert "rehab-bogus-v9" in err and FULL_ID in err
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["evaluate", "expert", "--env", ENV, "--out", str(blocker)]) == 1
    assert "cannot write" in capsys.readouterr().err
    assert main(["evaluate", "expert", "--env", ENV, "--out", str(blocker / "sub")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert main(["evaluate", "expert"]) == 2
    assert "--env" in capsys.readouterr().err


def test_cli_writes_json_trace_and_comparison(tmp_path: Path, capsys) -> None:
    out = tmp_path / "eval"
    code = main(["evaluate", "expert", "random", "--env", ENV, "--episodes", "1", "--seed",
                 "5", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    for label in ("expert", "random"):
        report = json.loads((out / label / "evaluation.json").read_text())
        assert report["episode_seeds"] == [5]
        with np.load(out / label / "trace.npz") as trace:
            assert set(trace.files) == set(TRACE_KEYS)
    table = (out / "comparison.md").read_text()
    assert "| metric" in table and "expert" in table and "SPARC" in table
    assert "success rate" in printed and "100 %" in printed
    assert not list(out.rglob("*.tmp"))


def _finished_run(tmp_path: Path, sac_model: Path) -> Path:
    """A run folder holding ``sac_model`` as its final model (SAC, seed 7), without a trace."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.zip").write_bytes(sac_model.read_bytes())
    (run / "manifest.json").write_text(json.dumps(
        {"env_id": FULL_ID, "algo": "sac", "seed": 7, "env_kwargs": {}}))
    return run


def test_ensure_trace_evaluates_a_run_once(tmp_path: Path, sac_model: Path) -> None:
    run = _finished_run(tmp_path, sac_model)
    path = ensure_trace(run)
    assert path == run / "evaluation" / "sac-seed7" / "trace.npz"
    with np.load(path) as trace:
        assert int(trace["seed"]) == 7 and str(trace["policy"]) == "sac-seed7"
    stamp = path.stat().st_mtime_ns
    assert ensure_trace(run) == path and path.stat().st_mtime_ns == stamp


def test_ensure_trace_never_writes_into_a_live_run(tmp_path: Path, sac_model: Path) -> None:
    from rehabbot.common.files import FolderLock, FolderLockedError

    run = _finished_run(tmp_path, sac_model)
    lock = FolderLock(run, ".lock").acquire("run folder")  # a live `rehabbot train`
    try:
        with pytest.raises(FolderLockedError, match=f"run folder {run} is being written"):
            ensure_trace(run)
    finally:
        lock.release()
    assert not (run / "evaluation").exists()
    assert ensure_trace(run).is_file()


# --------------------------------------------------------------------------- render


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_render_writes_a_video_of_the_episode(tmp_path: Path, capsys, suffix: str) -> None:
    import imageio.v3 as iio

    out = tmp_path / f"expert{suffix}"
    code = main(["render", "expert", "--env", ENV, "--out", str(out), "--width", "96",
                 "--height", "72", "--frame-every", "25"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    frames = iio.imread(out, index=None)
    # An expert episode lasts 300-450 decisions: 1 reset frame + one per 25 decisions + end.
    assert 13 <= len(frames) <= 20
    assert frames.shape[1:3] == (72, 96)
    assert frames[0].std() > 5  # a picture, not a blank frame
    assert "success" in printed
    assert [p.name for p in tmp_path.iterdir()] == [out.name]  # no temporary file left


def test_render_rejects_bad_suffix(tmp_path: Path, capsys) -> None:
    assert main(["render", "expert", "--env", ENV, "--out", str(tmp_path / "x.avi")]) == 2
    assert ".mp4" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------- list, bench


# --------------------------------------------------------------------------- listings


@pytest.mark.slow
def test_listings_2_and_3_train_save_load_and_evaluate(tmp_path: Path) -> None:
    listing2 = (REPO / "examples" / "listing2_train_sac.py").read_text()
    assert "model.learn(total_timesteps=200_000)" in listing2
    (tmp_path / "listing2.py").write_text(
        listing2.replace("total_timesteps=200_000", "total_timesteps=300"))
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    done = subprocess.run([sys.executable, "listing2.py"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    # SB3 reads ".5" as the suffix, so it appends no ".zip": the file is named as given.
    assert (tmp_path / "SAC-1.5M-R-2.5").is_file()
    assert any((tmp_path / "UR5e_tensorboard").rglob("events.out.tfevents.*"))
    done = subprocess.run([sys.executable, str(REPO / "examples" / "listing3_evaluate_sac.py")],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    line = next(line for line in done.stdout.splitlines() if line.startswith("Mean reward:"))
    mean = float(line.split()[2])
    # An untrained policy's return: below the expert's, above the worst safety penalty.
    assert -20_000 < mean < 100
