"""Measuring a patient's condition in the simulation, as a clinic would.

* :func:`stretch_test`: an isokinetic stretch, the instrumented version of the Modified Ashworth
  and Tardieu tests. The cuff is released, the robot stands aside, the limb's other compliant
  joints are held by stiff servos, and a velocity servo (the "dynamometer") moves one joint
  through part of its range at a constant speed. Returned per physics step: the angle, the
  dynamometer's torque, the stretch-reflex torque and the passive joint torque. On MyoSuite's
  legs (``patient_model="myo"``) the reflex excites the stretched muscles
  (:class:`~rehabbot.sim.muscle_drive.MuscleDrive`): its torque is their active force's, and the
  passive torque includes their passive force.
* :func:`tremor_spectrum`: the limb held still by the robot (zero actions) for some seconds;
  the power spectrum of one joint's angle (Hann window, linear trend removed) and its peak.

Both build a :class:`~rehabbot.envs.rehab_env.RehabEnv` of their own and change its model
(actuators become servos), so they never touch an env a user holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.sim import statics
from rehabbot.sim.conditions import PatientCondition, as_condition
from rehabbot.sim.muscle_drive import MuscleDrive
from rehabbot.sim.muscles import MuscleMeter, PassiveForce, moment_arms_m
from rehabbot.sim.patient_drive import PatientDrive
from rehabbot.sim.physics import WorkMeter

DYNAMOMETER_KV_NMS_PER_RAD = 1000.0  # velocity servo gain of the dynamometer
HOLD_KP_NM_PER_RAD = 500.0  # the servos that hold the other compliant joints
HOLD_KD_NMS_PER_RAD = 20.0


@dataclass
class StretchResult:
    """One isokinetic stretch (arrays per physics step of the sweep)."""

    joint: str
    speed_deg_s: float
    angle_deg: np.ndarray
    velocity_deg_s: np.ndarray
    dynamometer_nm: np.ndarray  # torque the dynamometer applies to keep the speed
    reflex_nm: np.ndarray  # the stretch reflex's torque on the joint (opposes the motion)
    passive_nm: np.ndarray  # the joint's passive spring and damper torque (and muscles')
    range_deg: tuple[float, float]  # the joint's range (reduced by rom_scale)

    @property
    def resistance_nm(self) -> np.ndarray:
        """The reflex's resistance to the motion [N·m] (>= 0)."""
        return -np.sign(self.speed_deg_s) * self.reflex_nm

    def resisted_fraction(self, threshold_nm: float = 0.05) -> float:
        """The share of the sweep where the reflex resists with more than ``threshold_nm``."""
        return float(np.mean(self.resistance_nm > threshold_nm))


def _probe_env(condition: PatientCondition, limb: str, side: str,
               patient_model: str = "rigid") -> RehabEnv:
    env = RehabEnv(limb=limb, side=side, condition=condition, weight_level=0,
                   reward="progress", terminate_on_safety=False, patient_model=patient_model)
    env.reset(seed=0)
    return env


def _make_servo(model: mujoco.MjModel, actuator: int, kp: float, kv: float) -> None:
    """Turn a patient effort actuator into ``force = kp (ctrl - q) - kv qdot`` (kp = 0: a
    velocity servo ``kv (ctrl - qdot)``), unlimited."""
    model.actuator_ctrllimited[actuator] = 0
    model.actuator_forcelimited[actuator] = 0
    model.actuator_biastype[actuator] = mujoco.mjtBias.mjBIAS_AFFINE
    model.actuator_gainprm[actuator, 0] = kp if kp > 0 else kv
    model.actuator_biasprm[actuator, :3] = (0.0, -kp, -kv)


