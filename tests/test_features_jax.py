"""Tracking-error features on the SBX backend (``rehabbot.rl.features_jax``): the JAX features
equal the NumPy and PyTorch ones, SBX's SAC, TD3 and PPO networks read them (their first layer
has 38 inputs, or 32 without the fine errors, not 23), the shipped ``sac``/``td3``/``ppo``
settings build them on SBX, a saved model loads with them, and the zoo exports them."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.rl.features_numpy import bounds_scaling, tracking_error_features
from rehabbot.rl.hyperparams import load_hyperparameters

pytest.importorskip("sbx")
from rehabbot.rl.features_jax import (
    TrackingErrorSBXNormalizedPPOPolicy,
    TrackingErrorSBXPPOPolicy,
    TrackingErrorSBXSACPolicy,
    TrackingErrorSBXTD3Policy,
    tracking_error_features_jax,
)

FULL_ID = "rehabbot/rehab-reach-v1"
FEATURES = 38  # 23 scaled + 6 joint errors + 3 tool errors + 6 fine joint errors


@pytest.fixture(scope="module")
def env() -> gym.Env:
    return gym.make(FULL_ID)


@pytest.fixture(scope="module")
def observations(env) -> np.ndarray:
    env.observation_space.seed(1)
    resets = [env.reset(seed=k)[0] for k in range(3)]
    return np.stack(resets + [env.observation_space.sample() for _ in range(40)])


def test_jax_features_equal_numpy_and_torch(env, observations) -> None:
    center, half_range = bounds_scaling(env.observation_space.low, env.observation_space.high)
    expected = tracking_error_features(observations, center, half_range, 0.05)
    actual = np.asarray(tracking_error_features_jax(observations, tuple(center),
                                                    tuple(half_range), 0.05))
    assert actual.shape == (len(observations), FEATURES)
    assert np.max(np.abs(actual - expected)) < 1e-5
    coarse = np.asarray(tracking_error_features_jax(observations, tuple(center),
                                                    tuple(half_range), None))
    assert coarse.shape == (len(observations), FEATURES - 6)

    torch = pytest.importorskip("torch")
    from rehabbot.rl.features import TrackingErrorFeatures

    extractor = TrackingErrorFeatures(env.observation_space, fine_scale_rad=0.05)
    with torch.no_grad():
        reference = extractor(torch.as_tensor(observations)).numpy()
    assert np.max(np.abs(actual - reference)) < 1e-5


def _first_kernel_inputs(params) -> int:
    """Input size of the first dense layer found in a (possibly vmapped) Flax param tree."""
    tree = params.get("params", params)
    while "Dense_0" not in tree:
        tree = next(iter(tree.values()))
    return int(tree["Dense_0"]["kernel"].shape[-2])


SHIPPED = {"sac": (TrackingErrorSBXSACPolicy, {"fine_scale_rad": 0.05, "net_arch": [64, 64]},
                   FEATURES),
           "td3": (TrackingErrorSBXTD3Policy, {"fine_scale_rad": 0.05, "net_arch": [64, 64]},
                   FEATURES),
           "ppo": (TrackingErrorSBXNormalizedPPOPolicy,
                   {"log_std_init": -1.0, "fine_scale_rad": 0.05}, FEATURES)}


def _small_model(algo: str, policy, env, policy_kwargs):
    import sbx

    if algo == "ppo":
        return sbx.PPO(policy, env, n_steps=64, batch_size=32, n_epochs=2, seed=0,
                       policy_kwargs=policy_kwargs)
    cls = {"sac": sbx.SAC, "td3": sbx.TD3}[algo]
    return cls(policy, env, learning_starts=50, batch_size=32, buffer_size=500, seed=0,
               policy_kwargs=policy_kwargs)


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_shipped_settings_build_the_feature_network_on_sbx(algo, env, tmp_path) -> None:
    hp = load_hyperparameters(algo, FULL_ID, algo, "sbx")
    expected_class, expected_kwargs, n_features = SHIPPED[algo]
    assert hp.policy is expected_class
    assert (hp.kwargs.get("policy_kwargs") or {}) == expected_kwargs
    assert [c["key"] for c in hp.backend_changes] == ["policy"]
    assert hp.backend_changes[0]["used"] == f"rehabbot.rl.features_jax.{expected_class.__name__}"

    model = _small_model(algo, hp.policy, env, hp.kwargs.get("policy_kwargs"))
    model.learn(130)
    # The actor and the critics read the features (Q-critics: the features + the 6 actions;
    # PPO's value network: the features).
    assert _first_kernel_inputs(model.policy.actor_state.params) == n_features
    if algo == "ppo":
        assert _first_kernel_inputs(model.policy.vf_state.params) == n_features
    else:
        assert _first_kernel_inputs(model.policy.qf_state.params) == n_features + 6
    # Saved and loaded, the model acts the same.
    model.save(tmp_path / "model.zip")
    loaded = type(model).load(tmp_path / "model.zip")
    assert type(loaded.policy) is expected_class
    obs = env.reset(seed=3)[0]
    assert np.array_equal(model.predict(obs, deterministic=True)[0],
                          loaded.predict(obs, deterministic=True)[0])


@pytest.mark.slow
def test_features_change_the_action_with_the_target(env) -> None:
    """Two observations that differ only in theta* get different actions from a fresh actor,
    and moving theta and theta* together keeps the error features (not the action) equal."""
    import sbx

    model = sbx.SAC(TrackingErrorSBXSACPolicy, env, seed=0,
                    policy_kwargs={"fine_scale_rad": 0.05, "net_arch": [16]})
    obs = env.reset(seed=0)[0]
    moved = obs.copy()
    moved[0] += 0.3  # theta*_0
    assert not np.allclose(model.predict(obs, deterministic=True)[0],
                           model.predict(moved, deterministic=True)[0])


def test_non_rehabbot_observation_and_bad_scale_are_refused() -> None:
    import sbx

    with pytest.raises(ValueError, match=r"RehabBot observation .* got \(3,\)"):
        sbx.SAC(TrackingErrorSBXSACPolicy, gym.make("Pendulum-v1"))
    with pytest.raises(ValueError, match=r"fine_scale_rad=-1\.0 must be > 0"):
        sbx.SAC(TrackingErrorSBXSACPolicy, gym.make(FULL_ID),
                policy_kwargs={"fine_scale_rad": -1.0})


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_zoo_exports_the_feature_actor(algo, env, observations, tmp_path) -> None:
    from rehabbot.rl.zoo import export_policy, load_file

    # PPO: the plain Gaussian (the normalized one: tests/test_normalized_actions.py).
    policy = TrackingErrorSBXPPOPolicy if algo == "ppo" else SHIPPED[algo][0]
    model = _small_model(algo, policy, env, {"fine_scale_rad": 0.05, "net_arch": [32, 32]})
    model.learn(130)
    export_policy(model, "rehab-reach-v1", algo, tmp_path / f"{algo}.npz", episodes=0)
    exported = load_file(tmp_path / f"{algo}.npz")
    assert exported.ops[0] == "tracking_error"
    expected, _ = model.predict(observations, deterministic=True)
    actual, _ = exported.predict(observations)
    assert np.max(np.abs(actual - expected)) < 1e-5
