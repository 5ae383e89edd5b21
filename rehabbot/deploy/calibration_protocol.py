"""The calibration protocol: the motions that measure a patient's limb, and their recording.

Per calibrated joint (a compliant exercised joint that the limb's workspace box moves:
:data:`rehabbot.tasks.workspace.WORKSPACE_DEG`), with every other exercised joint held:

* **slow ramps** over the joint's range, both ways, at ``ramp_speed_rad_s`` (5 deg/s by
  default: below every Modified Ashworth grade's reflex threshold, so quasi-static: the
  passive spring, gravity and any voluntary effort);
* **fast stretches** at two speeds (trapezoidal velocity, both ways, first away from the
  end nearer rest): the stretch reflex's catch that grades spasticity;
* **small oscillations** (the other joints at rest): sinusoids of
  :data:`OSCILLATION_AMPLITUDE_RAD` at :data:`OSCILLATION_FREQUENCIES_HZ` about
  :data:`OSCILLATION_CENTRES` of the range, the amplitude raised and lowered over one period
  at either end: continuous speeds and accelerations that the damping and the limb's inertia
  are fitted on (a ramp's speed is its command's, so the two cannot be told apart there);
* ``repetitions`` of the ramps and stretches, the whole set at two postures of the other
  calibrated joint where there is one (the elbow with the shoulder at home and near the far
  end of its range): the gravity torque on a joint turns with the posture of the joints
  before it, its spring does not, which is what tells them apart.

The ramps and oscillations of every joint come first, the stretches (which may reach the
force limit and stop the session) last. Each motion is a :class:`ProtocolSegment` of patient
joint targets at the backend's control period; the robot targets come from the scene's
inverse kinematics (:func:`rehabbot.sim.paths.coupled_path`: the setpoints that carry the
limb at that pose, as the env's targets are built), solved once per degree along each line
and interpolated. Segments are joined by minimum-jerk moves, one joint at a time.

:func:`run_protocol` drives any :class:`~rehabbot.deploy.backend.RobotBackend` through it
(``command`` and ``state`` at ``control_dt_s``) and records a :class:`Recording`: time,
the patient's joint angles and speeds, and the force vector the cuff applies to the limb.
It needs what the interface leaves optional: the patient's joint angles in
``RobotState.patient_q_rad`` and the cuff's force vector (``cuff_force_vector_n()``; on a real
robot a force/torque sensor at the cuff). The session stops (``backend.stop()``) when the cuff
force exceeds ``max_cuff_force_n``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import DataError, UsageError
from rehabbot.sim.paths import coupled_path, minimum_jerk
from rehabbot.sim.scene import Scene
from rehabbot.tasks.exercises import exercise_table
from rehabbot.tasks.workspace import WORKSPACE_DEG

SEGMENT_KINDS = ("move", "hold", "ramp", "stretch", "oscillation")
RAMP_SPEED_RAD_S = math.radians(5.0)
STRETCH_SPEEDS_RAD_S = (math.radians(60.0), math.radians(180.0))
STRETCH_ACCELERATION_RAD_S2 = 30.0
MOVE_SPEED_RAD_S = math.radians(4.0)  # mean speed of the moves: min-jerk peaks below 10 deg/s
HOLD_S = 1.0
RANGE_MARGIN_RAD = math.radians(2.0)  # the ramps stop this short of the range's ends
KNOT_SPACING_RAD = math.radians(1.0)
POSTURE_SHIFT_RAD = math.radians(20.0)  # the second posture's least distance from home
#: The default ramps span the limb's exercises (and the resting angle), widened by this on
#: either side, inside the workspace box and the patient's range.
EXERCISE_WIDENING_RAD = math.radians(15.0)
#: The oscillations' amplitude.
OSCILLATION_AMPLITUDE_RAD = math.radians(8.0)
#: The oscillations' frequencies, about each centre.
OSCILLATION_FREQUENCIES_HZ = (0.5, 1.0, 1.5)
#: The oscillations' centres, as fractions of the ramps' range.
OSCILLATION_CENTRES = (1.0 / 3.0, 2.0 / 3.0)
#: An oscillation stays at least this long, and two periods, at full amplitude.
OSCILLATION_STEADY_S = 1.5
RECORDING_FORMAT = "rehabbot-calibration-recording/1"


@dataclass(frozen=True)
class ProtocolSettings:
    """How the protocol moves each joint (SI units; defaults in the module docstring)."""

    ramp_speed_rad_s: float = RAMP_SPEED_RAD_S
    stretch_speeds_rad_s: tuple[float, float] = STRETCH_SPEEDS_RAD_S
    stretch_acceleration_rad_s2: float = STRETCH_ACCELERATION_RAD_S2
    repetitions: int = 2
    hold_s: float = HOLD_S
    margin_rad: float = RANGE_MARGIN_RAD
    max_cuff_force_n: float = 150.0

    def __post_init__(self) -> None:
        checks = (("ramp_speed_rad_s", self.ramp_speed_rad_s, 1e-3, 0.5),
                  ("stretch_acceleration_rad_s2", self.stretch_acceleration_rad_s2, 1.0, 200.0),
                  ("hold_s", self.hold_s, 0.0, 10.0), ("margin_rad", self.margin_rad, 0.0, 0.3),
                  ("max_cuff_force_n", self.max_cuff_force_n, 1.0, 1000.0))
        for name, value, low, high in checks:
            if not (isinstance(value, (int, float)) and low <= value <= high):
                raise UsageError(f"ProtocolSettings.{name}={value!r} must be in [{low}, {high}]")
        speeds = tuple(self.stretch_speeds_rad_s)
        if len(speeds) != 2 or not all(0.2 <= s <= 6.0 for s in speeds) or speeds[0] >= speeds[1]:
            raise UsageError(f"ProtocolSettings.stretch_speeds_rad_s={speeds!r} must be two "
                             "increasing speeds in [0.2, 6] rad/s")
        if not isinstance(self.repetitions, int) or not 1 <= self.repetitions <= 20:
            raise UsageError(f"ProtocolSettings.repetitions={self.repetitions!r} must be an "
                             "integer in [1, 20]")


@dataclass(frozen=True)
class ProtocolSegment:
    """One motion: patient joint targets [rad] (rows: control periods; columns: the scene's
    exercised joints) and what it measures."""

    kind: str  # one of SEGMENT_KINDS
    joint: str  # the moving joint ("" for a move of several joints)
    speed_rad_s: float  # nominal (peak) speed of the moving joint; 0 for a hold
    repetition: int
    patient_q_rad: np.ndarray
    # The ramps and stretches of one joint at one posture share a block, "joint/posture";
    # the faster speed's stretches are skipped when the slower ones predict a force above
    # the session's limit: the ramps' peak force plus the slower stretches' excess over it,
    # scaled by the speed ratio (an oscillation, by the square of the ratio to the previous
    # one's speed: only it is skipped). "" for the moves.
    block: str = ""


@dataclass
class Protocol:
    """The segments of a calibration and the robot targets of every row."""

    joints: tuple[str, ...]  # calibrated joints (full names)
    ranges_rad: dict[str, tuple[float, float]]  # per calibrated joint: the ramps' ends
    patient_rom_rad: dict[str, tuple[float, float]]  # per calibrated joint: patient's range
    dt_s: float
    segments: list[ProtocolSegment]
    robot_targets_rad: list[np.ndarray] = field(default_factory=list)  # per segment (T, n)

    @property
    def steps(self) -> int:
        """Control periods of the whole protocol."""
        return sum(len(s.patient_q_rad) for s in self.segments)


def calibrated_joints(scene: Scene) -> tuple[str, ...]:
    """The joints of ``scene`` a protocol can calibrate: compliant, exercised and moved by the
    limb's workspace box."""
    model = scene.model
    compliant = [model.joint(int(model.dof_jntid[d])).name for d in scene.compliant_dof_adr]
    box = WORKSPACE_DEG[_limb(scene)]
    return tuple(j for j in compliant if j.rsplit("_", 1)[0] in box)


