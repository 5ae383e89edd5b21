"""Golden episodes: seeded rollouts of every registered id in every control mode, for every
(exercise, weight level), recorded once and compared by ``tests/test_golden.py``.

They pin what an agent sees and is paid (observations, rewards, terminations and every entry
of ``info``) so that a refactoring cannot change an episode unnoticed. The rollouts use only
the public API (``gym.make(id, control_mode=...)``, ``reset``, ``step``) and the paper's
observation layout, so they survive any reorganisation of the package.

Each rollout starts with ``reset(seed=s, options={"exercise": e, "weight_level": l})`` and
takes ``STEPS`` steps of a fixed, seeded policy: in the setpoint modes a proportional move
towards the active target (what the scripted expert does) plus uniform noise of 60 % of the
action bound, so that actions are sometimes clipped (in ``joint_position`` mode the setpoint
jumps by 0.8 rad on one joint now and then); in torque mode small uniform random torques.
An episode that ends is reset (with the same options, without a seed) and the rollout goes
on, so that safety stops, target switches and resets all appear.

Regenerate (only in a commit that says which defect it fixes and why the episodes change)::

    python tests/golden_episodes.py --write [--only rehabbot/rehab-bilateral-v1 ...]

``--only`` re-records the named ids and keeps every other stored rollout byte for byte (a
recording made on another CPU can differ from the stored one in the last bits). ``--stops``
re-records only the rollouts in which a safety rule stops an episode (a fix of the safety
penalty), after checking that every other rollout is reproduced as the test compares it.

What is stored (:func:`stored_form`): every discrete field in every row, and the float fields
(observation, rewards, forces, torques, positions, work) in the *sampled* rows: every
``SAMPLE_EVERY``-th row of a rollout, its last row, and each row where an event happens (a
reset, a termination, a truncation, a safety stop, a target switch, a success: any discrete
field but ``action_clipped`` differs from the row before) with the row after it. A real change
moves the floats in every row from its first on (a model, a controller, a reward weight) or
in the rows of an event (a bonus, a stop), so the sampled rows catch it, and about a third of
the rows keep the file small (``tests/golden_storage.py`` encodes them losslessly; float64
fields other than the rewards are stored as float32, far finer than the comparison's
tolerance).
"""

from __future__ import annotations

import argparse
import math
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path

import golden_storage
import numpy as np

GOLDEN_PATH = Path(__file__).with_name("golden") / "episodes.npz.xz"
IDS = ("rehabbot/rehab-reach-v0", "rehabbot/rehab-reach-l-v0", "rehabbot/rehab-hip-v0",
       "rehabbot/rehab-knee-v0", "rehabbot/rehab-reach-v1", "rehabbot/rehab-reach-l-v1",
       "rehabbot/rehab-hip-v1", "rehabbot/rehab-knee-v1",
       # patients with conditions (rehabbot.envs.registration.CONDITION_VARIANTS)
       "rehabbot/rehab-reach-spastic-v1", "rehabbot/rehab-reach-tremor-v1",
       "rehabbot/rehab-reach-active-v1", "rehabbot/rehab-hip-spastic-v1",
       "rehabbot/rehab-knee-weak-v1", "rehabbot/rehab-knee-stiff-v1",
       "rehabbot/rehab-knee-resistive-v1",
       # a patient of the "train" population each episode (POPULATION_VARIANTS)
       "rehabbot/rehab-reach-population-v1", "rehabbot/rehab-knee-population-v1",
       # both arms, a robot on each hand (rehabbot.envs.bilateral_env)
       "rehabbot/rehab-bilateral-v1")
MODES = ("joint_delta", "joint_position", "joint_velocity", "torque")
EXERCISES = (0, 1)
# The bilateral id's table is (exercise, pattern): 0 is shoulder flexion done symmetrically,
# 2 the same done alternating.
EXERCISES_OF = {"rehabbot/rehab-bilateral-v1": (0, 2)}
WEIGHT_LEVELS = (0, 1, 2, 3, 4)
STEPS = 100
DT_S = 0.02  # the paper's decision period (50 Hz)
DELTA_RAD = math.pi / 400  # the paper's action bound
NOISE_FRACTION = 0.6
TORQUE_AMPLITUDE = 0.05
JUMP_PROBABILITY, JUMP_RAD = 0.05, 0.8
VIOLATIONS = (None, "instability", "range_of_motion", "cuff_force", "unintended_contact")

