"""The zoo of trained agents (``rehabbot.rl.zoo``, ``rehabbot.zoo``): exported NumPy actors
reproduce the models they come from, damaged files and files naming anything but a registered
id are refused, ``zoo:ENV/ALGO`` runs in ``rehabbot evaluate`` / ``render``, every agent
shipped in ``rehabbot/zoo/`` loads and succeeds as often as its metadata says, and full
models (not shipped) are fetched verified from a file, a folder, a URL or a clone's history
(``rehabbot.rl.zoo_full``)."""

from __future__ import annotations

import errno
import functools
import hashlib
import http.server
import json
import os
import shutil
import subprocess
import sys
import threading
import zipfile
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rehabbot
import rehabbot.zoo
from rehabbot.common.errors import UsageError
from rehabbot.envs.registration import env_short_name
from rehabbot.rl import zoo, zoo_full
from rehabbot.rl.zoo import (
    ZooError,
    available,
    load,
    load_file,
    tracking_error_features,
    write_zoo_file,
)
from rehabbot.rl.zoo_export import export_policy
from rehabbot.tasks.observation import P_STAR, THETA, THETA_STAR, P

FULL_ID = "rehabbot/rehab-reach-v0"
ENV = "rehab-reach-v0"
TOLERANCE = 1e-5
SHIPPED_SUCCESS_MARGIN = 0.34  # one episode of three
SHIPPED_EPISODES = 3
REQUIRED_METADATA = ("env_id", "algo", "backend", "training_steps", "seed", "success_rate",
                     "train_command", "rehabbot_version", "weights_sha256")
SHIPPED = zoo.available() if "REHABBOT_ZOO_DIR" not in os.environ else []
NOTHING_SHIPPED = pytest.param(
    None, None, marks=pytest.mark.skip(reason="the zoo ships no agents yet (no .npz under "
                                              "rehabbot/zoo/): nothing to check"))


@pytest.fixture(scope="module")
def env() -> gym.Env:
    return gym.make(FULL_ID)


@pytest.fixture(scope="module")
def observations(env) -> np.ndarray:
    """Reset observations and samples from the whole observation box."""
    env.observation_space.seed(0)
    resets = [env.reset(seed=k)[0] for k in range(4)]
    return np.stack(resets + [env.observation_space.sample() for _ in range(60)])


@pytest.fixture(autouse=True)
def cache_root(tmp_path, monkeypatch) -> Path:
    """A cache folder of the test's own (full models fetched go there, never to ~/.cache)."""
    root = tmp_path / "cache"
    monkeypatch.setenv(zoo_full.CACHE_DIR_ENV, str(root))
    return root


@pytest.fixture
def zoo_root(tmp_path, monkeypatch) -> Path:
    """An empty zoo folder in place of the package's."""
    root = tmp_path / "zoo"
    root.mkdir()
    monkeypatch.delenv(zoo.ZOO_DIR_ENV, raising=False)
    monkeypatch.setattr(zoo, "ZOO_DIR", root)
    return root


def linear_tracker(env: gym.Env, path: Path, env_id: str = FULL_ID, **metadata) -> Path:
    """A zoo file written by hand: ``clip(0.5 (theta* - theta), action box)``, a linear
    controller that finishes reach exercises (no library needed)."""
    weight = np.zeros((6, env.observation_space.shape[0]), np.float32)
    for j in range(6):
        weight[j, THETA_STAR.start + j], weight[j, THETA.start + j] = 0.5, -0.5
    ops = [("dense", {"weight": weight, "bias": np.zeros(6)}),
           ("clip", {"low": env.action_space.low, "high": env.action_space.high})]
    write_zoo_file(path, ops, env.observation_space, env.action_space,
                   {"env_id": env_id, "algo": path.stem, **metadata})
    return path


def assert_same_actions(model, exported: zoo.ZooPolicy, observations: np.ndarray,
                        action_space: gym.spaces.Box) -> None:
    """The exported actor's actions equal the model's deterministic ones, batched and single,
    in the env's units (and relative to the action box for a squashed actor)."""
    expected, _ = model.predict(observations, deterministic=True)
    actual, state = exported.predict(observations)
    assert state is None and actual.shape == expected.shape and actual.dtype == np.float32
    assert np.max(np.abs(actual - expected)) < TOLERANCE
    if exported.ops[-1] == "unscale":  # squashed: also equal to 1e-5 of the action box
        span = action_space.high - action_space.low
        assert np.max(np.abs((actual - expected) / span)) < TOLERANCE
    assert np.ptp(actual, axis=0).min() > 0  # the actions vary: a non-trivial network
    for obs in observations[:3]:
        single, _ = exported.predict(obs)
        assert single.shape == action_space.shape
        assert np.max(np.abs(single - model.predict(obs, deterministic=True)[0])) < TOLERANCE


# --------------------------------------------------------------------------- features


