"""Training backends (:mod:`rehabbot.rl.backends`: SBX or Stable-Baselines3), the settings
translated for SBX (:mod:`rehabbot.rl.sbx_settings`), and learning from the scripted expert
(:mod:`rehabbot.rl.demonstrations`: ``--demos`` into the replay buffer, ``--bc`` for PPO).
Tests that need SBX skip without ``sbx-rl``/``jax``; SBX's first updates of a model compile
for seconds, so its runs are marked slow."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason='training tests need "rehabbot[train]"')
pytest.importorskip("yaml", reason="hyperparameter files need PyYAML")

from rehabbot.cli import CliError, main
from rehabbot.cli.train import add_train_parser, cmd_train
from rehabbot.rl import backends, demonstrations
from rehabbot.rl.algorithms import PolicyError, algo_class, detect_algo, detect_model
from rehabbot.rl.hyperparams import (
    HyperparameterError,
    hyperparameters_from_mapping,
    load_hyperparameters,
)
from rehabbot.rl.policies import load_policy
from rehabbot.rl.training import plan_seeds

ENV = "rehab-reach-v0"
FULL_ID = "rehabbot/rehab-reach-v0"
V2 = "rehab-reach-v2"  # an id the shipped settings have an entry for
SHORT = {"max_episode_steps": 60}
SAC_SMALL = {"learning_starts": 100, "buffer_size": 5000, "batch_size": 32, "train_freq": 4,
             "gradient_steps": 4, "policy_kwargs": "dict(net_arch=[16, 16])"}
# Few gradient updates (a run must update its model: rehabbot.rl.planning.check_run_updates);
# updates never change the buffer, which holds exactly what was collected.
NO_UPDATES = {"learning_starts": 5, "batch_size": 8, "buffer_size": 5000,
              "policy_kwargs": "dict(net_arch=[16, 16])"}
# One PPO update of a negligible size (a learning rate must be > 0): after --bc, the cloned
# policy is what the run saves, give or take 1e-12 (Adam steps by about the learning rate).
PPO_FROZEN = {"n_steps": 64, "batch_size": 64, "n_epochs": 1, "learning_rate": 1e-12}


@pytest.fixture
def sbx() -> None:
    """Skip without SBX and JAX."""
    pytest.importorskip("sbx", reason='the sbx backend needs "rehabbot[jax]"')
    pytest.importorskip("jax", reason='the sbx backend needs "rehabbot[jax]"')


def _parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="rehabbot")
    add_train_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["train", *argv])


def _args(tmp_path: Path, algo: str, out: Path, hp: dict, *extra: str,
          env_kwargs: dict | None = None) -> argparse.Namespace:
    import yaml

    hp_file = tmp_path / f"{algo}-hp.yml"
    hp_file.write_text(yaml.safe_dump(hp))
    return _parse(ENV, "--algo", algo, "--hyperparams", str(hp_file), "--out", str(out),
                  "--env-kwargs", json.dumps(env_kwargs or SHORT), "--no-progress", *extra)


def _manifest(run_dir: Path) -> dict:
    return json.loads((run_dir / "manifest.json").read_text())


def _files(run_dir: Path) -> set[str]:
    """The run folder's files, TensorBoard event files by folder only."""
    return {p.relative_to(run_dir).parent.as_posix() + "/events" if "tfevents" in p.name
            else p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if p.is_file()}


def _cli_error(args: argparse.Namespace) -> CliError:
    with pytest.raises(CliError) as caught:
        cmd_train(args)
    assert "\n" not in str(caught.value)
    return caught.value


def _bound_units(actions: np.ndarray, space: gym.spaces.Box) -> np.ndarray:
    return (actions - (space.high + space.low) / 2) / ((space.high - space.low) / 2)


# --------------------------------------------------------------------------- backends


