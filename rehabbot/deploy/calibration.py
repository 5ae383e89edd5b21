"""Patient calibration: run the protocol on a robot, fit the limb, write the patient.

:func:`calibrate` runs the protocol of :mod:`rehabbot.deploy.calibration_protocol` on any
backend and fits it (:mod:`rehabbot.deploy.calibration_fit`); :func:`fit_recording` fits a
recorded session. The result is a :class:`Calibration`: per calibrated joint the passive
stiffness and damping, the limb's inertia, the gravity torque and the range the ramps
covered; for the patient the Modified Ashworth grade, the effort, a body profile and a
:class:`~rehabbot.sim.conditions.PatientCondition`.

The written patient (:func:`save_patient`, ``rehabbot calibrate --out patient.json``) is what
``gym.make`` takes: ``gym.make(env_id, **load_patient("patient.json"))`` (keys ``profile`` and
``condition``, the env's own keyword arguments). How each field is derived:

* ``condition.spasticity_mas``, ``effort``: the fit's winning hypothesis; a resistive share
  ``s`` of the healthy strength becomes ``effort_fraction = s`` (``strength_fraction`` 1);
* ``condition.stiffness_scale``: the geometric mean over the calibrated joints of the fitted
  stiffness over the body model's nominal one (:data:`rehabbot.sim.patient.EXERCISED_PASSIVE`);
* ``condition.rom_scale``: the median, over the calibrated joints' ends, of the patient's
  range (the one the protocol was given) over the anatomical range, both measured from the
  resting posture;
* ``profile``: height and sex as given (default: the body model's: they are not estimated);
  the mass from the fitted gravity torque, which at a given height scales with the body mass
  (de Leva's segment fractions), unless a mass is given.

Not estimated: tremor, fatigue, the reaction delay, and an ``active_assisted`` effort (a
patient who follows the targets shows no torque law the protocol can tell from gravity).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from rehabbot.common.errors import DataError, UsageError
from rehabbot.deploy.calibration_fit import Fit, JointSignals, fit_signals, joint_signals
from rehabbot.deploy.calibration_protocol import (
    KNOT_SPACING_RAD,
    ProtocolSettings,
    Recording,
    build_protocol,
    protocol_ranges,
    run_protocol,
)
from rehabbot.sim import patient as pt
from rehabbot.sim import statics
from rehabbot.sim.conditions import CONDITION_RANGES, PatientCondition
from rehabbot.sim.scene import Scene

PATIENT_FORMAT = "rehabbot-patient/1"
#: The env keyword arguments of a simulated calibration session. One fixed body (no weight
#: level drawn), targets the session never reaches (so the exercise never ends it), a
#: horizon longer than the protocol, and a command every physics step (500 Hz, a real arm's
#: servo rate; the fit averages the samples over its own period, ``block_average``).
SIMULATOR_KWARGS: dict[str, Any] = {"weight_level": 0, "target_tolerance_rad": 1e-6,
                                    "max_episode_steps": 10**6, "exercise": 0,
                                    "frame_skip": 1}
HOLDING_SHARE = 0.7  # the ramps stay where holding the limb needs at most this of the limit
ENCODER_NOISE_RAD = 1e-3
FORCE_NOISE_N = 1.0


@dataclass
class Calibration:
    """A fitted session (module docstring)."""

    recording: Recording
    fit: Fit
    profile: pt.PatientProfile
    condition: PatientCondition
    gravity_scale: float  # fitted gravity torque / the body model's, least squares

    def patient(self) -> dict[str, Any]:
        """The env's keyword arguments for this patient: ``profile`` and ``condition``."""
        return {"profile": dataclasses.asdict(self.profile),
                "condition": self.condition.to_dict()}

    def joint_table(self) -> dict[str, dict[str, Any]]:
        """Per calibrated joint, the fitted numbers (SI units)."""
        return {name: {"stiffness_nm_per_rad": j.stiffness_nm_per_rad,
                       "damping_nms_per_rad": j.damping_nms_per_rad,
                       "inertia_kg_m2": j.inertia_kg_m2[0],
                       "vaf": j.vaf, "rms_residual_nm": j.rms_residual_nm,
                       "range_reached_rad": list(j.range_reached_rad),
                       "patient_range_rad": list(self.recording.patient_rom_rad[name])}
                for name, j in self.fit.joints.items()}


