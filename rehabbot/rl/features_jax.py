"""Tracking-error features for the SBX (JAX) backend: the features of
:class:`rehabbot.rl.features.TrackingErrorFeatures`, computed inside SBX's actor and critic
networks, so that the shipped ``sac`` and ``td3`` settings build the same network on both
backends.

SBX's policies have no features extractor: its networks read the observation as it is. Here
the first step of the actor's and the critics' forward pass maps the observation to::

    [(obs - center) / half_range,            23: the observation scaled to [-1, 1]
     (theta* - theta) / 0.5 rad,              6: joint tracking errors
     (p* - p) / 0.1 m,                        3: tool tracking errors
     tanh((theta* - theta) / fine_scale_rad)] 6: only when fine_scale_rad is given

in the order of operations of :func:`rehabbot.rl.features_numpy.tracking_error_features`
(``tests/test_features_jax.py`` compares the three implementations). The replay buffer keeps
the observation as the env returned it; the env's spaces are unchanged.

Why it matters: with a plain MLP, SAC on the ``-v1`` ids learned one direction per joint and
pushed it whatever the target (README, Results); its critic ranked the expert's action below
its reverse on later targets of an exercise, which the agent rarely reaches early in training.
The tracking errors make "towards the active target" the same feature on every target.

Classes:

* :class:`TrackingErrorSBXSACPolicy`: SBX's SAC ``MlpPolicy`` with these features in the actor
  and both critics (``policy_kwargs``: ``fine_scale_rad``, ``scale_to_bounds`` as
  ``features_extractor_kwargs`` of the PyTorch policy).
* :class:`TrackingErrorSBXTD3Policy`: the same for SBX's TD3.
* :class:`TrackingErrorSBXPPOPolicy`: the same for SBX's PPO (its Gaussian actor and its value
  network), the counterpart of ``TrackingErrorActorCriticPolicy``;
  :class:`TrackingErrorSBXNormalizedPPOPolicy` also draws the Gaussian in units of the action
  bound (``TrackingErrorNormalizedActionPolicy``).

This module imports JAX, Flax and SBX: import it only when the SBX backend is used.
"""

from __future__ import annotations

import functools
from typing import Any

import jax.numpy as jnp
import numpy as np
import tensorflow_probability.substrates.jax as tfp
from sbx.common.policies import SquashedGaussianActor, VectorCritic
from sbx.ppo.policies import Actor as PPOActor
from sbx.ppo.policies import Critic as PPOCritic
from sbx.ppo.policies import PPOPolicy
from sbx.sac.policies import SACPolicy
from sbx.td3.policies import Actor as TD3Actor
from sbx.td3.policies import TD3Policy

from rehabbot.rl.features_numpy import (
    JOINT_ERROR_SCALE_RAD,
    TOOL_ERROR_SCALE_M,
    action_bound_units,
    bounds_scaling,
)
from rehabbot.tasks.observation import tracking_slices


def tracking_error_features_jax(obs: jnp.ndarray, center: tuple[float, ...],
                                half_range: tuple[float, ...],
                                fine_scale_rad: float | None) -> jnp.ndarray:
    """The features of a batch ``obs`` of shape ``(n, 23)`` (module docstring)."""
    obs = obs.reshape((obs.shape[0], -1)).astype(jnp.float32)
    theta_star, p_star, theta, p = tracking_slices(obs.shape[1])
    joint_error = (obs[:, theta_star] - obs[:, theta]) / np.float32(JOINT_ERROR_SCALE_RAD)
    tool_error = (obs[:, p_star] - obs[:, p]) / np.float32(TOOL_ERROR_SCALE_M)
    scaled = (obs - jnp.asarray(center, jnp.float32)) / jnp.asarray(half_range, jnp.float32)
    parts = [scaled, joint_error, tool_error]
    if fine_scale_rad is not None:
        parts.append(jnp.tanh(joint_error * np.float32(JOINT_ERROR_SCALE_RAD / fine_scale_rad)))
    return jnp.concatenate(parts, axis=1)


# Each module below carries the feature constants as Flax fields (hashable tuples, so that
# Flax can compare module definitions): center, half_range, fine_scale_rad.


class TrackingErrorActor(SquashedGaussianActor):
    """SBX's SAC actor (a tanh-squashed Gaussian) reading the tracking-error features."""

    center: tuple[float, ...] = ()
    half_range: tuple[float, ...] = ()
    fine_scale_rad: float | None = None

    def __call__(self, x: jnp.ndarray) -> Any:
        features = tracking_error_features_jax(x, self.center, self.half_range,
                                               self.fine_scale_rad)
        return SquashedGaussianActor.__call__(self, features)


