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
        mode = base.control_mode if base is not None else _mode_of(env)
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
        space = env.single_action_space if hasattr(env, "single_action_space") \
            else env.action_space
        self._space = space
        n_joints = int(space.shape[0])
        layout = base.layout if base is not None else paper_layout(n_joints)
        self._theta_star, self._theta = layout.slice("theta_star"), layout.slice("theta")
        # Largest setpoint change per decision [rad] that the mode allows.
        if mode == "joint_velocity":
            self._dt_s = base.dt_s if base is not None else _first_dt(env)
            self._step_max = space.high.astype(float) * self._dt_s
        elif mode == "joint_position":
            self._step_max = np.full(n_joints, PAPER_DELTA_RAD)
        else:
            self._step_max = space.high.astype(float)

    def predict(self, observation: np.ndarray, state=None, episode_start=None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """Action(s) for one observation or a batch of them; SB3's signature."""
        obs = np.asarray(observation, dtype=float)
        batch = obs.reshape(-1, obs.shape[-1])
        error = batch[:, self._theta_star] - batch[:, self._theta]
        step = self.gain * error
        limit = self.speed_fraction * self._step_max
        scale = np.max(np.abs(step) / limit, axis=1, keepdims=True)
        step = step / np.maximum(scale, 1.0)
        if self.mode == "joint_delta":
            action = step
        elif self.mode == "joint_velocity":
            action = step / self._dt_s
        else:
            action = self._base.controller.setpoint_rad + step[0]
            action = np.clip(action, self._space.low, self._space.high)[None]
        action = action.astype(np.float32)
        return (action[0] if obs.ndim == 1 else action), state

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.predict(observation)[0]


def _first_dt(env) -> float:
    """The decision period of a vector env's sub-envs."""
    if hasattr(env, "get_attr"):
        return float(env.get_attr("dt_s")[0])
    return float(_rehab_env(env.envs[0]).dt_s)


def _rehab_env(env) -> RehabEnv | None:
    """The RehabEnv under ``env``'s wrappers (or a PopulationEnv, which passes every attribute
    on to its episode's RehabEnv), or None for a vector env."""
    unwrapped = getattr(env, "unwrapped", None)
    return unwrapped if isinstance(getattr(unwrapped, "config", None), RehabEnvConfig) else None


def _mode_of(env) -> str:
    """Control mode of a vector env's sub-envs (Gymnasium or SB3 vector env)."""
    if hasattr(env, "get_attr"):
        return env.get_attr("control_mode")[0]
    if hasattr(env, "envs"):
        return _rehab_env(env.envs[0]).control_mode
    raise ValueError(f"cannot find the control mode of {env!r}")