def test_the_tracking_error_step_gives_the_v1_networks_input(env, observations,
                                                              tmp_path) -> None:
    """The first step of the -v1 agents: the observation scaled to its box, the joint and tool
    tracking errors (0.5 rad, 0.1 m scales) and, with ``fine_scale_rad``, their tanh at that
    scale; float32 throughout. A NaN ``fine_scale_rad`` in a file means none."""
    space = env.observation_space
    center = (space.high + space.low) / np.float32(2)
    half_range = (space.high - space.low) / np.float32(2)
    joint = (observations[:, THETA_STAR] - observations[:, THETA]) / np.float32(0.5)
    tool = (observations[:, P_STAR] - observations[:, P]) / np.float32(0.1)
    coarse = tracking_error_features(observations, center, half_range, None)
    assert coarse.shape == (len(observations), 23 + 6 + 3) and coarse.dtype == np.float32
    np.testing.assert_array_equal(coarse, np.concatenate(
        [(observations - center) / half_range, joint, tool], axis=1))
    fine = tracking_error_features(observations, center, half_range, 0.05)
    np.testing.assert_array_equal(fine[:, :32], coarse)
    np.testing.assert_allclose(fine[:, 32:], np.tanh(joint * 10), rtol=0, atol=1e-6)
    for value, expected in ((np.nan, coarse), (0.05, fine)):
        ops = [("tracking_error", {"center": center, "half_range": half_range,
                                   "fine_scale_rad": value})]
        write_zoo_file(tmp_path / "f.npz", ops, space, gym.spaces.Box(-1e3, 1e3, (38,)),
                       {"env_id": FULL_ID, "algo": "f"})
        features, _ = load_file(tmp_path / "f.npz").predict(observations)
        np.testing.assert_array_equal(features[:, :expected.shape[1]], expected)


# --------------------------------------------------------------------------- export


def _perturbed(model, seed: int = 0):
    """``model`` with its weights (and any running statistics) moved far from their
    initial values, so that every layer matters."""
    import torch

    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for param in model.policy.parameters():
            param.add_(torch.randn(param.shape, generator=generator) * 0.3)
        for module in model.policy.modules():
            if type(module).__name__ == "BatchRenorm1d":
                module.ra_mean.copy_(torch.randn(module.ra_mean.shape, generator=generator))
                module.ra_var.copy_(torch.rand(module.ra_var.shape, generator=generator) + 0.5)
    return model


def _sb3_model(algo: str, env: gym.Env):
    if algo in ("tqc", "crossq"):
        contrib = pytest.importorskip("sb3_contrib")
        cls = getattr(contrib, {"tqc": "TQC", "crossq": "CrossQ"}[algo])
        return cls("MlpPolicy", env, learning_starts=100, buffer_size=1000, seed=0,
                   policy_kwargs={"net_arch": [32, 32]})
    import stable_baselines3 as sb3

    cls = {"sac": sb3.SAC, "td3": sb3.TD3, "ppo": sb3.PPO}[algo]
    kwargs = ({"n_steps": 128, "batch_size": 64, "n_epochs": 1} if algo == "ppo"
              else {"learning_starts": 100, "buffer_size": 1000})
    return cls("MlpPolicy", env, seed=0, policy_kwargs={"net_arch": [32, 32]}, **kwargs)


@pytest.mark.parametrize("algo", ["sac", "td3", "ppo", "tqc", "crossq"])
def test_exported_sb3_actor_reproduces_the_model(algo, env, observations, tmp_path) -> None:
    pytest.importorskip("stable_baselines3")
    model = _perturbed(_sb3_model(algo, env))
    meta = export_policy(model, ENV, algo, tmp_path / f"{algo}.npz", episodes=0)
    exported = load_file(tmp_path / f"{algo}.npz")
    assert meta["backend"] == "sb3" and meta["algo"] == algo and meta["env_id"] == FULL_ID
    assert exported.ops[0] == ("batch_norm" if algo == "crossq" else "dense")
    assert exported.ops[-1] == ("clip" if algo == "ppo" else "unscale")
    assert_same_actions(model, exported, observations, env.action_space)


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_exported_trained_sb3_run_reproduces_the_model(algo, env, observations,
                                                       tmp_path) -> None:
    """A few hundred steps of training, saved as a run folder and exported from it."""
    pytest.importorskip("stable_baselines3")
    model = _sb3_model(algo, env)
    model.learn(300)
    run = tmp_path / "run"
    run.mkdir()
    model.save(run / "model")
    manifest = {"env_id": FULL_ID, "algo": algo, "seed": 7, "env_kwargs": {},
                "timesteps_done": 300, "command": ["/somewhere/rehabbot", "train", ENV]}
    (run / "manifest.json").write_text(json.dumps(manifest))
    meta = export_policy(run, None, None, tmp_path / "out.npz", episodes=0)
    assert meta["seed"] == 7 and meta["training_steps"] == 300
    assert meta["train_command"] == f"rehabbot train {ENV}"
    assert_same_actions(model, load_file(tmp_path / "out.npz"), observations,
                        env.action_space)


def test_vecnormalize_statistics_are_exported(env, observations, tmp_path) -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    venv = VecNormalize(DummyVecEnv([lambda: gym.make(FULL_ID)]), norm_reward=False)
    venv.seed(0)
    venv.action_space.seed(0)  # the same statistics every run (float32 noise varies with them)
    venv.reset()
    for _ in range(50):
        venv.step(np.array([venv.action_space.sample()]))
    run = tmp_path / "run"
    run.mkdir()
    model = _perturbed(_sb3_model("ppo", env))
    model.save(run / "model")
    from rehabbot.rl.vecnormalize_io import save_vecnormalize

    save_vecnormalize(venv, run / "vecnormalize.json")
    (run / "manifest.json").write_text(json.dumps({"env_id": FULL_ID, "algo": "ppo",
                                                   "seed": 0}))
    export_policy(run, None, None, tmp_path / "ppo.npz", episodes=0)
    exported = load_file(tmp_path / "ppo.npz")
    assert exported.ops[0] == "normalize"
    expected, _ = model.predict(venv.normalize_obs(observations), deterministic=True)
    assert np.max(np.abs(exported.predict(observations)[0] - expected)) < TOLERANCE