@pytest.mark.slow
def test_sbx_trains_the_same_run_folder_as_sb3_and_it_evaluates(sbx, tmp_path: Path,
                                                                capsys) -> None:
    hp = {**SAC_SMALL, "policy": "stable_baselines3.sac.policies.MlpPolicy"}
    run_dirs = {}
    for backend in ("sb3", "sbx"):
        out = tmp_path / backend
        assert cmd_train(_args(tmp_path, "sac", out, hp, "--timesteps", "300",
                               "--checkpoint-freq", "150", "--eval-freq", "150",
                               "--eval-episodes", "1", "--backend", backend)) == 0
        run_dirs[backend] = out / ENV / "sac" / "seed0"
    assert _files(run_dirs["sbx"]) == _files(run_dirs["sb3"])
    assert {"manifest.json", "model.zip", "monitor/train_0.monitor.csv", "eval/evaluations.npz",
            "checkpoints/rl_model_300_steps.zip", "tb/SAC_1/events",
            "checkpoints/rl_model_replay_buffer_300_steps.npz"} <= _files(run_dirs["sbx"])
    err = capsys.readouterr().err
    assert "note: sbx backend: policy 'stable_baselines3.sac.policies.MlpPolicy' -> " \
           "MlpPolicy (a PyTorch policy class cannot run on JAX" in err

    manifest = _manifest(run_dirs["sbx"])
    assert manifest["backend"] == "sbx" and manifest["status"] == "finished"
    assert manifest["backend_version"] == backends.backend_version("sbx")
    assert manifest["versions"]["sbx"] and manifest["versions"]["jax"]
    hp_block = manifest["hyperparameters"]
    assert hp_block["backend"] == "sbx"
    assert hp_block["policy"] == "MlpPolicy"
    assert [c["key"] for c in hp_block["backend_changes"]] == ["policy"]
    assert hp_block["kwargs"]["train_freq"] == 4 and hp_block["kwargs"]["policy_kwargs"] == \
        {"net_arch": [16, 16]}
    assert _manifest(run_dirs["sb3"])["backend"] == "sb3"
    assert _manifest(run_dirs["sb3"])["hyperparameters"]["backend_changes"] == []

    model_path = run_dirs["sbx"] / "model.zip"
    assert detect_model(model_path) == ("sac", "sbx")
    assert detect_model(run_dirs["sb3"] / "model.zip") == ("sac", "sb3")
    env = gym.make(FULL_ID, **SHORT)
    policy = load_policy(model_path, env)
    assert (policy.algo, policy.backend) == ("sac", "sbx")
    assert env.action_space.contains(policy.act(env.reset(seed=0)[0]))
    assert main(["evaluate", str(run_dirs["sbx"]), "--episodes", "1",
                 "--out", str(tmp_path / "evaluation")]) == 0
    report = json.loads((tmp_path / "evaluation" / "sac-seed0" / "evaluation.json").read_text())
    assert report["policy"]["backend"] == "sbx" and len(report["per_episode"]) == 1

    # Resuming keeps the backend the run was trained with; another one is refused.
    err = _cli_error(_args(tmp_path, "sac", tmp_path / "sbx", hp, "--timesteps", "400",
                           "--resume", "--backend", "sb3"))
    assert "trained with the sbx backend" in str(err) and err.exit_code == 2
    assert cmd_train(_args(tmp_path, "sac", tmp_path / "sbx", hp, "--timesteps", "400",
                           "--checkpoint-freq", "150", "--eval-freq", "0", "--resume")) == 0
    manifest = _manifest(run_dirs["sbx"])
    assert manifest["backend"] == "sbx" and manifest["timesteps_done"] == 400
    assert [s["start_timesteps"] for s in manifest["segments"]] == [0, 300]
    assert algo_class("sac", "sbx").load(model_path).num_timesteps == 400


def test_backend_sb3_is_honoured_and_auto_prefers_sbx(tmp_path: Path, monkeypatch) -> None:
    out = tmp_path / "runs"
    assert cmd_train(_args(tmp_path, "ppo", out, {**PPO_FROZEN, "learning_rate": 3e-4},
                           "--timesteps", "64", "--eval-freq", "0", "--checkpoint-freq", "0",
                           "--backend", "sb3")) == 0
    run_dir = out / ENV / "ppo" / "seed0"
    manifest = _manifest(run_dir)
    assert manifest["backend"] == "sb3"
    assert manifest["backend_version"] == backends.backend_version("sb3")
    assert detect_model(run_dir / "model.zip") == ("ppo", "sb3")
    import stable_baselines3

    assert stable_baselines3.PPO.load(run_dir / "model.zip").num_timesteps == 64

    plan = plan_seeds(ENV, "sac", [0], 101, tmp_path / "plans")[0]
    assert plan.backend == ("sbx" if backends.sbx_available() else "sb3")
    assert plan.hp.backend == plan.backend
    monkeypatch.setattr(backends, "sbx_available", lambda: False)
    plan = plan_seeds(ENV, "sac", [0], 101, tmp_path / "plans")[0]
    assert plan.backend == "sb3" and plan.hp.source == "sb3 defaults"
    assert not (tmp_path / "plans").exists()


