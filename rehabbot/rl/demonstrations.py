"""Learning from the scripted expert before reinforcement learning starts.

* :func:`fill_replay_buffer` (``rehabbot train --demos N``, off-policy algorithms): runs
  :class:`~rehabbot.rl.experts.ScriptedExpert` for ``N`` episodes in the training env (same
  id and env kwargs) and adds every transition to the model's replay buffer, as the algorithm
  itself would have stored it: the observation and next observation as the env returned them
  (the buffer holds unnormalised values, like SB3 with VecNormalize), the action scaled to
  [-1, 1] by the policy's ``scale_action``, the env's reward, and ``done`` with
  ``TimeLimit.truncated`` when the time limit (not a termination) ended the episode, so that
  the critic bootstraps there.
* :func:`behaviour_clone` (``--bc``, PPO): fits the mean of PPO's Gaussian policy to the
  expert's actions on the expert's states before PPO starts. The loss is the mean squared
  error between the policy's mean action and the expert's action, both in units of the action
  bound (the action box mapped onto [-1, 1], per action dimension), minimised with Adam
  (learning rate :data:`BC_LEARNING_RATE`) over shuffled mini-batches of
  :data:`BC_BATCH_SIZE`, for :data:`BC_EPOCHS` epochs or more, so that there are at least
  :data:`BC_MIN_UPDATES` updates (a few episodes make few mini-batches). Only the actor's mean
  (its network and action layer) is fitted: the value function and the log standard deviation
  (PPO's exploration noise, set by ``log_std_init``) are left as they were. Both backends:
  PyTorch for SB3, JAX/Optax for SBX. SBX's PPO initialises its last layer without SB3's
  0.01-scaled orthogonal weights (``ortho_init=False``), so its mean starts far outside the
  tiny action box (a loss of thousands, not about 1) and clones less closely in the same
  updates; ``policy_kwargs: "dict(ortho_init=True)"`` gives it SB3's initialisation.

Episode ``i`` of the expert is seeded ``run seed + DEMO_SEED_OFFSET + i`` (the evaluation env
uses ``+ 10 000``); the manifest records every seed. PyTorch, JAX and Stable-Baselines3 are
imported inside functions only.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.rl.experts import ScriptedExpert
from rehabbot.rl.planning import TrainingUsageError

DEMO_SEED_OFFSET = 20_000
BC_EPOCHS = 30
BC_MIN_UPDATES = 1000
BC_BATCH_SIZE = 256
BC_LEARNING_RATE = 1e-3
BC_LOSS = ("mean squared error between the policy's mean action and the expert's action, in "
           "units of the action bound (the action box mapped onto [-1, 1])")


def demo_seed(run_seed: int) -> int:
    """The seed of the first expert episode of a run seeded ``run_seed``."""
    return int(run_seed) + DEMO_SEED_OFFSET


def _expert(env: gym.Env) -> ScriptedExpert:
    try:
        return ScriptedExpert(env)
    except ValueError as err:
        raise TrainingUsageError(f"--demos/--bc need the scripted expert, which cannot act "
                                 f"here: {err}") from err


def check_expert(env_id: str, env_kwargs: dict[str, Any]) -> None:
    """Raise :class:`TrainingUsageError` unless the scripted expert can act in the env (it
    cannot in ``torque`` control mode)."""
    env = gym.make(env_id, **env_kwargs)
    try:
        _expert(env)
    finally:
        env.close()


@dataclass
class ExpertEpisodes:
    """The transitions of the expert's episodes, one row per env step, in order."""

    observations: np.ndarray
    next_observations: np.ndarray
    actions: np.ndarray  # in the env's units
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    seeds: list[int]
    returns: list[float]
    lengths: list[int]
    successes: list[bool]
    expert: dict[str, Any]

    def summary(self) -> dict[str, Any]:
        """JSON-able figures for the manifest."""
        return {"episodes": len(self.seeds), "seeds": self.seeds,
                "transitions": len(self.rewards), "expert": self.expert,
                "episode_lengths": self.lengths,
                "mean_return": round(float(np.mean(self.returns)), 4) if self.returns else None,
                "success_rate": float(np.mean(self.successes)) if self.successes else None}


def _step(env: gym.Env, expert: ScriptedExpert, obs: np.ndarray) -> tuple[Any, ...]:
    space = env.action_space
    action = np.clip(expert.predict(obs)[0], space.low, space.high).astype(space.dtype)
    next_obs, reward, terminated, truncated, info = env.step(action)
    return action, next_obs, float(reward), bool(terminated), bool(truncated), info