def _limb(scene: Scene) -> str:
    if scene.preset.startswith("upper"):
        return "arm"
    return scene.preset  # "hip" or "knee"


def protocol_ranges(scene: Scene, patient_rom_rad: tuple[np.ndarray, np.ndarray],
                    joints: Sequence[str] | None = None,
                    ranges_deg: dict[str, tuple[float, float]] | None = None,
                    margin_rad: float = RANGE_MARGIN_RAD) -> dict[str, tuple[float, float]]:
    """Per joint to calibrate: the range [rad] its ramps cover. Default: the span of the
    limb's exercises and the resting angle, widened by :data:`EXERCISE_WIDENING_RAD` on
    either side, within the workspace box and the patient's range of motion, ``margin_rad``
    short of either end (the exercises are the poses the env is known to hold); ``ranges_deg``
    (joint -> (low, high) deg) replaces it and must lie inside both. ``UsageError`` naming
    an unknown joint or a range outside the patient's or the workspace."""
    allowed = calibrated_joints(scene)
    bases = {j.rsplit("_", 1)[0]: j for j in allowed}
    chosen = list(allowed) if joints is None else [_full_name(j, bases, allowed) for j in joints]
    if not chosen:
        raise UsageError("calibration: no joint to calibrate")
    given = {_full_name(j, bases, allowed): r for j, r in (ranges_deg or {}).items()}
    exercised = list(scene.exercised_joints)
    box = WORKSPACE_DEG[_limb(scene)]
    home = scene.home_qpos[scene.exercised_qpos_adr]
    out = {}
    for joint in chosen:
        i = exercised.index(joint)
        rom = (float(patient_rom_rad[0][i]), float(patient_rom_rad[1][i]))
        ws = tuple(math.radians(v) for v in box[joint.rsplit("_", 1)[0]])
        used = _exercise_span_rad(scene, joint)
        low = max(rom[0], ws[0], min(used[0], home[i]) - EXERCISE_WIDENING_RAD) + margin_rad
        high = min(rom[1], ws[1], max(used[1], home[i]) + EXERCISE_WIDENING_RAD) - margin_rad
        if joint in given:
            low, high = (math.radians(float(v)) for v in given[joint])
            rom_deg = f"[{math.degrees(rom[0]):.1f}, {math.degrees(rom[1]):.1f}]"
            ws_deg = f"[{math.degrees(ws[0]):.1f}, {math.degrees(ws[1]):.1f}]"
            if not low < high:
                raise UsageError(f"calibration: range of {joint} {given[joint]!r} deg must "
                                 "be (low, high) with low < high")
            if low < rom[0] or high > rom[1]:
                raise UsageError(f"calibration: range of {joint} {list(given[joint])} deg "
                                 f"lies outside the patient's range of motion {rom_deg} deg")
            if low < ws[0] or high > ws[1]:
                raise UsageError(f"calibration: range of {joint} {list(given[joint])} deg "
                                 f"lies outside the robot's workspace box {ws_deg} deg")
        if high - low < math.radians(10.0):
            raise UsageError(f"calibration: {joint} can move only "
                             f"{math.degrees(high - low):.1f} deg inside the patient's range "
                             "and the workspace; at least 10 deg are needed")
        out[joint] = (low, high)
    unknown = sorted(set(given) - set(out))
    if unknown:
        raise UsageError(f"calibration: ranges given for {unknown}, which are not calibrated")
    return out