def test_backend_sbx_without_sbx_is_one_clear_line(tmp_path: Path, monkeypatch,
                                                   capsys) -> None:
    monkeypatch.setattr(backends, "sbx_available", lambda: False)
    out = tmp_path / "runs"
    err = _cli_error(_parse(ENV, "--algo", "sac", "--backend", "sbx", "--out", str(out)))
    assert err.exit_code == 2
    assert "--backend sbx needs the sbx-rl and jax packages" in str(err)
    assert 'pip install "rehabbot[jax]"' in str(err)
    assert main(["train", ENV, "--algo", "tqc", "--backend", "sbx", "--out", str(out)]) == 2
    line = capsys.readouterr().err
    assert line.startswith("rehabbot: error: --backend sbx needs") and line.count("\n") == 1
    assert not out.exists()


def test_detect_model_knows_tqc_and_crossq(tmp_path: Path) -> None:
    pytest.importorskip("sb3_contrib", reason="TQC and CrossQ on sb3 need sb3-contrib")
    env = gym.make(FULL_ID)
    for algo in ("tqc", "crossq"):
        model = algo_class(algo, "sb3")("MlpPolicy", env, buffer_size=10,
                                        policy_kwargs={"net_arch": [8, 8]})
        model.save(tmp_path / algo)
        assert detect_model(tmp_path / f"{algo}.zip") == (algo, "sb3")
        assert detect_algo(tmp_path / f"{algo}.zip") == algo
    # PPO's policy class is SB3's common one, which A2C uses too: told apart by PPO's arguments.
    from stable_baselines3 import A2C, PPO

    for cls in (PPO, A2C):
        cls("MlpPolicy", env, policy_kwargs={"net_arch": [8]}).save(tmp_path / cls.__name__)
    assert detect_model(tmp_path / "PPO.zip") == ("ppo", "sb3")
    with pytest.raises(PolicyError, match="saved by an algorithm rehabbot does not run"):
        detect_model(tmp_path / "A2C.zip")


@pytest.mark.slow
def test_detect_model_knows_every_sbx_algorithm(sbx, tmp_path: Path) -> None:
    env = gym.make(FULL_ID)
    for algo in ("ppo", "sac", "td3", "tqc", "crossq"):
        extra = {} if algo == "ppo" else {"buffer_size": 10}
        model = algo_class(algo, "sbx")("MlpPolicy", env, policy_kwargs={"net_arch": [8, 8]},
                                        **extra)
        model.save(tmp_path / algo)
        assert detect_model(tmp_path / f"{algo}.zip") == (algo, "sbx"), algo


# --------------------------------------------------------------------------- settings