# The comparison (:func:`first_difference`). Another CPU rounds differently in the last bits
# (other SIMD paths in MuJoCo), and a few of these rollouts amplify that: in ``torque`` mode
# the servos are off and random torques swing the limb, so a 1e-16 difference grows to 1e-5
# within 40-80 steps, and an event near a threshold (a contact, a clamp, a float32
# rounding of the observation fed back by the policy) can jump. So the comparison has two tiers:
# 1. every float within ``RTOL``/``ATOL`` and every discrete field equal (a rollout that is
#    not sensitive, on the recording machine: all of them);
# 2. where that fails, the rollout's own sensitivity is measured on this machine: it is run
#    again ``len(SHADOW_SEEDS)`` times with noise of ``SHADOW_NOISE`` (rad/s, per step, on
#    every joint velocity), and each float may differ by
#    ``SPREAD_FACTOR`` times the spread of those runs in that row on top of ``RTOL``/``ATOL``;
#    discrete fields (kinds, terminations, the rule that fired, the target index) must be equal
#    up to the first row where a shadow run's differ (after it the rollout has forked by
#    chance, and its rows are not compared).
# A real change moves values from the first steps on, where the shadow runs agree to 1e-12:
# tests/test_golden.py proves that a rollout perturbed by 1e-12 passes and that a change of
# 1e-4 in a reward weight, 0.1 % in one link's mass or one safety threshold fails.
RTOL = 1e-6
ATOL = 1e-6
# 1e-10 rad/s is the smallest noise (of 1e-14, 1e-12, 1e-10) whose shadow runs, on an AMD EPYC
# with AVX-512, reproduce the differences from the recording machine seen on such a CPU:
# a MuJoCo event in the step (the cuff's impact at a safety stop) that a difference far below
# 1e-12 can flip, moving the force by 0.013 N in one row while the rows before agree to 1e-7.
SHADOW_NOISE = 1e-10
SHADOW_SEEDS = (1, 2, 3, 4)
SPREAD_FACTOR = 10.0
# The fields whose values are discrete: compared for equality.
DISCRETE_FIELDS = ("kind", "terminated", "truncated", "is_success", "safety_violation",
                   "target_index", "num_targets", "exercise", "weight_level", "action_clipped")
# What is stored (module docstring): the float fields in every SAMPLE_EVERY-th row and around
# events, the rows where one of EVENT_FIELDS changes. A stored rollout lists its sampled rows
# under SAMPLED_ROWS (not an info key: info keys are identifiers).
SAMPLE_EVERY = 4
EVENT_FIELDS = tuple(name for name in DISCRETE_FIELDS if name != "action_clipped")
SAMPLED_ROWS = "@sampled_rows"


@dataclass(frozen=True)
class Perturbation:
    """Noise added to a rollout's physics state: ``initial`` [rad] on every joint position
    after the seeded reset, ``per_step`` [rad/s] on every joint velocity before each step
    (Gaussian, from ``np.random.default_rng(seed)``, not from the env's own random stream)."""

    initial: float = 0.0
    per_step: float = 0.0
    seed: int = 0


def exercises_of(env_id: str) -> tuple[int, ...]:
    """The exercises recorded for ``env_id``."""
    return EXERCISES_OF.get(env_id, EXERCISES)


def _joint_slices(size: int) -> tuple[slice, slice]:
    """theta* and theta in an observation of ``size`` values (the paper's order; both robots'
    joints side by side in the bilateral layout)."""
    from rehabbot.tasks.observation import tracking_slices

    theta_star, _, theta, _ = tracking_slices(size)
    return theta_star, theta


def rollout_seed(env_id: str, mode: str, exercise: int, level: int) -> int:
    """The reset and noise seed of one rollout (stable across processes and platforms)."""
    return zlib.crc32(f"{env_id}|{mode}|{exercise}|{level}".encode()) % (2**31)


