"""Stable-Baselines3's ``VecEnv`` over the CPU vector env: ``rehabbot train --vec threads``.

:class:`ThreadedVecEnv` steps :class:`~rehabbot.envs.vector.RehabVectorEnv` (the worlds'
physics on threads, Gymnasium's ``SAME_STEP`` autoreset) and hands SB3 and SBX what their
``DummyVecEnv`` of Monitor-wrapped ``gym.make`` envs hands them: the same observations,
rewards and dones, and per world an ``info`` with ``"TimeLimit.truncated"``,
``"terminal_observation"`` and, at an episode's end, SB3's ``"episode"`` entry. Each world's
episodes are written to a monitor file of its own as SB3's ``Monitor`` writes them (its
``ResultsWriter``: the same columns, ``info_keywords`` included), so the run folder, the
learning curves and resuming read them unchanged.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.monitor import ResultsWriter
from stable_baselines3.common.vec_env import VecEnv

from rehabbot.envs.vector import RehabVectorEnv


class _WorldMonitor:
    """One world's episodes, counted and written as SB3's ``Monitor`` counts and writes
    them."""

    def __init__(self, env_id: str, filename: str | None, info_keywords: tuple[str, ...],
                 append: bool, time_offset_s: float) -> None:
        self.t_start = time.time() - time_offset_s
        self.info_keywords = info_keywords
        self.rewards: list[float] = []
        self.writer = None
        if filename is not None:
            self.writer = ResultsWriter(filename, header={"t_start": self.t_start,
                                                          "env_id": env_id},
                                        extra_keys=info_keywords,
                                        override_existing=not (append and Path(filename).is_file()))

    def step(self, reward: float, done: bool, info: dict[str, Any]) -> None:
        self.rewards.append(float(reward))
        if not done:
            return
        episode = {"r": round(sum(self.rewards), 6), "l": len(self.rewards),
                   "t": round(time.time() - self.t_start, 6)}
        for key in self.info_keywords:
            episode[key] = info[key]
        if self.writer is not None:
            self.writer.write_row(episode)
        info["episode"] = episode
        self.rewards = []

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


class ThreadedVecEnv(VecEnv):
    """``n_envs`` worlds of ``env_id`` (``env_kwargs``: its keyword arguments) for SB3 and
    SBX (module docstring).

    Args:
        monitor_files: one monitor file per world (None: count episodes, write nothing).
        info_keywords: ``info`` entries each monitor row records (SB3's ``Monitor``).
        append: continue existing monitor files (a resumed run) instead of replacing them.
        time_offsets_s: per world, the ``t`` its monitor continues from.
        threads: the threads that step the physics (:class:`RehabVectorEnv`).
    """

    def __init__(self, env_id: str, n_envs: int, env_kwargs: dict[str, Any] | None = None, *,
                 monitor_files: Sequence[str] | None = None,
                 info_keywords: Sequence[str] = (), append: bool = False,
                 time_offsets_s: Sequence[float] = (), threads: int | None = None) -> None:
        if monitor_files is not None and len(monitor_files) != n_envs:
            raise ValueError(f"{len(monitor_files)} monitor files for {n_envs} worlds")
        self.vector = RehabVectorEnv(env_id, n_envs, threads=threads,
                                     autoreset_mode=AutoresetMode.SAME_STEP,
                                     **dict(env_kwargs or {}))
        super().__init__(n_envs, self.vector.single_observation_space,
                         self.vector.single_action_space)
        keywords = tuple(info_keywords)
        self.monitors = [
            _WorldMonitor(env_id, None if monitor_files is None else str(monitor_files[i]),
                          keywords, append,
                          time_offsets_s[i] if i < len(time_offsets_s) else 0.0)
            for i in range(n_envs)]
        self._actions: np.ndarray | None = None

    # -- SB3's VecEnv ----------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        seeds = self._seeds if any(seed is not None for seed in self._seeds) else None
        options = self._options[0] if self._options and self._options[0] else None
        if any(option != self._options[0] for option in self._options):
            raise ValueError("ThreadedVecEnv passes one options dict to every world; got "
                             f"{self._options}")
        obs, _info = self.vector.reset(seed=seeds, options=options)
        self.reset_infos = [dict(info) for info in self.vector.world_infos]
        for monitor in self.monitors:
            monitor.rewards = []
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, rewards, terminated, truncated, _infos = self.vector.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = []
        for i, world_info in enumerate(self.vector.world_infos):
            if dones[i]:  # SAME_STEP: the ended episode's last info and observation
                info = dict(world_info["final_info"])
                info["terminal_observation"] = world_info["final_obs"]
                self.reset_infos[i] = {key: value for key, value in world_info.items()
                                       if key not in ("final_info", "final_obs")}
            else:
                info = dict(world_info)
            info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            self.monitors[i].step(rewards[i], bool(dones[i]), info)
            infos.append(info)
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.vector.close()
        for monitor in self.monitors:
            monitor.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.vector.envs[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        for i in self._get_indices(indices):
            setattr(self.vector.envs[i], attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        return [getattr(self.vector.envs[i], method_name)(*method_args, **method_kwargs)
                for i in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        """No world is wrapped (the monitor is this VecEnv's own)."""
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return list(self.vector.render())
