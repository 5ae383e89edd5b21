"""PPO on the batched env (``rehabbot train --backend rsl_rl``): the exported actor is the
trained actor, the run folder is written, evaluated on the CPU env, interrupted and resumed,
and what does not fit is refused by name. Training runs on MuJoCo Warp's CPU device here."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("warp")
torch = pytest.importorskip("torch")
pytest.importorskip("rsl_rl")

from tensordict import TensorDict  # noqa: E402

from rehabbot.cli import main  # noqa: E402
from rehabbot.common.errors import UsageError  # noqa: E402
from rehabbot.rl import batch_training as bt  # noqa: E402
from rehabbot.rl.policies import load_policy  # noqa: E402
from rehabbot.rl.zoo import ZooPolicy, write_zoo_file  # noqa: E402

ENV = "rehabbot/rehab-reach-v2"
WORLDS = 8


def _actor(obs_dim: int, act_dim: int, normalization: bool = True):
    from rsl_rl.models import MLPModel

    obs = TensorDict({"policy": torch.zeros(4, obs_dim)}, batch_size=[4])
    return MLPModel(obs, {"actor": ["policy"]}, "actor", act_dim, hidden_dims=(32, 16),
                    activation="elu", obs_normalization=normalization,
                    distribution_cfg={"class_name":
                                      "rsl_rl.modules.distribution.GaussianDistribution",
                                      "init_std": 0.5})


def _program_actions(ops, obs, low, high, tmp_path: Path) -> np.ndarray:
    space = gym.spaces.Box(-np.inf, np.inf, (obs.shape[1],), np.float32)
    path = tmp_path / "actor.npz"
    write_zoo_file(path, ops, space, gym.spaces.Box(low, high, dtype=np.float32), {})
    return ZooPolicy.from_file(path).predict(obs)[0]


def test_exported_actor_is_the_rsl_rl_actor(tmp_path):
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    actor = _actor(7, 3)
    data = rng.normal(3.0, 4.0, (256, 7)).astype(np.float32)
    actor.update_normalization(TensorDict({"policy": torch.from_numpy(data)}, batch_size=[256]))
    low, high = -np.ones(3, np.float32), np.ones(3, np.float32)
    obs = rng.normal(3.0, 4.0, (64, 7)).astype(np.float32)
    with torch.no_grad():
        mean = actor(TensorDict({"policy": torch.from_numpy(obs)}, batch_size=[64])).numpy()
    exported = _program_actions(bt.actor_program(actor, low, high), obs, low, high, tmp_path)
    assert np.abs(exported - np.clip(mean, low, high)).max() < 1e-5
    assert (np.abs(mean) > 0.2).any()
    low, high = -0.2 * np.ones(3, np.float32), 0.2 * np.ones(3, np.float32)
    exported = _program_actions(bt.actor_program(actor, low, high), obs, low, high, tmp_path)
    assert np.abs(exported - np.clip(mean, low, high)).max() < 1e-5  # clipped to the box
    # Without the normalisation the actions are far off: the comparison can fail.
    bare = [op for op in bt.actor_program(actor, low, high) if op[0] != "normalize"]
    assert np.abs(_program_actions(bare, obs, low, high, tmp_path) - exported).max() > 1e-2


def test_settings_refuse_bad_values():
    with pytest.raises(UsageError, match="unknown rsl_rl PPO settings \\['gama'\\]"):
        bt.RslPpoSettings.from_mapping({"gama": 0.9})
    with pytest.raises(UsageError, match="num_steps_per_env=0"):
        bt.RslPpoSettings.from_mapping({"num_steps_per_env": 0})
    with pytest.raises(UsageError, match="schedule='cosine'"):
        bt.RslPpoSettings.from_mapping({"schedule": "cosine"})
    cfg = bt.RslPpoSettings.from_mapping({"actor_hidden_dims": [64]}).train_cfg()
    assert cfg["actor"]["hidden_dims"] == [64] and cfg["num_steps_per_env"] == 24


@pytest.mark.parametrize(("argv", "named"), [
    (["--algo", "sac"], "trains PPO only, not 'sac'"),
    (["--algo", "ppo", "--demos", "5"], "--demos is not used"),
    (["--algo", "ppo"], "rehab-reach-myo-v2"),
])
def test_cli_refuses_by_name_and_writes_nothing(tmp_path, capsys, argv, named):
    out = tmp_path / "runs"
    code = main(["train", named if named.startswith("rehab-") else "rehab-reach-v2",
                 *argv, "--backend", "rsl_rl", "--num-envs", "2", "--timesteps", "48",
                 "--out", str(out)])
    assert code == 2
    assert named in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_rsl_vec_env_counts_a_stopped_episode():
    from rehabbot.rl.rsl_vec_env import RslVecEnv

    vec = RslVecEnv(ENV, 2, seed=0, env_kwargs={"exercise": 0, "weight_level": 0})
    obs = vec.get_observations()["policy"]
    assert obs.shape == (2, vec.batched.observation_size)
    total, steps = torch.zeros(2), 0
    push = torch.tensor([[1.0] * vec.num_actions, [0.0] * vec.num_actions])
    while not vec.finished.returns and steps < vec.max_episode_length:
        _obs, rewards, _dones, extras = vec.step(push)
        total += rewards
        steps += 1
    tally = vec.finished.take()
    # The pushed world stops on a safety rule; the still one runs on.
    assert tally.stops == [True] and tally.successes == [False]
    assert tally.lengths == [steps]
    assert tally.returns[0] == pytest.approx(float(total[0]), rel=1e-6)
    assert float(extras["time_outs"][0]) == 0.0 and int(vec.episode_length_buf[0]) == 0
    assert int(vec.episode_length_buf[1]) == steps
    assert vec.finished.take().summary()["episodes"] == 0


def _train(out: Path, *extra: str, timesteps: int = 2 * 24 * WORLDS) -> list[str]:
    return [sys.executable, "-m", "rehabbot", "train", "rehab-reach-v2", "--algo", "ppo",
            "--backend", "rsl_rl", "--num-envs", str(WORLDS), "--timesteps", str(timesteps),
            "--out", str(out), *extra]


@pytest.mark.slow
def test_train_interrupt_resume_evaluate_ship(tmp_path, monkeypatch, capsys):
    out = tmp_path / "runs"
    run_dir = out / "rehab-reach-v2" / "ppo" / "seed0"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "error::UserWarning"}
    # Interrupted by SIGINT after its first iteration: a checkpoint, then exit 130.
    proc = subprocess.Popen(_train(out, "--checkpoint-freq", "0", timesteps=10**6),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None
    for line in proc.stdout:
        if "iteration 1:" in line:
            proc.send_signal(signal.SIGINT)
            break
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 130, stderr
    assert "resume with:" in stdout
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["status"] == "interrupted" and manifest["backend"] == "rsl_rl"
    done = manifest["timesteps_done"]
    assert done >= 24 * WORLDS and done % (24 * WORLDS) == 0
    assert (run_dir / manifest["last_checkpoint"]).is_file()
    assert not (run_dir / "policy.npz").exists()
    # A run is there: without --resume or --overwrite it is refused.
    again = subprocess.run(_train(out), capture_output=True, text=True, env=env, timeout=300)
    assert again.returncode == 2 and "--resume" in again.stderr
    # Resumed towards 1M steps with a wall-clock budget half a second past what the run has
    # used: building the worlds takes longer, so it ends, finished, after one more iteration.
    total = done + 24 * WORLDS
    used_s = manifest["wall_clock_s"]
    start = time.monotonic()
    resumed = subprocess.run(_train(out, "--resume", "--time-limit-s", f"{used_s + 0.5}",
                                    timesteps=10**6),
                             capture_output=True, text=True, env=env, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stderr == ""  # quiet: no library's warning or print
    assert "done at the" in resumed.stdout and "s time limit" in resumed.stdout
    assert time.monotonic() - start < 600
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["status"] == "finished" and manifest["timesteps_done"] == total
    assert manifest["stopped_by"] == "time_limit" and manifest["total_timesteps"] == 10**6
    assert manifest["time_limit_s"] == pytest.approx(used_s + 0.5)
    assert manifest["wall_clock_s"] >= used_s + 0.5
    # Its budget spent, it is refused another segment under the same limit, by name.
    assert main(["train", "rehab-reach-v2", "--algo", "ppo", "--backend", "rsl_rl",
                 "--num-envs", str(WORLDS), "--timesteps", str(10**6), "--out", str(out),
                 "--resume", "--time-limit-s", f"{used_s + 0.5}"]) == 2
    assert "has already trained for" in capsys.readouterr().err
    assert [s["start_timesteps"] for s in manifest["segments"]] == [0, done]
    assert manifest["seeds"] == {"jax_worlds": 0, "torch": 0}
    assert manifest["versions"]["rsl-rl-lib"] and manifest["versions"]["warp-lang"]
    with (run_dir / "training_log.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["timesteps"]) for r in rows] == list(range(24 * WORLDS, total + 1,
                                                             24 * WORLDS))
    # The exported actor is the final model's actor, on the CPU env's observations.
    cpu = gym.make(ENV)
    policy = load_policy(str(run_dir), cpu)
    assert policy.kind == "model" and policy.backend == "rsl_rl" and policy.label == "ppo-seed0"
    obs = np.stack([cpu.reset(seed=k)[0] for k in range(4)])
    state = torch.load(run_dir / "model.pt", weights_only=True)
    from rsl_rl.models import MLPModel

    hidden = bt.RslPpoSettings().actor_hidden_dims
    actor = MLPModel(TensorDict({"policy": torch.zeros(1, obs.shape[1])}, batch_size=[1]),
                     {"actor": ["policy"]}, "actor", cpu.action_space.shape[0],
                     hidden_dims=hidden, activation="elu",
                     obs_normalization=bt.RslPpoSettings().obs_normalization,
                     distribution_cfg={"class_name":
                                       "rsl_rl.modules.distribution.GaussianDistribution"})
    actor.load_state_dict(state["actor_state_dict"])
    with torch.no_grad():
        mean = actor(TensorDict({"policy": torch.from_numpy(obs)}, batch_size=[4])).numpy()
    acted = np.stack([policy.act(o) for o in obs])
    assert np.abs(acted - np.clip(mean, -1, 1)).max() < 1e-5
    # rehabbot evaluate runs it on the CPU env.
    assert main(["evaluate", str(run_dir), "--episodes", "1"]) == 0
    assert (run_dir / "evaluation" / "ppo-seed0" / "evaluation.json").is_file()
    # ... and ships it to the zoo, the same actor.
    from rehabbot.rl import zoo

    monkeypatch.setenv("REHABBOT_ZOO_DIR", str(tmp_path / "zoo"))
    assert main(["zoo", "export", str(run_dir), "--episodes", "1"]) == 0
    shipped = zoo.load(ENV, "ppo-rsl_rl")  # beside, not instead of, the CPU-trained ppo
    assert shipped.metadata["backend"] == "rsl_rl" and shipped.metadata["training_steps"] == total
    assert np.array_equal(shipped.predict(obs)[0], policy.policy.predict(obs)[0])
    assert main(["zoo", "export", str(run_dir), "--full", "--out",
                 str(tmp_path / "full.npz")]) == 2


def test_cli_passes_its_options_to_the_plan(tmp_path, monkeypatch, capsys):
    plans = []

    def fake_train(plan, report=None):
        plans.append(plan)
        return plan.run_dir

    monkeypatch.setattr(bt, "train_batched", fake_train)
    settings = tmp_path / "ppo.yml"
    settings.write_text("rehab-reach-v2:\n  num_mini_batches: 8\n  gamma: 0.98\n")
    code = main(["train", "rehab-reach-v2", "--algo", "ppo", "--backend", "rsl_rl",
                 "--num-envs", "64", "--timesteps", "5000", "--seeds", "3", "4",
                 "--env-kwargs", '{"max_episode_steps": 20}', "--hyperparams", str(settings),
                 "--checkpoint-freq", "1000", "--time-limit-s", "600",
                 "--out", str(tmp_path / "runs")])
    assert code == 0
    assert [p.seed for p in plans] == [3, 4]
    plan = plans[0]
    assert plan.env_kwargs == {"max_episode_steps": 20} and plan.num_envs == 64
    assert plan.total_timesteps == 5000 and plan.checkpoint_freq == 1000
    assert plan.time_limit_s == 600.0
    assert plan.settings.num_mini_batches == 8 and plan.settings.gamma == 0.98
    assert plan.settings.num_learning_epochs == bt.RslPpoSettings().num_learning_epochs
    assert "64 worlds" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "named"), [
    (["--backend", "sb3", "--time-limit-s", "60"], "--time-limit-s 60 is used by --backend "
                                                   "rsl_rl only, not --backend sb3"),
    (["--backend", "rsl_rl", "--time-limit-s", "0"], "--time-limit-s: must be a number in "
                                                      "(0, 1e+07], got '0'"),
    (["--backend", "rsl_rl", "--time-limit-s", "nan"], "got 'nan'"),
    (["--backend", "rsl_rl", "--time-limit-s", "ten"], "got 'ten'"),
])
def test_time_limit_is_refused_by_name(tmp_path, capsys, argv, named):
    out = tmp_path / "runs"
    try:
        code = main(["train", "rehab-reach-v2", "--algo", "ppo", "--timesteps", "48",
                     "--out", str(out), *argv])
    except SystemExit as err:  # argparse's refusal
        code = err.code
    assert code == 2
    assert named in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(UsageError, match=r"time_limit_s=-1\.0 must be"):
        bt.BatchRunPlan(ENV, seed=0, total_timesteps=48, out_dir=out, time_limit_s=-1.0)