def _expert_rows(env_id: str, env_kwargs: dict[str, Any], n_envs: int, episodes: int,
                 first_seed: int, record: dict[str, Any]) -> Iterator[tuple[list, list]]:
    """Run the scripted expert in ``n_envs`` envs side by side (episode seeds ``first_seed``,
    ``first_seed + 1``, ... in the order the episodes start) until ``episodes`` episodes have
    ended; yield each row: the envs' observations and their steps (:func:`_step`).
    ``record`` gets the seeds, returns, lengths and successes of the episodes and the expert;
    at the end, ``cut``: the envs whose episode was still running."""
    envs = [gym.make(env_id, **env_kwargs) for _ in range(n_envs)]
    try:
        experts = [_expert(env) for env in envs]
        record.update(seeds=[], returns=[], lengths=[], successes=[],
                      expert={"class": "rehabbot.rl.experts.ScriptedExpert",
                              "gain": experts[0].gain,
                              "speed_fraction": experts[0].speed_fraction})
        current: list[np.ndarray | None] = [None] * n_envs
        running = [[0.0, 0] for _ in range(n_envs)]
        while len(record["returns"]) < episodes:
            for j in range(n_envs):
                if current[j] is None:
                    record["seeds"].append(first_seed + len(record["seeds"]))
                    current[j], _ = envs[j].reset(seed=record["seeds"][-1])
                    running[j] = [0.0, 0]
            steps = [_step(envs[j], experts[j], current[j]) for j in range(n_envs)]
            yield list(current), steps
            for j, (_, next_obs, reward, terminated, truncated, info) in enumerate(steps):
                running[j] = [running[j][0] + reward, running[j][1] + 1]
                current[j] = next_obs
                if terminated or truncated:
                    record["returns"].append(running[j][0])
                    record["lengths"].append(running[j][1])
                    record["successes"].append(bool(info.get("is_success", False)))
                    current[j] = None
        record["cut"] = [j for j in range(n_envs) if current[j] is not None]
    finally:
        for env in envs:
            env.close()


def collect_expert_episodes(env_id: str, env_kwargs: dict[str, Any], episodes: int,
                            first_seed: int) -> ExpertEpisodes:
    """Run the scripted expert for ``episodes`` episodes of ``env_id`` seeded
    ``first_seed``, ``first_seed + 1``, ...; every transition, in order."""
    record: dict[str, Any] = {}
    rows = [(obs[0], *steps[0][:5]) for obs, steps in
            _expert_rows(env_id, env_kwargs, 1, episodes, first_seed, record)]
    obs, actions, next_obs, rewards, terminated, truncated = (
        list(column) for column in zip(*rows, strict=True)) if rows else ([],) * 6
    return ExpertEpisodes(
        observations=np.asarray(obs, dtype=np.float32),
        next_observations=np.asarray(next_obs, dtype=np.float32),
        actions=np.asarray(actions, dtype=np.float32),
        rewards=np.asarray(rewards, dtype=np.float32),
        terminated=np.asarray(terminated, dtype=bool), truncated=np.asarray(truncated, dtype=bool),
        seeds=record["seeds"], returns=record["returns"], lengths=record["lengths"],
        successes=record["successes"], expert=record["expert"])


# --------------------------------------------------------------------------- replay buffer


def fill_replay_buffer(model: Any, env_id: str, env_kwargs: dict[str, Any], episodes: int,
                       first_seed: int) -> dict[str, Any]:
    """Add ``episodes`` expert episodes to ``model.replay_buffer``; returns the manifest's
    ``demos`` record.

    With one training env the buffer gets exactly the episodes' transitions, in order. With
    ``n_envs`` > 1 the buffer stores one transition per env per row, so ``n_envs`` expert
    envs run side by side (episode seeds in the order the episodes start) until ``episodes``
    episodes have ended; each episode still running then is kept up to its last step and
    marked as cut by the time limit (``done`` with ``TimeLimit.truncated``).

    Raises:
        TrainingUsageError: the expert cannot act in the env, or the buffer is too small.
    """
    buffer = model.replay_buffer
    n_envs = int(buffer.n_envs)
    record: dict[str, Any] = {}
    rows = 0
    expert_rows = _expert_rows(env_id, env_kwargs, n_envs, episodes, first_seed, record)
    with contextlib.closing(expert_rows):  # a full buffer closes the envs at once
        for current, steps in expert_rows:
            if buffer.full:
                raise TrainingUsageError(
                    f"the replay buffer (buffer_size={buffer.buffer_size * n_envs}) is too "
                    f"small for {episodes} expert episodes; raise buffer_size or lower --demos")
            actions = np.stack([model.policy.scale_action(step[0]) for step in steps])
            buffer.add(np.stack(current), np.stack([step[1] for step in steps]), actions,
                       np.array([step[2] for step in steps], dtype=np.float32),
                       np.array([step[3] or step[4] for step in steps]),
                       [{"TimeLimit.truncated": step[4] and not step[3]} for step in steps])
            rows += 1
    last = (buffer.pos - 1) % buffer.buffer_size
    for j in record["cut"]:  # cut: bootstrap from its last next observation
        buffer.dones[last, j] = True
        buffer.timeouts[last, j] = True
    return {"episodes": episodes, "episodes_started": len(record["seeds"]),
            "seeds": record["seeds"], "first_seed": first_seed,
            "seed_rule": f"run seed + {DEMO_SEED_OFFSET} + i", "transitions": rows * n_envs,
            "episode_lengths": record["lengths"],
            "mean_return": round(float(np.mean(record["returns"])), 4),
            "success_rate": float(np.mean(record["successes"])), "expert": record["expert"]}