@pytest.mark.slow
def test_exported_sbx_sac_reproduces_the_model(env, observations, tmp_path) -> None:
    sbx = pytest.importorskip("sbx")
    model = sbx.SAC("MlpPolicy", env, learning_starts=100, buffer_size=1000, batch_size=64,
                    seed=0, policy_kwargs={"net_arch": [32, 32]})
    model.learn(300)
    meta = export_policy(model, ENV, "sac", tmp_path / "sac.npz", episodes=0)
    assert meta["backend"] == "sbx"
    assert_same_actions(model, load_file(tmp_path / "sac.npz"), observations,
                        env.action_space)


# --------------------------------------------------------------------------- the files


def test_policy_is_deterministic_numpy_with_sb3_signature(env, observations,
                                                          tmp_path) -> None:
    policy = load_file(linear_tracker(env, tmp_path / "linear.npz"))
    action, state = policy.predict(observations[0], None, None, True)
    assert action.shape == (6,) and state is None
    batch, _ = policy.predict(observations[:5])
    assert batch.shape == (5, 6)
    np.testing.assert_array_equal(batch[0], action)
    assert env.action_space.contains(action)
    with pytest.raises(ValueError, match="deterministic"):
        policy.predict(observations[0], deterministic=False)
    with pytest.raises(ValueError, match="does not fit"):
        policy.predict(np.zeros(5))


def _rewrite(path: Path, change) -> None:
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    change(arrays)
    np.savez(path, **arrays)


def test_tampered_or_damaged_files_are_refused_by_name(env, tmp_path) -> None:
    original = linear_tracker(env, tmp_path / "sac.npz")
    load_file(original)  # intact

    def bump_a_weight(arrays: dict) -> None:
        arrays["op0.weight"] = arrays["op0.weight"].copy()
        arrays["op0.weight"][0, 0] += 1e-3

    cases = {
        "modified": bump_a_weight,
        "lacks": lambda arrays: arrays.pop("op1.high"),
        "lacks metadata": lambda arrays: arrays.pop("metadata"),
        "unreadable metadata": lambda arrays: arrays.update(metadata=np.array("{not json")),
        "unknown ops": lambda arrays: arrays.update(ops=np.array(["dense", "softmax"])),
    }
    for message, change in cases.items():
        path = tmp_path / f"{message.replace(' ', '_')}.npz"
        path.write_bytes(original.read_bytes())
        _rewrite(path, change)
        with pytest.raises(ZooError, match=message) as err:
            load_file(path)
        assert str(path) in str(err.value)
    broken = tmp_path / "broken.npz"
    broken.write_bytes(original.read_bytes()[:200])
    with pytest.raises(ZooError, match="not a readable zoo file") as err:
        load_file(broken)
    assert str(broken) in str(err.value)
    with pytest.raises(ZooError, match="not found"):
        load_file(tmp_path / "missing.npz")
    assert zipfile.is_zipfile(original)


def test_available_and_unknown_ids_or_algorithms(env, zoo_root) -> None:
    with pytest.raises(UsageError, match="holds no agents yet"):
        load(ENV, "sac")
    assert available() == []
    linear_tracker(env, zoo_root / ENV / "sac.npz")
    assert available() == [(FULL_ID, "sac")]
    assert load(FULL_ID, "SAC").env_id == FULL_ID  # full id or short name, any case
    assert rehabbot.zoo.load(ENV, "sac").algo == "sac"
    assert rehabbot.zoo.available() == [(FULL_ID, "sac")]
    for env_id, algo in ((ENV, "td3"), ("rehab-bogus-v9", "sac")):
        with pytest.raises(UsageError, match=f"available: {ENV}/sac"):
            load(env_id, algo)
    with pytest.raises(UsageError, match="zoo:ENV/ALGO"):
        zoo.load_spec("zoo:sac")
    # A file in the wrong folder says so.
    linear_tracker(env, zoo_root / "rehab-knee-v0" / "sac.npz")
    with pytest.raises(ZooError, match="holds an agent for 'rehabbot/rehab-reach-v0'"):
        load("rehab-knee-v0", "sac")
    # An agent trained with another robot is named after both, and runs with its kwargs.
    assert zoo.agent_name("SAC", {"robot": "fr3"}) == "sac-fr3"
    assert zoo.agent_name("sac", {"robot": "ur5e", "weight_level": 2}) == "sac"
    linear_tracker(env, zoo_root / ENV / "sac-fr3.npz", algo="sac", env_kwargs={"robot": "fr3"})
    assert load(ENV, "sac-fr3").metadata["env_kwargs"] == {"robot": "fr3"}
    assert (FULL_ID, "sac-fr3") in available()
    linear_tracker(env, zoo_root / ENV / "td3.npz", algo="td3", env_kwargs={"robot": "fr3"})
    with pytest.raises(ZooError, match="holds the agent 'td3-fr3'"):
        load(ENV, "td3")


