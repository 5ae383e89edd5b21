"""A Gymnasium ``VectorEnv`` backed by the batched env: ``num_envs`` worlds stepped in one
jitted, vmapped call, with NumPy arrays in and out.

Gymnasium's door, ``gym.make_vec(env_id, num_envs=N, vectorization_mode="vector_entry_point")``,
opens after :func:`register_vector_entry_points` (an explicit call: with a vector entry point
registered, ``gym.make_vec`` *without* a mode also picks it, so ``import rehabbot`` does not
register it and existing ``make_vec`` calls keep Gymnasium's ``SyncVectorEnv``).

Episodes restart in the same step (Gymnasium's ``AutoresetMode.SAME_STEP``): a world that
ends returns the next episode's first observation, and the last observation of the ended
episode is in ``info["final_obs"]`` (masked by ``info["_final_obs"]``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import jax
import jax.numpy as jp
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from rehabbot.batch.env import BatchedRehabEnv
from rehabbot.batch.env_tables import BATCHED_IDS
from rehabbot.envs.vector import checked_actions as cpu_checked_actions

CONTACTS_PER_WORLD = 16  # MuJoCo Warp's contact slots per world (naconmax = this x worlds)


class BatchedVectorEnv(VectorEnv):
    """``num_envs`` worlds of ``env_id`` (a :data:`~rehabbot.batch.env_tables.BATCHED_IDS` id)
    on MuJoCo Warp; ``**kwargs`` are the CPU env's keyword arguments (and ``naconmax``,
    ``njmax``: :class:`~rehabbot.batch.env.BatchedRehabEnv`)."""

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP}  # noqa: RUF012

    def __init__(self, env_id: str, num_envs: int, **kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} must be a positive integer")
        kwargs.setdefault("naconmax", CONTACTS_PER_WORLD * num_envs)
        self.env = BatchedRehabEnv(env_id, **kwargs)
        self.num_envs = num_envs
        cpu = self.env.cpu_env
        self.single_observation_space = cpu.observation_space
        self.single_action_space = cpu.action_space
        self.observation_space = batch_space(cpu.observation_space, num_envs)
        self.action_space = batch_space(cpu.action_space, num_envs)
        self.spec = None
        self._reset = jax.jit(jax.vmap(self.env.reset))
        env = self.env

        def step(state, action):
            stepped = env.step(state, action)
            return env.restart_done(stepped), stepped.obs

        self._step = jax.jit(jax.vmap(step))
        self._state = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Every world starts an episode (its patient of a population, exercise and weight
        level drawn per world unless the config fixes them). ``options`` are the CPU env's
        (``exercise``, ``weight_level``; ``patient`` for a population id), for every world's
        first episode; the worlds' later episodes draw again, as the CPU env's do."""
        exercise, level, patient = self.env.check_reset_options(options)
        super().reset(seed=seed)
        key = jax.random.key(int(self.np_random.integers(2**31)))
        fill = np.full(self.num_envs, 0, np.int32)
        self._state = self._reset(jax.random.split(key, self.num_envs), fill + exercise,
                                  fill + level, fill + patient)
        return np.asarray(self._state.obs), self._info(self._state)

    def step(self, actions):
        """One decision of every world. ``actions`` are checked first, as the CPU env checks
        its action (:func:`checked_actions`: ``ValueError`` naming the world and the value
        for NaN/inf, a wrong shape, a dtype that is not a real number); then
        ``gymnasium.error.ResetNeeded`` before the first :meth:`reset`."""
        actions = checked_actions(actions, self.action_space.shape)
        if self._state is None:
            raise gym.error.ResetNeeded("step() called before reset(); call reset() first")
        self._state, final_obs = self._step(self._state, jp.asarray(actions))
        state = self._state
        done = np.asarray(state.done) > 0
        truncated = np.asarray(state.info["truncation"]) > 0
        info = self._info(state)
        if done.any():
            final = np.asarray(final_obs)
            info["final_obs"] = np.array([final[k] if done[k] else None
                                          for k in range(self.num_envs)], dtype=object)
            info["_final_obs"] = done
        return (np.asarray(state.obs), np.asarray(state.reward, dtype=np.float64),
                done & ~truncated, truncated, info)

    @staticmethod
    def _info(state: Any) -> dict[str, np.ndarray]:
        return {name: np.asarray(value) for name, value in state.metrics.items()}


def checked_actions(actions: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``actions`` (one row per world) as float32, refused as the CPU vector env refuses them
    (:func:`rehabbot.envs.vector.checked_actions`: ``ValueError`` for a wrong shape, a dtype
    that is not a real number and NaN/inf, naming each bad world, its indices and its
    action). The jitted step would read a non-finite entry as 0; a finite value beyond
    float32's range is clipped to it (the step clips to [-1, 1] anyway) rather than becoming
    inf."""
    a = cpu_checked_actions(actions, shape)
    if a.dtype != np.float32:
        limit = float(np.finfo(np.float32).max)
        a = np.clip(a.astype(np.float64), -limit, limit).astype(np.float32)
    return a


def make_vec(env_id: str, num_envs: int, **kwargs: Any) -> BatchedVectorEnv:
    """:class:`BatchedVectorEnv` of ``env_id`` (what ``gym.make_vec``'s door returns)."""
    return BatchedVectorEnv(env_id, num_envs, **kwargs)


def _creator(env_id: str):
    def create(num_envs: int = 1, **kwargs: Any) -> BatchedVectorEnv:
        return BatchedVectorEnv(env_id, num_envs, **kwargs)

    create.__doc__ = f"The vector entry point of {env_id}."
    return create


# One creator per id, by name (Gymnasium passes a vector entry point the number of envs and
# the id's keyword arguments, not the id).
VECTOR_ENTRY_POINTS: dict[str, str] = {}
for _env_id in BATCHED_IDS:
    _name = "vector_" + _env_id.split("/")[-1].replace("-", "_")
    globals()[_name] = _creator(_env_id)
    VECTOR_ENTRY_POINTS[_env_id] = f"{__name__}:{_name}"


def register_vector_entry_points() -> None:
    """Give every batched id its vector entry point, so that ``gym.make_vec(env_id,
    num_envs=N, vectorization_mode="vector_entry_point")`` returns a
    :class:`BatchedVectorEnv` (module docstring: ``make_vec`` without a mode then picks it
    too)."""
    for env_id, entry_point in VECTOR_ENTRY_POINTS.items():
        gym.registry[env_id].vector_entry_point = entry_point
