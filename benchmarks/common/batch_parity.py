"""The batched env (:mod:`rehabbot.batch`, MuJoCo Warp) against the CPU env, episode by episode:
the same actions in both, and what came out of each.

* :func:`cpu_episode`: one CPU episode from ``reset(seed=0, options=START)``, the scripted
  expert's or a constant action's;
* :func:`batched_rollout`: the same start in every world of the batched env and a sequence of
  actions per world, stepped in one ``jax.lax.scan``;
* :func:`replay_expert` and :func:`replay_stops`: the comparisons the parity tests assert and
  ``benchmarks/results/batch_parity.py`` publishes (target switches, termination step, return,
  observation error, robot work; the stop's step and rule).

Needs ``pip install "rehabbot[gpu]"``; JAX and the batched env are imported when called.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.rl.experts import ScriptedExpert

START = {"exercise": 0, "weight_level": 0}


def cpu_episode(env_id: str, actions: np.ndarray | None = None, max_steps: int | None = None,
                start: dict | None = None, **kwargs: Any) -> dict:
    """One CPU episode from ``reset(seed=0, options=start)`` (:data:`START` by default; a
    dict of ``exercise`` and ``weight_level``): the scripted expert's
    (``actions`` None) or a constant action's, to its end or ``max_steps``. Arrays per step:
    ``actions``, ``obs`` (the reset's first), ``rewards``, ``index`` (the target index, the
    reset's first); ``violation`` (the stop's rule or None), ``robot_work_j`` and
    ``patient_work_j`` at the end; ``ended``: whether the episode ended (a stop, success or the
    step limit) rather than being cut at ``max_steps``."""
    env = gym.make(env_id, **kwargs).unwrapped
    obs, info = env.reset(seed=0, options=start or START)
    expert = ScriptedExpert(env) if actions is None else None
    out: dict[str, Any] = {"actions": [], "obs": [obs], "rewards": [], "index": [0],
                           "violation": None, "robot_work_j": 0.0, "patient_work_j": 0.0,
                           "ended": False}
    for _ in range(max_steps or env.max_episode_steps):
        action = np.asarray(expert.predict(obs)[0] if expert else actions, np.float32)
        obs, reward, terminated, _truncated, info = env.step(action)
        out["actions"].append(action)
        out["obs"].append(obs)
        out["rewards"].append(reward)
        out["index"].append(info["target_index"])
        out["robot_work_j"] = info["robot_work_j"]
        out["patient_work_j"] = info["patient_work_j"]
        if terminated:
            out["violation"] = info["safety_violation"]
            break
    out["ended"] = bool(terminated) or len(out["actions"]) >= env.max_episode_steps
    env.close()
    return {k: np.asarray(v) if isinstance(v, list) else v for k, v in out.items()}


def batched_rollout(env_id: str, actions: np.ndarray, start: dict | None = None,
                    world_patients: Sequence[int] | None = None, **kwargs: Any) -> dict:
    """Every world's observations, rewards, dones, target indices, safety rules, robot and
    patient work for the actions ``(steps, worlds, n)``, from the same start as :func:`cpu_episode`
    (no auto-reset: a stopped world stays stopped). ``world_patients``: a population id's
    patient of each world (drawn when None)."""
    import jax
    import jax.numpy as jp

    import rehabbot.batch as batch

    worlds = actions.shape[1]
    env = batch.make(env_id, naconmax=16 * worlds, **(start or START), **kwargs)

    def run(state, action_seq):
        def body(state, action):
            state = jax.vmap(env.step)(state, action)
            m = state.metrics
            return state, (state.obs, state.reward, state.done, m["target_index"],
                           m["safety_violation"], m["robot_work_j"], m["patient_work_j"])
        return jax.lax.scan(body, state, action_seq)

    chosen = jp.asarray(world_patients if world_patients is not None else [-1] * worlds,
                        jp.int32)
    state = jax.jit(jax.vmap(env.reset, in_axes=(0, None, None, 0)))(
        jax.random.split(jax.random.key(0), worlds), -1, -1, chosen)
    _, out = jax.jit(run)(state, jp.asarray(actions))
    names = ("obs", "rewards", "done", "index", "violation", "robot_work_j", "patient_work_j")
    return {"reset_obs": np.asarray(state.obs),
            **{k: np.asarray(v) for k, v in zip(names, out, strict=True)}}


def switches(index: np.ndarray) -> list[int]:
    """The steps (0-based) after which the target index moved on."""
    return np.flatnonzero(np.diff(index)).tolist()


def replay_expert(env_id: str, other_world_offset: float = 0.3, start: dict | None = None,
                  max_steps: int | None = None, **kwargs: Any) -> dict:
    """The CPU scripted expert's episode replayed in world 0 of two (world 1 acts the same
    actions plus ``other_world_offset``, so that its contacts and constraints would show if
    they reached world 0); what each env gave. ``start``: the exercise and weight level
    (:data:`START` by default); ``max_steps``: only the episode's first steps (its end, then,
    is None on both sides unless it came before them); ``kwargs``: both envs' keyword
    arguments (a ``condition``, for example)."""
    start = start or START
    cpu = cpu_episode(env_id, start=start, max_steps=max_steps, **kwargs)
    steps = len(cpu["actions"])
    actions = np.repeat(cpu["actions"][:, None], 2, axis=1)
    actions[:, 1] = np.clip(actions[:, 1] + other_world_offset, -1, 1)
    out = batched_rollout(env_id, actions, start=start, **kwargs)
    done = np.flatnonzero(out["done"][:, 0])
    return {
        "id": env_id, "start": start, "steps": steps,
        "switches_cpu": switches(cpu["index"]),
        "switches_batched": switches(np.r_[0, out["index"][:, 0]]),
        "end_cpu": steps - 1 if cpu["ended"] else None,
        "end_batched": int(done[0]) if done.size else None,
        "stop_cpu": cpu["violation"], "stop_batched": int(out["violation"][:, 0].max()),
        "return_cpu": float(cpu["rewards"].sum()),
        "return_batched": float(out["rewards"][:steps, 0].sum()),
        "reset_obs_error": float(np.abs(out["reset_obs"][0] - cpu["obs"][0]).max()),
        "obs_error": float(np.abs(out["obs"][:steps, 0] - cpu["obs"][1:]).max()),
        "reward_error": float(np.abs(out["rewards"][:steps, 0] - cpu["rewards"]).max()),
        "robot_work_cpu_j": float(cpu["robot_work_j"]),
        "robot_work_batched_j": float(out["robot_work_j"][steps - 1, 0]),
        "patient_work_cpu_j": float(cpu["patient_work_j"]),
        "patient_work_batched_j": float(out["patient_work_j"][steps - 1, 0]),
    }


def replay_population(env_id: str, world_patients: Sequence[int], start: dict | None = None,
                      max_steps: int | None = None, **kwargs: Any) -> list[dict]:
    """The CPU population env's scripted-expert episode of each patient of ``world_patients``
    (from ``reset(seed=0, options={**start, "patient": k})``), all replayed at once: patient
    ``world_patients[i]`` in world ``i`` of one batch, each world with its own patient's
    model fields and tables. What each env gave, per patient (as :func:`replay_expert`, with
    its ``max_steps``); ``kwargs``: both envs' keyword arguments (``patients="test"``, for
    example)."""
    start = start or START
    cpus = [cpu_episode(env_id, start={**start, "patient": k}, max_steps=max_steps, **kwargs)
            for k in world_patients]
    steps = max(len(c["actions"]) for c in cpus)
    actions = np.zeros((steps, len(cpus), cpus[0]["actions"].shape[1]), np.float32)
    for world, cpu in enumerate(cpus):
        actions[:len(cpu["actions"]), world] = cpu["actions"]
    out = batched_rollout(env_id, actions, start=start, world_patients=world_patients, **kwargs)
    rows = []
    for world, (patient, cpu) in enumerate(zip(world_patients, cpus, strict=True)):
        n = len(cpu["actions"])
        done = np.flatnonzero(out["done"][:, world])
        rows.append({
            "id": env_id, "patient": int(patient), "start": start, "steps": n,
            "switches_cpu": switches(cpu["index"]),
            "switches_batched": switches(np.r_[0, out["index"][:n, world]]),
            "end_cpu": n - 1 if cpu["ended"] else None,
            "end_batched": int(done[0]) if done.size else None,
            "stop_cpu": cpu["violation"], "stop_batched": int(out["violation"][:n, world].max()),
            "return_cpu": float(cpu["rewards"].sum()),
            "return_batched": float(out["rewards"][:n, world].sum()),
            "reset_obs_error": float(np.abs(out["reset_obs"][world] - cpu["obs"][0]).max()),
            "obs_error": float(np.abs(out["obs"][:n, world] - cpu["obs"][1:]).max()),
            "patient_work_cpu_j": float(cpu["patient_work_j"]),
            "patient_work_batched_j": float(out["patient_work_j"][n - 1, world]),
        })
    return rows


def replay_stops(env_id: str, unit_actions: Sequence[Sequence[float]],
                 **kwargs: Any) -> list[dict]:
    """Each constant unit action of ``unit_actions`` held in its own world (side by side in
    one batch) and alone on the CPU, until the CPU episode stops: where and why each env
    stopped, the last reward and the return."""
    from rehabbot.batch import RULE_CODES

    cpus = [cpu_episode(env_id, np.asarray(a, np.float32), **kwargs) for a in unit_actions]
    steps = max(len(c["actions"]) for c in cpus) + 5
    actions = np.repeat(np.asarray(unit_actions, np.float32)[None], steps, axis=0)
    out = batched_rollout(env_id, actions, **kwargs)
    codes = {code: rule for rule, code in RULE_CODES.items()}
    rows = []
    for world, cpu in enumerate(cpus):
        stops = np.flatnonzero(out["done"][:, world])
        stop = int(stops[0]) if stops.size else None
        rewards = out["rewards"][:(stop if stop is not None else steps - 1) + 1, world]
        rows.append({
            "id": env_id, "kwargs": kwargs, "unit_action": list(unit_actions[world]),
            "stop_cpu": len(cpu["actions"]) - 1 if cpu["violation"] else None,
            "rule_cpu": cpu["violation"], "stop_batched": stop,
            "rule_batched": None if stop is None else codes.get(
                int(out["violation"][stop, world])),
            "last_reward_cpu": float(cpu["rewards"][-1]),
            "last_reward_batched": float(rewards[-1]),
            "return_cpu": float(cpu["rewards"].sum()), "return_batched": float(rewards.sum()),
        })
    return rows


def hold_still(env_id: str, steps: int, seeds: Sequence[int], **kwargs: Any) -> dict:
    """The patient's exercised joint angles [rad] while the robot holds still (a zero unit
    action) for ``steps`` control steps from :data:`START`: one CPU episode per seed of
    ``seeds`` (``cpu``, ``(steps, seeds, joints)``) and as many batched worlds (``batched``,
    the same shape). Batched world ``k`` starts its tremor where CPU seed ``k`` drew it (its
    phases, drift and modulation), so the two differ only by the drift's and modulation's
    random steps during the hold; ``drawn`` are the batched worlds' own start phases
    ``(seeds, compliant joints)``. ``dt_s`` is the control step."""
    import jax
    import jax.numpy as jp

    import rehabbot.batch as batch

    cpu_angles, starts = [], []
    for seed in seeds:
        env = gym.make(env_id, **kwargs).unwrapped
        env.reset(seed=seed, options=START)
        tremor = env.physics.drive.tremor
        starts.append((list(tremor.phase), tremor.drift_hz, tremor.modulation))
        adr, rows = env.scene.exercised_qpos_adr, []
        for _ in range(steps):
            _obs, _reward, terminated, _truncated, info = env.step(
                np.zeros(env.action_space.shape, np.float32))
            if terminated:
                raise RuntimeError(f"{env_id}: the CPU hold stopped ({info['safety_violation']})")
            rows.append(env.data.qpos[adr].copy())
        cpu_angles.append(rows)
        env.close()
    worlds = len(seeds)
    benv = batch.make(env_id, naconmax=16 * worlds, **START, **kwargs)
    adr = jp.asarray(benv.tables.phi_adr)

    def run(state):
        def body(state, _):
            state = jax.vmap(benv.step)(state, jp.zeros((worlds, benv.action_size)))
            return state, (state.data.qpos[:, adr], state.done)
        return jax.lax.scan(body, state, None, length=steps)

    state = jax.jit(jax.vmap(benv.reset))(jax.random.split(jax.random.key(1), worlds))
    drawn = np.asarray(state.info["tremor_phase"])
    phase, drift, modulation = zip(*starts, strict=True)
    info = {**state.info, "tremor_phase": jp.asarray(phase, jp.float32),
            "tremor_drift_hz": jp.asarray(drift, jp.float32),
            "tremor_modulation": jp.asarray(modulation, jp.float32)}
    _, (angles, done) = jax.jit(run)(state.replace(info=info))
    if np.asarray(done).any():
        raise RuntimeError(f"{env_id}: a batched hold stopped")
    return {"batched": np.asarray(angles, float), "cpu": np.swapaxes(np.asarray(cpu_angles), 0, 1),
            "drawn": drawn, "dt_s": benv.dt_s}


def tremor_spectrum(angles: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The frequencies [Hz] and the power of ``angles`` ``(steps, runs, joints)`` (each run's
    and joint's mean and linear trend removed), summed over the runs and joints."""
    steps = angles.shape[0]
    t = np.arange(steps)
    flat = angles.reshape(steps, -1)
    slope, intercept = np.polyfit(t, flat, 1)
    residual = flat - (np.outer(t, slope) + intercept)
    power = np.abs(np.fft.rfft(residual, axis=0)) ** 2
    return np.fft.rfftfreq(steps, dt_s), power.sum(axis=1)


def band_rms(angles: np.ndarray, dt_s: float, low_hz: float, high_hz: float) -> float:
    """The root mean square [rad] of ``angles`` ``(steps, runs, joints)`` in the band
    ``[low_hz, high_hz]`` (Parseval over the detrended signal), over runs and joints."""
    freqs, power = tremor_spectrum(angles, dt_s)
    steps, runs = angles.shape[0], angles.shape[1] * angles.shape[2]
    band = (freqs >= low_hz) & (freqs <= high_hz)
    return float(np.sqrt(2.0 * power[band].sum() / (steps * steps * runs)))