def _with_metadata(path: Path, **changes) -> Path:
    """``path`` with metadata entries changed behind the writer's back (the arrays' SHA-256
    does not cover the metadata)."""

    def change(arrays: dict) -> None:
        arrays["metadata"] = np.array(json.dumps({**json.loads(str(arrays["metadata"])),
                                                  **changes}))

    _rewrite(path, change)
    return path


EVIL_MODULE = "rehabbot_test_evilmod"


@pytest.fixture
def evil_module(tmp_path, monkeypatch) -> Iterator[Path]:
    """A module on ``sys.path`` that leaves a marker file when imported: importing it is the
    attack (``gym.make("module:id")`` imports ``module``)."""
    folder = tmp_path / "site"
    folder.mkdir()
    marker = tmp_path / "imported"
    (folder / f"{EVIL_MODULE}.py").write_text(f"open({str(marker)!r}, 'w').close()\n")
    monkeypatch.syspath_prepend(str(folder))
    yield marker
    sys.modules.pop(EVIL_MODULE, None)


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@pytest.mark.parametrize("named", [f"{EVIL_MODULE}:{FULL_ID}", "rehabbot/rehab-bogus-v9",
                                   f"other/{ENV}", ENV, 42])
def test_a_zoo_file_names_only_a_registered_id_exactly(named, env, zoo_root,
                                                       evil_module) -> None:
    """A file whose env_id is anything but a registered rehabbot/ id is refused by name
    before anything makes its env, so no module it names is imported."""
    path = linear_tracker(env, zoo_root / ENV / "sac.npz", backend="sb3")
    model = b"the bytes of a full model"
    path.with_suffix(".zip").write_bytes(model)
    _with_metadata(path, env_id=named, full_model_sha256=sha256(model))
    attempts = {"load": lambda: load(ENV, "sac"), "load_file": lambda: load_file(path),
                "load_full_model": lambda: zoo_full.load_full_model(ENV, "sac"),
                "spec": lambda: zoo.load_spec(f"zoo:{ENV}/sac")}
    for name, attempt in attempts.items():
        with pytest.raises(ZooError, match="not a registered rehabbot/ id") as err:
            attempt()
        assert str(path) in str(err.value) and repr(named) in str(err.value), name
    assert not evil_module.exists() and EVIL_MODULE not in sys.modules
    with pytest.raises(ZooError, match="not a registered rehabbot/ id"):  # nor written
        linear_tracker(env, zoo_root / ENV / "td3.npz", env_id=named)
    assert not (zoo_root / ENV / "td3.npz").exists()


def test_the_id_asked_for_is_a_rehabbot_id_matched_whole(env, zoo_root, evil_module) -> None:
    linear_tracker(env, zoo_root / ENV / "sac.npz")
    for asked in (f"{EVIL_MODULE}:{FULL_ID}", f"other/{ENV}", f"x/{FULL_ID}"):
        with pytest.raises(UsageError, match="is not a rehabbot id"):
            load(asked, "sac")
        with pytest.raises(UsageError, match="is not a rehabbot id"):
            zoo.load_spec(f"zoo:{asked}/sac")
    # The file of another id, in this id's folder: the whole id is compared.
    linear_tracker(env, zoo_root / "rehab-reach-l-v0" / "sac.npz")
    with pytest.raises(ZooError, match="holds an agent for 'rehabbot/rehab-reach-v0', not "
                                       "'rehabbot/rehab-reach-l-v0'"):
        load("rehabbot/rehab-reach-l-v0", "sac")
    assert not evil_module.exists()


def test_export_refuses_a_note_that_sets_a_reserved_key(tmp_path) -> None:
    """The exporter writes the env id, algorithm, provenance and hashes; a note adds keys of
    its own only (checked before the model is read)."""
    for key in ("env_id", "algo", "weights_sha256", "full_model_sha256", "env_kwargs"):
        with pytest.raises(UsageError, match=f"the metadata '{key}' cannot be set by a note"):
            export_policy(object(), ENV, "sac", tmp_path / "x.npz",
                          metadata={key: f"{EVIL_MODULE}:{FULL_ID}", "why": "test"})
    assert not (tmp_path / "x.npz").exists()
    assert set(REQUIRED_METADATA) <= zoo.RESERVED_METADATA


def test_loading_and_acting_import_no_torch_or_jax(env, tmp_path) -> None:
    root = tmp_path / "zoo"
    linear_tracker(env, root / ENV / "sac.npz")
    probe = (
        "import sys, numpy as np, rehabbot.zoo\n"
        f"policy = rehabbot.zoo.load({ENV!r}, 'sac')\n"
        "policy.predict(np.zeros(23, np.float32))\n"
        "from rehabbot.rl.policies import env_for\n"
        f"env_for(['zoo:{ENV}/sac'])\n"
        "heavy = ('torch', 'jax', 'flax', 'sbx', 'stable_baselines3', 'sb3_contrib')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy))\n")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                            env={**os.environ, zoo.ZOO_DIR_ENV: str(root)}, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == "[]"


# --------------------------------------------------------------------------- the CLI