class TrackingErrorTD3Actor(TD3Actor):
    """SBX's TD3 actor reading the tracking-error features."""

    center: tuple[float, ...] = ()
    half_range: tuple[float, ...] = ()
    fine_scale_rad: float | None = None

    def __call__(self, x: jnp.ndarray) -> jnp.ndarray:
        features = tracking_error_features_jax(x, self.center, self.half_range,
                                               self.fine_scale_rad)
        return TD3Actor.__call__(self, features)


class TrackingErrorVectorCritic(VectorCritic):
    """SBX's ensemble of Q-networks reading the tracking-error features and the action."""

    center: tuple[float, ...] = ()
    half_range: tuple[float, ...] = ()
    fine_scale_rad: float | None = None

    def __call__(self, obs: jnp.ndarray, action: jnp.ndarray) -> jnp.ndarray:
        features = tracking_error_features_jax(obs, self.center, self.half_range,
                                               self.fine_scale_rad)
        return VectorCritic.__call__(self, features, action)


class TrackingErrorPPOActor(PPOActor):
    """SBX's PPO actor (a diagonal Gaussian) reading the tracking-error features."""

    center: tuple[float, ...] = ()
    half_range: tuple[float, ...] = ()
    fine_scale_rad: float | None = None

    def __call__(self, x: jnp.ndarray) -> Any:
        features = tracking_error_features_jax(x, self.center, self.half_range,
                                               self.fine_scale_rad)
        return PPOActor.__call__(self, features)


class TrackingErrorPPOCritic(PPOCritic):
    """SBX's PPO value network reading the tracking-error features."""

    center: tuple[float, ...] = ()
    half_range: tuple[float, ...] = ()
    fine_scale_rad: float | None = None

    def __call__(self, x: jnp.ndarray) -> jnp.ndarray:
        features = tracking_error_features_jax(x, self.center, self.half_range,
                                               self.fine_scale_rad)
        return PPOCritic.__call__(self, features)


class TrackingErrorNormalizedPPOActor(TrackingErrorPPOActor):
    """:class:`TrackingErrorPPOActor` whose Gaussian lives in units of the action bound: the
    action is ``action_center + action_half * u`` with standard deviation
    ``action_half * exp(log_std)`` (see
    :class:`rehabbot.rl.features.TrackingErrorNormalizedActionPolicy`)."""

    action_center: tuple[float, ...] = ()
    action_half: tuple[float, ...] = ()

    def __call__(self, x: jnp.ndarray) -> Any:
        units = TrackingErrorPPOActor.__call__(self, x)
        center = jnp.asarray(self.action_center, jnp.float32)
        half = jnp.asarray(self.action_half, jnp.float32)
        return tfp.distributions.MultivariateNormalDiag(loc=center + half * units.mean(),
                                                        scale_diag=half * units.stddev())


def _feature_fields(observation_space: Any, scale_to_bounds: bool,
                    fine_scale_rad: float | None) -> dict[str, Any]:
    shape = observation_space.shape
    try:
        tracking_slices(shape[0]) if len(shape) == 1 else None
    except ValueError:
        shape = None
    if shape is None or len(shape) != 1:
        raise ValueError(f"tracking-error features need a RehabBot observation (2 n + 11 "
                         f"values for a robot of n joints, 4 n + 20 for two), got "
                         f"{observation_space.shape}")
    if fine_scale_rad is not None and not fine_scale_rad > 0:
        raise ValueError(f"fine_scale_rad={fine_scale_rad!r} must be > 0 or None")
    center, half_range = bounds_scaling(observation_space.low, observation_space.high,
                                        scale_to_bounds)
    return {"center": tuple(float(v) for v in center),
            "half_range": tuple(float(v) for v in half_range),
            "fine_scale_rad": None if fine_scale_rad is None else float(fine_scale_rad)}


class TrackingErrorSBXSACPolicy(SACPolicy):
    """SBX's SAC ``MlpPolicy`` whose actor and critics read the tracking-error features.

    ``scale_to_bounds`` and ``fine_scale_rad`` mean what they mean for
    :class:`rehabbot.rl.features.TrackingErrorFeatures`; every other argument is SBX's."""

    ALGO = "sac"
    FEATURE_KWARGS = ("scale_to_bounds", "fine_scale_rad")

    def __init__(self, observation_space: Any, action_space: Any, lr_schedule: Any,
                 *args: Any, scale_to_bounds: bool = True,
                 fine_scale_rad: float | None = None, **kwargs: Any) -> None:
        fields = _feature_fields(observation_space, scale_to_bounds, fine_scale_rad)
        kwargs.setdefault("actor_class", functools.partial(TrackingErrorActor, **fields))
        kwargs.setdefault("vector_critic_class",
                          functools.partial(TrackingErrorVectorCritic, **fields))
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)
        self.feature_fields = fields