def _exercise_span_rad(scene: Scene, joint: str) -> tuple[float, float]:
    """The angles [rad] of ``joint`` over the key poses of the limb's exercises."""
    base = joint.rsplit("_", 1)[0]
    angles = [math.radians(pose[base]) for exercise in exercise_table(_limb(scene), None)
              for pose in exercise.key_poses_deg if base in pose]
    home = float(scene.home_qpos[scene.model.joint(joint).qposadr[0]])
    return (min(angles, default=home), max(angles, default=home))


def _full_name(name: str, bases: dict[str, str], allowed: Sequence[str]) -> str:
    if name in allowed:
        return name
    if name in bases:
        return bases[name]
    raise UsageError(f"calibration: unknown joint {name!r}; this scene calibrates "
                     f"{list(allowed)} (or their side-less names {list(bases)})")


# -- the segments ----------------------------------------------------------------------------
def ramp_profile(start: float, end: float, speed: float, dt_s: float) -> np.ndarray:
    """Angles [rad] from ``start`` to ``end`` at constant ``speed``, one per period (the
    first period's angle is one step along; the last is ``end``)."""
    n = max(1, math.ceil(abs(end - start) / (speed * dt_s)))
    return start + (end - start) * np.arange(1, n + 1) / n


def stretch_profile(start: float, end: float, speed: float, acceleration: float,
                    dt_s: float) -> np.ndarray:
    """Angles [rad] of a trapezoidal-velocity stretch from ``start`` to ``end``: ramp up at
    ``acceleration`` to ``speed``, cruise, ramp down (a triangle when the range is short)."""
    distance = abs(end - start)
    t_acc = speed / acceleration
    if acceleration * t_acc ** 2 > distance:  # triangle
        t_acc = math.sqrt(distance / acceleration)
        speed = acceleration * t_acc
    t_cruise = (distance - acceleration * t_acc ** 2) / speed
    total = 2 * t_acc + t_cruise
    t = np.arange(1, max(1, math.ceil(total / dt_s)) + 1) * dt_s
    t = np.minimum(t, total)
    s = np.where(t < t_acc, 0.5 * acceleration * t ** 2,
                 np.where(t < t_acc + t_cruise,
                          0.5 * acceleration * t_acc ** 2 + speed * (t - t_acc),
                          distance - 0.5 * acceleration * np.maximum(total - t, 0.0) ** 2))
    return start + math.copysign(1.0, end - start) * s


