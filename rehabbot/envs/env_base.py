"""What every RehabBot env class shares (:class:`rehabbot.envs.rehab_env.RehabEnv` and
:class:`rehabbot.envs.bilateral_env.BilateralEnv`): rendering and ``close``, the episode's state
as read-only properties, the config's settings read as attributes, and the errors of a
``step()`` out of turn. Each subclass builds itself and steps its own way."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from rehabbot.envs.config import RENDER_MODES, kwarg_names
from rehabbot.tasks.targets import TargetSequence


class RehabEnvBase(gym.Env):
    """The shared part of the RehabBot envs. A subclass sets :attr:`config_class` and, in its
    constructor, ``config``, ``dt_s``, ``render_mode``, ``_rendering``, ``_healthy_low`` and
    ``_healthy_high``; ``reset`` and ``step`` keep ``_steps``, ``_target_index``,
    ``_exercise``, ``_sequence``, ``_closed`` and ``_needs_reset``."""

    metadata: ClassVar[dict] = {"render_modes": list(RENDER_MODES), "render_fps": 50}
    config_class: ClassVar[type]

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode="
                            "'human', 'rgb_array' or 'depth_array' to the constructor")
            return None
        if self._closed:
            raise RuntimeError("render() called after close()")
        targets = self._render_targets()
        if self.render_mode == "human":
            self._rendering.human(self.data, targets, self._target_index)
            return None
        return self._rendering.offscreen(self.data, self.render_mode == "depth_array",
                                         targets, self._target_index)

    def close(self) -> None:
        self._rendering.close()
        self._closed = True
        self._needs_reset = True

    # ------------------------------------------------------------------------------------------
    # Properties
    # ------------------------------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Seconds per step (``frame_skip x timestep``), as in Gymnasium's MuJoCo envs."""
        return self.dt_s

    @property
    def healthy_obs_low(self) -> np.ndarray:
        """Lower corner of the box (this patient's setpoint bounds and joint limits) that a
        healthy observation stays in; leaving it is an "instability"."""
        return self._healthy_low

    @property
    def healthy_obs_high(self) -> np.ndarray:
        """Upper corner of the healthy box (see :attr:`healthy_obs_low`)."""
        return self._healthy_high

    @property
    def episode_steps(self) -> int:
        """Steps taken since the last ``reset()``."""
        return self._steps

    @property
    def target_index(self) -> int:
        """Index of the active target in the episode's sequence."""
        return self._target_index

    @property
    def exercise(self) -> int:
        """The episode's exercise (an index into :attr:`exercises`)."""
        return self._exercise

    @property
    def target_sequence(self) -> TargetSequence:
        """The episode's targets (patient and robot joint space)."""
        return self._sequence

    def __getattr__(self, name: str) -> Any:
        # The config's settings read as attributes (env.limb, env.target_tolerance_rad, ...).
        config = self.__dict__.get("config")
        if config is not None and name in kwarg_names(self.config_class):
            return getattr(config, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    # ------------------------------------------------------------------------------------------
    # Helpers
    # ------------------------------------------------------------------------------------------
    def _render_targets(self) -> np.ndarray:
        """The target tool positions the rendering marks (robot base frame)."""
        return self._sequence.tool_pos_base_m

    def _refuse_step(self) -> None:
        if self._closed:
            raise RuntimeError("step() called after close(); make a new env")
        if self._steps == 0:
            raise gym.error.ResetNeeded("step() called before reset(); call env.reset() first")
        raise gym.error.ResetNeeded("step() called after the episode terminated; call "
                                    "env.reset() to start the next one")
