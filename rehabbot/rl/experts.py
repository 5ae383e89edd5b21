"""Scripted experts: controllers that finish every exercise of every id (a baseline and a test
oracle), with Stable-Baselines3's ``predict`` signature so that
``stable_baselines3.common.evaluation.evaluate_policy`` can evaluate them.

:class:`ScriptedExpert` reads only the observation (theta* and theta): each decision moves the
robot's setpoints towards the active target along a straight line in joint space, proportionally
to the remaining error and at most ``speed_fraction`` of the action bound. Because the setpoint
integrates the error, the load-dependent tracking offset of the impedance controller vanishes.
"""

from __future__ import annotations

import numpy as np

from rehabbot.envs.config import RehabEnvConfig
from rehabbot.envs.control import PAPER_DELTA_RAD
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.tasks.agent_observation import JOINT_FINE_SCALE_RAD, JOINT_SCALE_RAD, agent_layout
from rehabbot.tasks.observation import paper_layout

SUPPORTED_MODES = ("joint_delta", "joint_velocity", "joint_position")


class ScriptedExpert:
    """Saturated proportional setpoint control towards the active target.

    ============================ ==========================================================
    ``env``                      the env (or a wrapper, or a Gymnasium/SB3 vector env whose
                                 sub-envs share its spaces) it acts in
    ``gain``                     fraction of the joint error closed per decision
    ``speed_fraction``           fraction of the action bound used at most (<= 1)
    ============================ ==========================================================

    ``joint_position`` mode needs the env's current setpoints, so there the expert must be
    given a single (unvectorised) env. ``torque`` mode is not supported (``ValueError``).
    """

    def __init__(self, env, gain: float = 0.5, speed_fraction: float = 1.0) -> None:
        if not (0.0 < gain <= 1.0):
            raise ValueError(f"gain={gain!r} must be in (0, 1]")
        if not (0.0 < speed_fraction <= 1.0):
            raise ValueError(f"speed_fraction={speed_fraction!r} must be in (0, 1]")
        base = _rehab_env(env)
        config = base.config if base is not None else _sub_env_attr(env, "config")
        mode = config.control_mode
        if mode not in SUPPORTED_MODES:
            raise ValueError(f"ScriptedExpert supports control_mode in {list(SUPPORTED_MODES)}, "
                             f"not {mode!r}")
        if mode == "joint_position" and base is None:
            raise ValueError("joint_position mode needs a single env (the expert reads its "
                             "current setpoints)")
        self.env = env
        self.mode = mode
        self.gain = gain
        self.speed_fraction = speed_fraction
        self._base = base
        # The controller's own action box (the env's space is Box(-1, 1) with unit actions).
        low, high = native_action_box(base if base is not None else env, config)
        self._native_low, self._native_high = low, high
        self._unit = config.action_scale == "unit"
        self._center, self._half = (high + low) / 2, (high - low) / 2
        n_joints = low.size
        self._agent = config.observation == "agent"
        if self._agent:
            n_arms = 2 if hasattr(config, "bilateral_table") else 1  # a BilateralEnv's
            layout = agent_layout(n_joints // n_arms, n_arms, 1)
            self._fine = layout.slice("joint_error_fine")
            self._coarse = layout.slice("joint_error")
        else:
            layout = base.layout if base is not None else paper_layout(n_joints)
            self._theta_star, self._theta = layout.slice("theta_star"), layout.slice("theta")
        # Largest setpoint change per decision [rad] that the mode allows.
        if mode == "joint_velocity":
            self._dt_s = float(base.dt_s if base is not None else _sub_env_attr(env, "dt_s"))
            self._step_max = high * self._dt_s
        elif mode == "joint_position":
            self._step_max = np.full(n_joints, PAPER_DELTA_RAD)
        else:
            self._step_max = high.copy()

    def joint_error(self, batch: np.ndarray) -> np.ndarray:
        """``theta* - theta`` of each observation of ``batch``: read from the paper's fields,
        or recovered from the agent observation's ``tanh`` errors (the fine one where it is
        not saturated)."""
        if not self._agent:
            return batch[:, self._theta_star] - batch[:, self._theta]
        fine = np.clip(batch[:, self._fine], -1.0, 1.0)
        coarse = np.clip(batch[:, self._coarse], -1 + 1e-7, 1 - 1e-7)
        from_fine = JOINT_FINE_SCALE_RAD * np.arctanh(np.clip(fine, -0.99, 0.99))
        return np.where(np.abs(fine) < 0.99, from_fine, JOINT_SCALE_RAD * np.arctanh(coarse))

    def predict(self, observation: np.ndarray, state=None, episode_start=None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """Action(s) for one observation or a batch of them; SB3's signature."""
        obs = np.asarray(observation, dtype=float)
        batch = obs.reshape(-1, obs.shape[-1])
        step = self.gain * self.joint_error(batch)
        limit = self.speed_fraction * self._step_max
        scale = np.max(np.abs(step) / limit, axis=1, keepdims=True)
        step = step / np.maximum(scale, 1.0)
        if self.mode == "joint_delta":
            action = step
        elif self.mode == "joint_velocity":
            action = step / self._dt_s
        else:
            action = self._base.controller.setpoint_rad + step[0]
            action = np.clip(action, self._native_low, self._native_high)[None]
        if self._unit:
            action = np.clip((action - self._center) / self._half, -1.0, 1.0)
        action = action.astype(np.float32)
        return (action[0] if obs.ndim == 1 else action), state

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.predict(observation)[0]


def _rehab_env(env) -> RehabEnv | None:
    """The RehabEnv under ``env``'s wrappers (or a PopulationEnv, which passes every attribute
    on to its episode's RehabEnv), or None for a vector env."""
    unwrapped = getattr(env, "unwrapped", None)
    return unwrapped if isinstance(getattr(unwrapped, "config", None), RehabEnvConfig) else None


def _sub_env_attr(env, name: str):
    """The attribute ``name`` of a vector env's first sub-env (Gymnasium or SB3 vector env)."""
    if hasattr(env, "get_attr"):
        return env.get_attr(name)[0]
    if hasattr(env, "envs"):
        return getattr(_rehab_env(env.envs[0]), name)
    raise ValueError(f"cannot find the {name} of {env!r}")


def native_action_box(env, config: RehabEnvConfig) -> tuple[np.ndarray, np.ndarray]:
    """The controller's action box ``(low, high)`` (float64): the env's action space with
    native actions, the box that ``Box(-1, 1)`` maps onto with unit actions."""
    if config.action_scale == "unit":  # the controller's (a vector env's: a sub-env's)
        controller = env.controller if hasattr(env, "controller") \
            else _sub_env_attr(env, "controller")
        return controller.clip_low.astype(float), controller.clip_high.astype(float)
    space = env.single_action_space if hasattr(env, "single_action_space") else env.action_space
    return space.low.astype(float), space.high.astype(float)