def oscillation_profile(centre: float, amplitude: float, frequency_hz: float,
                        dt_s: float) -> np.ndarray:
    """Angles [rad] of a sinusoid about ``centre``: one period of rising amplitude (a raised
    cosine), whole periods at ``amplitude`` (at least two and :data:`OSCILLATION_STEADY_S`),
    one period of falling amplitude; it starts and ends at ``centre`` at rest."""
    steady = max(2, math.ceil(OSCILLATION_STEADY_S * frequency_hz))
    period = 1.0 / frequency_hz
    total = (steady + 2) * period
    t = np.arange(1, round(total / dt_s) + 1) * dt_s
    t[-1] = total
    envelope = np.clip(np.minimum(t, total - t) / period, 0.0, 1.0)
    envelope = 0.5 - 0.5 * np.cos(math.pi * envelope)
    return centre + amplitude * envelope * np.sin(2.0 * math.pi * frequency_hz * t)


def build_protocol(scene: Scene, ranges_rad: dict[str, tuple[float, float]],
                   patient_rom_rad: tuple[np.ndarray, np.ndarray], dt_s: float,
                   settings: ProtocolSettings | None = None,
                   start_q_rad: np.ndarray | None = None) -> Protocol:
    """The protocol's segments for ``ranges_rad`` (from :func:`protocol_ranges`) at the
    control period ``dt_s``, starting from ``start_q_rad`` (default: the scene's home), and
    their robot targets."""
    settings = settings or ProtocolSettings()
    if not (isinstance(dt_s, float | int) and 1e-4 <= dt_s <= 0.1):
        raise UsageError(f"calibration: control period dt_s={dt_s!r} must be in [1e-4, 0.1] s")
    exercised = list(scene.exercised_joints)
    home = scene.home_qpos[scene.exercised_qpos_adr].astype(float)
    current = home.copy() if start_q_rad is None else np.asarray(start_q_rad, float).copy()
    segments: list[ProtocolSegment] = []
    joints = tuple(ranges_rad)

    block = ""

    def add(kind: str, joint: str, speed: float, rep: int, rows: list[np.ndarray]) -> None:
        if rows:
            segments.append(ProtocolSegment(kind, joint, speed, rep, np.array(rows), block))
            current[:] = rows[-1]

    def move_to(pose: np.ndarray) -> None:
        for i in range(len(exercised)):  # one joint at a time
            if abs(pose[i] - current[i]) < 1e-12:
                continue
            n = max(2, math.ceil(abs(pose[i] - current[i]) / (MOVE_SPEED_RAD_S * dt_s)))
            shape = minimum_jerk(np.arange(1, n + 1) / n)
            start = current[i]
            rows = []
            for s in shape:
                row = current.copy()
                row[i] = start + s * (pose[i] - start)
                rows.append(row)
            add("move", exercised[i], MOVE_SPEED_RAD_S, 0, rows)

    def hold(joint: str) -> None:
        n = round(settings.hold_s / dt_s)
        add("hold", joint, 0.0, 0, [current.copy() for _ in range(n)])

    def along(kind: str, joint: str, speed: float, rep: int, angles: np.ndarray) -> None:
        i = exercised.index(joint)
        rows = []
        for a in angles:
            row = current.copy()
            row[i] = a
            rows.append(row)
        add(kind, joint, speed, rep, rows)

    # The gentle motions of every joint first, the stretches (which may reach the force
    # limit and stop the session) last.
    for fast in (False, True):
        for joint in joints:
            i = exercised.index(joint)
            low, high = ranges_rad[joint]
            for p, posture in enumerate(_postures(joint, ranges_rad, exercised, home)):
                block = ""
                # The stretches go first away from the end nearer rest (the lighter start).
                ends = (low, high) if abs(low - home[i]) > abs(high - home[i]) else (high, low)
                start = posture.copy()
                start[i] = ends[1] if fast else low
                move_to(start)
                block = f"{joint}/{p}"
                hold(joint)
                if fast:
                    for speed in settings.stretch_speeds_rad_s:
                        for rep in range(settings.repetitions):
                            for a, b in (ends[::-1], ends):
                                along("stretch", joint, speed, rep, stretch_profile(
                                    a, b, speed, settings.stretch_acceleration_rad_s2, dt_s))
                                hold(joint)
                    continue
                for rep in range(settings.repetitions):
                    for a, b in ((low, high), (high, low)):
                        along("ramp", joint, settings.ramp_speed_rad_s, rep,
                              ramp_profile(a, b, settings.ramp_speed_rad_s, dt_s))
                        hold(joint)
                if p == 0:  # the oscillations, the other joints at rest
                    for fraction in OSCILLATION_CENTRES:
                        along("move", joint, MOVE_SPEED_RAD_S, 0,
                              _move_profile(current[i], low + fraction * (high - low), dt_s))
                        hold(joint)
                        for frequency in OSCILLATION_FREQUENCIES_HZ:
                            along("oscillation", joint,
                                  2 * math.pi * frequency * OSCILLATION_AMPLITUDE_RAD, 0,
                                  oscillation_profile(current[i], OSCILLATION_AMPLITUDE_RAD,
                                                      frequency, dt_s))
                            hold(joint)
            block = ""
    move_to(home)
    rom = {j: (float(patient_rom_rad[0][exercised.index(j)]),
               float(patient_rom_rad[1][exercised.index(j)])) for j in joints}
    protocol = Protocol(joints, dict(ranges_rad), rom, float(dt_s), segments)
    protocol.robot_targets_rad = robot_targets(scene, segments)
    return protocol


