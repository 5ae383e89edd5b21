"""The settings files shipped in ``rehabbot/rl/hyperparams/`` are read unchanged by RL Zoo
(``python -m rl_zoo3.train --gym-packages rehabbot --conf-file ...``) and by rehabbot's own
loader, which gives the same settings as before they were respelled for RL Zoo; models with
rehabbot's policy classes save and load back. The RL Zoo runs are slow (``pytest --full``) and
skipped without ``rl_zoo3``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason='RL tests need "rehabbot[train]"')
pytest.importorskip("yaml", reason="hyperparameter files need PyYAML")

import yaml

import rehabbot  # noqa: F401  (registers the envs)
from rehabbot.envs.registration import ENV_SPECS
from rehabbot.rl.algorithms import algo_class
from rehabbot.rl.features import TRACKING_ERROR_POLICIES, TrackingErrorFeatures
from rehabbot.rl.hyperparams import (
    SCHEDULE_KEYS,
    HyperparameterError,
    Hyperparameters,
    hyperparameters_from_mapping,
    load_hyperparameters,
    parse_python_expression,
    settings_names,
    settings_path,
)
from rehabbot.rl.policies import load_model

ID = "rehabbot/rehab-reach-v0"
FINE = "features_extractor_kwargs=dict(fine_scale_rad=0.05), "
# The shipped settings as they were spelled before RL Zoo could read them (a flat mapping, the
# extractor class named in policy_kwargs); rehabbot's loader still reads this spelling.
OLD_SPELLING: dict[str, tuple[str, dict[str, Any]]] = {
    "sac": ("sac", {"n_timesteps": 200000, "n_steps": 10, "policy_kwargs":
                    f"dict(features_extractor_class=TrackingErrorFeatures, {FINE}"
                    "net_arch=[64, 64])"}),
    "td3": ("td3", {"n_timesteps": 200000, "n_steps": 10, "noise_type": "normal",
                    "noise_std": 0.1, "policy_kwargs":
                    f"dict(features_extractor_class=TrackingErrorFeatures, {FINE}"
                    "net_arch=[64, 64])"}),
    "ppo": ("ppo", {"n_timesteps": 200000,
                    "policy_kwargs": "dict(features_extractor_class=TrackingErrorFeatures)"}),
    "ablations/sac-1step": ("sac", {
        "n_timesteps": 200000,
        "policy_kwargs": "dict(features_extractor_class=TrackingErrorFeatures, "
                         "net_arch=[64, 64])"}),
    "ablations/sac-coarse-features": ("sac", {
        "n_timesteps": 200000, "n_steps": 10,
        "policy_kwargs": "dict(features_extractor_class=TrackingErrorFeatures, "
                         "net_arch=[64, 64])"}),
    "ablations/sac-gsde": ("sac", {
        "n_timesteps": 200000, "use_sde": True, "train_freq": 64, "gradient_steps": 64,
        "learning_starts": 10000,
        "policy_kwargs": "dict(features_extractor_class=TrackingErrorFeatures, "
                         "net_arch=[64, 64])"}),
    "ablations/td3-coarse-features": ("td3", {
        "n_timesteps": 200000, "n_steps": 10, "noise_type": "normal", "noise_std": 0.1,
        "policy_kwargs": "dict(features_extractor_class=TrackingErrorFeatures, "
                         "net_arch=[64, 64])"}),
}
# Keep the off-policy models small: the shipped buffer holds a million transitions.
SMALL = {"sac": {"buffer_size": 1000}, "td3": {"buffer_size": 1000},
         "tqc": {"buffer_size": 1000}, "crossq": {"buffer_size": 1000},
         "ppo": {"n_steps": 64, "batch_size": 32, "n_epochs": 2}}


@pytest.fixture(scope="module")
def env() -> gym.Env:
    return gym.make(ID)


def _algo_of(name: str) -> str:
    """``sb3-defaults/td3`` -> ``td3``, ``ablations/sac-gsde`` -> ``sac``."""
    return name.split("/")[-1].split("-")[0]


def _build(hp: Hyperparameters, env: gym.Env, **overrides: Any) -> Any:
    kwargs = {**hp.kwargs, **SMALL[hp.algo], **overrides}
    return algo_class(hp.algo)(hp.policy, env, seed=0, device="cpu", **kwargs)


def _extractor(model: Any) -> Any:
    policy = model.policy
    return policy.features_extractor if hasattr(policy, "mlp_extractor") \
        else policy.actor.features_extractor


def _structure(model: Any) -> dict[str, Any]:
    """What makes two policies the same network: constructor arguments and weight shapes."""
    params = {key: value for key, value in model.policy._get_constructor_parameters().items()
              if key != "lr_schedule"}
    return {"params": params,
            "shapes": {key: tuple(value.shape) for key, value in
                       model.policy.state_dict().items()}}


def _load(algo: str, path: Path) -> Any:
    with warnings.catch_warnings():  # the saved n-step buffer class overrides n_steps: fine
        warnings.filterwarnings("ignore", message=".*n_steps.*is ignored because")
        return algo_class(algo).load(path, device="cpu")


# --------------------------------------------------------------------------- rehabbot's loader


@pytest.mark.parametrize("name", sorted(OLD_SPELLING))
def test_loader_gives_the_settings_of_before(env, name: str) -> None:
    algo, old_mapping = OLD_SPELLING[name]
    new = load_hyperparameters(name, ID, algo)
    old = hyperparameters_from_mapping(old_mapping, algo)
    assert new.entry == "default" and new.policy is TRACKING_ERROR_POLICIES[algo]
    assert (new.n_timesteps, new.n_envs, new.normalize) == \
        (old.n_timesteps, old.n_envs, old.normalize)
    assert (new.noise_type, new.noise_std) == (old.noise_type, old.noise_std)
    assert {k: v for k, v in new.kwargs.items() if k != "policy_kwargs"} == \
        {k: v for k, v in old.kwargs.items() if k != "policy_kwargs"}
    new_model, old_model = _build(new, env), _build(old, env)
    assert _structure(new_model) == _structure(old_model)
    assert type(_extractor(new_model)) is TrackingErrorFeatures


@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_shipped_settings_values(env, algo: str) -> None:
    hp = load_hyperparameters(algo, ID, algo)
    model = _build(hp, env)
    extractor = _extractor(model)
    assert type(extractor) is TrackingErrorFeatures and hp.n_timesteps == 200_000
    if algo == "ppo":
        assert extractor.fine_scale_rad is None and "n_steps" not in hp.kwargs
        assert model.policy.net_arch == {"pi": [64, 64], "vf": [64, 64]}
    else:
        assert extractor.fine_scale_rad == 0.05 and model.policy.net_arch == [64, 64]
        assert hp.kwargs["n_steps"] == 10 and model.n_steps == 10
    assert (hp.noise_type, hp.noise_std) == (("normal", 0.1) if algo == "td3" else (None, None))
    manifest = json.loads(json.dumps(hp.to_manifest()))  # JSON-able, classes by dotted name
    dotted = f"rehabbot.rl.features.{TRACKING_ERROR_POLICIES[algo].__name__}"
    assert manifest["policy"] == manifest["kwargs"]["policy"] == manifest["given"]["policy"] \
        == dotted


@pytest.mark.parametrize("name", settings_names())
def test_shipped_files_have_the_shape_rl_zoo_reads(name: str) -> None:
    data = yaml.safe_load(settings_path(name).read_text(encoding="utf-8"))
    assert data and all(key == "default" or key in ENV_SPECS for key in data), list(data)
    for entry in data.values():
        assert "n_timesteps" in entry
        policy_kwargs = entry.get("policy_kwargs", "dict()")
        # RL Zoo evaluates a string in its own namespace and passes a mapping on unread: a
        # string of literals (and torch's nn.*) only.
        assert isinstance(policy_kwargs, str) and "extractor_class" not in policy_kwargs
        parse_python_expression(policy_kwargs)
        for key in SCHEDULE_KEYS:
            assert key not in entry or entry[key] is not None, key  # RL Zoo refuses null
    for env_id in ENV_SPECS:  # and so does rehabbot's loader, for every env
        if "default" in data or env_id in data:
            load_hyperparameters(name, env_id, _algo_of(name))


def test_policy_classes_keep_every_sb3_argument(env) -> None:
    from stable_baselines3.common.torch_layers import FlattenExtractor

    hp = hyperparameters_from_mapping({"policy": "rehabbot.rl.features.TrackingErrorSACPolicy",
                                       "policy_kwargs": {"features_extractor_class":
                                                         FlattenExtractor}}, "sac")
    assert type(_extractor(_build(hp, env))) is FlattenExtractor  # the default is overridable
    sb3 = hyperparameters_from_mapping({"policy": "stable_baselines3.sac.policies.MlpPolicy"},
                                       "sac")
    assert sb3.policy_name == "stable_baselines3.sac.policies.SACPolicy"


@pytest.mark.parametrize(("algo", "policy", "why"), [
    ("sac", "this.Zen", "outside the packages"),  # `import this` would print: not imported
    ("sac", "os.system", "outside the packages"),
    ("sac", "rehabbot.rl.features.TrackingErrorTD3Policy",
     "not a subclass of stable_baselines3.sac.policies.SACPolicy"),
    ("ppo", "rehabbot.rl.features.TrackingErrorFeatures",
     "not a subclass of stable_baselines3.common.policies.ActorCriticPolicy"),
    ("td3", "rehabbot.rl.features.TRACKING_ERROR_POLICIES", "not a subclass"),
    ("td3", "rehabbot.rl.features.NoSuchPolicy", "cannot be imported"),
    ("td3", "rehabbot.no_such_module.Policy", "cannot be imported"),
    ("ppo", "Mlp", "neither an alias nor a dotted class name"),
    ("ppo", 3, "neither an alias"),
])
def test_bad_policies_are_refused_by_name(tmp_path: Path, algo: str, policy: Any,
                                          why: str) -> None:
    with pytest.raises(HyperparameterError) as caught:
        hyperparameters_from_mapping({"policy": policy}, algo)
    assert repr(policy) in str(caught.value) and why in str(caught.value)
    assert "MlpPolicy" in str(caught.value)  # and says what would do
    assert "this" not in sys.modules
    path = tmp_path / "hp.yml"
    path.write_text(yaml.safe_dump({"default": {"policy": policy}}))
    with pytest.raises(HyperparameterError, match=r"hp\.yml \[default\]: policy"):
        load_hyperparameters(path, ID, algo)


@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_models_with_rehabbot_policies_save_and_load(tmp_path: Path, env, algo: str) -> None:
    hp = load_hyperparameters(algo, ID, algo)
    model = _build(hp, env)
    model.learn(64 if algo == "ppo" else 150)  # a few updates: the weights move
    path = tmp_path / "model.zip"
    model.save(path)
    loaded = _load(algo, path)
    assert type(loaded.policy) is hp.policy and type(_extractor(loaded)) is TrackingErrorFeatures
    assert _structure(loaded) == _structure(model)
    for key, value in model.policy.state_dict().items():
        assert np.array_equal(loaded.policy.state_dict()[key].numpy(), value.numpy()), key
    obs, _ = env.reset(seed=1)
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0],
                                  model.predict(obs, deterministic=True)[0])
    assert load_model(path, env).algo == algo  # what `rehabbot evaluate` does


# --------------------------------------------------------------------------- RL Zoo


ZOO_RUNS = {  # RL Zoo's own --hyperparams overrides keep each run to a few seconds
    "sac": ["buffer_size:1000"],
    "td3": ["buffer_size:1000"],
    "ppo": ["n_steps:64", "batch_size:32", "n_epochs:2"],
}
ZOO_TIMESTEPS = 300


def _zoo_command(algo: str, conf_file: Path, log_folder: Path) -> list[str]:
    return [sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", ID,
            "--gym-packages", "rehabbot", "--conf-file", str(conf_file),
            "-n", str(ZOO_TIMESTEPS), "--eval-freq", "-1", "--log-folder", str(log_folder),
            "--seed", "0", "--num-threads", "1", "--device", "cpu",
            "--hyperparams", *ZOO_RUNS[algo]]


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_rl_zoo_trains_with_the_shipped_file(tmp_path: Path, env, algo: str) -> None:
    pytest.importorskip("rl_zoo3", reason="needs rl_zoo3 (pip install rl_zoo3==2.9.2)")
    conf_file = settings_path(algo)
    before = conf_file.read_bytes()
    env_vars = {**os.environ, "MUJOCO_GL": "egl", "OMP_NUM_THREADS": "1"}
    done = subprocess.run(_zoo_command(algo, conf_file, tmp_path / "logs"), cwd=tmp_path,
                          env=env_vars, capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "Using 'default' hyperparameters" in done.stdout
    assert conf_file.read_bytes() == before
    zips = list((tmp_path / "logs" / algo).glob("*/*.zip"))
    assert len(zips) == 1, zips
    model = _load(algo, zips[0])
    entry = yaml.safe_load(before)["default"]
    policy_kwargs = parse_python_expression(entry.get("policy_kwargs", "dict()"))
    fine = policy_kwargs.get("features_extractor_kwargs", {}).get("fine_scale_rad")
    net_arch = policy_kwargs.get("net_arch", {"pi": [64, 64], "vf": [64, 64]})
    assert f"{type(model.policy).__module__}.{type(model.policy).__name__}" == entry["policy"]
    assert type(_extractor(model)) is TrackingErrorFeatures
    assert _extractor(model).fine_scale_rad == fine and model.policy.net_arch == net_arch
    assert model.num_timesteps >= ZOO_TIMESTEPS
    if algo != "ppo":
        assert model.n_steps == entry["n_steps"] == 10
    if algo == "td3":
        np.testing.assert_allclose(model.action_noise._sigma, entry["noise_std"])
    assert load_model(zips[0], env).algo == algo  # `rehabbot evaluate` runs it


@pytest.mark.slow
@pytest.mark.parametrize("name", settings_names())
def test_rl_zoo_builds_the_model_of_every_shipped_file(tmp_path: Path, name: str) -> None:
    pytest.importorskip("rl_zoo3", reason="needs rl_zoo3 (pip install rl_zoo3==2.9.2)")
    import argparse

    from rl_zoo3.exp_manager import ExperimentManager

    algo = _algo_of(name)
    overrides = dict(SMALL[algo])
    manager = ExperimentManager(argparse.Namespace(), algo, ID, str(tmp_path), eval_freq=-1,
                                hyperparams=overrides, config=str(settings_path(name)),
                                seed=0, verbose=0, device="cpu")
    model, _ = manager.setup_experiment()
    try:
        hp = load_hyperparameters(name, ID, algo)
        expected = hp.policy if not isinstance(hp.policy, str) \
            else algo_class(algo).policy_aliases[hp.policy]
        assert type(model.policy) is expected
        assert _structure(model) == _structure(_build(hp, model.env, **overrides))
    finally:
        model.env.close()
