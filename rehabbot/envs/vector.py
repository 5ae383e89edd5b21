"""A CPU vector env: ``num_envs`` worlds of one id, their physics stepped on threads.

``gym.make_vec(env_id, num_envs=N, vectorization_mode="vector_entry_point")`` (and
``gym.make_vec(env_id, num_envs=N)``: Gymnasium picks a registered vector entry point when no
mode is given) returns a :class:`RehabVectorEnv`; it needs only the core install.

Each world is the env ``gym.make(env_id)`` builds, without wrappers. One ``step``:

1. every world's action is checked (``ValueError`` naming the world) and written into its
   controls (:meth:`~rehabbot.envs.core.RehabEnvCore.prepare_step`), on the calling thread;
2. the worlds' physics (``frame_skip`` MuJoCo steps, the patient's torques and the work meters:
   :meth:`~rehabbot.envs.core.RehabEnvCore.advance_physics`) run on ``threads`` threads: MuJoCo
   releases Python's GIL inside ``mj_step``, so the worlds' physics run on several cores;
3. then each world's safety rules, observation, reward and target switch
   (:meth:`~rehabbot.envs.core.RehabEnvCore.finish_step`) run on the calling thread.

Every world runs its env's own code on its own MuJoCo data and its own ``np_random``, so the
results are those of Gymnasium's ``SyncVectorEnv`` of the same id and seeds, bit for bit
(``reset(seed=s)`` seeds world ``i`` with ``s + i``, as ``SyncVectorEnv`` does); only the
wall clock differs (``benchmarks/performance/vector_throughput.py``).

Episodes end at ``max_episode_steps`` (the id's, or ``make_vec``'s ``max_episode_steps=``) as
``gym.make``'s ``TimeLimit`` ends them, and restart as Gymnasium's vector envs restart them:
``autoreset_mode`` is ``AutoresetMode.NEXT_STEP`` by default (``SyncVectorEnv``'s default),
or ``SAME_STEP`` (the ended episode's last observation and ``info`` in ``info["final_obs"]``
and ``info["final_info"]``) or ``DISABLED``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from rehabbot.envs.registration import (
    ENV_SPECS,
    refuse_condition_override,
    vector_creator_name,
)


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity; the CPU count where that is unknown)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def autoreset_mode_of(mode: AutoresetMode | str) -> AutoresetMode:
    """Gymnasium's ``AutoresetMode`` of ``mode``: the member, its value (``"NextStep"``) or its
    name in any case (``"next_step"``); ``ValueError`` names anything else."""
    if isinstance(mode, AutoresetMode):
        return mode
    for member in AutoresetMode:
        if isinstance(mode, str) and mode in (member.value, member.name, member.name.lower()):
            return member
    raise ValueError(f"autoreset_mode={mode!r} is not one of "
                     f"{[member.name.lower() for member in AutoresetMode]}")


class RehabVectorEnv(VectorEnv):
    """``num_envs`` worlds of ``env_id`` stepped together, their physics on ``threads``
    threads (module docstring).

    Args:
        env_id: a registered RehabBot id.
        num_envs: the number of worlds.
        threads: the threads that step the worlds' physics; default: one per usable CPU, at
            most ``num_envs``.
        autoreset_mode: Gymnasium's ``AutoresetMode``, or its name (``"next_step"``,
            ``"same_step"``, ``"disabled"``).
        **kwargs: the id's keyword arguments (``gym.make(env_id, **kwargs)``), and
            ``max_episode_steps`` (the time limit; the id's by default).

    Attributes:
        envs: every world's env (unwrapped), in world order.
        world_infos: each world's ``info`` of the last ``reset`` or ``step``, as its env
            returned it (``final_obs`` and ``final_info`` added where ``SAME_STEP`` restarted
            it; empty for a world a masked ``reset`` left alone), before they are merged
            into the vector ``info``.
    """

    def __init__(self, env_id: str, num_envs: int = 1, *, threads: int | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 **kwargs: Any) -> None:
        if env_id not in ENV_SPECS:
            raise ValueError(f"{env_id!r} is not a RehabBot id; valid ids: "
                             f"{', '.join(ENV_SPECS)}")
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} must be a positive integer")
        if threads is None:
            threads = min(num_envs, usable_cpus())
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"threads={threads!r} must be a positive integer")
        self.autoreset_mode = autoreset_mode_of(autoreset_mode)
        spec = gym.spec(env_id)
        kwargs = {**spec.kwargs, **kwargs}
        refuse_condition_override(env_id, kwargs)
        limit = kwargs.setdefault("max_episode_steps", spec.max_episode_steps)
        if isinstance(limit, bool) or not isinstance(limit, int) or limit <= 0:
            raise ValueError(f"max_episode_steps={limit!r} must be a positive integer (the "
                             "episodes' time limit)")
        self.max_episode_steps: int = limit
        create = load_env_creator(spec.entry_point)
        self.envs: list[Any] = []
        try:
            for _ in range(num_envs):
                self.envs.append(create(**kwargs))
        except BaseException:
            for env in self.envs:
                env.close()
            raise
        first = self.envs[0]
        self.num_envs = num_envs
        self.threads = threads
        self.metadata = {**first.metadata, "autoreset_mode": self.autoreset_mode}
        self.render_mode = first.render_mode
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(first.observation_space, num_envs)
        self.action_space = batch_space(first.action_space, num_envs)
        self._observations = create_empty_array(first.observation_space, num_envs, fn=np.zeros)
        self._env_obs: list[Any] = [None] * num_envs
        self._rewards = np.zeros(num_envs, np.float64)
        self._terminations = np.zeros(num_envs, np.bool_)
        self._truncations = np.zeros(num_envs, np.bool_)
        self._autoreset_envs = np.zeros(num_envs, np.bool_)
        self._elapsed = np.zeros(num_envs, np.int64)
        self._started = False
        self.world_infos: list[dict[str, Any]] = []
        # The calling thread steps one chunk of the worlds itself: the pool, the others.
        self._pool = ThreadPoolExecutor(threads - 1, thread_name_prefix="rehabbot-physics") \
            if threads > 1 else None

    # -- Gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every world (``options["reset_mask"]``: those it marks), as
        ``SyncVectorEnv.reset``: ``seed`` ``s`` seeds world ``i`` with ``s + i``; a list
        gives each world's; ``options`` go to every world's ``reset``."""
        seeds = self._seeds(seed)
        options = dict(options) if options is not None else None
        mask = np.ones(self.num_envs, np.bool_)
        if options is not None and "reset_mask" in options:
            mask = self._checked_mask(options.pop("reset_mask"))
        world_infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(mask).tolist():
            self._env_obs[i], world_infos[i] = self.envs[i].reset(seed=seeds[i],
                                                                  options=options)
        self.world_infos = world_infos
        infos = merge_infos(world_infos)
        self._terminations[mask] = self._truncations[mask] = self._autoreset_envs[mask] = False
        self._elapsed[mask] = 0
        self._started = True
        self._observations = concatenate(self.single_observation_space, self._env_obs,
                                         self._observations)
        return self._observations.copy(), infos

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        """One decision of every world (module docstring); a world whose episode ended last
        step restarts instead (``NEXT_STEP``). ``ValueError`` names the world of a bad action
        before any world moves."""
        if not self._started:
            raise gym.error.ResetNeeded("step() called before reset(); call reset() first")
        actions = checked_actions(actions, self.action_space.shape)
        if self.autoreset_mode is AutoresetMode.DISABLED and self._autoreset_envs.any():
            ended = np.flatnonzero(self._autoreset_envs).tolist()
            raise gym.error.ResetNeeded(
                f"worlds {ended} ended their episodes and autoreset_mode is DISABLED: reset "
                "them first (reset(options={'reset_mask': ...}))")
        restart = self._autoreset_envs if self.autoreset_mode is AutoresetMode.NEXT_STEP \
            else np.zeros(self.num_envs, np.bool_)
        stepping = np.flatnonzero(~restart).tolist()
        envs = self.envs
        applied = {}
        for i in stepping:
            try:
                applied[i] = envs[i].prepare_step(actions[i])
            except ValueError as err:
                raise ValueError(f"world {i}: {err}") from err
        self._advance(stepping)
        world_infos: list[dict[str, Any]] = []
        for i in range(self.num_envs):
            if restart[i]:
                self._env_obs[i], info = envs[i].reset()
                self._rewards[i] = 0.0
                self._terminations[i] = self._truncations[i] = False
                self._elapsed[i] = 0
            else:
                obs, reward, terminated, truncated, info = envs[i].finish_step(applied[i])
                self._elapsed[i] += 1
                truncated = truncated or self._elapsed[i] >= self.max_episode_steps
                self._env_obs[i], self._rewards[i] = obs, reward
                self._terminations[i], self._truncations[i] = terminated, truncated
                if self.autoreset_mode is AutoresetMode.SAME_STEP and (terminated or truncated):
                    final = {"final_obs": obs, "final_info": info}
                    self._env_obs[i], info = envs[i].reset()
                    info = {**final, **info}
                    self._elapsed[i] = 0
            world_infos.append(info)
        self.world_infos = world_infos
        infos = merge_infos(world_infos)
        self._observations = concatenate(self.single_observation_space, self._env_obs,
                                         self._observations)
        self._autoreset_envs = self._terminations | self._truncations
        return (self._observations.copy(), self._rewards.copy(), self._terminations.copy(),
                self._truncations.copy(), infos)

    def render(self) -> tuple[Any, ...] | None:
        """Every world's ``render()`` (as ``SyncVectorEnv``'s)."""
        return tuple(env.render() for env in self.envs)

    def close_extras(self, **kwargs: Any) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        for env in self.envs:
            env.close()

    # -- SyncVectorEnv's attribute access ----------------------------------------------------
    def get_attr(self, name: str) -> tuple[Any, ...]:
        """``name`` of every world's env."""
        return tuple(getattr(env, name) for env in self.envs)

    def set_attr(self, name: str, values: Any) -> None:
        """Set ``name`` on every world's env: one value for all, or a list or tuple of one
        per world."""
        if not isinstance(values, list | tuple):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(f"set_attr({name!r}) got {len(values)} values for "
                             f"{self.num_envs} worlds")
        for env, value in zip(self.envs, values, strict=True):
            setattr(env, name, value)

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Call ``name`` on every world's env (or read it, when it is not callable)."""
        results = []
        for env in self.envs:
            attribute = getattr(env, name)
            results.append(attribute(*args, **kwargs) if callable(attribute) else attribute)
        return tuple(results)

    # -- helpers -----------------------------------------------------------------------------
    def _advance(self, worlds: list[int]) -> None:
        """Step the physics of ``worlds``, split into ``threads`` contiguous chunks: the pool
        steps every chunk but the first, this thread the first; return when all are done.
        (Finishing the first chunk's worlds while the pool still steps the others would make
        the pool's threads wait for the GIL behind this thread's Python.)"""
        envs = self.envs
        chunks = np.array_split(np.asarray(worlds, dtype=np.int64), self.threads)
        futures: list[Future] = []
        if self._pool is not None:
            futures = [self._pool.submit(_advance_worlds, [envs[i] for i in chunk])
                       for chunk in chunks[1:] if len(chunk)]
        _advance_worlds([envs[i] for i in chunks[0]])
        for future in futures:
            future.result()

    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, int | np.integer) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(self.num_envs)]
        seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(f"seed has {len(seeds)} entries for {self.num_envs} worlds")
        return seeds

    def _checked_mask(self, mask: Any) -> np.ndarray:
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ \
                or mask.shape != (self.num_envs,):
            raise ValueError(f"options['reset_mask'] must be a bool array of shape "
                             f"({self.num_envs},); got {mask!r}")
        if not mask.any():
            raise ValueError("options['reset_mask'] marks no world")
        return mask


