"""The settings files shipped in ``rehabbot/rl/hyperparams/`` name only the libraries' classes
and are read unchanged by RL Zoo (``python -m rl_zoo3.train --gym-packages rehabbot
--conf-file ...``) and by rehabbot's own loader, which builds the same models; policies are
named by alias or by a library's dotted class name, anything else is refused by name. The RL
Zoo runs are slow (``pytest --full``) and skipped without ``rl_zoo3``."""

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

ID = "rehabbot/rehab-reach-v2"
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


# The shipped entry of ID for each algorithm: (n_timesteps, n_envs, kwargs, policy_kwargs,
# noise_type, noise_std); every policy is the library's MlpPolicy.
SHIPPED = {
    "sac": (100_000, None, {"n_steps": 10, "train_freq": 4, "gradient_steps": 4}, {},
            None, None),
    "td3": (100_000, None, {"n_steps": 10, "train_freq": 4, "gradient_steps": 4}, {},
            "normal", 0.1),
    "ppo": (1_000_000, 8, {"n_steps": 256}, {"log_std_init": -1.0}, None, None),
}


@pytest.mark.parametrize("algo", sorted(SHIPPED))
def test_shipped_settings_values(env, algo: str) -> None:
    hp = load_hyperparameters(algo, ID, algo)
    steps, n_envs, kwargs, policy_kwargs, noise_type, noise_std = SHIPPED[algo]
    assert (hp.entry, hp.policy, hp.n_timesteps, hp.n_envs) == (ID, "MlpPolicy", steps, n_envs)
    assert {k: v for k, v in hp.kwargs.items() if k != "learning_rate"} == \
        {**kwargs, **({"policy_kwargs": policy_kwargs} if policy_kwargs else {})}
    assert (hp.noise_type, hp.noise_std) == (noise_type, noise_std)
    model = _build(hp, env)
    assert type(model.policy) is algo_class(algo).policy_aliases["MlpPolicy"]
    if algo == "ppo":  # a learning rate that decays linearly to 0
        assert hp.given["learning_rate"] == "lin_3e-4" and model.lr_schedule(0.0) == 0.0
    manifest = json.loads(json.dumps(hp.to_manifest()))  # JSON-able
    assert manifest["policy"] == manifest["kwargs"]["policy"] == manifest["given"]["policy"] \
        == "MlpPolicy"


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


def test_a_library_policy_may_be_named_by_its_dotted_name() -> None:
    sb3 = hyperparameters_from_mapping({"policy": "stable_baselines3.sac.policies.MlpPolicy"},
                                       "sac")
    assert sb3.policy is algo_class("sac").policy_aliases["MlpPolicy"]
    assert sb3.policy_name == "stable_baselines3.sac.policies.SACPolicy"


@pytest.mark.parametrize(("algo", "policy", "why"), [
    ("sac", "this.Zen", "outside the packages"),  # `import this` would print: not imported
    ("sac", "os.system", "outside the packages"),
    ("sac", "rehabbot.rl.training.TrainingError", "outside the packages"),
    ("sac", "stable_baselines3.td3.policies.TD3Policy",
     "not a subclass of stable_baselines3.sac.policies.SACPolicy"),
    ("ppo", "stable_baselines3.common.torch_layers.FlattenExtractor",
     "not a subclass of stable_baselines3.common.policies.ActorCriticPolicy"),
    ("td3", "stable_baselines3.td3.policies.__name__", "not a subclass"),
    ("td3", "stable_baselines3.td3.policies.NoSuchPolicy", "cannot be imported"),
    ("td3", "stable_baselines3.no_such_module.Policy", "cannot be imported"),
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


@pytest.mark.parametrize("policy", ["rehabbot.rl.features.TrackingErrorSACPolicy",
                                    "rehabbot.rl.features_jax.TrackingErrorSBXSACPolicy"])
@pytest.mark.parametrize("backend", ["sb3", "sbx"])
def test_settings_naming_a_removed_policy_class_say_so(tmp_path: Path, policy: str,
                                                        backend: str) -> None:
    """rehabbot 0.3's own policy classes are gone: a settings file that names one is refused
    with the class, the issue and the release that still has it, on either backend."""
    if backend == "sbx":
        pytest.importorskip("sbx")
    path = tmp_path / "old.yml"
    path.write_text(yaml.safe_dump({"rehabbot/rehab-reach-v1": {"policy": policy}}))
    with pytest.raises(HyperparameterError) as caught:
        load_hyperparameters(path, "rehab-reach-v1", "sac", backend)
    assert str(caught.value) == (
        f"{path} [rehabbot/rehab-reach-v1]: the policy class {policy} is refused: rehabbot "
        "does not define it (the -v2 ids observe what an agent needs, and the libraries' "
        "own MlpPolicy learns them); rehabbot at commit 51d9d71 defines and loads it")


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
    assert conf_file.read_bytes() == before
    zips = list((tmp_path / "logs" / algo).glob("*/*.zip"))
    assert len(zips) == 1, zips
    model = _load(algo, zips[0])
    entry = yaml.safe_load(before)[ID]  # the id's own entry, as rehabbot reads it
    hp = load_hyperparameters(algo, ID, algo)
    assert entry["policy"] == "MlpPolicy"
    assert type(model.policy) is algo_class(algo).policy_aliases["MlpPolicy"]
    assert _structure(model) == _structure(_build(hp, env, **SMALL[algo]))
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
