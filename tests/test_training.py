"""``rehabbot train`` (:mod:`rehabbot.rl.training`, :mod:`rehabbot.cli.train`): runs,
checkpoints, resume, interruption,
hyperparameter files and user errors. Kept short: 100-step episodes, tiny networks, few
gradient steps. These runs are Stable-Baselines3's (``--backend sb3``; the default, ``auto``,
would pick SBX where it is installed); tests/test_training_backends.py covers SBX."""

from __future__ import annotations

import argparse
import csv
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason='training tests need "rehabbot[train]"')
pytest.importorskip("yaml", reason="hyperparameter files need PyYAML")

from swallowed_signals import swallowed_interrupt

from rehabbot.cli import CliError
from rehabbot.cli.train import add_train_parser, cmd_train
from rehabbot.envs.registration import ENV_SPECS
from rehabbot.rl.hyperparams import (
    HyperparameterError,
    hyperparameters_from_mapping,
    load_hyperparameters,
    parse_python_expression,
)
from rehabbot.rl.training import TrainingInterrupted, train_run

ENV = "rehab-reach-v0"
FULL_ID = "rehabbot/rehab-reach-v0"
V2 = "rehab-reach-v2"  # an id the shipped settings have an entry for
ENV_KWARGS = {"max_episode_steps": 100}
# How long a trainer may take to get somewhere before the test calls it hung: only a hang
# guard, far above what it takes on a loaded machine (ten times an idle machine's time).
HANG_GUARD_S = 600
SMALL = {
    "ppo": {"n_steps": 256, "batch_size": 64, "n_epochs": 2,
            "policy_kwargs": "dict(net_arch=[32, 32], activation_fn=nn.Tanh)"},
    # Few gradient steps: learning starts late.
    "sac": {"learning_starts": 1600, "buffer_size": 5000, "batch_size": 64,
            "policy_kwargs": "dict(net_arch=[32, 32])"},
    "td3": {"learning_starts": 1600, "buffer_size": 5000, "batch_size": 64,
            "policy_kwargs": {"net_arch": [32, 32], "activation_fn": "nn.ReLU"}},
}
MANIFEST_KEYS = ("env_id", "algo", "seed", "total_timesteps", "timesteps_done", "n_envs",
                 "env_kwargs", "hyperparameters", "versions", "git_commit", "command", "status",
                 "started_at", "finished_at", "wall_clock_s", "resumed_from", "model")
VERSION_KEYS = ("python", "rehabbot", "stable_baselines3", "torch", "gymnasium", "mujoco",
                "numpy")


def _algo_class(algo: str):
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]


def _parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="rehabbot")
    add_train_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["train", *argv])


def _yaml(path: Path, data: dict) -> Path:
    import yaml

    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _train_args(tmp_path: Path, algo: str, out: Path, *extra: str, hp: dict | None = None,
                freq: int = 1000) -> argparse.Namespace:
    hp_file = _yaml(tmp_path / f"{algo}.yml", {FULL_ID: hp if hp is not None else SMALL[algo]})
    return _parse(ENV, "--algo", algo, "--hyperparams", str(hp_file), "--out", str(out),
                  "--checkpoint-freq", str(freq), "--eval-freq", str(freq),
                  "--eval-episodes", "1", "--env-kwargs", json.dumps(ENV_KWARGS),
                  "--no-progress", "--backend", "sb3", *extra)


def _manifest(run_dir: Path) -> dict:
    return json.loads((run_dir / "manifest.json").read_text())


def _monitor_rows(run_dir: Path) -> tuple[list[str], list[dict]]:
    path = run_dir / "monitor" / "train_0.monitor.csv"
    lines = path.read_text().splitlines()
    return lines, list(csv.DictReader(lines[1:]))


def _no_temp_files(run_dir: Path) -> bool:
    return not [p for p in run_dir.rglob("*") if p.name.endswith(".tmp")]


# --------------------------------------------------------------------------- full runs


@pytest.mark.parametrize("algo", ["ppo", pytest.param("sac", marks=pytest.mark.slow),
                                  pytest.param("td3", marks=pytest.mark.slow)])