# --------------------------------------------------------------------------- behaviour cloning


def _bound_units(action_space: gym.spaces.Box) -> tuple[np.ndarray, np.ndarray]:
    """``(center, half_range)``: ``(a - center) / half_range`` maps the box onto [-1, 1]."""
    low, high = action_space.low.astype(np.float64), action_space.high.astype(np.float64)
    return ((high + low) / 2).astype(np.float32), ((high - low) / 2).astype(np.float32)


def _batches(n: int, rng: np.random.Generator) -> list[np.ndarray]:
    order = rng.permutation(n)
    return [order[i:i + BC_BATCH_SIZE] for i in range(0, n, BC_BATCH_SIZE)]


def bc_epochs(transitions: int) -> int:
    """Epochs of behaviour cloning: :data:`BC_EPOCHS`, or more for at least
    :data:`BC_MIN_UPDATES` mini-batch updates."""
    per_epoch = -(-transitions // BC_BATCH_SIZE)
    return max(BC_EPOCHS, -(-BC_MIN_UPDATES // max(per_epoch, 1)))


def _clone_torch(policy: Any, obs: np.ndarray, target: np.ndarray, center: np.ndarray,
                 half: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    import torch

    device = policy.device
    obs_t = torch.as_tensor(obs, device=device)
    target_t = torch.as_tensor(target, device=device)
    center_t, half_t = (torch.as_tensor(x, device=device) for x in (center, half))
    critic = ("value_net", "mlp_extractor.value_net", "vf_features_extractor")
    params = [param for name, param in policy.named_parameters()
              if name != "log_std" and not name.startswith(critic)]
    optimizer = torch.optim.Adam(params, lr=BC_LEARNING_RATE)

    def loss_of(index: Any) -> torch.Tensor:
        mean = policy.get_distribution(obs_t[index]).distribution.mean
        return torch.mean(((mean - center_t) / half_t - target_t[index]) ** 2)

    policy.set_training_mode(False)
    with torch.no_grad():
        before = float(loss_of(slice(None)))
    for _ in range(bc_epochs(len(obs))):
        for index in _batches(len(obs), rng):
            optimizer.zero_grad()
            loss = loss_of(torch.as_tensor(index, device=device))
            loss.backward()
            optimizer.step()
    with torch.no_grad():
        after = float(loss_of(slice(None)))
    return before, after


def _clone_jax(policy: Any, obs: np.ndarray, target: np.ndarray, center: np.ndarray,
               half: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    import jax
    import jax.numpy as jnp
    import optax

    state = policy.actor_state
    apply = state.apply_fn
    optimizer = optax.adam(BC_LEARNING_RATE)

    def loss_fn(params: Any, batch_obs: Any, batch_target: Any) -> Any:
        mean = apply(params, batch_obs).mean()
        return jnp.mean(((mean - center) / half - batch_target) ** 2)

    @jax.jit
    def update(params: Any, opt_state: Any, batch_obs: Any, batch_target: Any) -> Any:
        loss, grads = jax.value_and_grad(loss_fn)(params, batch_obs, batch_target)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    full_loss = jax.jit(loss_fn)
    params, opt_state = state.params, optimizer.init(state.params)
    before = float(full_loss(params, obs, target))
    for _ in range(bc_epochs(len(obs))):
        for index in _batches(len(obs), rng):
            params, opt_state, _ = update(params, opt_state, obs[index], target[index])
    after = float(full_loss(params, obs, target))
    policy.actor_state = state.replace(params=params)
    return before, after


def behaviour_clone(model: Any, backend: str, episodes: ExpertEpisodes,
                    seed: int) -> dict[str, Any]:
    """Fit PPO's mean action to the expert's on ``episodes`` (see the module docstring);
    returns the manifest's ``bc`` record with the loss before and after.

    Observations are normalised first when the run normalises them (VecNormalize, with its
    statistics at the start of training)."""
    obs = episodes.observations
    normalizer = model.get_vec_normalize_env()
    if normalizer is not None:
        obs = normalizer.normalize_obs(obs).astype(np.float32)
    center, half = _bound_units(model.action_space)
    target = ((episodes.actions - center) / half).astype(np.float32)
    rng = np.random.default_rng(seed)
    clone = _clone_jax if backend == "sbx" else _clone_torch
    before, after = clone(model.policy, obs, target, center, half, rng)
    return {"episodes": len(episodes.seeds), "seeds": episodes.seeds,
            "seed_rule": f"run seed + {DEMO_SEED_OFFSET} + i",
            "transitions": len(obs), "expert": episodes.expert,
            "expert_success_rate": episodes.summary()["success_rate"],
            "loss": BC_LOSS, "epochs": bc_epochs(len(obs)), "batch_size": BC_BATCH_SIZE,
            "learning_rate": BC_LEARNING_RATE, "optimizer": "Adam",
            "fitted": "the actor's mean (network and action layer); value function and log "
                      "std unchanged",
            "loss_before": round(before, 6), "loss_after": round(after, 6)}