def _move_profile(start: float, end: float, dt_s: float) -> np.ndarray:
    """A minimum-jerk move of one joint at the mean speed :data:`MOVE_SPEED_RAD_S`."""
    n = max(2, math.ceil(abs(end - start) / (MOVE_SPEED_RAD_S * dt_s)))
    return start + (end - start) * minimum_jerk(np.arange(1, n + 1) / n)


def _postures(joint: str, ranges_rad: dict[str, tuple[float, float]], exercised: list[str],
              home: np.ndarray) -> list[np.ndarray]:
    """The postures of the other joints for ``joint``'s motions: home, and each other
    calibrated joint at the middle of its range, or at its end farther from home where the
    middle lies within :data:`POSTURE_SHIFT_RAD` of home."""
    postures = [home.copy()]
    for other, (low, high) in ranges_rad.items():
        if other == joint:
            continue
        k = exercised.index(other)
        pose = home.copy()
        middle = 0.5 * (low + high)
        far = low if abs(low - home[k]) > abs(high - home[k]) else high
        pose[k] = middle if abs(middle - home[k]) >= POSTURE_SHIFT_RAD else far
        postures.append(pose)
    return postures


def robot_targets(scene: Scene, segments: Sequence[ProtocolSegment]) -> list[np.ndarray]:
    """Per segment, the robot's joint targets (T, n_joints) [rad]: the servo setpoints that
    carry the limb at each row's pose. Each row moves one joint from a posture of the others;
    the IK is solved on a 1-degree grid of that line (cached per line) and interpolated."""
    lines: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    out = []
    n = len(scene.exercised_joints)
    for segment in segments:
        rows = segment.patient_q_rad
        targets = np.zeros((len(rows), scene.n_robot_joints))
        for t, row in enumerate(rows):
            moving = _moving_index(segment, scene, row)
            key = (moving, *(round(float(row[k]), 9) for k in range(n) if k != moving))
            if key not in lines:
                lines[key] = _line(scene, row, moving)
            grid, setpoints = lines[key]
            for j in range(scene.n_robot_joints):
                targets[t, j] = np.interp(row[moving], grid, setpoints[:, j])
        out.append(targets)
    return out