def policy_action(mode: str, obs: np.ndarray, high: np.ndarray,
                  rng: np.random.Generator) -> np.ndarray:
    """The fixed policy of the golden rollouts (float32 action)."""
    n = len(high)
    if mode == "torque":
        return rng.uniform(-TORQUE_AMPLITUDE, TORQUE_AMPLITUDE, n).astype(np.float32)
    theta_star, theta = _joint_slices(len(obs))
    error = obs[theta_star].astype(float) - obs[theta].astype(float)
    step = np.clip(0.5 * error, -DELTA_RAD, DELTA_RAD)
    noise = rng.uniform(-NOISE_FRACTION, NOISE_FRACTION, n)
    if mode == "joint_delta":
        action = step + noise * high
    elif mode == "joint_velocity":
        action = step / DT_S + noise * high
    else:  # joint_position: a setpoint near the current angles, now and then a jump
        action = obs[theta].astype(float) + step + noise * DELTA_RAD
        if rng.random() < JUMP_PROBABILITY:
            action[rng.integers(n)] += rng.choice((-JUMP_RAD, JUMP_RAD))
    return action.astype(np.float32)


def _info_row(info: dict) -> dict[str, np.ndarray]:
    row = {}
    for key, value in info.items():
        if key == "safety_violation":
            row[key] = np.int8(VIOLATIONS.index(value))
        elif isinstance(value, (bool, np.bool_)):
            row[key] = np.int8(value)
        elif isinstance(value, (int, np.integer)):
            row[key] = np.int32(value)
        elif isinstance(value, (float, np.floating)):
            row[key] = np.float64(value)
        else:
            row[key] = np.asarray(value, dtype=np.float64)
    return row


def record_rollout(env, env_id: str, mode: str, exercise: int, level: int,
                   perturbation: Perturbation | None = None) -> dict[str, np.ndarray]:
    """One rollout as arrays, one row per reset or step (``kind`` 0 or 1); with a
    ``perturbation``, of the physics state nudged as it says."""
    seed = rollout_seed(env_id, mode, exercise, level)
    rng = np.random.default_rng(seed)
    options = {"exercise": exercise, "weight_level": level}
    high = env.action_space.high.astype(float)
    rows: list[dict] = []
    noise = np.random.default_rng(perturbation.seed) if perturbation is not None else None

    obs, info = env.reset(seed=seed, options=options)
    if perturbation is not None and perturbation.initial:
        data = env.unwrapped.data  # read anew: a population env builds a patient per reset
        data.qpos[:] += perturbation.initial * noise.standard_normal(data.qpos.shape)
    rows.append({"kind": np.int8(0), "obs": obs, "reward": np.float64(0.0),
                 "terminated": np.int8(0), "truncated": np.int8(0), **_info_row(info)})
    for _ in range(STEPS):
        action = policy_action(mode, obs, high, rng)
        if perturbation is not None and perturbation.per_step:
            data = env.unwrapped.data
            data.qvel[:] += perturbation.per_step * noise.standard_normal(data.qvel.shape)
        obs, reward, terminated, truncated, info = env.step(action)
        rows.append({"kind": np.int8(1), "obs": obs, "reward": np.float64(reward),
                     "terminated": np.int8(terminated), "truncated": np.int8(truncated),
                     **_info_row(info)})
        if terminated or truncated:
            obs, info = env.reset(options=options)
            rows.append({"kind": np.int8(0), "obs": obs, "reward": np.float64(0.0),
                         "terminated": np.int8(0), "truncated": np.int8(0), **_info_row(info)})
    keys = rows[0].keys()
    return {key: np.stack([np.asarray(row[key]) for row in rows]) for key in keys}


def _discrete_rows(rollout: dict[str, np.ndarray]) -> np.ndarray:
    """The discrete fields of each row side by side, ``(rows, k)`` int64."""
    return np.stack([rollout[name].astype(np.int64) for name in DISCRETE_FIELDS
                     if name in rollout], axis=1)


def fork_row(rollout: dict[str, np.ndarray], shadows: list[dict[str, np.ndarray]]) -> int:
    """The first row at which a shadow run's discrete fields differ from ``rollout``'s (or
    where one of them ends); ``len(rollout["kind"])`` if none does."""
    mine = _discrete_rows(rollout)
    fork = len(mine)
    for shadow in shadows:
        theirs = _discrete_rows(shadow)
        n = min(len(mine), len(theirs))
        differ = np.flatnonzero((mine[:n] != theirs[:n]).any(axis=1))
        fork = min(fork, int(differ[0]) if len(differ) else n)
    return fork