def _advance_worlds(envs: list[Any]) -> None:
    """Step the physics of ``envs`` one after the other (a pool thread's chunk)."""
    for env in envs:
        env.advance_physics()


def merge_infos(world_infos: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The vector env's ``info`` from each world's (in world order): what Gymnasium's
    ``VectorEnv._add_info`` builds world by world, built key by key. Every key maps to an
    array over the worlds (its dtype that of the first world's value: a number's type, an
    array's shape and dtype, else objects; a dict is merged likewise), and ``"_" + key`` to
    the worlds that have it."""
    n = len(world_infos)
    keys = world_infos[0].keys() if n else ()
    if all(info.keys() == keys for info in world_infos):  # every world has every key
        everyone = np.ones(n, dtype=np.bool_)
        merged: dict[str, Any] = {}
        for key in keys:
            merged[key] = _merged_values(key, [info[key] for info in world_infos])
            merged[f"_{key}"] = everyone.copy()
        return merged
    entries: dict[str, list[tuple[int, Any]]] = {}
    for i, info in enumerate(world_infos):
        for key, value in info.items():
            entries.setdefault(key, []).append((i, value))
    merged = {}
    for key, pairs in entries.items():
        worlds = [i for i, _value in pairs]
        merged[key] = _merged_values(key, [value for _i, value in pairs], worlds, n)
        mask = np.zeros(n, dtype=np.bool_)
        mask[worlds] = True
        merged[f"_{key}"] = mask
    return merged


def _merged_values(key: str, values: list[Any], worlds: list[int] | None = None,
                   n: int | None = None) -> Any:
    """One key's values as ``_add_info`` holds them: an array over the ``n`` worlds with
    ``values`` at ``worlds`` (every world when None)."""
    if worlds is None:
        n = len(values)
        worlds = list(range(n))
    assert n is not None
    first = values[0]
    if key == "final_obs":
        array: Any = np.full(n, None, dtype=object)
        for i, value in zip(worlds, values, strict=True):
            array[i] = value
        return array
    if isinstance(first, dict):
        nested: list[dict[str, Any]] = [{} for _ in range(n)]
        for i, value in zip(worlds, values, strict=True):
            nested[i] = value
        return merge_infos(nested)
    kind = type(first)
    number = kind in (int, float, bool) or issubclass(kind, np.number)
    if number:
        if len(values) == n and len(set(map(type, values))) == 1:  # every world, one type
            return np.array(values, dtype=kind)
        array = np.zeros(n, dtype=kind)
    elif isinstance(first, np.ndarray):
        if len(values) == n and first.dtype != object:
            try:  # arrays of one shape: in one call (cast to the first's dtype)
                stacked = np.array(values, dtype=first.dtype)
            except ValueError:  # shapes that differ
                stacked = None
            if stacked is not None and stacked.shape == (n, *first.shape):
                return stacked
        array = np.zeros((n, *first.shape), dtype=first.dtype)
    else:
        array = np.full(n, None, dtype=object)
    for i, value in zip(worlds, values, strict=True):
        array[i] = value
    return array


def checked_actions(actions: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``actions`` (one row per world) as an array, refused before any world moves:
    ``ValueError`` for a wrong shape, a dtype that is not a real number (bool, complex, str,
    object: no silent casts) and NaN/inf, naming each bad world, its indices and its action.
    The dtype is kept (each world's env converts and checks its row as its ``step`` does)."""
    try:
        a = np.asarray(actions)
    except (TypeError, ValueError) as err:
        raise ValueError(f"actions {actions!r} cannot be read as {shape} floats: "
                         f"{err}") from None
    if a.dtype.kind not in "iuf":
        raise ValueError(f"actions have dtype {a.dtype}; expected {shape} real numbers "
                         "(float32 preferred)")
    if a.shape != shape:
        raise ValueError(f"actions have shape {a.shape}; expected {shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        worlds = np.flatnonzero(bad.reshape(len(a), -1).any(axis=1)).tolist()
        named = "; ".join(f"world {k} at indices {np.flatnonzero(bad[k]).tolist()}: "
                          f"{a[k].tolist()}" for k in worlds[:4])
        more = f"; and {len(worlds) - 4} more worlds" if len(worlds) > 4 else ""
        raise ValueError(f"actions have non-finite values in {len(worlds)} of {len(a)} "
                         f"worlds: {named}{more}")
    return a


def make_vec(env_id: str, num_envs: int = 1, **kwargs: Any) -> RehabVectorEnv:
    """:class:`RehabVectorEnv` of ``env_id`` (what ``gym.make_vec``'s vector entry point
    returns, without the spec ``make_vec`` adds)."""
    return RehabVectorEnv(env_id, num_envs, **kwargs)


def vector_entry_point(env_id: str) -> Callable[..., RehabVectorEnv]:
    """The creator ``gym.make_vec`` calls for ``env_id`` (it passes the number of worlds and
    the keyword arguments, not the id)."""

    def create(num_envs: int = 1, **kwargs: Any) -> RehabVectorEnv:
        return RehabVectorEnv(env_id, num_envs, **kwargs)

    create.__doc__ = f"The vector entry point of {env_id}: :class:`RehabVectorEnv`."
    return create


# Every id's vector entry point, by the name its registration gives (vector_creator_name).
for _env_id in ENV_SPECS:
    globals()[vector_creator_name(_env_id)] = vector_entry_point(_env_id)