@pytest.mark.slow
def test_train_writes_the_run_directory(tmp_path: Path, algo: str, capsys) -> None:
    out = tmp_path / "runs"
    assert cmd_train(_train_args(tmp_path, algo, out, "--timesteps", "2000")) == 0
    run_dir = out / ENV / algo / "seed0"

    model = _algo_class(algo).load(run_dir / "model.zip", device="cpu")
    env = gym.make(FULL_ID)
    assert model.observation_space == env.observation_space
    assert model.action_space == env.action_space
    assert model.num_timesteps == 2000  # PPO too: its partial last rollout is not trained on

    header, rows = _monitor_rows(run_dir)
    assert header[0].startswith("#")
    assert header[1].split(",") == ["r", "l", "t", "is_success", "safety_violation"]
    assert rows and 0 < sum(int(row["l"]) for row in rows) <= 2000
    assert {row["is_success"] for row in rows} <= {"True", "False"}

    with np.load(run_dir / "eval" / "evaluations.npz") as data:
        assert list(data["timesteps"]) == [1000, 2000]
        assert data["results"].shape == (2, 1)
        assert data["successes"].shape == (2, 1)
    events = list((run_dir / "tb").rglob("events.out.tfevents.*"))
    assert len(events) == 1 and events[0].parent.name == f"{algo.upper()}_1"

    manifest = _manifest(run_dir)
    for key in MANIFEST_KEYS:
        assert key in manifest, key
    assert manifest["env_id"] == FULL_ID and manifest["algo"] == algo
    assert manifest["status"] == "finished"
    assert manifest["total_timesteps"] == manifest["timesteps_done"] == 2000
    assert manifest["env_kwargs"] == ENV_KWARGS
    assert manifest["model"] == "model.zip" and manifest["resumed_from"] is None
    assert manifest["finished_at"] >= manifest["started_at"]
    assert manifest["wall_clock_s"] > 0
    assert set(VERSION_KEYS) <= set(manifest["versions"])
    assert manifest["seeds"] == {"model": 0, "train_env": 0, "eval_env": 10_000}
    hp = manifest["hyperparameters"]
    assert hp["source"] == str(tmp_path / f"{algo}.yml")
    assert hp["kwargs"]["batch_size"] == 64
    assert hp["kwargs"]["policy_kwargs"]["net_arch"] == [32, 32]
    assert hp["kwargs"]["gamma"] == 0.99  # SB3 defaults filled in
    json.dumps(manifest)

    checkpoints = run_dir / "checkpoints"
    assert (checkpoints / "rl_model_1000_steps.zip").is_file()
    assert (checkpoints / "rl_model_2000_steps.zip").is_file()
    if algo != "ppo":  # only the newest replay buffer is kept
        assert (checkpoints / "rl_model_replay_buffer_2000_steps.npz").is_file()
        assert not (checkpoints / "rl_model_replay_buffer_1000_steps.npz").exists()
    assert _no_temp_files(run_dir)
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-1].startswith(f"{run_dir}: 2000 steps")
    assert "last eval at 2000 steps: success" in lines[-1] and "mean return" in lines[-1]


@pytest.mark.slow
def test_resume_continues_to_the_requested_total(tmp_path: Path, capsys) -> None:
    out = tmp_path / "runs"
    hp = {**SMALL["td3"], "normalize": True, "noise_type": "normal", "noise_std": 0.2,
          "learning_starts": 800}
    assert cmd_train(_train_args(tmp_path, "td3", out, "--timesteps", "1000", hp=hp,
                                 freq=500)) == 0
    run_dir = out / ENV / "td3" / "seed0"
    first = _manifest(run_dir)
    lines_before, rows_before = _monitor_rows(run_dir)
    assert (run_dir / "vecnormalize.json").is_file()

    assert cmd_train(_train_args(tmp_path, "td3", out, "--timesteps", "2000", "--resume",
                                 hp=hp, freq=500)) == 0
    model = _algo_class("td3").load(run_dir / "model.zip", device="cpu")
    assert model.num_timesteps == 2000
    manifest = _manifest(run_dir)
    assert manifest["status"] == "finished" and manifest["timesteps_done"] == 2000
    assert manifest["total_timesteps"] == 2000
    assert manifest["resumed_from"] == "checkpoints/rl_model_1000_steps.zip"
    assert manifest["started_at"] == first["started_at"]
    assert manifest["wall_clock_s"] > first["wall_clock_s"]
    assert [s["start_timesteps"] for s in manifest["segments"]] == [0, 1000]
    assert manifest["hyperparameters"]["noise_type"] == "normal"

    lines_after, rows_after = _monitor_rows(run_dir)
    assert lines_after[:len(lines_before)] == lines_before  # rows kept, then appended
    assert len(rows_after) > len(rows_before)
    assert sum(line.startswith("#") for line in lines_after) == 1
    times = [float(row["t"]) for row in rows_after]
    assert times == sorted(times)
    with np.load(run_dir / "eval" / "evaluations.npz") as data:
        assert list(data["timesteps"]) == [500, 1000, 1500, 2000]
    tb_runs = [p for p in (run_dir / "tb").iterdir() if p.is_dir()]
    assert [p.name for p in tb_runs] == ["TD3_1"]
    assert len(list(tb_runs[0].glob("events.out.tfevents.*"))) == 2
    assert (run_dir / "checkpoints" / "rl_model_vecnormalize_2000_steps.json").is_file()

    capsys.readouterr()
    assert cmd_train(_train_args(tmp_path, "td3", out, "--resume", hp=hp, freq=500)) == 0
    assert "already finished 2000 steps" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.parametrize("damaged", ["checkpoint", "replay_buffer", "manifest"])