def test_settings_for_sbx_list_what_changed(sbx) -> None:
    # The shipped settings name only library options: the same on both backends.
    for algo in ("sac", "td3", "ppo"):
        hp = load_hyperparameters(algo, "rehab-knee-v2", algo, "sbx")
        assert hp.backend == "sbx" and hp.policy == "MlpPolicy" and hp.backend_changes == []
        sb3 = load_hyperparameters(algo, "rehab-knee-v2", algo)
        assert hp.given == sb3.given and hp.kwargs.keys() == sb3.kwargs.keys()
    # A PyTorch policy class becomes SBX's MlpPolicy, and the change is listed.
    plain = hyperparameters_from_mapping(
        {"policy": "stable_baselines3.common.policies.ActorCriticPolicy"}, "ppo", backend="sbx")
    assert plain.policy == "MlpPolicy"
    assert {c["key"]: c["used"] for c in plain.backend_changes}["policy"] == "MlpPolicy"
    # A features extractor is dropped, by name: SBX's networks read the observation.
    other = hyperparameters_from_mapping(
        {"policy_kwargs": {"features_extractor_class": "my.Extractor",
                           "features_extractor_kwargs": {"bogus": 1}, "net_arch": [8]}},
        "sac", backend="sbx")
    assert other.kwargs["policy_kwargs"] == {"net_arch": [8]}
    dropped = {c["key"] for c in other.backend_changes if c["used"] is None}
    assert dropped == {"policy_kwargs.features_extractor_class",
                       "policy_kwargs.features_extractor_kwargs"}

    import flax.linen
    import optax

    hp = hyperparameters_from_mapping(
        {"target_update_interval": 2, "qf_learning_rate": 1e-3,
         "policy_kwargs": "dict(activation_fn=nn.Tanh, optimizer_class=optim.Adam, "
                          "optimizer_kwargs=dict(betas=(0.5, 0.999), weight_decay=0.0))"},
        "sac", backend="sbx")
    assert hp.kwargs["qf_learning_rate"] == 1e-3 and "target_update_interval" not in hp.kwargs
    policy_kwargs = hp.kwargs["policy_kwargs"]
    assert policy_kwargs["activation_fn"] is flax.linen.tanh
    assert policy_kwargs["optimizer_class"] is optax.adam
    assert policy_kwargs["optimizer_kwargs"] == {"b1": 0.5, "b2": 0.999}
    changes = {c["key"]: c for c in hp.backend_changes}
    assert changes["target_update_interval"]["used"] is None
    assert changes["policy_kwargs.optimizer_kwargs.weight_decay"]["used"] is None
    assert changes["policy_kwargs.activation_fn"]["used"] == "flax.linen.tanh"
    json.dumps(hp.to_manifest())
    import torch  # a torch class without a JAX twin of its name: SBX's default, and why

    odd = hyperparameters_from_mapping({"policy_kwargs": {"activation_fn": torch.nn.Hardswish}},
                                       "sac", backend="sbx")
    assert odd.kwargs["policy_kwargs"] == {}
    assert odd.backend_changes == [{
        "key": "policy_kwargs.activation_fn", "given": "torch.nn.modules.activation.Hardswish",
        "used": None, "why": "no Flax function of that name; SBX's default activation is used"}]
    with pytest.raises(HyperparameterError, match="'qf_learning_rate' for SAC"):
        hyperparameters_from_mapping({"qf_learning_rate": 1e-3}, "sac")  # SBX only

    pytest.importorskip("sb3_contrib")
    crossq = hyperparameters_from_mapping({"policy_kwargs": {"batch_norm_momentum": 0.01}},
                                          "crossq", backend="sbx")
    assert crossq.kwargs["policy_kwargs"]["batch_norm_momentum"] == pytest.approx(0.99)


@pytest.mark.parametrize("name", ["tqc", "crossq"])
def test_new_settings_files_read_the_same_on_both_backends(name: str) -> None:
    from rehabbot.rl.hyperparams import settings_path

    text = settings_path(name).read_text()
    assert text.startswith(f"# {'TQC' if name == 'tqc' else 'CrossQ'} settings.")
    assert "except:" in text and "train_freq 4 with gradient_steps 4" in text
    read = {}
    for backend in ("sb3", "sbx"):
        if backend == "sbx" and not backends.sbx_available():
            continue
        if backend == "sb3":
            pytest.importorskip("sb3_contrib")
        hp = load_hyperparameters(name, V2, name, backend)
        assert hp.backend_changes == [] and hp.policy == "MlpPolicy"
        assert (hp.kwargs["train_freq"], hp.kwargs["gradient_steps"], hp.kwargs["n_steps"]) \
            == (4, 4, 10)
        read[backend] = hp.kwargs
    assert len(set(map(json.dumps, read.values()))) == 1


# --------------------------------------------------------------------------- --demos


