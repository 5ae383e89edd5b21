"""A Stable-Baselines3 features extractor for the RehabBot observation: the observation itself
plus the tracking errors that the reward is made of, and the SB3 policies that use it.

The paper's 23-D observation holds the target and the current joint angles (theta*, theta)
and tool positions (p*, p) side by side; the reward and every good action depend on their
differences. :class:`TrackingErrorFeatures` appends ``theta* - theta`` (6) and ``p* - p`` (3)
to the observation (32 features), so that the first layer of the actor and of the critic
sees the error directly instead of having to learn to subtract. It has no parameters and
leaves the env's spaces untouched: it is a choice of the agent's network, made in a
hyperparameter file by naming one of the policies below, which are SB3's own with this
extractor as their default::

    policy: rehabbot.rl.features.TrackingErrorSACPolicy
    policy_kwargs: "dict(features_extractor_kwargs=dict(fine_scale_rad=0.05), net_arch=[64, 64])"

Both ``rehabbot train`` and RL Zoo (``python -m rl_zoo3.train --gym-packages rehabbot``) import
a dotted ``policy``, and a model saved with one loads back with ``SAC.load``. (``rehabbot
train`` also reads the older ``policy_kwargs: "dict(features_extractor_class=
TrackingErrorFeatures)"``, which RL Zoo cannot; in Python pass the classes themselves.) The
extractor needs the unnormalised observation layout of :mod:`rehabbot.tasks.observation` (23
values); VecNormalize'd observations still work, since normalisation is affine per entry, but
the errors are then in normalised units. :func:`rehabbot.rl.features_numpy.
tracking_error_features` computes the same features in NumPy (for exported agents,
:mod:`rehabbot.rl.zoo`).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.sac.policies import SACPolicy
from stable_baselines3.td3.policies import TD3Policy

from rehabbot.rl.features_numpy import (
    JOINT_ERROR_SCALE_RAD,
    TOOL_ERROR_SCALE_M,
    action_bound_units,
)
from rehabbot.tasks.observation import tracking_slices


class TrackingErrorFeatures(BaseFeaturesExtractor):
    """``[obs scaled to [-1, 1], (theta* - theta) / 0.5 rad, (p* - p) / 0.1 m]``: 23 + 6 + 3 =
    32 features, no parameters. With ``fine_scale_rad`` (e.g. the target tolerance, 0.05 rad)
    six more: ``tanh((theta* - theta) / fine_scale_rad)``, which resolve the last few
    hundredths of a radian that decide whether a target counts as reached."""

    def __init__(self, observation_space: gym.spaces.Box, scale_to_bounds: bool = True,
                 fine_scale_rad: float | None = None) -> None:
        shape = observation_space.shape
        try:
            slices = tracking_slices(shape[0]) if len(shape) == 1 else None
        except ValueError:
            slices = None
        if slices is None:
            raise ValueError(f"TrackingErrorFeatures needs a RehabBot observation (2 n + 11 "
                             f"values for a robot of n joints, 4 n + 20 for two), got {shape}")
        if fine_scale_rad is not None and not fine_scale_rad > 0:
            raise ValueError(f"fine_scale_rad={fine_scale_rad!r} must be > 0 or None")
        self._theta_star, self._p_star, self._theta, self._p = slices
        joints = self._theta.stop - self._theta.start
        errors = joints + self._p.stop - self._p.start
        fine = 0 if fine_scale_rad is None else joints
        super().__init__(observation_space, features_dim=shape[0] + errors + fine)
        self.fine_scale_rad = fine_scale_rad
        low = torch.as_tensor(observation_space.low, dtype=torch.float32)
        high = torch.as_tensor(observation_space.high, dtype=torch.float32)
        if not scale_to_bounds:
            low, high = -torch.ones_like(low), torch.ones_like(high)
        self.register_buffer("_center", (high + low) / 2)
        self.register_buffer("_half_range", (high - low) / 2)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        joint_error = (observations[:, self._theta_star] - observations[:, self._theta]) \
            / JOINT_ERROR_SCALE_RAD
        tool_error = (observations[:, self._p_star] - observations[:, self._p]) \
            / TOOL_ERROR_SCALE_M
        scaled = (observations - self._center) / self._half_range
        if self.fine_scale_rad is None:
            return torch.cat((scaled, joint_error, tool_error), dim=1)
        fine = torch.tanh(joint_error * (JOINT_ERROR_SCALE_RAD / self.fine_scale_rad))
        return torch.cat((scaled, joint_error, tool_error, fine), dim=1)


# --------------------------------------------------------------------------- policies
# SB3 builds a policy as ``policy_class(observation_space, action_space, lr_schedule,
# **policy_kwargs)``: the extractor is a keyword argument, so a ``features_extractor_class``
# in policy_kwargs still overrides the default below.


class TrackingErrorSACPolicy(SACPolicy):
    """SB3's SAC ``MlpPolicy`` with :class:`TrackingErrorFeatures` as its default extractor."""

    def __init__(self, *args: Any,
                 features_extractor_class: type[BaseFeaturesExtractor] = TrackingErrorFeatures,
                 **kwargs: Any) -> None:
        super().__init__(*args, features_extractor_class=features_extractor_class, **kwargs)


