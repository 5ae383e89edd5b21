"""``rehabbot.rl.features``: TrackingErrorFeatures, the agent-side features of the tuned settings,
and the SB3 policies that use it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import rehabbot  # noqa: F401
from rehabbot.rl.features import (
    JOINT_ERROR_SCALE_RAD,
    TOOL_ERROR_SCALE_M,
    TrackingErrorFeatures,
)
from rehabbot.rl.hyperparams import hyperparameters_from_mapping, load_hyperparameters
from rehabbot.tasks.observation import P_STAR, THETA, THETA_STAR, P

ID = "rehabbot/rehab-reach-v0"


@pytest.fixture(scope="module")
def env() -> gym.Env:
    return gym.make(ID)


def test_features_are_scaled_observation_plus_errors(env) -> None:
    extractor = TrackingErrorFeatures(env.observation_space)
    obs, _ = env.reset(seed=0)
    batch = np.stack([obs, env.observation_space.sample()])
    features = extractor(torch.as_tensor(batch)).numpy()
    assert features.shape == (2, 32) and extractor.features_dim == 32
    low, high = env.observation_space.low, env.observation_space.high
    # Observations inside their bounds map into [-1, 1], bounds to -1 and +1.
    assert np.all(np.abs(features[:, :23]) <= 1 + 1e-5)
    edges = extractor(torch.as_tensor(np.stack([low, high]))).numpy()[:, :23]
    np.testing.assert_allclose(edges, [[-1] * 23, [1] * 23], atol=1e-5)
    # The appended errors are exactly theta* - theta and p* - p, in their scales.
    np.testing.assert_allclose(features[:, 23:29],
                               (batch[:, THETA_STAR] - batch[:, THETA]) / JOINT_ERROR_SCALE_RAD,
                               rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(features[:, 29:32],
                               (batch[:, P_STAR] - batch[:, P]) / TOOL_ERROR_SCALE_M,
                               rtol=1e-5, atol=1e-5)
    assert not list(extractor.parameters())  # nothing to learn: it is a fixed transform


def test_fine_features_resolve_errors_near_the_tolerance(env) -> None:
    extractor = TrackingErrorFeatures(env.observation_space, fine_scale_rad=0.05)
    obs, _ = env.reset(seed=0)
    obs = obs.copy()
    error = np.array([0.0, 0.02, -0.05, 0.07, 0.5, -2.0], np.float32)
    obs[THETA] = obs[THETA_STAR] - error
    features = extractor(torch.as_tensor(obs[None])).numpy()[0]
    assert features.shape == (38,) and extractor.features_dim == 38
    np.testing.assert_allclose(features[32:], np.tanh(error / 0.05), atol=1e-4)
    # 0.05 rad (the tolerance) is tanh(1) = 0.76: near the target the fine features still
    # change by ~0.4 per 0.02 rad, where the coarse ones change by 0.04.
    assert features[32 + 2] == pytest.approx(-np.tanh(1.0), abs=1e-4)
    with pytest.raises(ValueError, match="fine_scale_rad"):
        TrackingErrorFeatures(env.observation_space, fine_scale_rad=0.0)


def test_other_observation_shapes_are_refused() -> None:
    # Any robot's layout (2 n + 11) and the two-arm one (4 n + 20) are read; others refused.
    for shape in [(3,), (26,), (23, 2)]:
        with pytest.raises(ValueError, match=rf"2 n \+ 11 .*got \({shape[0]},"):
            TrackingErrorFeatures(gym.spaces.Box(-1, 1, shape))


@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_shipped_settings_build_the_extractor_into_each_algorithm(env, algo: str) -> None:
    from rehabbot.rl.algorithms import algo_class
    from rehabbot.rl.features import TRACKING_ERROR_POLICIES

    hp = load_hyperparameters(algo, ID, algo)  # the settings file shipped with the package
    assert hp.policy is TRACKING_ERROR_POLICIES[algo]
    assert issubclass(hp.policy, algo_class(algo).policy_aliases["MlpPolicy"])
    kwargs = hp.kwargs.get("policy_kwargs", {})
    assert "features_extractor_class" not in kwargs  # the policy's default: RL Zoo reads it
    model = algo_class(algo)(hp.policy, env, policy_kwargs=kwargs, seed=0,
                             **({"n_steps": 64, "batch_size": 32} if algo == "ppo" else
                                {"buffer_size": 100}))
    extractor = (model.policy.actor.features_extractor if algo != "ppo"
                 else model.policy.features_extractor)
    assert isinstance(extractor, TrackingErrorFeatures)
    if algo != "ppo":  # the critics have their own extractor, of the same kind
        assert isinstance(model.policy.critic.features_extractor, TrackingErrorFeatures)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action)


def test_old_spelling_still_names_the_extractor() -> None:
    """Users' own files may name the extractor in policy_kwargs, as the shipped ones did."""
    for name in ("TrackingErrorFeatures", "rehabbot.rl.features.TrackingErrorFeatures",
                 "rehabbot.features.TrackingErrorFeatures"):
        hp = hyperparameters_from_mapping(
            {"policy_kwargs": f"dict(features_extractor_class={name}, net_arch=[64, 64])"},
            "sac")
        assert hp.policy == "MlpPolicy"
        assert hp.kwargs["policy_kwargs"]["features_extractor_class"] is TrackingErrorFeatures