def _moving_index(segment: ProtocolSegment, scene: Scene, row: np.ndarray) -> int:
    return list(scene.exercised_joints).index(segment.joint) if segment.joint else 0


def _line(scene: Scene, row: np.ndarray, moving: int) -> tuple[np.ndarray, np.ndarray]:
    """The grid of the moving joint's angles over its anatomical range and the setpoints."""
    model = scene.model
    joint = model.joint(scene.exercised_joints[moving])
    low, high = (float(v) for v in model.jnt_range[joint.id])
    grid = np.linspace(low, high, 1 + math.ceil((high - low) / KNOT_SPACING_RAD))
    home = scene.home_qpos[scene.exercised_qpos_adr][moving]
    # Solve outwards from the angle nearest home, so the IK stays on the home branch.
    start = int(np.argmin(np.abs(grid - home)))
    setpoints = np.zeros((len(grid), scene.n_robot_joints))
    for part in (grid[start:], grid[:start + 1][::-1]):
        poses = np.repeat(row[None, :], len(part), axis=0)
        poses[:, moving] = part
        path = coupled_path(scene, np.degrees(poses), dt_s=1.0)
        index = np.searchsorted(grid, part)
        setpoints[index] = path.servo_setpoint_rad[:, 0]
    return grid, setpoints