def test_evaluate_runs_a_zoo_spec_in_the_agents_env(env, zoo_root, tmp_path,
                                                    capsys) -> None:
    from rehabbot.cli import main

    pytest.importorskip("stable_baselines3")
    model = _perturbed(_sb3_model("sac", env))
    meta = export_policy(model, ENV, "sac", zoo.zoo_path(ENV, "sac"), episodes=1, seed=5)
    assert meta["evaluation"] == {"episodes": 1, "seed": 5, "deterministic": True,
                                  "successes": int(meta["success_rate"])}
    linear_tracker(env, zoo_root / ENV / "linear.npz")
    out = tmp_path / "evaluation"
    code = main(["evaluate", f"zoo:{ENV}/sac", f"zoo:{ENV}/linear", "--episodes", "1",
                 "--seed", "5", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    report = json.loads((out / "zoo-sac" / "evaluation.json").read_text())
    assert report["env_id"] == FULL_ID  # from the zoo file, without --env
    assert report["policy"]["kind"] == "zoo" and report["policy"]["train_seed"] == 0
    assert report["summary"]["success_rate"] == meta["success_rate"]
    linear = json.loads((out / "zoo-linear" / "evaluation.json").read_text())
    assert linear["summary"]["success_rate"] == 1.0
    assert main(["evaluate", f"zoo:{ENV}/td3", "--out", str(out)]) == 2
    assert "available:" in capsys.readouterr().err
    assert main(["evaluate", f"zoo:{ENV}/linear", "--stochastic", "--episodes", "1",
                 "--out", str(tmp_path / "stochastic")]) == 2
    assert "deterministic" in capsys.readouterr().err


@pytest.mark.slow
def test_render_runs_a_zoo_spec(env, zoo_root, tmp_path) -> None:
    pytest.importorskip("imageio")
    from rehabbot.cli import main

    linear_tracker(env, zoo_root / ENV / "sac.npz")
    out = tmp_path / "zoo.gif"
    assert main(["render", f"zoo:{ENV}/sac", "--out", str(out), "--width", "64",
                 "--height", "48", "--frame-every", "25"]) == 0
    assert out.stat().st_size > 0


@pytest.fixture
def td3_run(env, tmp_path) -> Path:
    """A run folder of a (perturbed, untrained) SB3 TD3 model on rehab-reach-v0."""
    pytest.importorskip("stable_baselines3")
    run = tmp_path / "run"
    run.mkdir()
    _perturbed(_sb3_model("td3", env)).save(run / "model")
    (run / "manifest.json").write_text(json.dumps({"env_id": FULL_ID, "algo": "td3",
                                                   "seed": 3, "timesteps_done": 10}))
    return run


def test_export_command_writes_the_zoo_file(td3_run, zoo_root, tmp_path, capsys) -> None:
    run = td3_run
    from rehabbot.cli import main

    assert main(["zoo", "export", str(run), "--episodes", "0", "--note", '{"why": "test"}']) == 0
    assert f"wrote {zoo_root / ENV / 'td3.npz'}: {FULL_ID} td3 (sb3)" in capsys.readouterr().out
    assert load(ENV, "td3").metadata["seed"] == 3 and load(ENV, "td3").metadata["why"] == "test"
    assert main(["zoo", "list"]) == 0
    assert f"{ENV}/td3" in capsys.readouterr().out
    assert main(["zoo", "export", str(run / "model.zip"), "--env", ENV, "--algo", "a2c"]) == 2
    assert main(["zoo", "export", str(tmp_path / "nowhere.zip"), "--env", ENV,
                 "--algo", "sac"]) == 1
    with pytest.raises(SystemExit) as stop:  # argparse: --note must be a JSON object
        main(["zoo", "export", str(run), "--note", "[1]"])
    assert stop.value.code == 2 and "must be a JSON object" in capsys.readouterr().err


def test_export_command_refuses_bad_numbers_folders_and_notes(td3_run, zoo_root, tmp_path,
                                                              capsys) -> None:
    """Every number is bounded, --out's folder must exist (nothing is created above it), a
    note cannot set a reserved key: exit 2, one line naming the value, nothing written."""
    from rehabbot.cli import main

    for option, value in (("--episodes", "-1"), ("--episodes", "1e9"), ("--seed", "-5"),
                          ("--seed", "1e20")):
        with pytest.raises(SystemExit) as stop:
            main(["zoo", "export", str(td3_run), option, value])
        err = capsys.readouterr().err
        assert stop.value.code == 2, (option, value)
        assert f"{option}: must be an integer in [0, " in err and repr(value) in err
    missing = tmp_path / "no" / "such" / "agent.npz"
    assert main(["zoo", "export", str(td3_run), "--episodes", "0", "--out", str(missing)]) == 2
    assert f"its folder {str(missing.parent)!r} does not exist" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()
    assert main(["zoo", "export", str(td3_run), "--out", str(tmp_path / "agent.txt")]) == 2
    assert "a zoo file ends in .npz" in capsys.readouterr().err
    note = json.dumps({"env_id": f"{EVIL_MODULE}:{FULL_ID}"})
    assert main(["zoo", "export", str(td3_run), "--episodes", "0", "--note", note]) == 2
    assert "the metadata 'env_id' cannot be set by a note" in capsys.readouterr().err
    assert list(zoo_root.rglob("*")) == [] and not (tmp_path / "agent.txt").exists()


def _no_space(*_args) -> None:
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("full", [True, False])
def test_a_full_disk_names_the_file_export_cannot_write(full, td3_run, tmp_path, monkeypatch,
                                                         capsys) -> None:
    """A full disk (simulated: flushing a written file fails with ENOSPC) exits 1 with one
    line naming the file: the full model's copy first (--full), else the zoo file; nothing
    is left, temporaries included."""
    from rehabbot.cli import main

    out = tmp_path / "out"
    out.mkdir()
    named = out / ("agent.zip" if full else "agent.npz")
    with monkeypatch.context() as patch:
        patch.setattr(os, "fsync", _no_space)
        code = main(["zoo", "export", str(td3_run), "--episodes", "0", "--out",
                     str(out / "agent.npz"), *(["--full"] if full else [])])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1, err
    assert f"cannot write {str(named)!r}: No space left on device" in err
    assert list(out.iterdir()) == []


# --------------------------------------------------------------------------- shipped agents


@pytest.mark.parametrize("env_id, algo", SHIPPED or [NOTHING_SHIPPED])
def test_each_shipped_agent_loads_and_fits_its_env(env_id, algo) -> None:
    policy = load(env_id, algo)
    missing = [key for key in REQUIRED_METADATA if key not in policy.metadata]
    assert missing == [], f"{policy.path} lacks metadata {missing}"
    assert policy.path.stat().st_size < 2_000_000, "zoo files should stay small"
    shipped_env = gym.make(env_id, **policy.metadata.get("env_kwargs", {}))
    assert policy.observation_space == shipped_env.observation_space
    assert policy.action_space == shipped_env.action_space
    obs, _ = shipped_env.reset(seed=0)
    assert shipped_env.action_space.contains(policy.predict(obs)[0])


@pytest.mark.slow
@pytest.mark.parametrize("env_id, algo", SHIPPED or [NOTHING_SHIPPED])
def test_each_shipped_agent_succeeds_as_recorded(env_id, algo) -> None:
    """3 episodes on the first seeds of the recorded evaluation: the success rate is at
    least the recorded one minus one episode in three."""
    from rehabbot.analysis.evaluation import evaluate

    meta = load(env_id, algo).metadata
    seed = int((meta.get("evaluation") or {}).get("seed", zoo.DEFAULT_SEED))
    report, _trace = evaluate(f"zoo:{env_short_name(env_id)}/{algo}", episodes=SHIPPED_EPISODES,
                              seed=seed)
    measured = report["summary"]["success_rate"]
    assert measured >= meta["success_rate"] - SHIPPED_SUCCESS_MARGIN, (
        f"{env_id} {algo}: {measured:.0%} success on seeds {seed}..{seed + 2}, "
        f"recorded {meta['success_rate']:.0%}")


# --------------------------------------------------------------------------- full models

REPOSITORY = Path(__file__).resolve().parents[1]
MODEL_BYTES = b"the bytes of a full model, " * 1000


@pytest.fixture
def agent_with_model(env, zoo_root) -> zoo_full.FullModel:
    """A zoo agent whose metadata pins the SHA-256 of ``MODEL_BYTES`` as its full model's."""
    linear_tracker(env, zoo_root / ENV / "sac.npz", backend="sb3",
                   full_model_sha256=sha256(MODEL_BYTES))
    return zoo_full.full_model(ENV, "sac")


def _cached_files(cache: Path) -> list[Path]:
    return sorted(p for p in cache.rglob("*") if p.is_file()) if cache.exists() else []


def test_a_full_model_is_found_beside_the_actor_or_in_the_cache(agent_with_model,
                                                                cache_root) -> None:
    model = agent_with_model
    assert model.cached.parent == cache_root / "full-models" / ENV
    assert model.cached.name == f"sac-{model.sha256[:16]}.zip"
    with pytest.raises(ZooError, match="is not on this machine") as err:
        zoo_full.find_full_model(ENV, "sac")
    assert str(model.beside) in str(err.value) and str(model.cached) in str(err.value)
    assert f"rehabbot zoo fetch {ENV}/sac --from" in str(err.value)
    model.cached.parent.mkdir(parents=True)
    model.cached.write_bytes(MODEL_BYTES)
    assert zoo_full.find_full_model(ENV, "sac") == model.cached
    model.beside.write_bytes(MODEL_BYTES)  # a zoo exported with --full: beside comes first
    assert zoo_full.find_full_model(ENV, "sac") == model.beside
    model.beside.write_bytes(MODEL_BYTES + b"\0")
    with pytest.raises(ZooError, match="not the model this agent was exported from") as err:
        zoo_full.find_full_model(ENV, "sac")
    assert str(model.beside) in str(err.value)


def test_fetch_copies_a_verified_file_from_a_file_or_a_folder(agent_with_model, tmp_path,
                                                              cache_root) -> None:
    model = agent_with_model
    wrong = tmp_path / "wrong.zip"
    wrong.write_bytes(MODEL_BYTES + b"!")
    with pytest.raises(ZooError, match=f"its SHA-256 is {sha256(MODEL_BYTES + b'!')}, not "
                                       "the agent's") as err:
        zoo_full.fetch_full_model(ENV, "sac", wrong)
    assert str(wrong) in str(err.value)
    assert _cached_files(cache_root) == []  # nothing, temporaries included
    with pytest.raises(UsageError, match="no such file or folder, and not an http"):
        zoo_full.fetch_full_model(ENV, "sac", tmp_path / "nowhere")
    for layout in (f"{ENV}/sac.zip", f"rehabbot/zoo/{ENV}/sac.zip", "model.zip", None):
        source = tmp_path / "sources" / str(layout).replace("/", "_")
        given = source / layout if layout else source.with_suffix(".zip")
        given.parent.mkdir(parents=True, exist_ok=True)
        given.write_bytes(MODEL_BYTES)
        fetched = zoo_full.fetch_full_model(ENV, "sac", source if layout else given)
        assert fetched.path == model.cached and fetched.origin == str(given)
        assert model.cached.read_bytes() == MODEL_BYTES
        assert zoo_full.find_full_model(ENV, "sac") == model.cached
        again = zoo_full.fetch_full_model(ENV, "sac", source / "not-read")
        assert again.origin is None and again.path == model.cached  # already here
        model.cached.unlink()
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ZooError, match="not a git clone whose history holds"):
        zoo_full.fetch_full_model(ENV, "sac", empty)


@pytest.fixture
def http_folder(tmp_path, monkeypatch) -> Iterator[tuple[str, Path]]:
    """A folder served over HTTP on 127.0.0.1 (a free port) for the test, then stopped."""
    served = tmp_path / "served"
    served.mkdir()
    monkeypatch.setenv("no_proxy", "127.0.0.1")
    monkeypatch.setenv("NO_PROXY", "127.0.0.1")

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *_args) -> None:
            pass

    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), functools.partial(Quiet, directory=str(served)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", served
    finally:
        server.shutdown()
        server.server_close()
        thread.join()


def test_fetch_downloads_a_verified_file_over_http(agent_with_model, http_folder,
                                                   cache_root) -> None:
    model = agent_with_model
    url, served = http_folder
    with pytest.raises(ZooError, match="HTTP 404") as err:
        zoo_full.fetch_full_model(ENV, "sac", url)
    assert f"{url}/{ENV}/sac.zip" in str(err.value)
    (served / ENV).mkdir()
    (served / ENV / "sac.zip").write_bytes(MODEL_BYTES[::-1])  # the wrong bytes
    with pytest.raises(ZooError, match="not the agent's full_model_sha256"):
        zoo_full.fetch_full_model(ENV, "sac", url + "/")
    assert _cached_files(cache_root) == []
    (served / ENV / "sac.zip").write_bytes(MODEL_BYTES)
    fetched = zoo_full.fetch_full_model(ENV, "sac", url + "/")  # a folder laid out as the zoo
    assert fetched.origin == f"{url}/{ENV}/sac.zip" and fetched.path == model.cached
    model.cached.unlink()
    (served / "renamed.zip").write_bytes(MODEL_BYTES)
    fetched = zoo_full.fetch_full_model(ENV, "sac", f"{url}/renamed.zip")  # the file itself
    assert fetched.origin == f"{url}/renamed.zip"
    assert _cached_files(cache_root) == [model.cached]
    assert model.cached.read_bytes() == MODEL_BYTES


def _git(folder: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(folder), "-c", "user.name=test", "-c",
                           "user.email=test@example.org", "-c", "commit.gpgsign=false", *args],
                          check=True, capture_output=True, text=True).stdout.strip()


