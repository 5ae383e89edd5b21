"""The Gymnasium plumbing every RehabBot env shares (:class:`rehabbot.envs.core.RehabEnvCore`,
whose ``reset`` and ``step`` serve :class:`rehabbot.envs.rehab_env.RehabEnv` and
:class:`rehabbot.envs.bilateral_env.BilateralEnv`): rendering and ``close``, the episode's state
as read-only properties, the start of an episode and the errors of a ``step()`` out of turn.
The settings are read from the config (``env.config.reward.time_cost``); the env forwards none
of them as its own attributes."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np

from rehabbot.common.checks import check_number, check_options
from rehabbot.envs.config import NUMBER_RANGES, RENDER_MODES
from rehabbot.envs.time_limit import MakeTimeLimit
from rehabbot.sim.scene import WEIGHT_LEVELS, check_weight_level
from rehabbot.tasks import feasibility
from rehabbot.tasks.targets import TargetSequence

RESET_OPTIONS = ("exercise", "weight_level")


class RehabEnvBase(MakeTimeLimit, gym.Env):
    """The shared plumbing of the RehabBot envs. A subclass sets :attr:`config_class` and, in
    its constructor, ``config``, calls :meth:`_adopt_parts` on its built parts, and sets
    ``_rendering``, ``_healthy_low`` and ``_healthy_high``; ``reset`` and ``step`` keep
    ``_steps``, ``_target_index``, ``_exercise``, ``_sequence``, ``_closed`` and
    ``_needs_reset``."""

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

    def set_time_limit(self, max_episode_steps: int) -> None:
        """Make ``max_episode_steps`` the env's horizon everywhere it is used: the config, the
        safety penalties of the reward and the rendering's trace (``gym.make`` calls this with
        the limit of its ``TimeLimit``: :class:`rehabbot.envs.time_limit.MakeTimeLimit`).
        Between episodes only; ``ValueError`` for a limit outside ``config.NUMBER_RANGES``."""
        low, high, _integer = NUMBER_RANGES["max_episode_steps"]
        limit = check_number("max_episode_steps", max_episode_steps, low, high, integer=True)
        if limit == self.max_episode_steps:
            return
        if not self._needs_reset:
            raise RuntimeError("set_time_limit() called during an episode; call it before "
                               "reset()")
        self.config = self.config.replace(max_episode_steps=limit)
        self.max_episode_steps = limit
        self._reward.max_episode_steps = limit
        self._rendering.trace = np.zeros((limit + 1, 3))
        self._rendering.trace_len = 0

    # ------------------------------------------------------------------------------------------
    # Helpers
    # ------------------------------------------------------------------------------------------
    def _adopt_parts(self, parts: Any, config: Any) -> None:
        """Take what both env classes read from their built parts (``build_parts`` and
        ``build_bilateral_parts``) and from the config: the model and its data, the setpoint
        bounds, targets, controller, safety rules, reward, layout and spaces, and the timing."""
        self.scene = parts.scene
        self.model = parts.scene.model
        self.data = mujoco.MjData(self.model)
        self.setpoint_low_rad, self.setpoint_high_rad = (parts.setpoint_low_rad,
                                                         parts.setpoint_high_rad)
        self.targets: tuple[TargetSequence, ...] = parts.targets
        self.controller = parts.controller
        self.safety = parts.safety
        self.layout = parts.layout
        self.action_space = self.controller.action_space
        self.observation_space = parts.observation_space
        self.render_mode = config.render_mode
        self.frame_skip = config.frame_skip
        self.max_episode_steps = config.max_episode_steps
        self.dt_s = self.frame_skip * self.model.opt.timestep
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.dt_s)}
        self._unusable_levels = parts.unusable_levels

    @property
    def unusable_weight_levels(self) -> dict:
        """The weight levels this patient cannot do the exercises at, each with the reason
        (empty for most patients); a reset at one is refused."""
        return dict(self._unusable_levels)

    def paper_observation(self) -> np.ndarray:
        """The paper's observation of the current state (a copy; its fields in
        :attr:`layout`), whatever the id's ``observation``."""
        return self._obs.copy()

    def _start_episode(self, seed: int | None, options: dict | None) -> None:
        """The part of ``reset`` both env classes share: seed, check the options, draw the
        exercise and weight level (both drawn every reset, so that the draws stay the same
        whichever the options fix), load the level and put the scene at home in ``data``."""
        super().reset(seed=seed)
        options = check_options(options, RESET_OPTIONS)
        drawn_exercise = int(self.np_random.integers(len(self.targets)))
        drawn_level = int(self.np_random.integers(len(WEIGHT_LEVELS)))
        exercise = options.get("exercise", self.config.exercise)
        exercise = drawn_exercise if exercise is None else exercise
        if isinstance(exercise, bool) or exercise not in range(len(self.targets)):
            raise ValueError(f"exercise={exercise!r} is not one of "
                             f"{list(range(len(self.targets)))}")
        level = options.get("weight_level", self.config.weight_level)
        level = drawn_level if level is None else check_weight_level(level)
        if level in self._unusable_levels:
            feasibility.refuse(self._unusable_levels, WEIGHT_LEVELS, level)
        if level != self.scene.weight_level:
            self.scene.set_weight_level(level)
        self._exercise = int(exercise)
        self._sequence = self.targets[self._exercise]
        self._target_index = self._steps = 0
        self.scene.reset_data(self.data)

    def _render_targets(self) -> np.ndarray:
        """The target tool positions the rendering marks: the first robot's (its base
        frame)."""
        return self._sequence.tool_pos_base_m[:, :3]

    def _refuse_step(self) -> None:
        if self._closed:
            raise RuntimeError("step() called after close(); make a new env")
        if self._steps == 0:
            raise gym.error.ResetNeeded("step() called before reset(); call env.reset() first")
        raise gym.error.ResetNeeded("step() called after the episode terminated; call "
                                    "env.reset() to start the next one")