def _check_demos_in_buffer(run_dir: Path, env_kwargs: dict, episodes: int,
                           trained_steps: int) -> None:
    manifest = _manifest(run_dir)
    demos = manifest["demos"]
    expert = demonstrations.collect_expert_episodes(FULL_ID, env_kwargs, episodes,
                                                    demonstrations.demo_seed(0))
    n = len(expert.rewards)
    assert demos["episodes"] == episodes and demos["transitions"] == n
    assert demos["seeds"] == expert.seeds == [20_000 + i for i in range(episodes)]
    assert demos["episode_lengths"] == expert.lengths and sum(expert.lengths) == n
    buffers = sorted((run_dir / "checkpoints").glob("rl_model_replay_buffer_*_steps.npz"))
    with np.load(buffers[-1]) as buffer:
        # The expert's transitions first, then the training steps: nothing else.
        assert int(buffer["pos"]) == n + trained_steps and not bool(buffer["full"])
        np.testing.assert_array_equal(buffer["observations"][:n, 0], expert.observations)
        np.testing.assert_array_equal(buffer["next_observations"][:n, 0],
                                      expert.next_observations)
        space = gym.make(FULL_ID).action_space
        np.testing.assert_allclose(buffer["actions"][:n, 0],
                                   _bound_units(expert.actions, space), atol=1e-6)
        assert np.abs(buffer["actions"][:n]).max() <= 1.0
        # The rewards the env paid for the expert's actions, and the episode ends with
        # time-limit truncation kept apart from termination.
        np.testing.assert_array_equal(buffer["rewards"][:n, 0], expert.rewards)
        np.testing.assert_array_equal(buffer["dones"][:n, 0],
                                      expert.terminated | expert.truncated)
        np.testing.assert_array_equal(buffer["timeouts"][:n, 0],
                                      expert.truncated & ~expert.terminated)
    ends = np.cumsum(expert.lengths) - 1
    assert set(np.flatnonzero(expert.terminated | expert.truncated)) == set(ends)


def test_demos_fill_the_sb3_replay_buffer_with_the_expert_transitions(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    env_kwargs = {"max_episode_steps": 340}  # one exercise ends before the limit, one at it
    assert cmd_train(_args(tmp_path, "td3", out, NO_UPDATES, "--timesteps", "20",
                           "--eval-freq", "0", "--checkpoint-freq", "0", "--demos", "3",
                           "--backend", "sb3", env_kwargs=env_kwargs)) == 0
    run_dir = out / ENV / "td3" / "seed0"
    _check_demos_in_buffer(run_dir, env_kwargs, 3, trained_steps=20)
    # The demos do not count as training steps, and do not show in the training monitor.
    manifest = _manifest(run_dir)
    assert manifest["timesteps_done"] == 20 and manifest["bc"] is None
    assert manifest["demos"]["expert"]["class"] == "rehabbot.rl.experts.ScriptedExpert"
    lengths = [int(line.split(",")[1]) for line in
               (run_dir / "monitor" / "train_0.monitor.csv").read_text().splitlines()[2:]]
    assert sum(lengths) <= 20


@pytest.mark.slow
def test_demos_fill_the_sbx_replay_buffer_with_the_expert_transitions(sbx,
                                                                      tmp_path: Path) -> None:
    out = tmp_path / "runs"
    assert cmd_train(_args(tmp_path, "sac", out, NO_UPDATES, "--timesteps", "20",
                           "--eval-freq", "0", "--checkpoint-freq", "0", "--demos", "2",
                           "--backend", "sbx")) == 0
    run_dir = out / ENV / "sac" / "seed0"
    assert _manifest(run_dir)["backend"] == "sbx"
    _check_demos_in_buffer(run_dir, SHORT, 2, trained_steps=20)


def test_demos_with_several_envs_cut_unfinished_episodes() -> None:
    from stable_baselines3 import SAC
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: gym.make(FULL_ID)] * 2)
    model = SAC("MlpPolicy", venv, buffer_size=1000, policy_kwargs={"net_arch": [8]})
    # Seed 100 draws a 419-step episode, seed 101 a 325-step one (both reach every target).
    record = demonstrations.fill_replay_buffer(model, FULL_ID, {}, 1, 100)
    buffer = model.replay_buffer
    assert buffer.pos == 325 and record["transitions"] == 650
    assert record["seeds"] == [100, 101] and record["episode_lengths"] == [325]
    assert not buffer.dones[:324].any()
    # The finished episode ends as terminated; the other one is cut like a time limit.
    assert buffer.dones[324].tolist() == [True, True]
    assert buffer.timeouts[324].tolist() == [True, False]
    venv.close()


def test_demos_larger_than_the_replay_buffer_are_refused() -> None:
    from stable_baselines3 import SAC

    from rehabbot.rl.planning import TrainingUsageError

    model = SAC("MlpPolicy", gym.make(FULL_ID), buffer_size=50, policy_kwargs={"net_arch": [8]})
    with pytest.raises(TrainingUsageError, match=r"buffer_size=50\) is too small for 1 expert"):
        demonstrations.fill_replay_buffer(model, FULL_ID, {}, 1, 100)  # a 419-step episode


# --------------------------------------------------------------------------- --bc


