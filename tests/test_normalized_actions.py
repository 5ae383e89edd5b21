"""PPO's Gaussian in units of the action bound (``TrackingErrorNormalizedActionPolicy`` and its
JAX twin ``TrackingErrorSBXNormalizedPPOPolicy``): the mean is ``center + half * u``, the
standard deviation ``half * exp(log_std)``, so exploration stays mostly inside the action box
(with SB3's plain Gaussian it is clipped to the box's corners), the two backends agree, the
zoo exports the scaling, and bad spaces are refused."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.rl.features_numpy import action_bound_units

torch = pytest.importorskip("torch")
from stable_baselines3 import PPO  # noqa: E402

from rehabbot.rl.features import (  # noqa: E402
    TrackingErrorActorCriticPolicy,
    TrackingErrorNormalizedActionPolicy,
)

FULL_ID = "rehabbot/rehab-hip-v1"


@pytest.fixture(scope="module")
def env() -> gym.Env:
    return gym.make(FULL_ID)


@pytest.fixture(scope="module")
def observations(env) -> np.ndarray:
    env.observation_space.seed(2)
    resets = [env.reset(seed=k)[0] for k in range(3)]
    return np.stack(resets + [env.observation_space.sample() for _ in range(20)])


def _inside_share(actions: np.ndarray, space: gym.spaces.Box) -> float:
    return float(np.mean((actions > space.low) & (actions < space.high)))


def test_action_bound_units_of_the_env(env) -> None:
    center, half = action_bound_units(env.action_space)
    np.testing.assert_allclose(center, 0.0, atol=1e-9)
    np.testing.assert_allclose(half, np.pi / 400, rtol=1e-6)  # a setpoint step of pi/400 rad
    with pytest.raises(ValueError, match="bounded Box action space, got Box"):
        action_bound_units(gym.spaces.Box(-np.inf, np.inf, (2,)))
    with pytest.raises(ValueError, match="got Discrete"):
        action_bound_units(gym.spaces.Discrete(3))


def test_sb3_gaussian_lives_in_units_of_the_bound(env, observations) -> None:
    model = PPO(TrackingErrorNormalizedActionPolicy, env, seed=0, device="cpu",
                policy_kwargs={"log_std_init": -1.0})
    policy = model.policy
    center, half = action_bound_units(env.action_space)
    obs_t = torch.as_tensor(observations)
    with torch.no_grad():
        dist = policy.get_distribution(obs_t).distribution
        features = policy.extract_features(obs_t)
        units = policy.action_net(policy.mlp_extractor.forward_actor(features))
    np.testing.assert_allclose(dist.mean.numpy(), center + half * units.numpy(), atol=1e-9)
    np.testing.assert_allclose(dist.stddev.numpy(), np.broadcast_to(half * np.exp(-1.0),
                                                                     dist.stddev.shape),
                               rtol=1e-5)
    # Exploration stays inside the box; SB3's plain Gaussian with log_std -2 (std 17x the
    # bound) is clipped to a face of the box in nearly every coordinate.
    with torch.no_grad():
        sampled = policy.get_distribution(obs_t).sample().numpy()
    assert _inside_share(sampled, env.action_space) > 0.9
    plain = PPO(TrackingErrorActorCriticPolicy, env, seed=0, device="cpu",
                policy_kwargs={"log_std_init": -2.0})
    with torch.no_grad():
        wild = plain.policy.get_distribution(obs_t).sample().numpy()
    assert _inside_share(wild, env.action_space) < 0.1


def test_sb3_refuses_gsde(env) -> None:
    with pytest.raises(ValueError, match=r"does not support gSDE \(use_sde=True\)"):
        PPO(TrackingErrorNormalizedActionPolicy, env, use_sde=True, device="cpu")


@pytest.mark.slow
def test_sb3_model_saves_loads_and_exports(env, observations, tmp_path) -> None:
    from rehabbot.rl.zoo import export_policy, load_file

    model = PPO(TrackingErrorNormalizedActionPolicy, env, n_steps=64, batch_size=32,
                n_epochs=2, seed=0, device="cpu")
    model.learn(128)
    model.save(tmp_path / "model.zip")
    loaded = PPO.load(tmp_path / "model.zip", device="cpu")
    expected, _ = model.predict(observations, deterministic=True)
    np.testing.assert_array_equal(loaded.predict(observations, deterministic=True)[0], expected)
    export_policy(model, "rehab-hip-v1", "ppo", tmp_path / "ppo.npz", episodes=0)
    exported = load_file(tmp_path / "ppo.npz")
    assert list(exported.ops[-2:]) == ["unscale", "clip"]
    half = action_bound_units(env.action_space)[1]
    actual, _ = exported.predict(observations)
    assert np.max(np.abs(actual - expected) / half) < 1e-5


def test_sbx_gaussian_matches_the_sb3_definition(env, observations) -> None:
    sbx = pytest.importorskip("sbx")
    import jax

    from rehabbot.rl.features_jax import TrackingErrorPPOActor, TrackingErrorSBXNormalizedPPOPolicy

    model = sbx.PPO(TrackingErrorSBXNormalizedPPOPolicy, env, seed=0,
                    policy_kwargs={"log_std_init": -1.0, "fine_scale_rad": 0.05})
    state = model.policy.actor_state
    center, half = action_bound_units(env.action_space)
    dist = state.apply_fn(state.params, observations)
    # The same network without the scaling: its mean is u, its std exp(log_std).
    units = TrackingErrorPPOActor(
        **{f: getattr(model.policy.actor, f) for f in (
            "action_dim", "net_arch", "log_std_init", "activation_fn", "center",
            "half_range", "fine_scale_rad")}).apply(state.params, observations)
    np.testing.assert_allclose(np.asarray(dist.mean()),
                               center + half * np.asarray(units.mean()), atol=1e-9)
    np.testing.assert_allclose(np.asarray(dist.stddev()),
                               np.broadcast_to(half * np.exp(-1.0), (len(observations), 6)),
                               rtol=1e-5)
    sampled = np.asarray(dist.sample(seed=jax.random.PRNGKey(0)))
    assert _inside_share(sampled, env.action_space) > 0.9


@pytest.mark.slow
def test_sbx_settings_load_save_and_export(env, observations, tmp_path) -> None:
    sbx = pytest.importorskip("sbx")
    from rehabbot.rl.features_jax import TrackingErrorSBXNormalizedPPOPolicy
    from rehabbot.rl.hyperparams import hyperparameters_from_mapping
    from rehabbot.rl.zoo import export_policy, load_file

    hp = hyperparameters_from_mapping(
        {"policy": "rehabbot.rl.features.TrackingErrorNormalizedActionPolicy",
         "policy_kwargs": "dict(log_std_init=-1.0, "
                          "features_extractor_kwargs=dict(fine_scale_rad=0.05))"},
        "ppo", backend="sbx")
    assert hp.policy is TrackingErrorSBXNormalizedPPOPolicy
    assert hp.kwargs["policy_kwargs"] == {"log_std_init": -1.0, "fine_scale_rad": 0.05}
    model = sbx.PPO(hp.policy, env, n_steps=64, batch_size=32, n_epochs=2, seed=0,
                    policy_kwargs=hp.kwargs["policy_kwargs"])
    model.learn(128)
    model.save(tmp_path / "model.zip")
    loaded = sbx.PPO.load(tmp_path / "model.zip")
    assert type(loaded.policy) is TrackingErrorSBXNormalizedPPOPolicy
    expected, _ = model.predict(observations, deterministic=True)
    np.testing.assert_array_equal(loaded.predict(observations, deterministic=True)[0], expected)
    # The loaded model is exported: its activation (jax.numpy.tanh, jitted) comes back from
    # the zip without a name.
    export_policy(loaded, "rehab-hip-v1", "ppo", tmp_path / "ppo.npz", episodes=0)
    exported = load_file(tmp_path / "ppo.npz")
    assert exported.ops[0] == "tracking_error" and list(exported.ops[-2:]) == ["unscale", "clip"]
    half = action_bound_units(env.action_space)[1]
    actual, _ = exported.predict(observations)
    assert np.max(np.abs(actual - expected) / half) < 1e-5