def test_fetch_reads_a_clones_history(agent_with_model, tmp_path, monkeypatch,
                                      capsys) -> None:
    """A clone of the repository holds the full models in its history (the pinned commit)
    after its tree dropped them; the error of load_full_model, run in the clone, gives the
    command that fetches from it."""
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    from rehabbot.cli import main

    model = agent_with_model
    clone = (tmp_path / "clone").resolve()
    clone.mkdir()
    _git(clone, "init", "-q")
    tracked = clone / "rehabbot" / "zoo" / ENV / "sac.zip"
    tracked.parent.mkdir(parents=True)
    tracked.write_bytes(MODEL_BYTES)
    (clone / "rehabbot" / "__init__.py").write_text("")
    _git(clone, "add", "-A")
    _git(clone, "commit", "-q", "-m", "with the full models")
    monkeypatch.setattr(zoo_full, "HISTORY_COMMIT", _git(clone, "rev-parse", "HEAD"))
    _git(clone, "rm", "-q", str(tracked.relative_to(clone)))
    _git(clone, "commit", "-q", "-m", "without them")
    monkeypatch.chdir(clone / "rehabbot")  # anywhere in the clone
    with pytest.raises(ZooError) as err:
        zoo_full.load_full_model(ENV, "sac")
    assert f"get it with `rehabbot zoo fetch {ENV}/sac --from {clone}`" in str(err.value)
    assert main(["zoo", "fetch", f"{ENV}/sac", "--from", str(clone)]) == 0
    out = capsys.readouterr().out
    assert f"{ENV}/sac: verified (sha256 {model.sha256[:12]})" in out
    assert f"in the git history of {clone}" in out
    assert model.cached.read_bytes() == MODEL_BYTES
    assert main(["zoo", "fetch", "--all", "--from", str(clone)]) == 0
    assert f"{ENV}/sac: already here, verified: {model.cached}" in capsys.readouterr().out