def _bc_run(tmp_path: Path, backend: str, hp: dict) -> tuple[dict, Path]:
    out = tmp_path / backend
    # PPO_FROZEN's learning rate of 1e-12: PPO's own update leaves the cloned policy as it is.
    assert cmd_train(_args(tmp_path, "ppo", out, hp, "--timesteps", "64", "--eval-freq", "0",
                           "--checkpoint-freq", "0", "--bc", "--demos", "3",
                           "--backend", backend)) == 0
    run_dir = out / ENV / "ppo" / "seed0"
    return _manifest(run_dir), run_dir / "model.zip"


def _clone_error(model_path: Path) -> tuple[float, float]:
    """MSE (in units of the action bound) of the model's deterministic action against the
    expert's, on the expert's states of the cloned episodes and of others."""
    env = gym.make(FULL_ID, **SHORT)
    policy = load_policy(model_path, env)
    errors = []
    for first_seed in (demonstrations.demo_seed(0), 555):
        expert = demonstrations.collect_expert_episodes(FULL_ID, SHORT, 3, first_seed)
        actions = policy.policy.predict(expert.observations, deterministic=True)[0]
        errors.append(float(np.mean((_bound_units(actions, env.action_space)
                                     - _bound_units(expert.actions, env.action_space)) ** 2)))
    return errors[0], errors[1]


@pytest.mark.slow
def test_bc_warm_starts_sb3_ppo_close_to_the_expert(tmp_path: Path) -> None:
    manifest, model_path = _bc_run(tmp_path, "sb3", PPO_FROZEN)
    bc = manifest["bc"]
    assert bc["episodes"] == 3 and bc["seeds"] == [20_000, 20_001, 20_002]
    assert bc["transitions"] == 180 and bc["epochs"] >= demonstrations.BC_EPOCHS
    assert bc["loss_before"] > 0.5  # an untrained PPO's mean is far from the expert's
    assert bc["loss_after"] < bc["loss_before"] / 5
    assert manifest["demos"] is None
    seen, unseen = _clone_error(model_path)
    assert seen <= bc["loss_after"] + 1e-6  # predict clips the mean to the action box
    assert seen < 0.15 and unseen < 0.25
    # The run resumes with the flags it was started with (the cloned episodes are recorded
    # under "bc", not "demos"), and refuses other counts.
    out = tmp_path / "sb3"
    resume = ("--eval-freq", "0", "--checkpoint-freq", "0", "--resume", "--backend", "sb3")
    err = _cli_error(_args(tmp_path, "ppo", out, PPO_FROZEN, "--timesteps", "128", "--bc",
                           "--demos", "4", *resume))
    assert "started with 3 expert episodes and --bc" in str(err)
    assert cmd_train(_args(tmp_path, "ppo", out, PPO_FROZEN, "--timesteps", "128", "--bc",
                           "--demos", "3", *resume)) == 0
    assert _manifest(out / ENV / "ppo" / "seed0")["timesteps_done"] >= 128


@pytest.mark.slow
def test_bc_warm_starts_sbx_ppo_close_to_the_expert(sbx, tmp_path: Path) -> None:
    manifest, model_path = _bc_run(tmp_path, "sbx", {
        **PPO_FROZEN, "policy_kwargs": "dict(ortho_init=True)"})
    bc = manifest["bc"]
    assert manifest["backend"] == "sbx"
    assert bc["loss_after"] < bc["loss_before"] / 5
    seen, unseen = _clone_error(model_path)
    assert seen <= bc["loss_after"] + 1e-6  # predict clips the mean to the action box
    assert seen < 0.15 and unseen < 0.25


# --------------------------------------------------------------------------- user errors