class TrackingErrorTD3Policy(TD3Policy):
    """SB3's TD3 ``MlpPolicy`` with :class:`TrackingErrorFeatures` as its default extractor."""

    def __init__(self, *args: Any,
                 features_extractor_class: type[BaseFeaturesExtractor] = TrackingErrorFeatures,
                 **kwargs: Any) -> None:
        super().__init__(*args, features_extractor_class=features_extractor_class, **kwargs)


class TrackingErrorActorCriticPolicy(ActorCriticPolicy):
    """SB3's PPO (and A2C) ``MlpPolicy`` with :class:`TrackingErrorFeatures` as its default
    extractor."""

    def __init__(self, *args: Any,
                 features_extractor_class: type[BaseFeaturesExtractor] = TrackingErrorFeatures,
                 **kwargs: Any) -> None:
        super().__init__(*args, features_extractor_class=features_extractor_class, **kwargs)


class TrackingErrorNormalizedActionPolicy(TrackingErrorActorCriticPolicy):
    """:class:`TrackingErrorActorCriticPolicy` whose Gaussian lives in units of the action bound:
    the network's output ``u`` and ``log_std`` give the action ``center + half * u`` with
    standard deviation ``half * exp(log_std)``, where ``center`` and ``half`` are the middle and
    half-width of the action box.

    Why: the RehabBot action is a setpoint step of at most ``pi/400`` rad, and SB3's PPO draws
    its Gaussian in the action's own units. With ``log_std_init=0`` its standard deviation is
    127 times the bound (``-2``: 17 times), so nearly every sampled action is clipped to a
    corner of the box whatever the mean: exploration is bang-bang noise, which on the leg ids
    drives the cuff into its force limit, and one Adam step on the output layer moves the mean
    by more than the whole bound. Here the noise is a fraction of the bound and the network's
    output is of order one, as for an env whose action box is ``[-1, 1]`` (Stable-Baselines3's
    advice), while the env keeps its action space. gSDE is not supported.
    """

    ACTIONS_IN_BOUND_UNITS = True

    def __init__(self, observation_space: gym.spaces.Space, action_space: gym.spaces.Space,
                 *args: Any, **kwargs: Any) -> None:
        center, half = action_bound_units(action_space)
        if kwargs.get("use_sde"):
            raise ValueError(f"{type(self).__name__} does not support gSDE (use_sde=True)")
        super().__init__(observation_space, action_space, *args, **kwargs)
        self.register_buffer("action_center", torch.as_tensor(center))
        self.register_buffer("action_half", torch.as_tensor(half))

    def _get_action_dist_from_latent(self, latent_pi: torch.Tensor) -> Any:
        mean_units = self.action_net(latent_pi)
        return self.action_dist.proba_distribution(
            self.action_center + self.action_half * mean_units,
            self.log_std + torch.log(self.action_half))


# The policy of each algorithm in the shipped settings files.
TRACKING_ERROR_POLICIES = {"sac": TrackingErrorSACPolicy, "td3": TrackingErrorTD3Policy,
                           "ppo": TrackingErrorActorCriticPolicy}
