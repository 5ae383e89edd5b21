"""An assist-as-needed controller: the clinical baseline beside the scripted expert.

Emken et al. (2007) found that people adapting to a robot behave like an error-based learner
with forgetting, and that a robot which does the same, ``u[k+1] = f u[k] + g e[k]`` (forgetting
factor ``f`` < 1, error gain ``g``), assists only as much as needed: the assistance grows while
the patient falls behind and decays while the patient succeeds. :class:`AssistAsNeeded`
applies that law at every decision, in the robot's joint space:

* a **reference** ``r`` walks towards the active target theta* at ``speed_fraction`` of the
  action bound (the pace of the exercise, the same straight joint-space line as the expert's);
  a patient who moves ahead of it along that line takes the reference along (the robot never
  brakes progress);
* the **tracking error** is ``e = r - theta`` (theta: the robot's joint angles, which follow the
  limb through the cuff);
* the **assistance** is the servo setpoint's offset from the current angles, ``d = s - theta``:
  the impedance servo pushes the limb with ``K d``. Each decision ``d <- f d + g e``, and the
  action moves the setpoint to ``theta + d`` (clipped to the action bound).

A passive patient lets the error grow until ``d`` carries the limb, so the controller ends up
assisting fully; an active patient who keeps up keeps ``e`` small, ``d`` decays and the robot's
share of the work on the limb (``info["assistance_ratio"]``) falls. It reads the observation and
the env's current setpoints (a single, unvectorised env), like the expert in
``joint_position`` mode. Only ``joint_delta`` mode is supported. On the ``-v2`` ids it reads
the paper's fields from the env (``paper_observation()``: the agent observation holds no raw
angles) and writes its action in ``Box(-1, 1)`` (the controller's box mapped to it).
"""

from __future__ import annotations

import numpy as np

from rehabbot.envs.config import RehabEnvConfig
from rehabbot.rl.experts import native_action_box

FORGETTING = 0.98  # f per decision (time constant 50 decisions = 1 s at 50 Hz)
ERROR_GAIN = 0.05  # g per decision


class AssistAsNeeded:
    """Error-based assistance with forgetting (Emken et al. 2007); SB3's ``predict`` signature.

    ============================ ==========================================================
    ``env``                      the env (or a wrapper of one RehabEnv) it acts in
    ``forgetting``               ``f`` in (0, 1]: the share of the assistance kept per decision
    ``error_gain``               ``g`` > 0: assistance added per rad of tracking error
    ``speed_fraction``           pace of the reference, fraction of the action bound (<= 1)
    ============================ ==========================================================
    """

    def __init__(self, env, forgetting: float = FORGETTING, error_gain: float = ERROR_GAIN,
                 speed_fraction: float = 0.75) -> None:
        if not (0.0 < forgetting <= 1.0):
            raise ValueError(f"forgetting={forgetting!r} must be in (0, 1]")
        if not (0.0 < error_gain <= 1.0):
            raise ValueError(f"error_gain={error_gain!r} must be in (0, 1]")
        if not (0.0 < speed_fraction <= 1.0):
            raise ValueError(f"speed_fraction={speed_fraction!r} must be in (0, 1]")
        base = getattr(env, "unwrapped", None)
        if not isinstance(getattr(base, "config", None), RehabEnvConfig):
            raise ValueError("AssistAsNeeded needs a single RehabEnv or PopulationEnv (or a "
                             "wrapper of one): it reads the env's current setpoints")
        if base.config.control.control_mode != "joint_delta":
            raise ValueError(f"AssistAsNeeded supports control_mode='joint_delta', not "
                             f"{base.config.control.control_mode!r}")
        self.env = env
        self.forgetting = forgetting
        self.error_gain = error_gain
        self.speed_fraction = speed_fraction
        self._base = base
        self._theta_star = base.layout.slice("theta_star")
        self._theta = base.layout.slice("theta")
        low, high = native_action_box(base, base.config)  # the controller's own box
        self._bound = high
        self._unit = base.config.action_scale == "unit"
        self._center, self._half = (high + low) / 2.0, (high - low) / 2.0
        self._paper_obs = base.config.observation == "paper"
        self._reference = np.zeros(len(self._bound))
        self._assistance = np.zeros(len(self._bound))
        self._episode_steps = -1

    def predict(self, observation: np.ndarray, state=None, episode_start=None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """The action for one observation of the env it was built with."""
        obs = np.asarray(observation, dtype=float)
        if obs.ndim != 1:
            raise ValueError(f"AssistAsNeeded acts in one env; got observations of shape "
                             f"{obs.shape}")
        if not self._paper_obs:  # the agent observation: the paper's fields from the env
            obs = np.asarray(self._base.paper_observation(), dtype=float)
        theta, target = obs[self._theta], obs[self._theta_star]
        setpoint = np.asarray(self._base.controller.setpoint_rad, dtype=float)
        steps = self._base.episode_steps
        if steps <= self._episode_steps or steps == 0:  # a new episode: start from rest
            self._reference[:] = theta
            self._assistance[:] = setpoint - theta  # the servo's pre-load carries the limb
        self._episode_steps = steps
        # A patient ahead of the reference (between it and the target) leads: the reference
        # jumps to the patient, so the robot never brakes progress.
        ahead = (theta - self._reference) * (target - theta) > 0.0
        self._reference[ahead] = theta[ahead]
        step = target - self._reference
        limit = self.speed_fraction * self._bound
        scale = float(np.max(np.abs(step) / limit))
        self._reference += step / max(scale, 1.0)
        error = self._reference - theta
        self._assistance = self.forgetting * self._assistance + self.error_gain * error
        action = np.clip(theta + self._assistance - setpoint, -self._bound, self._bound)
        if self._unit:
            action = np.clip((action - self._center) / self._half, -1.0, 1.0)
        return action.astype(np.float32), None

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.predict(observation)[0]
