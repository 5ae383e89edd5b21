"""The batched env (:mod:`rehabbot.batch`) as an `rsl_rl <https://github.com/leggedrobotics/rsl_rl>`_
``VecEnv``: PyTorch tensors in and out, on the device JAX runs on, through DLPack (no copy
where both sit on the same device).

``reset`` and ``step_auto_reset`` of :class:`~rehabbot.batch.env.BatchedRehabEnv` are
``jax.vmap``-ed over ``num_envs`` worlds and ``jax.jit``-ed once. A world whose episode ends
starts its next one in the same step (same-step auto-reset): the observation returned for it
is the new episode's first, ``dones`` is 1 and ``extras["time_outs"]`` is 1 only where the
time limit ended it (rsl_rl's PPO bootstraps those). Finished episodes are counted in
:attr:`RslVecEnv.finished` (return, length, success, safety stop) for the trainer's log.

The random stream is JAX's: world ``i`` of a vector env seeded with ``seed`` draws its
exercises and weight levels from ``jax.random.split(jax.random.key(seed), num_envs)[i]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from rehabbot.batch.env import BatchedRehabEnv
from rehabbot.batch.vector import CONTACTS_PER_WORLD

OBS_GROUP = "policy"


def to_torch(array: jax.Array) -> torch.Tensor:
    """A JAX array as a PyTorch tensor on the same device (DLPack)."""
    return torch.from_dlpack(array)


def to_jax(tensor: torch.Tensor) -> jax.Array:
    """A PyTorch tensor as a JAX array on the same device (DLPack)."""
    return jax.dlpack.from_dlpack(tensor.detach().contiguous())


@dataclass
class EpisodeTally:
    """The episodes that ended since the last :meth:`take`: their returns, lengths, successes
    and safety stops (rule code > 0)."""

    returns: list[float] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)
    successes: list[bool] = field(default_factory=list)
    stops: list[bool] = field(default_factory=list)

    def add(self, returns: np.ndarray, lengths: np.ndarray, successes: np.ndarray,
            stops: np.ndarray) -> None:
        self.returns += returns.tolist()
        self.lengths += lengths.astype(int).tolist()
        self.successes += successes.astype(bool).tolist()
        self.stops += stops.astype(bool).tolist()

    def take(self) -> EpisodeTally:
        """The tally so far; this one starts again empty."""
        taken = EpisodeTally(self.returns, self.lengths, self.successes, self.stops)
        self.returns, self.lengths, self.successes, self.stops = [], [], [], []
        return taken

    def summary(self) -> dict[str, float | int | None]:
        """Count and means (None where no episode ended)."""
        count = len(self.returns)

        def mean(values: list) -> float | None:
            return float(np.mean(values)) if values else None

        return {"episodes": count, "mean_return": mean(self.returns),
                "mean_length": mean(self.lengths), "success_rate": mean(self.successes),
                "safety_stop_rate": mean(self.stops)}


class RslVecEnv(VecEnv):
    """``num_envs`` worlds of ``env_id`` (``-v2`` ids that :mod:`rehabbot.batch` builds) as an
    rsl_rl ``VecEnv``. Observations come as a ``TensorDict`` with one group, ``"policy"``.

    Args:
        env_id: the registered id.
        num_envs: worlds stepped together.
        seed: the JAX key of the worlds' draws (module docstring).
        env_kwargs: the CPU env's keyword arguments.
    """

    def __init__(self, env_id: str, num_envs: int, seed: int,
                 env_kwargs: dict[str, Any] | None = None) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} must be a positive integer")
        self.batched = BatchedRehabEnv(env_id, naconmax=CONTACTS_PER_WORLD * num_envs,
                                       **dict(env_kwargs or {}))
        self.num_envs = num_envs
        self.num_actions = self.batched.action_size
        self.max_episode_length = self.batched.tables.max_episode_steps
        self.cfg: dict[str, Any] = {"env_id": env_id, "env_kwargs": dict(env_kwargs or {})}
        self._reset = jax.jit(jax.vmap(self.batched.reset))
        self._step = jax.jit(jax.vmap(self.batched.step_auto_reset))
        self.finished = EpisodeTally()
        self.reset(seed)

    def reset(self, seed: int) -> TensorDict:
        """Every world starts a new episode, drawn from the key of ``seed``."""
        keys = jax.random.split(jax.random.key(seed), self.num_envs)
        self.state = self._reset(keys)
        self.device = to_torch(self.state.obs).device
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long,
                                              device=self.device)
        self._return = torch.zeros(self.num_envs, device=self.device)
        return self.get_observations()

    def get_observations(self) -> TensorDict:
        return TensorDict({OBS_GROUP: to_torch(self.state.obs)}, batch_size=[self.num_envs],
                          device=self.device)

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor,
                                                   dict]:
        self.state = state = self._step(self.state, to_jax(actions.float()))
        rewards, dones = to_torch(state.reward), to_torch(state.done)
        self.episode_length_buf += 1
        self._return += rewards
        ended = dones > 0
        if bool(ended.any()):
            success = to_torch(state.metrics["is_success"])[ended]
            stop = to_torch(state.metrics["safety_violation"])[ended] > 0
            self.finished.add(self._return[ended].cpu().numpy(),
                              self.episode_length_buf[ended].cpu().numpy(),
                              success.cpu().numpy() > 0, stop.cpu().numpy())
            self.episode_length_buf[ended] = 0
            self._return[ended] = 0.0
        extras = {"time_outs": to_torch(state.info["truncation"]), "log": {}}
        return self.get_observations(), rewards, dones, extras