def test_zoo_fetch_says_what_it_refuses(env, agent_with_model, zoo_root, tmp_path,
                                        capsys) -> None:
    from rehabbot.cli import main

    linear_tracker(env, zoo_root / ENV / "td3.npz")  # exported without --full
    wrong = tmp_path / "wrong.zip"
    wrong.write_bytes(b"not it")
    cases = [(["--from", str(tmp_path)], 2, "name the agents (ENV/ALGO ...) or give --all"),
             ([f"{ENV}/sac", "--all", "--from", str(tmp_path)], 2, "not both"),
             ([f"{ENV}/td3", "--from", str(tmp_path)], 2, "keeps only the actor of "
                                                          f"{ENV}/td3"),
             ([f"{ENV}/sac", "--from", str(tmp_path / "x")], 2, "no such file or folder"),
             ([f"{ENV}/sac", "--from", str(wrong)], 1, "no verified copy of "
                                                       f"{ENV}/sac's full model")]
    for args, code, words in cases:
        assert main(["zoo", "fetch", *args]) == code, args
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1, (args, err)
    with pytest.raises(SystemExit) as stop:
        main(["zoo", "fetch", f"{ENV}/sac"])  # --from is required
    assert stop.value.code == 2 and "--from" in capsys.readouterr().err


def test_an_agent_without_a_full_model_says_so(env, zoo_root) -> None:
    linear_tracker(env, zoo_root / ENV / "sac.npz")
    with pytest.raises(UsageError, match=f"keeps only the actor of {ENV}/sac"):
        zoo_full.load_full_model(ENV, "sac")
    linear_tracker(env, zoo_root / ENV / "td3.npz", full_model_sha256="not a hash")
    with pytest.raises(ZooError, match="has full_model_sha256 'not a hash', not a SHA-256"):
        zoo_full.load_full_model(ENV, "td3")