class TrackingErrorSBXTD3Policy(TD3Policy):
    """SBX's TD3 ``MlpPolicy`` whose actor and critics read the tracking-error features.

    SBX's TD3 policy builds its actor and critics from fixed classes, so :meth:`build` swaps
    them for the feature-reading ones around SBX's own build."""

    ALGO = "td3"
    FEATURE_KWARGS = ("scale_to_bounds", "fine_scale_rad")

    def __init__(self, observation_space: Any, action_space: Any, lr_schedule: Any,
                 *args: Any, scale_to_bounds: bool = True,
                 fine_scale_rad: float | None = None, **kwargs: Any) -> None:
        self.feature_fields = _feature_fields(observation_space, scale_to_bounds,
                                              fine_scale_rad)
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)

    def build(self, *args: Any, **kwargs: Any) -> Any:
        import sbx.td3.policies as td3_policies

        saved = td3_policies.Actor, td3_policies.VectorCritic
        td3_policies.Actor = functools.partial(TrackingErrorTD3Actor, **self.feature_fields)
        td3_policies.VectorCritic = functools.partial(TrackingErrorVectorCritic,
                                                      **self.feature_fields)
        try:
            return super().build(*args, **kwargs)
        finally:
            td3_policies.Actor, td3_policies.VectorCritic = saved


class TrackingErrorSBXPPOPolicy(PPOPolicy):
    """SBX's PPO ``MlpPolicy`` whose actor and value network read the tracking-error features
    (SB3's counterpart: :class:`rehabbot.rl.features.TrackingErrorActorCriticPolicy`)."""

    ALGO = "ppo"
    FEATURE_KWARGS = ("scale_to_bounds", "fine_scale_rad")

    def __init__(self, observation_space: Any, action_space: Any, lr_schedule: Any,
                 *args: Any, scale_to_bounds: bool = True,
                 fine_scale_rad: float | None = None, **kwargs: Any) -> None:
        fields = _feature_fields(observation_space, scale_to_bounds, fine_scale_rad)
        kwargs.setdefault("actor_class", self._actor_class(fields, action_space))
        kwargs.setdefault("critic_class", functools.partial(TrackingErrorPPOCritic, **fields))
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)
        self.feature_fields = fields

    @classmethod
    def _actor_class(cls, fields: dict[str, Any], action_space: Any) -> Any:
        return functools.partial(TrackingErrorPPOActor, **fields)


class TrackingErrorSBXNormalizedPPOPolicy(TrackingErrorSBXPPOPolicy):
    """:class:`TrackingErrorSBXPPOPolicy` with its Gaussian in units of the action bound (SB3's
    counterpart: :class:`rehabbot.rl.features.TrackingErrorNormalizedActionPolicy`)."""

    ACTIONS_IN_BOUND_UNITS = True

    @classmethod
    def _actor_class(cls, fields: dict[str, Any], action_space: Any) -> Any:
        center, half = action_bound_units(action_space)
        return functools.partial(TrackingErrorNormalizedPPOActor, **fields,
                                 action_center=tuple(float(v) for v in center),
                                 action_half=tuple(float(v) for v in half))


# The SBX counterpart of each PyTorch policy of rehabbot.rl.features that the shipped
# settings files name.
SBX_TRACKING_ERROR_POLICIES = {
    "rehabbot.rl.features.TrackingErrorSACPolicy": TrackingErrorSBXSACPolicy,
    "rehabbot.rl.features.TrackingErrorTD3Policy": TrackingErrorSBXTD3Policy,
    "rehabbot.rl.features.TrackingErrorActorCriticPolicy": TrackingErrorSBXPPOPolicy,
    "rehabbot.rl.features.TrackingErrorNormalizedActionPolicy":
        TrackingErrorSBXNormalizedPPOPolicy,
}

__all__ = ["SBX_TRACKING_ERROR_POLICIES", "TrackingErrorActor", "TrackingErrorNormalizedPPOActor",
           "TrackingErrorPPOActor", "TrackingErrorPPOCritic", "TrackingErrorSBXNormalizedPPOPolicy",
           "TrackingErrorSBXPPOPolicy", "TrackingErrorSBXSACPolicy",
           "TrackingErrorSBXTD3Policy", "TrackingErrorTD3Actor", "TrackingErrorVectorCritic",
           "tracking_error_features_jax"]