# -- running it on a backend ---------------------------------------------------------------
@dataclass
class Recording:
    """What a calibration session measured, one row per control period.

    ``patient_q_rad`` and ``patient_dq_rad_s`` (T, n_exercised); ``cuff_force_n`` (T, 3): the
    force the cuff applies to the limb, world frame; ``target_q_rad`` (T, n_exercised) the
    protocol's patient targets the row's command carried; ``segment`` (T,): the index of the
    protocol segment the row belongs to; ``segments``: per segment (kind, joint, speed,
    repetition, block); ``force_lag_s``: how much older the force is than the joint angles
    of its row (the simulator's: one physics step, the constraint force of the step's start).
    ``env_id``/``env_kwargs`` name the body model the torques are computed on."""

    time_s: np.ndarray
    patient_q_rad: np.ndarray
    patient_dq_rad_s: np.ndarray
    cuff_force_n: np.ndarray
    target_q_rad: np.ndarray
    segment: np.ndarray
    segments: list[tuple[str, str, float, int, str]]
    exercised_joints: tuple[str, ...]
    joints: tuple[str, ...]
    ranges_rad: dict[str, tuple[float, float]]
    patient_rom_rad: dict[str, tuple[float, float]]
    rest_q_rad: np.ndarray
    env_id: str = ""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    stopped_reason: str = ""
    force_lag_s: float = 0.0
    skipped_blocks: list[str] = field(default_factory=list)

    def save(self, path: str | Path) -> None:
        """Write the recording as a ``.npz`` (no pickles; the metadata as JSON text)."""
        import json

        from rehabbot.common.files import atomic_write

        meta = {"format": RECORDING_FORMAT, "segments": self.segments,
                "exercised_joints": list(self.exercised_joints), "joints": list(self.joints),
                "ranges_rad": self.ranges_rad, "patient_rom_rad": self.patient_rom_rad,
                "env_id": self.env_id, "env_kwargs": self.env_kwargs,
                "stopped_reason": self.stopped_reason, "force_lag_s": self.force_lag_s,
                "skipped_blocks": self.skipped_blocks}
        arrays = {"time_s": self.time_s, "patient_q_rad": self.patient_q_rad,
                  "patient_dq_rad_s": self.patient_dq_rad_s, "cuff_force_n": self.cuff_force_n,
                  "target_q_rad": self.target_q_rad,
                  "segment": self.segment, "rest_q_rad": self.rest_q_rad,
                  "meta": np.array(json.dumps(meta))}
        atomic_write(Path(path), lambda f: np.savez_compressed(f, **arrays))

    @classmethod
    def load(cls, path: str | Path) -> Recording:
        """Read a recording written by :meth:`save`; ``DataError`` naming a damaged file."""
        import json

        try:
            with np.load(Path(path), allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            meta = json.loads(str(arrays.pop("meta")))
        except (OSError, ValueError, KeyError) as err:
            raise DataError(f"{path}: not a calibration recording ({err})") from None
        if meta.get("format") != RECORDING_FORMAT:
            raise DataError(f"{path}: format {meta.get('format')!r} is not "
                            f"{RECORDING_FORMAT!r}")
        try:
            return cls(time_s=arrays["time_s"], patient_q_rad=arrays["patient_q_rad"],
                       patient_dq_rad_s=arrays["patient_dq_rad_s"],
                       cuff_force_n=arrays["cuff_force_n"], target_q_rad=arrays["target_q_rad"],
                       segment=arrays["segment"],
                       segments=[(str(k), str(j), float(s), int(r), str(b))
                                 for k, j, s, r, b in meta["segments"]],
                       exercised_joints=tuple(meta["exercised_joints"]),
                       joints=tuple(meta["joints"]),
                       ranges_rad={k: (float(a), float(b))
                                   for k, (a, b) in meta["ranges_rad"].items()},
                       patient_rom_rad={k: (float(a), float(b))
                                        for k, (a, b) in meta["patient_rom_rad"].items()},
                       rest_q_rad=arrays["rest_q_rad"], env_id=str(meta["env_id"]),
                       env_kwargs=dict(meta["env_kwargs"]),
                       stopped_reason=str(meta["stopped_reason"]),
                       force_lag_s=float(meta["force_lag_s"]),
                       skipped_blocks=[str(b) for b in meta["skipped_blocks"]])
        except (KeyError, TypeError, ValueError) as err:
            raise DataError(f"{path}: damaged calibration recording ({err})") from None


def limb_force_n(backend: Any) -> np.ndarray:
    """The force [N] the cuff applies to the limb, world frame, from a backend that measures
    it (``cuff_force_vector_n()``: the simulator's cuff constraint force, which acts on the
    robot's side of the cuff; the limb feels its opposite)."""
    reader = getattr(backend, "cuff_force_vector_n", None)
    if reader is None:
        raise UsageError("calibration: the backend measures no cuff force vector "
                         "(cuff_force_vector_n()); a real robot needs a force/torque sensor "
                         "at the cuff")
    return -np.asarray(reader(), dtype=float)


def run_protocol(backend: Any, protocol: Protocol, rest_q_rad: np.ndarray,
                 max_cuff_force_n: float = ProtocolSettings.max_cuff_force_n,
                 force_lag_s: float = 0.0) -> Recording:
    """Drive ``backend`` through ``protocol`` (one ``command`` per row) and record it. The
    session stops early (``backend.stop()``, the reason in ``stopped_reason``) when the cuff
    force exceeds ``max_cuff_force_n`` or the backend reports itself unhealthy; a block's
    faster stretches and an oscillation predicted above it are skipped (``ProtocolSegment``).
    ``force_lag_s``: how much older the backend's force is than its joint angles."""
    if abs(float(backend.control_dt_s) - protocol.dt_s) > 1e-12:
        raise UsageError(f"calibration: the protocol's period {protocol.dt_s} s is not the "
                         f"backend's control_dt_s {backend.control_dt_s} s")
    rows = protocol.steps
    n = len(rest_q_rad)
    times, q, dq = np.zeros(rows), np.zeros((rows, n)), np.zeros((rows, n))
    force, seg = np.zeros((rows, 3)), np.zeros(rows, dtype=int)
    goal = np.zeros((rows, n))
    k, reason = 0, ""
    # block -> [slower speed, its stretches' peak force, the holds' peak force]
    peaks: dict[str, list[float]] = {}
    skipped: list[str] = []
    wave = (math.inf, 0.0)  # the last oscillation's speed and peak force
    for s, (segment, targets) in enumerate(zip(protocol.segments, protocol.robot_targets_rad,
                                               strict=True)):
        if segment.block in skipped:
            continue
        if segment.kind == "oscillation" and segment.speed_rad_s > wave[0]:
            static = peaks.get(segment.block, [0.0, 0.0, 0.0])[2]
            if static + max(wave[1] - static, 0.0) * (segment.speed_rad_s / wave[0]) ** 2 \
                    > max_cuff_force_n:  # the inertia's share grows with the square
                skipped.append(f"{segment.block} oscillation at {segment.speed_rad_s:.2f} rad/s")
                continue
        if segment.kind == "stretch" and segment.block in peaks:
            slow, peak, static = peaks[segment.block]
            if segment.speed_rad_s > slow and static + (peak - static) * \
                    segment.speed_rad_s / slow > max_cuff_force_n:
                skipped.append(segment.block)
                continue
        start = k
        for target, patient_target in zip(targets, segment.patient_q_rad, strict=True):
            backend.command(target)
            goal[k] = patient_target
            state = backend.state()
            if len(state.patient_q_rad) != n:
                raise UsageError("calibration: the backend reports no patient joint angles "
                                 "(RobotState.patient_q_rad); it cannot be calibrated on")
            times[k], q[k], dq[k] = state.time_s, state.patient_q_rad, state.patient_dq_rad_s
            force[k], seg[k] = limb_force_n(backend), s
            k += 1
            last = getattr(backend, "last_step", None)
            ended = last is not None and (last[2] or last[3])
            magnitude = float(np.linalg.norm(force[k - 1]))
            if magnitude > max_cuff_force_n or not backend.healthy() or ended:
                reason = (f"cuff force {magnitude:.0f} N above {max_cuff_force_n:.0f} N"
                          if magnitude > max_cuff_force_n else "the backend stopped")
                reason += f" in segment {s} ({segment.kind} of {segment.joint})"
                if backend.healthy():
                    backend.stop()
                break
        if reason:
            break
        force_peak = float(np.linalg.norm(force[start:k], axis=1).max(initial=0.0))
        if segment.kind == "oscillation":
            wave = (segment.speed_rad_s, force_peak)
        if segment.block:
            entry = peaks.setdefault(segment.block, [math.inf, 0.0, 0.0])
            if segment.kind == "stretch":
                entry[0] = min(entry[0], segment.speed_rad_s)
            if segment.kind == "ramp":
                entry[2] = max(entry[2], force_peak)
            elif segment.kind == "stretch" and segment.speed_rad_s <= entry[0]:
                entry[1] = max(entry[1], force_peak)
    segments = [(s.kind, s.joint, float(s.speed_rad_s), int(s.repetition), s.block)
                for s in protocol.segments]
    return Recording(times[:k], q[:k], dq[:k], force[:k], goal[:k], seg[:k], segments,
                     tuple(_exercised_of(backend, n)), protocol.joints,
                     dict(protocol.ranges_rad), dict(protocol.patient_rom_rad),
                     np.asarray(rest_q_rad, dtype=float).copy(), stopped_reason=reason,
                     force_lag_s=float(force_lag_s),
                     skipped_blocks=skipped)


def _exercised_of(backend: Any, n: int) -> list[str]:
    env = getattr(backend, "env", None)
    if env is not None:
        return list(env.scene.exercised_joints)
    return [f"joint_{i}" for i in range(n)]