def sampled_rows(rollout: dict[str, np.ndarray]) -> np.ndarray:
    """The rows of ``rollout`` whose float fields are stored (module docstring), ascending."""
    rows = len(rollout["kind"])
    keep = np.arange(rows) % SAMPLE_EVERY == 0
    keep[-1] = True
    events = np.stack([rollout[name].astype(np.int64) for name in EVENT_FIELDS
                       if name in rollout], axis=1)
    changed = np.zeros(rows, dtype=bool)
    changed[1:] = (events[1:] != events[:-1]).any(axis=1)
    keep |= changed
    keep[1:] |= changed[:-1]  # and the row after an event
    return np.flatnonzero(keep)


def stored_form(rollout: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``rollout`` as the file keeps it: the float fields in the sampled rows only (listed
    under :data:`SAMPLED_ROWS`), float64 as float32 but for the rewards. A stored rollout is
    returned as it is."""
    if SAMPLED_ROWS in rollout:
        return rollout
    rows = sampled_rows(rollout)
    stored = {}
    for name, values in rollout.items():
        if values.dtype.kind == "f":
            values = values[rows]
            if values.dtype == np.float64 and not name.startswith("reward"):
                values = values.astype(np.float32)
        stored[name] = values
    stored[SAMPLED_ROWS] = rows
    return stored


def first_difference(actual: dict[str, np.ndarray], expected: dict[str, np.ndarray],
                     shadows: list[dict[str, np.ndarray]] | None = None) -> str | None:
    """Where ``actual`` departs from the recorded ``expected`` (a message), or None: tier 1
    without ``shadows``, tier 2 with them (see the comparison's constants). A stored
    ``expected`` (:func:`stored_form`) is compared in its sampled rows."""
    rows = len(actual["kind"])
    if shadows is None:
        if rows != len(expected["kind"]):
            return (f"{rows} rows (resets + steps), recorded {len(expected['kind'])}: an "
                    f"episode ended at another step")
        compared = rows
    else:
        compared = fork_row(actual, shadows)
        if len(expected["kind"]) < compared:
            return (f"{len(expected['kind'])} rows recorded, but the rollout and its shadow "
                    f"runs agree on {compared}")
    every_row = np.arange(compared)
    sampled = expected.get(SAMPLED_ROWS, every_row)
    sampled = sampled[sampled < compared]
    for name, want in expected.items():
        if name == SAMPLED_ROWS:
            continue
        if name not in actual:
            return f"info lost the entry {name!r}"
        rows = sampled if want.dtype.kind == "f" else every_row
        got, want = actual[name][rows], want[:len(rows)]
        if want.dtype.kind == "f":
            allowed = ATOL + RTOL * np.abs(want)
            if shadows is not None:
                spread = np.zeros_like(got, dtype=float)
                for shadow in shadows:
                    spread = np.maximum(spread, np.abs(shadow[name][rows] - got))
                allowed = allowed + SPREAD_FACTOR * spread
            bad = ~(np.abs(got - want) <= allowed) & ~(np.isnan(got) & np.isnan(want))
        else:
            bad = got != want
        if bad.any():
            at = int(np.argwhere(bad.reshape(len(bad), -1).any(axis=1))[0, 0])
            return f"{name} differs at row {rows[at]}: {got[at]!r} != {want[at]!r}"
    return None


def shadow_rollouts(env, env_id: str, mode: str, exercise: int,
                    level: int) -> list[dict[str, np.ndarray]]:
    """The rollout run again under :data:`SHADOW_NOISE`, once per :data:`SHADOW_SEEDS`."""
    return [record_rollout(env, env_id, mode, exercise, level,
                           Perturbation(per_step=SHADOW_NOISE, seed=seed))
            for seed in SHADOW_SEEDS]


def compare_rollout(env, env_id: str, mode: str, exercise: int, level: int,
                    expected: dict[str, np.ndarray],
                    actual: dict[str, np.ndarray] | None = None) -> str | None:
    """The rollout (``actual``, or recorded now) against ``expected``: tier 1, then tier 2
    (its shadow runs recorded on ``env``) if tier 1 fails. None when it matches."""
    if actual is None:
        actual = record_rollout(env, env_id, mode, exercise, level)
    difference = first_difference(actual, expected)
    if difference is None:
        return None
    return first_difference(actual, expected,
                            shadow_rollouts(env, env_id, mode, exercise, level))


def rollout_key(env_id: str, mode: str, exercise: int, level: int) -> str:
    return f"{env_id.split('/', 1)[-1]}|{mode}|e{exercise}|l{level}"


def each_rollout(ids=IDS, modes=MODES):
    """``(env, env_id, mode, exercise, level)`` of every rollout of ``ids`` x ``modes`` x
    exercises x weight levels, one env per id and mode (closed after its rollouts)."""
    import gymnasium as gym

    import rehabbot  # noqa: F401  (registers the ids)

    for env_id in ids:
        for mode in modes:
            env = gym.make(env_id, control_mode=mode)
            try:
                for exercise in exercises_of(env_id):
                    for level in WEIGHT_LEVELS:
                        yield env, env_id, mode, exercise, level
            finally:
                env.close()


def record_all(ids=IDS, modes=MODES) -> dict[str, dict[str, np.ndarray]]:
    """Every rollout of ``ids`` x ``modes`` x exercises x weight levels."""
    return {rollout_key(env_id, mode, exercise, level):
            record_rollout(env, env_id, mode, exercise, level)
            for env, env_id, mode, exercise, level in each_rollout(ids, modes)}


def load_golden(path: Path = GOLDEN_PATH) -> dict[str, dict[str, np.ndarray]]:
    """The stored rollouts, ``{rollout: {field: array}}`` (:func:`stored_form`)."""
    return golden_storage.read(path)


def write_golden(rollouts: dict[str, dict[str, np.ndarray]], path: Path = GOLDEN_PATH) -> int:
    """Store ``rollouts`` (recorded or stored) in their :func:`stored_form`; the file's size
    in bytes."""
    path.parent.mkdir(parents=True, exist_ok=True)
    return golden_storage.write(path, {key: stored_form(fields)
                                       for key, fields in rollouts.items()})


def _rerecord_stops() -> dict[str, dict[str, np.ndarray]]:
    """The stored rollouts with those that stop re-recorded (fresh or stored, either way);
    ``SystemExit`` if a rollout without a stop is not reproduced."""
    stored = load_golden()
    rollouts, renewed = {}, 0
    for env, env_id, mode, exercise, level in each_rollout():
        key = rollout_key(env_id, mode, exercise, level)
        old = stored[key]
        fresh = record_rollout(env, env_id, mode, exercise, level)
        if (old["safety_violation"] > 0).any() or (fresh["safety_violation"] > 0).any():
            rollouts[key] = fresh
            renewed += 1
            continue
        difference = compare_rollout(env, env_id, mode, exercise, level, old, actual=fresh)
        if difference is not None:
            raise SystemExit(f"{key} has no safety stop but changed: {difference}")
        rollouts[key] = old
    print(f"re-recorded {renewed} rollouts with a safety stop")
    return rollouts


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help=f"(re)write {GOLDEN_PATH}")
    parser.add_argument("--only", nargs="+", metavar="ID", choices=IDS,
                        help="re-record only these ids; keep the other stored rollouts")
    parser.add_argument("--stops", action="store_true",
                        help="re-record only the rollouts with a safety stop; every other "
                             "rollout must still be reproduced")
    args = parser.parse_args(argv)
    if args.stops:
        rollouts = _rerecord_stops()
    elif args.only:
        fresh = record_all(ids=tuple(args.only))
        rollouts = {key: fresh.pop(key, fields) for key, fields in load_golden().items()}
        rollouts.update(fresh)  # rollouts the file did not hold yet
    else:
        rollouts = record_all()
    ends = {"success": 0, "safety": 0, "resets": 0}
    for fields in rollouts.values():
        ends["success"] += int(fields["is_success"].sum())
        ends["safety"] += int((fields["safety_violation"] > 0).sum())
        ends["resets"] += int((fields["kind"] == 0).sum()) - 1
    print(f"{len(rollouts)} rollouts, {sum(len(f['kind']) for f in rollouts.values())} rows; "
          f"{ends}")
    if args.write:
        size_bytes = write_golden(rollouts)
        print(f"wrote {GOLDEN_PATH} ({size_bytes / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