def test_bad_demos_bc_algo_and_backend_are_clear_errors(tmp_path: Path, capsys) -> None:
    out = tmp_path / "runs"
    with pytest.raises(SystemExit) as stop:
        _parse(ENV, "--algo", "sac", "--demos", "-1")
    assert stop.value.code == 2
    assert "--demos: must be an integer in [0, 100,000], got '-1'" in capsys.readouterr().err
    from rehabbot.common.errors import UsageError
    from rehabbot.rl.training import train_run

    with pytest.raises(UsageError, match="--demos must be an integer >= 0"):
        train_run(ENV, "sac", 0, 10, out, demos=-1, backend="sb3")

    err = _cli_error(_parse(V2, "--algo", "sac", "--bc", "--out", str(out)))
    assert "--bc is for PPO only" in str(err) and "--demos N" in str(err)
    assert err.exit_code == 2
    err = _cli_error(_parse(V2, "--algo", "ppo", "--demos", "3", "--out", str(out)))
    assert "--demos needs --bc with PPO" in str(err) and err.exit_code == 2
    err = _cli_error(_parse(V2, "--algo", "ppo", "--bc", "--demos", "0", "--out", str(out)))
    assert "at least one expert episode" in str(err)
    err = _cli_error(_parse(ENV, "--algo", "dqn", "--out", str(out)))
    assert "'dqn'" in str(err) and "ppo, sac, td3, tqc, crossq" in str(err)
    assert err.exit_code == 2
    err = _cli_error(_parse(V2, "--algo", "sac", "--demos", "2", "--backend", "sb3",
                            "--env-kwargs", '{"control_mode": "torque"}', "--out", str(out)))
    assert "scripted expert" in str(err) and "torque" in str(err) and err.exit_code == 2
    with pytest.raises(SystemExit):
        _parse(ENV, "--algo", "sac", "--backend", "jax")
    assert "invalid choice: 'jax'" in capsys.readouterr().err
    assert not out.exists()


def test_resume_refuses_other_demonstrations(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    args = ("--timesteps", "10", "--eval-freq", "0", "--checkpoint-freq", "0",
            "--backend", "sb3")
    assert cmd_train(_args(tmp_path, "sac", out, NO_UPDATES, *args, "--demos", "1")) == 0
    err = _cli_error(_args(tmp_path, "sac", out, NO_UPDATES, "--timesteps", "20", "--resume",
                           "--demos", "2", "--backend", "sb3"))
    assert "started with 1 expert episodes" in str(err) and err.exit_code == 2
    assert cmd_train(_args(tmp_path, "sac", out, NO_UPDATES, "--timesteps", "20", "--resume",
                           "--demos", "1", "--backend", "sb3")) == 0
    assert _manifest(out / ENV / "sac" / "seed0")["timesteps_done"] == 20


# --------------------------------------------------------------------------- benchmark


def test_training_speed_benchmark_prints_the_table(capsys) -> None:
    from benchmarks.performance import training_speed

    assert training_speed.main(["--steps", "40", "--warmup", "110", "--rounds", "2",
                                "--algos", "sac", "td3", "--backends", "sb3",
                                "--net-arch", "8"]) == 0
    out = re.sub(" +", " ", capsys.readouterr().out)  # the Markdown table's padding out
    assert "| algo | sb3 steps/s | sb3 warm-up [s] | sb3 compile ≈ [s] | sb3 × SB3 SAC |" in out
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")]
            for line in out.splitlines() if line.startswith(("| sac ", "| td3 "))}
    assert float(rows["sac"][1]) > 0 and rows["sac"][4] == "1.00"
    assert float(rows["td3"][4]) > 0 and float(rows["td3"][3]) >= 0
    assert training_speed.main(["--algos", "dqn"]) == 2
    assert "unknown algorithm(s) dqn" in capsys.readouterr().err


@pytest.mark.slow
def test_sbx_and_the_shipped_settings_train_on_the_threaded_vector_env(sbx,
                                                                       tmp_path: Path) -> None:
    """``--vec threads`` with SBX and the shipped SAC settings (their expert episodes in the
    replay buffer): the run finishes with a monitor file per world that counts every step."""
    out = tmp_path / "runs"
    assert cmd_train(_parse(V2, "--algo", "sac", "--backend", "sbx", "--vec", "threads",
                            "--n-envs", "2", "--timesteps", "400", "--out", str(out),
                            "--eval-freq", "200", "--eval-episodes", "1", "--no-progress",
                            "--env-kwargs", json.dumps(SHORT))) == 0
    run_dir = out / V2 / "sac" / "seed0"
    manifest = _manifest(run_dir)
    assert manifest["status"] == "finished" and manifest["vec_env"] == "threads"
    assert manifest["backend"] == "sbx" and manifest["timesteps_done"] == 400
    for i in range(2):
        lines = (run_dir / "monitor" / f"train_{i}.monitor.csv").read_text().splitlines()
        lengths = [int(row.split(",")[1]) for row in lines[2:]]
        assert lengths and all(length <= SHORT["max_episode_steps"] for length in lengths)