@pytest.mark.skipif(bool(os.environ.get("REHABBOT_ZOO_DIR")), reason="another zoo")
def test_the_pinned_commit_holds_every_shipped_full_model() -> None:
    """Every shipped agent that has a full model can be fetched from a clone: the pinned
    commit's tree holds a file with its SHA-256 (run where the repository's history is)."""
    models = zoo_full.full_models()
    v2_agents = [(e, a) for e, a in zoo.available() if e.endswith("-v2")]
    actor_only = [(e, a) for e, a in v2_agents
                  if "full_model_sha256" not in load(e, a).metadata]
    # Every -v2 agent pins a full model, but the envelope-trained ones (actors only: their
    # models are in no commit of the repository).
    assert all("training_patients" in load(e, a).metadata for e, a in actor_only)
    assert len(models) == len(v2_agents) - len(actor_only) > 0
    if shutil.which("git") is None or zoo_full.history_clone(REPOSITORY, models[0]) is None:
        pytest.skip(f"not in a git clone that holds commit {zoo_full.HISTORY_COMMIT}")
    for model in models:
        blob = subprocess.run(["git", "-C", str(REPOSITORY), "cat-file", "blob",
                               f"{zoo_full.HISTORY_COMMIT}:{model.history_path}"],
                              check=True, capture_output=True).stdout
        assert sha256(blob) == model.sha256, model.name


@pytest.mark.slow
def test_the_full_model_ships_beside_the_actor_and_fine_tunes(zoo_root, tmp_path) -> None:
    """``--full`` keeps the run's model.zip beside the .npz, bound by its SHA-256:
    ``load_full_model`` gives the model (critics included) whose actor the .npz holds, ready
    to ``learn``; a changed zip is refused; a missing one is fetched back, verified, into
    the cache, and loads from there."""
    pytest.importorskip("sbx")
    from rehabbot.rl.training import train_run

    env_id = "rehabbot/rehab-knee-v2"
    run_dir = train_run(env_id, "sac", 0, 200, tmp_path / "runs", backend="sbx",
                        hyperparams={"learning_starts": 50, "batch_size": 32,
                                     "buffer_size": 1000, "policy_kwargs": "dict(net_arch=[16])"},
                        checkpoint_freq=0, eval_freq=0, progress_bar=False)
    from rehabbot.cli import main

    assert main(["zoo", "export", str(run_dir), "--episodes", "0", "--full"]) == 0
    agent = load(env_id, "sac")
    full = zoo_full.full_model(env_id, "sac")
    assert full.beside == zoo_root / "rehab-knee-v2" / "sac.zip" and full.beside.is_file()
    assert full.sha256 == sha256((run_dir / "model.zip").read_bytes())
    model = zoo_full.load_full_model(env_id, "sac")
    env = gym.make(env_id)
    observations = np.stack([env.reset(seed=k)[0] for k in range(5)])
    expected = model.predict(observations, deterministic=True)[0]
    assert np.max(np.abs(agent.predict(observations)[0] - expected)) < TOLERANCE
    model.learn(60, reset_num_timesteps=False)  # fine-tuning: critics and optimisers came too
    assert model.num_timesteps >= 260

    full.beside.write_bytes(full.beside.read_bytes() + b"\0")
    with pytest.raises(ZooError, match="not the model this agent was exported from"):
        zoo_full.load_full_model(env_id, "sac")
    full.beside.unlink()
    with pytest.raises(ZooError, match="rehabbot zoo fetch rehab-knee-v2/sac --from"):
        zoo_full.load_full_model(env_id, "sac")
    assert main(["zoo", "fetch", "rehab-knee-v2/sac", "--from", str(run_dir)]) == 0
    again = zoo_full.load_full_model(env_id, "sac")
    assert zoo_full.find_full_model(env_id, "sac") == full.cached
    assert np.max(np.abs(again.predict(observations, deterministic=True)[0] - expected)) \
        < TOLERANCE