def stretch_test(condition: PatientCondition | dict | None, joint: str = "elbow_flexion",
                 speed_deg_s: float = 100.0, limb: str = "arm", side: str = "right",
                 sweep: tuple[float, float] = (0.05, 0.95),
                 patient_model: str = "rigid") -> StretchResult:
    """Move ``joint`` (side-less name, a compliant joint of ``limb``) at ``speed_deg_s``
    (positive: the joint's positive direction) from ``sweep[0]`` to ``sweep[1]`` of its range
    (fractions from the start of the stretch) with the cuff released; ``patient_model="myo"``
    stretches MyoSuite's leg (``limb="knee"`` or ``"hip"``)."""
    condition = as_condition(condition)
    if not math.isfinite(speed_deg_s) or speed_deg_s == 0.0:
        raise ValueError(f"speed_deg_s={speed_deg_s!r} must be a finite, non-zero speed")
    env = _probe_env(condition, limb, side, patient_model)
    try:
        scene, model, data = env.scene, env.model, env.data
        names = [model.joint(int(model.dof_jntid[d])).name for d in scene.compliant_dof_adr]
        full = f"{joint}_{side[0]}"
        if full not in names:
            raise ValueError(f"joint={joint!r} is not a compliant joint of limb={limb!r}; "
                             f"valid: {[n.rsplit('_', 1)[0] for n in names]}")
        ranges = env.compliant_ranges_rad
        low, high = ranges[names.index(full)]
        start, end = sweep
        if speed_deg_s < 0:
            start, end = 1.0 - start, 1.0 - end
        q_start, q_end = low + start * (high - low), low + end * (high - low)
        data.eq_active[scene.robots[0].equality_id] = 0
        exercised = list(scene.exercised_joints)
        for name, actuator in zip(exercised, scene.patient_actuator_ids, strict=True):
            qadr = model.joint(name).qposadr[0]
            if name == full:
                _make_servo(model, actuator, 0.0, DYNAMOMETER_KV_NMS_PER_RAD)
                data.ctrl[actuator] = math.radians(speed_deg_s)
                data.qpos[qadr] = q_start
                data.qvel[model.joint(name).dofadr[0]] = math.radians(speed_deg_s)
            elif name in names:
                _make_servo(model, actuator, HOLD_KP_NM_PER_RAD, HOLD_KD_NMS_PER_RAD)
                data.ctrl[actuator] = data.qpos[qadr]
        scene.follow_coupled_joints(data.qpos)
        mujoco.mj_forward(model, data)
        coupling = statics.coupling_map(scene, data)
        if coupling is not None:  # the joints that follow the knee move with it from the start
            data.qvel[:] = coupling @ data.qvel
            mujoco.mj_forward(model, data)
        meter = WorkMeter(scene.robots[0].patient_cuff_site_id, env.safety.cuff_rows[0])
        muscles = None
        if len(scene.muscle_actuator_ids):
            drive: PatientDrive | MuscleDrive = MuscleDrive(scene, condition, ranges,
                                                            frame_skip=1)
            muscles = MuscleMeter(model, drive.muscle_ids, count_active=True)
            muscles.reset(data)
            passive = PassiveForce(model, drive.muscle_ids)
        else:
            drive = PatientDrive(scene, condition, ranges, frame_skip=1)
        drive.reset(data, env.np_random)
        meter.reset(data)
        j = names.index(full)
        dof = scene.compliant_dof_adr[j]
        qadr = model.joint(full).qposadr[0]
        actuator = scene.patient_actuator_ids[exercised.index(full)]
        goal = [float(data.qpos[model.joint(n).qposadr[0]]) for n in names]
        rows = []
        steps = int(abs(q_end - q_start) / abs(math.radians(speed_deg_s)) / model.opt.timestep)
        for _ in range(steps):
            passive_nm = 0.0
            if muscles is not None:
                drive.run(model, data, goal, env.np_random, meter, muscles)
                ids = drive.muscle_ids
                pull = moment_arms_m(model, data, ids).T @ passive.force_n(
                    data.actuator_length[ids])
                passive_nm = float(statics.reduced(scene, data, pull)[dof])
            else:
                drive.run(model, data, goal, env.np_random, meter)
            rows.append((data.qpos[qadr], data.qvel[dof], data.actuator_force[actuator],
                         drive.torque_nm[exercised.index(full)],
                         data.qfrc_passive[dof] + passive_nm))
    finally:
        env.close()
    table = np.array(rows, dtype=float)
    return StretchResult(joint=joint, speed_deg_s=float(speed_deg_s),
                         angle_deg=np.degrees(table[:, 0]),
                         velocity_deg_s=np.degrees(table[:, 1]), dynamometer_nm=table[:, 2],
                         reflex_nm=table[:, 3], passive_nm=table[:, 4],
                         range_deg=(math.degrees(low), math.degrees(high)))


@dataclass
class TremorSpectrum:
    """The power spectrum of a held joint's angle."""

    joint: str
    frequency_hz: np.ndarray
    power: np.ndarray
    peak_hz: float
    rms_deg: float  # the angle's RMS about its trend


def tremor_spectrum(condition: PatientCondition | dict | None, joint: str = "elbow_flexion",
                    limb: str = "arm", side: str = "right", seconds: float = 10.0,
                    seed: int = 0, band_hz: tuple[float, float] = (1.0, 20.0),
                    patient_model: str = "rigid") -> TremorSpectrum:
    """Hold the limb still (zero actions) for ``seconds`` after ``reset(seed=seed)`` and
    return the spectrum of ``joint``'s angle, sampled every physics step, and its peak within
    ``band_hz``; ``patient_model="myo"`` holds MyoSuite's limb, its muscles trembling."""
    condition = as_condition(condition)
    env = RehabEnv(limb=limb, side=side, condition=condition, weight_level=0,
                   reward="progress", frame_skip=1, max_episode_steps=10**6,
                   patient_model=patient_model)
    try:
        env.reset(seed=seed)
        qadr = env.model.joint(f"{joint}_{side[0]}").qposadr[0]
        zero = np.zeros(env.action_space.shape, dtype=np.float32)
        angles = []
        for _ in range(round(seconds / env.dt)):
            env.step(zero)
            angles.append(float(env.data.qpos[qadr]))
        dt = env.dt
    finally:
        env.close()
    angle = np.degrees(np.array(angles))
    t = np.arange(len(angle)) * dt
    detrended = angle - np.polyval(np.polyfit(t, angle, 1), t)
    power = np.abs(np.fft.rfft(detrended * np.hanning(len(angle)))) ** 2
    freq = np.fft.rfftfreq(len(angle), dt)
    band = (freq >= band_hz[0]) & (freq <= band_hz[1])
    peak = float(freq[band][np.argmax(power[band])])
    return TremorSpectrum(joint=joint, frequency_hz=freq, power=power, peak_hz=peak,
                          rms_deg=float(np.sqrt(np.mean(detrended**2))))