# -- running -----------------------------------------------------------------------------------
def simulator_backend(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> Any:
    """A :class:`~rehabbot.deploy.simulator.SimulatorBackend` for a calibration session:
    ``env_kwargs`` over :data:`SIMULATOR_KWARGS`, reset with seed 0."""
    from rehabbot.deploy.simulator import SimulatorBackend

    kwargs = {**SIMULATOR_KWARGS, **dict(env_kwargs or {})}
    try:
        backend = SimulatorBackend(env_id, **kwargs)
    except (TypeError, ValueError) as err:
        raise UsageError(f"calibration: cannot make {env_id!r} with {kwargs}: {err}") from None
    backend.reset(seed=0)
    return backend


def calibrate(backend: Any, scene: Scene, *, joints: Sequence[str] | None = None,
              ranges_deg: Mapping[str, tuple[float, float]] | None = None,
              settings: ProtocolSettings | None = None,
              patient_rom_rad: tuple[np.ndarray, np.ndarray] | None = None,
              given_profile: Mapping[str, Any] | None = None,
              noise_rng: np.random.Generator | None = None,
              source: tuple[str, Mapping[str, Any]] = ("", {})) -> Calibration:
    """Run the protocol on ``backend`` with the body model ``scene`` and fit it.

    ``patient_rom_rad``: the patient's range of the exercised joints (default: the
    backend's ``rom_bounds_rad()``, else the anatomical range); ``given_profile``: profile
    fields known to the user; ``noise_rng``: add sensor noise (:func:`add_sensor_noise`) to
    the recording before the fit, as a real robot's sensors would (simulated sessions);
    ``source``: the env id and keyword arguments of the body model, kept in the recording
    so that ``rehabbot calibrate --from-log`` can build it again."""
    settings = settings or ProtocolSettings()
    if patient_rom_rad is None:
        reader = getattr(backend, "rom_bounds_rad", None)
        patient_rom_rad = reader() if reader is not None else _anatomical_rom(scene)
    ranges = protocol_ranges(scene, patient_rom_rad, joints, dict(ranges_deg or {}),
                             settings.margin_rad)
    limit = settings.max_cuff_force_n
    reader = getattr(backend, "cuff_force_limit_n", None)
    if reader is not None:
        limit = min(limit, float(reader()))
    if not ranges_deg:
        ranges = contact_free(scene, within_force(scene, ranges, limit))
    rest = backend.state().patient_q_rad
    if len(rest) != len(scene.exercised_joints):
        raise UsageError("calibration: the backend reports no patient joint angles "
                         "(RobotState.patient_q_rad); it cannot be calibrated on")
    protocol = build_protocol(scene, ranges, patient_rom_rad, float(backend.control_dt_s),
                              settings, start_q_rad=rest)
    env = getattr(backend, "env", None)
    lag = float(env.model.opt.timestep) if env is not None else 0.0
    recording = run_protocol(backend, protocol, rest, limit, force_lag_s=lag)
    recording.env_id, recording.env_kwargs = source[0], dict(source[1])
    if noise_rng is not None:
        recording = add_sensor_noise(recording, noise_rng)
    return fit_recording(recording, scene, given_profile)


def holding_force_n(scene: Scene, pose_rad: np.ndarray) -> float:
    """The cuff force [N] that holds the limb still at the exercised-joint angles
    ``pose_rad`` (the body model's statics: gravity and the passive springs)."""
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    data.qpos[scene.exercised_qpos_adr] = pose_rad
    scene.follow_coupled_joints(data.qpos)
    mujoco.mj_forward(model, data)
    return float(np.linalg.norm(statics.cuff_load_force(scene, data)))


def within_force(scene: Scene, ranges_rad: dict[str, tuple[float, float]],
                 limit_n: float, share: float = HOLDING_SHARE) -> dict[str, tuple[float, float]]:
    """``ranges_rad`` narrowed, per joint (the others at rest), to the interval around the
    resting angle where holding the limb still needs at most ``share`` of ``limit_n``: the
    rest is left to the stretches' inertia and reflex. ``UsageError`` where less than 10
    degrees remain."""
    exercised = list(scene.exercised_joints)
    home = scene.home_qpos[scene.exercised_qpos_adr].astype(float)
    out = {}
    for joint, (low, high) in ranges_rad.items():
        i = exercised.index(joint)
        grid = np.linspace(low, high, 1 + math.ceil((high - low) / KNOT_SPACING_RAD))
        pose = home.copy()
        ok = []
        for angle in grid:
            pose[i] = angle
            ok.append(holding_force_n(scene, pose) <= share * limit_n)
        start = int(np.argmin(np.abs(grid - np.clip(home[i], low, high))))
        if not ok[start]:
            raise UsageError(f"calibration: holding {joint} at rest needs more than "
                             f"{share * limit_n:.0f} N at the cuff ({share:.0%} of its "
                             f"{limit_n:.0f} N limit)")
        a = b = start
        while a > 0 and ok[a - 1]:
            a -= 1
        while b < len(grid) - 1 and ok[b + 1]:
            b += 1
        if grid[b] - grid[a] < math.radians(10.0):
            raise UsageError(f"calibration: {joint} can be held within {share:.0%} of the "
                             f"cuff's {limit_n:.0f} N limit over only "
                             f"{math.degrees(grid[b] - grid[a]):.1f} deg")
        out[joint] = (float(grid[a]), float(grid[b]))
    return out


CONTACT_CLEARANCE_M = 0.001
#: An end of a range set by a contact stays this far inside it.
CONTACT_MARGIN_RAD = math.radians(3.0)


def contact_free(scene: Scene, ranges_rad: dict[str, tuple[float, float]],
                 clearance_m: float = CONTACT_CLEARANCE_M) -> dict[str, tuple[float, float]]:
    """``ranges_rad`` narrowed, per joint (the others at rest), to the interval around the
    resting angle (or the clear angle nearest it, where the limb rests on a support) where
    the limb moved by the joint stays ``clearance_m`` away from everything fixed to the world
    that it can touch (a leg rest, a chair, the floor): a contact would push on the limb with
    a force the cuff does not measure; an end set by a contact moves a further
    :data:`CONTACT_MARGIN_RAD` inward (a stretch overshoots its end, a compliant foot sags).
    ``UsageError`` where no angle is clear or less than 10 degrees remain."""
    model = scene.model
    data = mujoco.MjData(model)
    exercised = list(scene.exercised_joints)
    home = scene.home_qpos[scene.exercised_qpos_adr].astype(float)
    fixed = [g for g in range(model.ngeom) if int(model.body_weldid[model.geom_bodyid[g]]) == 0]
    out = {}
    for joint, (low, high) in ranges_rad.items():
        i = exercised.index(joint)
        first = int(model.jnt_bodyid[model.joint(joint).id])
        limb = [g for g in range(model.ngeom)
                if _descends(model, int(model.geom_bodyid[g]), first)]
        pairs = [(a, b) for a in limb for b in fixed
                 if model.geom_contype[a] & model.geom_conaffinity[b]
                 or model.geom_contype[b] & model.geom_conaffinity[a]]
        grid = np.linspace(low, high, 1 + math.ceil((high - low) / KNOT_SPACING_RAD))
        pose = home.copy()
        ok = []
        for angle in grid:
            pose[i] = angle
            data.qpos[:] = scene.home_qpos
            data.qpos[scene.exercised_qpos_adr] = pose
            scene.follow_coupled_joints(data.qpos)
            mujoco.mj_kinematics(model, data)
            ok.append(all(mujoco.mj_geomDistance(model, data, a, b, clearance_m, None)
                          >= clearance_m for a, b in pairs))
        clear = np.flatnonzero(ok)
        if not len(clear):
            raise UsageError(f"calibration: the limb moved by {joint} comes within "
                             f"{1000 * clearance_m:.0f} mm of a fixed object at every angle")
        a = b = int(clear[np.argmin(np.abs(grid[clear] - home[i]))])
        while a > 0 and ok[a - 1]:
            a -= 1
        while b < len(grid) - 1 and ok[b + 1]:
            b += 1
        start = float(grid[a]) + (CONTACT_MARGIN_RAD if a > 0 else 0.0)
        end = float(grid[b]) - (CONTACT_MARGIN_RAD if b < len(grid) - 1 else 0.0)
        if end - start < math.radians(10.0):
            raise UsageError(f"calibration: {joint} moves only "
                             f"{math.degrees(end - start):.1f} deg clear of fixed objects")
        out[joint] = (start, end)
    return out


def _descends(model: mujoco.MjModel, body: int, ancestor: int) -> bool:
    while body > 0:
        if body == ancestor:
            return True
        body = int(model.body_parentid[body])
    return False


def _anatomical_rom(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    model = scene.model
    ranges = np.array([model.jnt_range[model.joint(j).id] for j in scene.exercised_joints])
    return ranges[:, 0].copy(), ranges[:, 1].copy()


def add_sensor_noise(recording: Recording, rng: np.random.Generator,
                     encoder_rad: float = ENCODER_NOISE_RAD,
                     force_n: float = FORCE_NOISE_N) -> Recording:
    """A copy of ``recording`` with Gaussian noise on the joint angles (``encoder_rad``) and
    on each component of the cuff force (``force_n``), drawn from ``rng``."""
    if not isinstance(rng, np.random.Generator):
        raise UsageError(f"calibration: noise needs a numpy Generator, got {rng!r}")
    for name, value in (("encoder_rad", encoder_rad), ("force_n", force_n)):
        if not (isinstance(value, (int, float)) and 0.0 <= value <= 100.0):
            raise UsageError(f"calibration: sensor noise {name}={value!r} must be in [0, 100]")
    return dataclasses.replace(
        recording,
        patient_q_rad=recording.patient_q_rad + rng.normal(0.0, encoder_rad,
                                                           recording.patient_q_rad.shape),
        cuff_force_n=recording.cuff_force_n + rng.normal(0.0, force_n,
                                                         recording.cuff_force_n.shape))


# -- fitting -----------------------------------------------------------------------------------
def fit_recording(recording: Recording, scene: Scene,
                  given_profile: Mapping[str, Any] | None = None) -> Calibration:
    """Fit ``recording`` on the body model ``scene`` (module docstring)."""
    signals = joint_signals(recording, scene)
    fit = fit_signals(signals)
    scale = gravity_scale(scene, signals, fit)
    profile = _profile(scene, scale, dict(given_profile or {}))
    condition = _condition(scene, recording, fit)
    return Calibration(recording, fit, profile, condition, scale)


def model_gravity_nm(scene: Scene, q_rad: np.ndarray, joint: str) -> np.ndarray:
    """The body model's gravity torque [N·m] on ``joint`` at rows of exercised-joint angles
    (the generalised bias force at rest: what the cuff carries)."""
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    dof = int(model.joint(joint).dofadr[0])
    out = np.zeros(len(q_rad))
    result = np.zeros(model.nv)
    for t, row in enumerate(q_rad):
        data.qpos[scene.exercised_qpos_adr] = row
        scene.follow_coupled_joints(data.qpos)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_rne(model, data, 0, result)
        out[t] = result[dof]
    return out


#: Rows per joint the gravity comparison uses.
GRAVITY_SAMPLES = 200


def gravity_rows(signal: JointSignals) -> np.ndarray:
    """Indices of up to :data:`GRAVITY_SAMPLES` of the joint's own quasi-static rows."""
    rows = np.flatnonzero(signal.own & ~signal.stretch)
    return rows[np.linspace(0, len(rows) - 1, min(GRAVITY_SAMPLES, len(rows))).astype(int)]


def gravity_scale(scene: Scene, signals: Sequence[JointSignals], fit: Fit) -> float:
    """The least-squares factor from the body model's gravity torques to the fitted ones."""
    model_g, fitted = [], []
    for s in signals:
        rows = gravity_rows(s)
        model_g.append(model_gravity_nm(scene, s.q_all_rad[rows], s.joint))
        fitted.append(s.gravity[rows] @ fit.gravity_params)
    a, b = np.concatenate(model_g), np.concatenate(fitted)
    return float(a @ b / (a @ a))


def _profile(scene: Scene, scale: float, given: dict[str, Any]) -> pt.PatientProfile:
    unknown = sorted(set(given) - {"height_m", "mass_kg", "sex"})
    if unknown:
        raise UsageError(f"calibration: unknown profile fields {unknown}; valid: height_m, "
                         "mass_kg, sex")
    body = scene.profile
    height = given.get("height_m", body.height_m)
    sex = given.get("sex", body.sex)
    # At a fixed height, the limb's gravity torque scales with body mass.
    mass = given.get("mass_kg", body.mass_kg * scale * body.height_m / height)
    low, high = pt.MASS_RANGE_KG
    try:
        return pt.PatientProfile(height_m=height, mass_kg=float(min(max(mass, low), high)),
                                 sex=sex)
    except ValueError as err:
        raise UsageError(f"calibration: {err}") from None


def _condition(scene: Scene, recording: Recording, fit: Fit) -> PatientCondition:
    ratios = [joint.stiffness_nm_per_rad / pt.passive_for(name).stiffness_nm_per_rad
              for name, joint in fit.joints.items()]
    positive = [r for r in ratios if r > 0]
    low, high = CONDITION_RANGES["stiffness_scale"]
    stiffness = math.exp(float(np.mean(np.log(positive)))) if positive else 1.0
    fields: dict[str, Any] = {
        "spasticity_mas": fit.spasticity_mas,
        "stiffness_scale": round(min(max(stiffness, low), high), 3),
        "rom_scale": rom_scale(scene, recording)}
    share = round(min(fit.effort_share, 1.0), 3)
    if fit.effort == "resistive" and share > 0:  # a share below 0.0005 is no effort
        fields.update(effort="resistive", effort_fraction=share)
    return PatientCondition(**fields)


def rom_scale(scene: Scene, recording: Recording) -> float:
    """The median ratio of the patient's range to the anatomical one, per calibrated joint's
    end, both from the resting posture (module docstring)."""
    exercised = list(scene.exercised_joints)
    ratios = []
    for joint in recording.joints:
        home = float(recording.rest_q_rad[exercised.index(joint)])
        anatomical = [math.radians(v) for v in pt.JOINT_BY_NAME[joint].range_deg]
        for patient_end, end in zip(recording.patient_rom_rad[joint], anatomical, strict=True):
            if abs(end - home) > 1e-6:
                ratios.append((patient_end - home) / (end - home))
    low, high = CONDITION_RANGES["rom_scale"]
    return round(min(max(float(np.median(ratios)), low), high), 3) if ratios else 1.0


# -- the patient file --------------------------------------------------------------------------
def save_patient(path: str | Path, calibration: Calibration) -> None:
    """Write the patient JSON: the env's keyword arguments (``profile``, ``condition``) and,
    for the record, the fitted numbers per joint."""
    from rehabbot.common.files import atomic_write_json

    fit = calibration.fit
    document = {"format": PATIENT_FORMAT, **calibration.patient(),
                "calibration": {"spasticity_mas": fit.spasticity_mas, "effort": fit.effort,
                                "effort_share": fit.effort_share,
                                "gravity_scale": calibration.gravity_scale,
                                "joints": calibration.joint_table(),
                                "env_id": calibration.recording.env_id,
                                "stopped_reason": calibration.recording.stopped_reason,
                                "skipped_blocks": calibration.recording.skipped_blocks}}
    atomic_write_json(Path(path), document)


def load_patient(path: str | Path) -> dict[str, Any]:
    """The env's keyword arguments stored in a patient JSON (``gym.make(id, **them)``);
    ``DataError`` naming a missing, damaged or foreign file."""
    try:
        document = json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise DataError(f"{path}: cannot read a patient file ({err})") from None
    if not isinstance(document, dict) or document.get("format") != PATIENT_FORMAT:
        raise DataError(f"{path}: not a patient file (format {PATIENT_FORMAT!r})")
    try:
        profile = pt.PatientProfile(**document["profile"])
        condition = PatientCondition(**document["condition"])
    except (KeyError, TypeError, ValueError) as err:
        raise DataError(f"{path}: damaged patient file ({err})") from None
    return {"profile": dataclasses.asdict(profile), "condition": condition.to_dict()}


# -- the simulated patient's own values (the round trip's ground truth) -------------------------
def simulated_truth(backend: Any, calibration: Calibration) -> dict[str, Any]:
    """What the simulated patient of ``backend`` really is: per calibrated joint the model's
    stiffness and damping, the limb's inertia about the joint at the resting posture (the
    mass matrix's diagonal, armature included) and the gravity torque at the fit's rows;
    the condition's grade, effort and share, and the profile."""
    env = backend.env
    scene, model = env.scene, env.model
    condition = env.config.condition
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    data.qpos[scene.exercised_qpos_adr] = calibration.recording.rest_q_rad
    mujoco.mj_forward(model, data)
    mass_matrix = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass_matrix)
    share = condition.strength_fraction * condition.effort_fraction \
        if condition.effort != "passive" else 0.0
    joints = {}
    for name in calibration.fit.joints:
        joint = model.joint(name)
        dof = int(joint.dofadr[0])
        joints[name] = {"stiffness_nm_per_rad": float(model.jnt_stiffness[joint.id]),
                        "damping_nms_per_rad": float(model.dof_damping[dof]),
                        "inertia_kg_m2": float(mass_matrix[dof, dof])}
    return {"joints": joints, "spasticity_mas": condition.spasticity_mas,
            "effort": condition.effort, "effort_share": share,
            "profile": dataclasses.asdict(scene.profile)}


def gravity_error(scene: Scene, calibration: Calibration) -> dict[str, float]:
    """Per calibrated joint: the RMS of the fitted gravity torque's error against the body
    model's, over the joint's quasi-static rows, relative to the model's RMS."""
    signals = joint_signals(calibration.recording, scene)
    out = {}
    for s in signals:
        rows = gravity_rows(s)
        truth = model_gravity_nm(scene, s.q_all_rad[rows], s.joint)
        fitted = s.gravity[rows] @ calibration.fit.gravity_params
        out[s.joint] = float(np.sqrt(np.mean((fitted - truth) ** 2) / np.mean(truth ** 2)))
    return out
