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
recording made on another CPU can differ from the stored one in the last bits).
"""

from __future__ import annotations

import argparse
import math
import sys
import zlib
from pathlib import Path

import numpy as np

GOLDEN_PATH = Path(__file__).with_name("golden") / "episodes.npz"
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

# Tolerances of the comparison. The recording machine and CI run the same MuJoCo and NumPy
# wheels; the same binary on the same CPU reproduces an episode bit for bit (tested elsewhere).
# Another CPU may take other SIMD paths in MuJoCo and BLAS and round differently in the last
# bits; these episodes are dissipative (impedance control, damped limb), so such differences
# stay many orders of magnitude below these bounds, while any change of behaviour (a reward
# term, an observation field, a physics or control change) moves values by 1e-4 or more.
RTOL = 1e-6
ATOL = 1e-6


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


def record_rollout(env, env_id: str, mode: str, exercise: int,
                   level: int) -> dict[str, np.ndarray]:
    """One rollout as arrays, one row per reset or step (``kind`` 0 or 1)."""
    seed = rollout_seed(env_id, mode, exercise, level)
    rng = np.random.default_rng(seed)
    options = {"exercise": exercise, "weight_level": level}
    high = env.action_space.high.astype(float)
    rows: list[dict] = []

    obs, info = env.reset(seed=seed, options=options)
    rows.append({"kind": np.int8(0), "obs": obs, "reward": np.float64(0.0),
                 "terminated": np.int8(0), "truncated": np.int8(0), **_info_row(info)})
    for _ in range(STEPS):
        obs, reward, terminated, truncated, info = env.step(
            policy_action(mode, obs, high, rng))
        rows.append({"kind": np.int8(1), "obs": obs, "reward": np.float64(reward),
                     "terminated": np.int8(terminated), "truncated": np.int8(truncated),
                     **_info_row(info)})
        if terminated or truncated:
            obs, info = env.reset(options=options)
            rows.append({"kind": np.int8(0), "obs": obs, "reward": np.float64(0.0),
                         "terminated": np.int8(0), "truncated": np.int8(0), **_info_row(info)})
    keys = rows[0].keys()
    return {key: np.stack([np.asarray(row[key]) for row in rows]) for key in keys}


def rollout_key(env_id: str, mode: str, exercise: int, level: int) -> str:
    return f"{env_id.split('/', 1)[-1]}|{mode}|e{exercise}|l{level}"


def record_all(ids=IDS, modes=MODES) -> dict[str, dict[str, np.ndarray]]:
    """Every rollout of ``ids`` x ``modes`` x exercises x weight levels."""
    import gymnasium as gym

    import rehabbot  # noqa: F401  (registers the ids)

    rollouts = {}
    for env_id in ids:
        for mode in modes:
            env = gym.make(env_id, control_mode=mode)
            try:
                for exercise in exercises_of(env_id):
                    for level in WEIGHT_LEVELS:
                        rollouts[rollout_key(env_id, mode, exercise, level)] = record_rollout(
                            env, env_id, mode, exercise, level)
            finally:
                env.close()
    return rollouts


def flatten(rollouts: dict[str, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One array per field, the rollouts concatenated in order, plus ``rollout_keys`` and
    ``rollout_rows``. float64 fields other than the rewards are stored as float32, far finer
    than the comparison's tolerance, to keep the file small."""
    keys = list(rollouts)
    flat = {"rollout_keys": np.array(keys),
            "rollout_rows": np.array([len(rollouts[k]["kind"]) for k in keys])}
    names = list(dict.fromkeys(name for k in keys for name in rollouts[k]))
    for name in names:
        # A field that an id does not report (the -v0 and -v1 reward terms differ) is stored
        # as NaN in its rows (missing_fields tells it apart from a NaN value). A field whose
        # width differs between ids (the bilateral id's two robots) is stored once per width:
        # the first width under the field's name, the others as "<name>@<width>".
        shapes = list(dict.fromkeys(rollouts[k][name].shape[1:] for k in keys
                                    if name in rollouts[k]))
        for shape in shapes:
            stored = name if shape == shapes[0] else f"{name}@{'x'.join(map(str, shape))}"
            parts = []
            for k in keys:
                rows = len(rollouts[k]["kind"])
                if name in rollouts[k] and rollouts[k][name].shape[1:] == shape:
                    parts.append(rollouts[k][name])
                else:
                    parts.append(np.full((rows, *shape), np.nan))
            values = np.concatenate(parts)
            if values.dtype == np.float64 and not name.startswith("reward"):
                values = values.astype(np.float32)
            flat[stored] = values
    return flat


def load_golden(path: Path = GOLDEN_PATH) -> dict[str, dict[str, np.ndarray]]:
    """The stored rollouts, ``{rollout: {field: array}}``."""
    with np.load(path, allow_pickle=False) as data:
        keys = [str(k) for k in data["rollout_keys"]]
        ends = np.cumsum(data["rollout_rows"])
        starts = ends - data["rollout_rows"]
        fields = {name: data[name] for name in data.files
                  if name not in ("rollout_keys", "rollout_rows")}
    return {key: {name.split("@", 1)[0]: values[a:b] for name, values in fields.items()
                  if not (values.dtype.kind == "f" and np.isnan(values[a:b]).all())}
            for key, a, b in zip(keys, starts, ends, strict=True)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help=f"(re)write {GOLDEN_PATH}")
    parser.add_argument("--only", nargs="+", metavar="ID", choices=IDS,
                        help="re-record only these ids; keep the other stored rollouts")
    args = parser.parse_args(argv)
    if args.only:
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
        GOLDEN_PATH.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(GOLDEN_PATH, **flatten(rollouts))
        print(f"wrote {GOLDEN_PATH} ({GOLDEN_PATH.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