def test_resume_from_a_damaged_file_is_refused_and_changes_nothing(tmp_path: Path,
                                                                   damaged: str) -> None:
    out = tmp_path / "runs"
    hp = {**SMALL["sac"], "learning_starts": 200}
    assert cmd_train(_train_args(tmp_path, "sac", out, "--timesteps", "500", hp=hp,
                                 freq=500)) == 0
    run_dir = out / ENV / "sac" / "seed0"
    checkpoints = run_dir / "checkpoints"
    target = {"checkpoint": checkpoints / "rl_model_500_steps.zip",
              "replay_buffer": checkpoints / "rl_model_replay_buffer_500_steps.npz",
              "manifest": run_dir / "manifest.json"}[damaged]
    target.write_bytes(target.read_bytes()[: len(target.read_bytes()) // 2])  # torn write
    before = {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()}
    err = _cli_error(_train_args(tmp_path, "sac", out, "--timesteps", "1000", "--resume",
                                 hp=hp, freq=500))
    assert str(target) in str(err) and err.exit_code == 1
    assert "\n" not in str(err)
    after = {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()}
    assert after == before, "a refused resume leaves the run as it was"


@pytest.mark.slow
def test_sigint_saves_a_checkpoint_that_resumes(tmp_path: Path, capsys) -> None:
    out = tmp_path / "runs"
    hp_file = _yaml(tmp_path / "sac.yml", {**SMALL["sac"], "learning_starts": 999_999})
    argv = [ENV, "--algo", "sac", "--timesteps", "1000000", "--hyperparams", str(hp_file),
            "--out", str(out), "--checkpoint-freq", "500", "--eval-freq", "0",
            "--env-kwargs", json.dumps(ENV_KWARGS), "--no-progress", "--backend", "sb3"]
    run_dir = out / ENV / "sac" / "seed0"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.Popen([sys.executable, "-m", "rehabbot", "train", *argv], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + HANG_GUARD_S
        while not (run_dir / "checkpoints" / "rl_model_500_steps.zip").exists():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, f"no checkpoint within {HANG_GUARD_S} s"
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    resume_line = stdout.strip().splitlines()[-1]
    assert "interrupted at" in resume_line
    assert f"rehabbot train {ENV} --algo sac --timesteps 1000000 --seeds 0 --out" in resume_line
    assert resume_line.endswith("--resume")

    manifest = _manifest(run_dir)
    done = manifest["timesteps_done"]
    assert manifest["status"] == "interrupted" and done >= 500
    checkpoint = run_dir / manifest["last_checkpoint"]
    assert checkpoint.name == f"rl_model_{done}_steps.zip"
    model = _algo_class("sac").load(checkpoint, device="cpu")
    assert model.num_timesteps == done
    with np.load(run_dir / "checkpoints" / f"rl_model_replay_buffer_{done}_steps.npz") as buffer:
        # Only what was collected is saved (SB3 stops before storing the last transition).
        assert int(buffer["pos"]) in (done - 1, done) and not bool(buffer["full"])
        assert buffer["observations"].shape == (int(buffer["pos"]), 1, 23)
    assert not (run_dir / "model.zip").exists()
    assert _no_temp_files(run_dir)

    target = (done // 500 + 1) * 500 + 100
    assert cmd_train(_parse(*argv[:4], str(target), *argv[5:], "--resume")) == 0
    manifest = _manifest(run_dir)
    assert manifest["status"] == "finished" and manifest["timesteps_done"] == target
    # Periodic checkpoints stay on multiples of --checkpoint-freq after the resume.
    assert (run_dir / "checkpoints" / f"rl_model_{target - 100}_steps.zip").is_file()
    assert manifest["resumed_from"] == f"checkpoints/rl_model_{done}_steps.zip"
    assert _algo_class("sac").load(run_dir / "model.zip").num_timesteps == target


@pytest.mark.slow
def test_resume_after_a_hard_kill_drops_logs_past_the_checkpoint(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    hp_file = _yaml(tmp_path / "sac.yml", {**SMALL["sac"], "learning_starts": 999_999})
    argv = [ENV, "--algo", "sac", "--timesteps", "1000000", "--hyperparams", str(hp_file),
            "--out", str(out), "--checkpoint-freq", "1000", "--eval-freq", "500",
            "--eval-episodes", "1", "--env-kwargs", json.dumps(ENV_KWARGS), "--no-progress",
            "--backend", "sb3"]
    run_dir = out / ENV / "sac" / "seed0"
    proc = subprocess.Popen([sys.executable, "-m", "rehabbot", "train", *argv], cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + HANG_GUARD_S
        while True:  # SIGKILL once a checkpoint exists and episodes were logged after it
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, f"no checkpoint within {HANG_GUARD_S} s"
            if (run_dir / "checkpoints" / "rl_model_1000_steps.zip").exists() and \
                    sum(int(row["l"]) for row in _monitor_rows(run_dir)[1]) >= 1300:
                break
            time.sleep(0.02)
    finally:
        proc.kill()
        proc.wait(timeout=60)
    assert _manifest(run_dir)["status"] == "running"
    done = max(int(p.name.split("_")[2]) for p in (run_dir / "checkpoints").glob("rl_model_*"
                                                                                 "_steps.zip"))
    _, rows_before = _monitor_rows(run_dir)
    kept = np.searchsorted(np.cumsum([int(row["l"]) for row in rows_before]), done, "right")
    assert kept < len(rows_before)  # some episodes were logged after the checkpoint

    assert cmd_train(_parse(*argv[:4], str(done + 500), *argv[5:], "--resume")) == 0
    _, rows_after = _monitor_rows(run_dir)
    assert rows_after[:kept] == rows_before[:kept]
    assert sum(int(row["l"]) for row in rows_after[kept:]) <= 500  # new episodes only
    with np.load(run_dir / "eval" / "evaluations.npz") as data:
        steps = list(data["timesteps"])
    assert steps == list(range(500, done + 501, 500))  # none lost, none duplicated
    manifest = _manifest(run_dir)
    assert manifest["status"] == "finished" and manifest["timesteps_done"] == done + 500
    assert [s["status"] for s in manifest["segments"]] == ["killed", "finished"]


def test_a_ctrl_c_while_planning_is_not_lost(tmp_path: Path, monkeypatch,
                                             python_sigint_handler) -> None:
    from rehabbot.rl import training

    real = training.as_hyperparameters

    def importing_the_library(*args, **kwargs):
        swallowed_interrupt()
        return real(*args, **kwargs)

    monkeypatch.setattr(training, "as_hyperparameters", importing_the_library)
    before = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        train_run(ENV, "td3", 0, 1_000_000, tmp_path / "runs", env_kwargs=ENV_KWARGS,
                  eval_freq=0, progress_bar=False, backend="sb3",
                  hyperparams={**SMALL["td3"], "learning_starts": 999_999})
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == before
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").rglob("*.zip"))


def test_a_ctrl_c_while_setting_up_stops_before_learning_and_leaves_nothing(
        tmp_path: Path, monkeypatch, python_sigint_handler) -> None:
    from rehabbot.rl import training

    real = training._setup
    learned = []

    def setting_up(*args, **kwargs):
        model, *rest = real(*args, **kwargs)
        swallowed_interrupt()
        monkeypatch.setattr(model, "learn", lambda *a, **k: learned.append(True))
        return (model, *rest)

    monkeypatch.setattr(training, "_setup", setting_up)
    out = tmp_path / "runs"
    with pytest.raises(KeyboardInterrupt):
        train_run(ENV, "td3", 0, 1_000_000, out, env_kwargs=ENV_KWARGS, eval_freq=0,
                  progress_bar=False, backend="sb3",
                  hyperparams={**SMALL["td3"], "learning_starts": 999_999})
    assert learned == []
    assert not (out / ENV / "td3" / "seed0").exists()  # a new run leaves nothing behind


def test_a_ctrl_c_while_finishing_comes_out_after_the_run_is_whole(
        tmp_path: Path, monkeypatch, python_sigint_handler) -> None:
    from rehabbot.rl import training

    real = training.atomic_write

    def saving(path, *args, **kwargs):
        if Path(path).name == "model.zip":  # the final save, after the last step
            swallowed_interrupt()
        return real(path, *args, **kwargs)

    monkeypatch.setattr(training, "atomic_write", saving)
    out = tmp_path / "runs"
    with pytest.raises(KeyboardInterrupt):
        train_run(ENV, "td3", 0, 200, out, env_kwargs=ENV_KWARGS, eval_freq=0,
                  progress_bar=False, backend="sb3",
                  hyperparams={**SMALL["td3"], "learning_starts": 100})
    run_dir = out / ENV / "td3" / "seed0"
    assert _manifest(run_dir)["status"] == "finished" and (run_dir / "model.zip").is_file()


def test_sigterm_in_process_stops_and_restores_the_handlers(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    run_dir = out / ENV / "td3" / "seed0"
    before = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)

    def kill_after_first_checkpoint() -> None:
        deadline = time.monotonic() + HANG_GUARD_S
        while time.monotonic() < deadline:
            if (run_dir / "checkpoints" / "rl_model_300_steps.zip").exists():
                os.kill(os.getpid(), signal.SIGTERM)
                return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_after_first_checkpoint, daemon=True)
    killer.start()
    with pytest.raises(TrainingInterrupted) as caught:
        train_run(ENV, "td3", 0, 1_000_000, out, env_kwargs=ENV_KWARGS, checkpoint_freq=300,
                  eval_freq=0, progress_bar=False, backend="sb3",
                  hyperparams={**SMALL["td3"], "learning_starts": 999_999})
    killer.join()
    assert caught.value.exit_code == 143
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == before
    manifest = _manifest(run_dir)
    assert manifest["status"] == "interrupted"
    assert manifest["timesteps_done"] == caught.value.timesteps_done >= 300
    assert caught.value.checkpoint.is_file()


# --------------------------------------------------------------------------- hyperparameters


def test_zoo_strings_are_parsed_safely() -> None:
    import torch

    parsed = parse_python_expression(
        "dict(net_arch=dict(pi=[64, 64], vf=[128]), activation_fn=nn.ReLU, log_std_init=-2, "
        "ortho_init=False, optimizer_kwargs={'eps': 1e-5}, sizes=(1, 2))")
    assert parsed == {"net_arch": {"pi": [64, 64], "vf": [128]},
                      "activation_fn": torch.nn.ReLU, "log_std_init": -2, "ortho_init": False,
                      "optimizer_kwargs": {"eps": 1e-5}, "sizes": (1, 2)}
    assert parse_python_expression("dict(activation_fn=nn.LeakyReLU)")["activation_fn"] \
        is torch.nn.LeakyReLU
    for bad in ("__import__('os').system('echo pwned')", "dict(**kwargs)",
                "dict(activation_fn=nn.Module)", "open('/etc/passwd')", "[x for x in 'ab']",
                "lambda: 0", "dict(a=1 + 2)", "os.system"):
        with pytest.raises(ValueError, match=r"not allowed|not a valid"):
            parse_python_expression(bad)


def test_policy_kwargs_string_with_code_is_rejected(tmp_path: Path) -> None:
    path = _yaml(tmp_path / "hp.yml", {"policy_kwargs": "__import__('os').system('touch x')"})
    with pytest.raises(HyperparameterError, match=r"policy_kwargs.*not allowed"):
        load_hyperparameters(path, ENV, "sac")
    assert not (tmp_path / "x").exists()


def test_linear_schedule_and_numbers_from_strings() -> None:
    hp = hyperparameters_from_mapping({"learning_rate": "lin_3e-4", "buffer_size": "1e4",
                                       "tau": "5e-3", "train_freq": [1, "episode"]}, "sac")
    schedule = hp.kwargs["learning_rate"]
    assert schedule(1.0) == pytest.approx(3e-4)
    assert schedule(0.5) == pytest.approx(1.5e-4)
    assert schedule(0.0) == pytest.approx(0.0)
    assert hp.kwargs["buffer_size"] == 10_000 and isinstance(hp.kwargs["buffer_size"], int)
    assert hp.kwargs["tau"] == pytest.approx(5e-3)
    assert hp.kwargs["train_freq"] == (1, "episode")
    assert hp.to_manifest()["kwargs"]["learning_rate"] == "lin_3e-4"
    with pytest.raises(HyperparameterError, match="lin_"):
        hyperparameters_from_mapping({"learning_rate": "lin_fast"}, "sac")


def test_unknown_key_is_named(tmp_path: Path) -> None:
    path = _yaml(tmp_path / "hp.yml", {FULL_ID: {"n_stepz": 5}})
    with pytest.raises(HyperparameterError, match=r"unknown hyperparameter 'n_stepz' for PPO"):
        load_hyperparameters(path, ENV, "ppo")
    with pytest.raises(HyperparameterError, match=r"'policy_delay' for SAC"):
        hyperparameters_from_mapping({"policy_delay": 2}, "sac")
    with pytest.raises(HyperparameterError, match=r"'seed'.*--seeds"):
        hyperparameters_from_mapping({"seed": 3}, "td3")
    with pytest.raises(HyperparameterError, match="noise_type applies to SAC and TD3"):
        hyperparameters_from_mapping({"noise_type": "normal"}, "ppo")
    with pytest.raises(HyperparameterError, match="unknown normalize key 'norm_everything'"):
        hyperparameters_from_mapping({"normalize": {"norm_everything": True}}, "ppo")


def test_env_keyed_and_flat_files(tmp_path: Path) -> None:
    keyed = _yaml(tmp_path / "keyed.yml", {
        FULL_ID: {"batch_size": 32, "n_timesteps": 5000},
        "rehab-knee-v0": {"batch_size": 128, "normalize": "dict(norm_reward=False)"},
    })
    hp = load_hyperparameters(keyed, ENV, "sac")
    assert hp.kwargs == {"batch_size": 32} and hp.n_timesteps == 5000
    assert hp.entry == FULL_ID
    knee = load_hyperparameters(keyed, "rehabbot/rehab-knee-v0", "sac")
    assert knee.kwargs == {"batch_size": 128} and knee.normalize == {"norm_reward": False}
    assert knee.entry == "rehab-knee-v0"
    with pytest.raises(HyperparameterError, match="no entry for rehabbot/rehab-hip-v0"):
        load_hyperparameters(keyed, "rehab-hip-v0", "sac")

    flat = _yaml(tmp_path / "flat.yml", {"batch_size": 16, "n_envs": 2, "normalize": True,
                                         "noise_type": "ornstein-uhlenbeck"})
    hp = load_hyperparameters(flat, "rehab-hip-v0", "td3")
    assert hp.kwargs == {"batch_size": 16} and hp.n_envs == 2 and hp.normalize == {}
    assert (hp.noise_type, hp.noise_std) == ("ornstein-uhlenbeck", 0.1)
    assert hp.entry is None


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_shipped_files_spell_out_the_sb3_defaults(algo: str) -> None:
    import inspect

    cls = _algo_class(algo)
    defaults = inspect.signature(cls.__init__).parameters
    env = gym.make(FULL_ID)
    for env_id in ENV_SPECS:
        path = f"sb3-defaults/{algo}"  # shipped with the package
        hp = load_hyperparameters(path, env_id, algo)
        assert hp.entry == env_id and hp.policy == "MlpPolicy" and hp.normalize is None
        assert hp.n_timesteps == 200_000 and hp.n_envs == 1
        for key, value in hp.kwargs.items():
            if key != "policy_kwargs":
                assert value == defaults[key].default, (env_id, key)
    explicit = cls("MlpPolicy", env, policy_kwargs=hp.kwargs["policy_kwargs"], device="cpu",
                   buffer_size=10) if algo != "ppo" else \
        cls("MlpPolicy", env, policy_kwargs=hp.kwargs["policy_kwargs"], device="cpu")
    default = cls("MlpPolicy", env, device="cpu", buffer_size=10) if algo != "ppo" else \
        cls("MlpPolicy", env, device="cpu")
    assert str(explicit.policy) == str(default.policy)


# --------------------------------------------------------------------------- user errors


def _cli_error(args: argparse.Namespace) -> CliError:
    with pytest.raises(CliError) as caught:
        cmd_train(args)
    return caught.value


def test_user_errors_name_the_bad_value(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    err = _cli_error(_parse(ENV, "--algo", "dqn", "--out", str(out)))
    assert "'dqn'" in str(err) and "ppo, sac, td3" in str(err) and err.exit_code == 2
    err = _cli_error(_parse("rehab-elbow-v9", "--algo", "sac", "--out", str(out)))
    assert "'rehab-elbow-v9'" in str(err) and FULL_ID in str(err) and err.exit_code == 2
    err = _cli_error(_parse(ENV, "--algo", "sac", "--hyperparams", str(tmp_path / "no.yml"),
                            "--out", str(out)))
    assert "no.yml" in str(err) and "not found" in str(err) and err.exit_code == 2
    bad_yaml = tmp_path / "bad.yml"
    bad_yaml.write_text("batch_size: [1, 2\n")
    err = _cli_error(_parse(ENV, "--algo", "sac", "--hyperparams", str(bad_yaml),
                            "--out", str(out)))
    assert "not valid YAML" in str(err)
    unknown = _yaml(tmp_path / "unknown.yml", {"gamma": 0.9, "bogus_rate": 1})
    err = _cli_error(_parse(ENV, "--algo", "td3", "--hyperparams", str(unknown),
                            "--out", str(out)))
    assert "'bogus_rate'" in str(err) and "TD3" in str(err)
    blocker = tmp_path / "file"
    blocker.write_text("")
    err = _cli_error(_parse(V2, "--algo", "sac", "--out", str(blocker / "runs")))
    assert str(blocker / "runs") in str(err) and "is not a folder" in str(err)
    assert err.exit_code == 2
    err = _cli_error(_parse(V2, "--algo", "sac", "--out", str(tmp_path / "no" / "runs")))
    assert "does not exist" in str(err) and err.exit_code == 2
    assert not (tmp_path / "no").exists()
    err = _cli_error(_parse(V2, "--algo", "sac", "--out", str(out), "--env-kwargs", "{oops"))
    assert "--env-kwargs" in str(err)
    err = _cli_error(_parse(V2, "--algo", "sac", "--out", str(out),
                            "--env-kwargs", '{"bogus_kwarg": 1}'))
    assert "bogus_kwarg" in str(err)
    err = _cli_error(_parse(ENV, "--algo", "sac", "--out", str(out), "--resume"))
    assert "nothing to resume" in str(err)
    # Errors found before training leave nothing behind, including SB3's own checks.
    err = _cli_error(_train_args(tmp_path, "ppo", out, hp={"batch_size": 1}))
    assert "invalid hyperparameters for PPO" in str(err) and err.exit_code == 2
    assert not out.exists()


def test_existing_runs_need_resume_or_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    run_dir = out / ENV / "sac" / "seed0"
    (run_dir / "checkpoints").mkdir(parents=True)
    (run_dir / "checkpoints" / "rl_model_500_steps.zip").write_bytes(b"")
    (run_dir / "manifest.json").write_text(json.dumps(
        {"env_id": FULL_ID, "algo": "td3", "seed": 0, "status": "interrupted",
         "timesteps_done": 500, "total_timesteps": 1000, "n_envs": 1, "env_kwargs": {}}))
    err = _cli_error(_parse(ENV, "--algo", "sac", "--out", str(out), "--hyperparams",
                            "sb3-defaults/sac"))
    assert "--resume" in str(err) and "--overwrite" in str(err)
    err = _cli_error(_parse(ENV, "--algo", "sac", "--out", str(out), "--resume"))
    assert "algo 'td3'" in str(err) and err.exit_code == 2
    err = _cli_error(_parse(ENV, "--algo", "sac", "--out", str(out), "--resume",
                            "--overwrite"))
    assert "exclude" in str(err)
    assert (run_dir / "checkpoints" / "rl_model_500_steps.zip").exists()


def test_parser_defaults_short_ids_and_help() -> None:
    args = _parse(ENV, "--algo", "SAC")
    assert (args.timesteps, args.seeds, args.n_envs, args.out, args.resume) == \
        (None, None, None, None, False)  # --out: runs, created with its parents
    assert args.func is cmd_train
    assert _parse(FULL_ID, "--algo", "ppo", "--timesteps", "2e5").timesteps == 200_000
    assert _parse(ENV, "--algo", "td3", "--seeds", "0", "1", "2").seeds == [0, 1, 2]
    parser = argparse.ArgumentParser(prog="rehabbot")
    commands = parser.add_subparsers()
    add_train_parser(commands)
    text = commands.choices["train"].format_help()
    for needle in ("examples:", "--resume", "--hyperparams", "--checkpoint-freq",
                   "--eval-episodes", "--env-kwargs", "--no-progress", "rehabbot list"):
        assert needle in text, needle


def test_module_import_is_cheap() -> None:
    code = ("import sys, rehabbot.rl.training, rehabbot.cli.train; "
            "print(sorted(m for m in ('torch', 'stable_baselines3', 'yaml') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, timeout=60)
    assert result.stdout.strip() == "[]"


# --------------------------------------------------------------------------- too-short runs


@pytest.mark.parametrize(("algo", "timesteps", "hp", "words"), [
    ("ppo", 64, {}, "shorter than one ppo rollout (n_steps=2048 x 1 env = 2048 steps)"),
    ("ppo", 2000, {"n_steps": 256, "n_envs": 8},
     "(n_steps=256 x 8 envs = 2048 steps): the model would never update"),
    ("sac", 100, {}, "total_timesteps=100 ends before learning_starts=100"),
    ("td3", 500, {"learning_starts": 500}, "ends before learning_starts=500"),
])
def test_a_run_too_short_to_update_is_refused_before_anything_is_written(
        tmp_path: Path, algo: str, timesteps: int, hp: dict, words: str) -> None:
    """PPO shorter than one rollout, or an off-policy run that ends before learning_starts,
    would exit 0 with an untrained model: refused by name, nothing written."""
    out = tmp_path / "runs"
    with pytest.raises(CliError) as caught:
        cmd_train(_parse(FULL_ID, "--algo", algo, "--timesteps", str(timesteps), "--hyperparams",
                         str(_yaml(tmp_path / "hp.yml", hp)), "--out", str(out)))
    assert words in str(caught.value) and caught.value.exit_code == 2
    assert not out.exists()


def test_one_update_is_enough_to_run() -> None:
    from rehabbot.rl.hyperparams import as_hyperparameters
    from rehabbot.rl.planning import check_run_updates

    check_run_updates("ppo", 2048, 1, as_hyperparameters({}, FULL_ID, "ppo"))
    check_run_updates("sac", 101, 1, as_hyperparameters({}, FULL_ID, "sac"))


@pytest.mark.slow
def test_train_without_hyperparams_uses_the_shipped_file_and_says_so(tmp_path: Path,
                                                                      capsys) -> None:
    """``rehabbot train ID --algo A`` trains with the shipped settings of that id and algorithm
    (not the library's defaults, which learn nothing on RehabBot) and prints which."""
    from rehabbot.rl.training import plan_seeds

    out = tmp_path / "runs"
    plan = plan_seeds("rehab-knee-v2", "ppo", [0], None, out, hyperparams="ppo")[0]
    assert plan.hp.entry == "rehabbot/rehab-knee-v2" and plan.hp.policy == "MlpPolicy"
    assert plan.n_envs == 8 and plan.total_timesteps == 1_000_000
    # The shipped rollout (8 envs x 256 steps), not the library's 2048 x 1, is the one refused.
    assert "rollout (n_steps=256 x 8 envs = 2048 steps)" in str(_cli_error(_parse(
        "rehab-knee-v2", "--algo", "ppo", "--timesteps", "64", "--out", str(out))))
    capsys.readouterr()
    assert cmd_train(_parse("rehab-reach-v2", "--algo", "ppo", "--timesteps", "2048",
                            "--out", str(out), "--eval-freq", "0", "--checkpoint-freq", "0",
                            "--no-progress")) == 0
    err = capsys.readouterr().err
    assert "settings: the shipped 'ppo' file, entry 'rehabbot/rehab-reach-v2'" in err
    assert "sb3-defaults/ppo trains with the library's defaults" in err
    manifest = _manifest(out / "rehab-reach-v2" / "ppo" / "seed0")
    assert manifest["hyperparameters"]["policy"] == "MlpPolicy"


@pytest.mark.slow
def test_shipped_off_policy_settings_start_with_the_expert_episodes_they_were_validated_with(
        tmp_path: Path, capsys) -> None:
    """Without --hyperparams an off-policy run puts the scripted expert's episodes in its
    replay buffer (as the published -v2 results did) and says so; --demos 0 trains without,
    and a settings file given by name gets none unless asked."""
    out = tmp_path / "runs"
    common = ("--timesteps", "104", "--eval-freq", "0", "--checkpoint-freq", "0",
              "--no-progress", "--backend", "sb3")
    assert cmd_train(_parse("rehab-reach-v2", "--algo", "td3", "--out", str(out),
                            *common)) == 0
    assert "with 20 scripted-expert episodes in the replay buffer (--demos 0: none)" in \
        capsys.readouterr().err
    assert _manifest(out / "rehab-reach-v2" / "td3" / "seed0")["demos"]["episodes"] == 20
    for extra in (("--demos", "0"), ("--hyperparams", "td3")):
        assert cmd_train(_parse("rehab-reach-v2", "--algo", "td3", "--out", str(out),
                                "--overwrite", *extra, *common)) == 0
        assert "scripted-expert" not in capsys.readouterr().err
        manifest = _manifest(out / "rehab-reach-v2" / "td3" / "seed0")
        assert not (manifest.get("demos") or {}).get("episodes")


@pytest.mark.parametrize(("env_id", "algo", "words"), [
    ("rehab-reach-v1", "sac",
     "the shipped 'sac' settings have no entry for rehabbot/rehab-reach-v1: it observes the "
     "paper's 23 fields, from which a plain network does not learn (0 % in every "
     "configuration tried); train rehabbot/rehab-reach-v2 (the same task and reward with the "
     "agent observation), or pass --hyperparams sb3-defaults/sac to train this id with the "
     "library's defaults"),
    ("rehab-bilateral-v1", "ppo", "it observes the paper's 44 fields of both arms"),
    ("rehab-knee-weak-v1", "td3", "train rehabbot/rehab-knee-weak-v2 (the same task"),
    ("rehab-hip-v0", "tqc", "rehabbot/rehab-hip-v0: it is the paper's reference"),
    ("rehab-knee-v0", "crossq", "train rehabbot/rehab-knee-v2 (the same task with the "
                                "learnable -v1 reward and the agent observation)"),
])
def test_train_without_hyperparams_refuses_the_paper_observation_ids(
        tmp_path: Path, env_id: str, algo: str, words: str) -> None:
    """The shipped settings name only library options, which learn nothing from the paper's
    observation: a -v0 or -v1 id without --hyperparams is refused (exit 2) with the -v2 id to
    train instead, and sb3-defaults/<algo> still trains it."""
    out = tmp_path / "runs"
    err = _cli_error(_parse(env_id, "--algo", algo, "--out", str(out)))
    assert words in str(err) and err.exit_code == 2 and "\n" not in str(err)
    assert not out.exists()
    if algo in ("sac", "td3", "ppo"):
        from rehabbot.rl.training import plan_seeds

        plan = plan_seeds(env_id, algo, [0], None, out, hyperparams=f"sb3-defaults/{algo}")[0]
        assert plan.hp.entry == f"rehabbot/{env_id}" and plan.hp.policy == "MlpPolicy"


@pytest.mark.slow
def test_threads_train_the_same_model_as_dummy(tmp_path: Path) -> None:
    """``--vec threads`` (the CPU vector env) changes the wall clock only: the same episodes
    in the same monitor files and the same weights as ``--vec dummy``; a resumed run appends
    to its monitor files."""
    import torch

    runs = {}
    for vec in ("dummy", "threads"):
        out = tmp_path / vec
        assert cmd_train(_train_args(tmp_path, "ppo", out, "--timesteps", "1024", "--n-envs",
                                     "2", "--vec", vec, freq=512)) == 0
        runs[vec] = out / ENV / "ppo" / "seed0"
    for i in range(2):
        rows = {}
        for vec, run_dir in runs.items():
            lines = (run_dir / "monitor" / f"train_{i}.monitor.csv").read_text().splitlines()
            rows[vec] = [{k: v for k, v in row.items() if k != "t"}
                         for row in csv.DictReader(lines[1:])]
        assert rows["threads"] == rows["dummy"] and len(rows["dummy"]) >= 5
    weights = {vec: _algo_class("ppo").load(run_dir / "model.zip", device="cpu").policy
               for vec, run_dir in runs.items()}
    for a, b in zip(weights["dummy"].parameters(), weights["threads"].parameters(),
                    strict=True):
        assert torch.equal(a, b)
    assert _manifest(runs["threads"])["vec_env"] == "threads"

    _lines, before = _monitor_rows(runs["threads"])
    assert cmd_train(_train_args(tmp_path, "ppo", tmp_path / "threads", "--timesteps", "1536",
                                 "--n-envs", "2", "--vec", "threads", "--resume",
                                 freq=512)) == 0
    _lines, after = _monitor_rows(runs["threads"])
    assert after[:len(before)] == before and len(after) > len(before)
