"""Patient calibration: the protocol's segments, the estimator on synthetic torques, bad
inputs, the recording and patient files, and a round trip on a simulated patient."""

from __future__ import annotations

import argparse
import json
import math

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.common.errors import DataError, UsageError
from rehabbot.deploy import calibration as cal
from rehabbot.deploy import calibration_fit as cf
from rehabbot.deploy import calibration_protocol as cp
from rehabbot.deploy.backend import RobotState
from rehabbot.sim import build_scene
from rehabbot.sim.conditions import MAS_GRADES

DT_S = 0.02


@pytest.fixture(scope="module")
def knee_scene():
    return build_scene("knee")


# -- the estimator on synthetic torques --------------------------------------------------------
TRUE = {"stiffness": 3.0, "damping": 1.0, "inertia": 0.45, "gravity": (-8.0, 3.0),
        "share": 0.1}


def synthetic_signals(grade: str, resistive: bool, true: dict | None = None,
                      rng: np.random.Generator | None = None,
                      torque_noise_nm: float = 0.0) -> list[cf.JointSignals]:
    """One joint driven through slow ramps and holds, small oscillations and fast stretches,
    its cuff torque made from known parameters (gravity: a cos q + b sin q)."""
    true = true or TRUE
    t = np.arange(0.0, 60.0, DT_S)
    slow = 0.9 + 0.8 * np.sin(2 * np.pi * t / 30.0)
    wave = 0.9 + 0.14 * np.sin(2 * np.pi * t) * (1.0 + 0.5 * np.sin(2 * np.pi * t / 5.0))
    fast = 0.9 + 0.8 * np.sin(2 * np.pi * t / 1.5) * (np.sin(2 * np.pi * t / 7.0) > 0.3)
    oscillation = (t >= 30.0) & (t < 45.0)
    stretch = t >= 45.0
    q = np.where(stretch, fast, np.where(oscillation, wave, slow))
    dq = np.gradient(q, DT_S)
    ddq = np.gradient(dq, DT_S)
    gravity = np.column_stack([np.cos(q), np.sin(q)])
    strength = (130.0, 200.0)
    signals = cf.JointSignals(
        joint="knee_flexion_r", q_rad=q, q_all_rad=q[:, None], dq_rad_s=dq, ddq_rad_s2=ddq,
        delayed_dq_rad_s=np.interp(t - 0.03, t, dq, left=0.0),
        other_ddq_rad_s2=np.zeros((len(t), 0)), command_dq_rad_s=np.zeros(len(t)),
        stretch=stretch, oscillation=oscillation, tau_nm=np.zeros(len(t)), gravity=gravity,
        posture=np.zeros(len(t), dtype=int), own=np.ones(len(t), dtype=bool), rest_rad=0.9,
        rom_rad=(0.0, math.radians(135.0)), strength_nm=strength,
        reflex_gain_nms_per_rad=2.0)
    # The ramps' and stretches' own inertia, damping and command terms are nuisance columns;
    # give them the same physics.
    tau = (true["inertia"] * ddq + true["damping"] * dq + true["stiffness"] * (q - 0.9)
           + gravity @ np.array(true["gravity"]) - cf.reflex_column(signals, grade))
    if resistive:
        tau = tau + true["share"] * cf.resist_column(signals)
    if rng is not None:
        tau = tau + rng.normal(0.0, torque_noise_nm, len(t))
    signals.tau_nm = tau
    return [signals]


@pytest.mark.parametrize("grade", MAS_GRADES)
def test_exact_recovery_without_noise(grade):
    fit = cf.fit_signals(synthetic_signals(grade, resistive=False))
    joint = fit.joints["knee_flexion_r"]
    assert fit.spasticity_mas == grade
    assert fit.effort == "passive"
    assert joint.stiffness_nm_per_rad == pytest.approx(TRUE["stiffness"], rel=1e-6)
    assert joint.damping_nms_per_rad == pytest.approx(TRUE["damping"], rel=1e-6)
    assert joint.inertia_kg_m2[0] == pytest.approx(TRUE["inertia"], rel=1e-6)
    assert joint.vaf > 1 - 1e-9


def test_resistive_effort_and_its_share_recovered():
    fit = cf.fit_signals(synthetic_signals("1+", resistive=True))
    assert (fit.spasticity_mas, fit.effort) == ("1+", "resistive")
    assert fit.effort_share == pytest.approx(TRUE["share"], rel=1e-6)


def test_recovery_within_bounds_with_noise():
    rng = np.random.default_rng(7)
    fit = cf.fit_signals(synthetic_signals("2", resistive=False, rng=rng,
                                           torque_noise_nm=0.3))
    joint = fit.joints["knee_flexion_r"]
    assert fit.spasticity_mas == "2"
    assert abs(joint.stiffness_nm_per_rad / TRUE["stiffness"] - 1) < 0.1
    assert abs(joint.damping_nms_per_rad / TRUE["damping"] - 1) < 0.05
    assert abs(joint.inertia_kg_m2[0] / TRUE["inertia"] - 1) < 0.1
    assert joint.vaf > 0.8


def test_a_wrong_parameter_is_caught():
    """A patient 10 % stiffer (or more damped, or heavier) reads so; a grade left out of the
    hypotheses fits worse than the true one."""
    for key in ("stiffness", "damping", "inertia"):
        changed = {**TRUE, key: 1.1 * TRUE[key]}
        fit = cf.fit_signals(synthetic_signals("0", resistive=False, true=changed))
        joint = fit.joints["knee_flexion_r"]
        fitted = {"stiffness": joint.stiffness_nm_per_rad,
                  "damping": joint.damping_nms_per_rad, "inertia": joint.inertia_kg_m2[0]}
        assert fitted[key] == pytest.approx(1.1 * TRUE[key], rel=1e-6)
    signals = synthetic_signals("3", resistive=False)
    wrong = cf.fit_signals(signals, grades=("2",))
    right = cf.fit_signals(signals, grades=("3",))
    assert wrong.joints["knee_flexion_r"].vaf < right.joints["knee_flexion_r"].vaf - 1e-3


def test_damping_and_inertia_come_from_the_oscillations_only():
    """Off the oscillations, a velocity or acceleration term is a free nuisance: a torque
    that follows the ramps' speed (a servo's, not the limb's) leaves the damping as it is."""
    signals = synthetic_signals("0", resistive=False)
    s = signals[0]
    off = ~s.oscillation & ~s.stretch
    s.tau_nm = s.tau_nm + np.where(off, 0.7 * s.dq_rad_s + 0.2 * s.ddq_rad_s2, 0.0)
    joint = cf.fit_signals(signals).joints["knee_flexion_r"]
    assert joint.damping_nms_per_rad == pytest.approx(TRUE["damping"], rel=1e-6)
    assert joint.inertia_kg_m2[0] == pytest.approx(TRUE["inertia"], rel=1e-6)


def test_a_tiny_resistive_share_is_no_effort():
    """A push below MIN_EFFORT_SHARE of the healthy strength fits as the passive patient; one
    above it is found."""
    small = {**TRUE, "share": 0.5 * cf.MIN_EFFORT_SHARE}
    fit = cf.fit_signals(synthetic_signals("0", resistive=True, true=small))
    assert (fit.effort, fit.effort_share) == ("passive", 0.0)
    large = {**TRUE, "share": 2.0 * cf.MIN_EFFORT_SHARE}
    fit = cf.fit_signals(synthetic_signals("0", resistive=True, true=large))
    assert fit.effort == "resistive"
    assert fit.effort_share == pytest.approx(large["share"], rel=1e-6)


def small_recording(rows: int, dt_s: float, kinds: list[str]) -> cp.Recording:
    """A recording of ``rows`` samples split evenly into segments of ``kinds`` (the knee)."""
    joints = ("hip_flexion_r", "hip_abduction_r", "knee_flexion_r")
    segment = (np.arange(rows) * len(kinds)) // rows
    t = np.arange(rows) * dt_s
    q = np.column_stack([0.1 * t, 0.2 * t, 1.0 + 0.3 * t])
    return cp.Recording(
        time_s=t, patient_q_rad=q, patient_dq_rad_s=np.zeros((rows, 3)),
        cuff_force_n=np.column_stack([t, 2 * t, np.ones(rows)]), target_q_rad=q.copy(),
        segment=segment, segments=[(k, "knee_flexion_r", 0.1, 0, "") for k in kinds],
        exercised_joints=joints, joints=("knee_flexion_r",),
        ranges_rad={"knee_flexion_r": (0.2, 1.5)},
        patient_rom_rad={"knee_flexion_r": (0.0, 2.3)}, rest_q_rad=q[0].copy())


def test_block_average_means_whole_blocks():
    fast = small_recording(103, 0.002, ["hold", "oscillation"])
    slow = cf.block_average(fast, 0.02)
    assert len(slow.time_s) == 10  # the last 3 rows make no whole block
    assert np.allclose(slow.time_s, 0.002 * (np.arange(10) * 10 + 4.5), rtol=0, atol=1e-12)
    assert np.allclose(slow.cuff_force_n[:, 1], 2 * slow.time_s, rtol=0, atol=1e-12)
    assert np.allclose(slow.patient_q_rad[:, 2], 1.0 + 0.3 * slow.time_s, rtol=0, atol=1e-12)
    assert slow.segment.tolist() == [0] * 5 + [1] * 5  # each block's middle row's
    same = small_recording(50, 0.02, ["hold"])
    assert cf.block_average(same, 0.02) is same


def test_follower_accelerations_are_fitted_on_the_oscillation():
    """On an oscillation, the other joints' accelerations become their fit on the moving
    joint's motion: exact for a follower that is such a combination, its noise removed."""
    rows = 600
    recording = small_recording(rows, DT_S, ["hold", "oscillation"])
    t = recording.time_s
    q = np.column_stack([np.zeros(rows), np.zeros(rows), 1.0 + 0.1 * np.sin(2 * np.pi * t)])
    dq = np.column_stack([np.zeros(rows), np.zeros(rows), 0.2 * np.pi * np.cos(2 * np.pi * t)])
    ddq = np.column_stack([np.zeros(rows), np.zeros(rows), -(2 * np.pi) ** 2 * (q[:, 2] - 1)])
    follower = 0.3 * ddq[:, 2] + 0.05 * dq[:, 2]
    ddq[:, 0] = follower
    out = cf._follower_accelerations(recording, q, dq, ddq)
    wave = recording.segment == 1
    assert np.allclose(out[wave, 0], follower[wave], rtol=0, atol=1e-9)
    assert np.array_equal(out[:, 2], ddq[:, 2])  # the moving joint is left alone
    noise = np.random.default_rng(3).normal(0.0, 0.5, rows)
    ddq[:, 0] = follower + noise
    out = cf._follower_accelerations(recording, q, dq, ddq)
    assert np.array_equal(out[~wave, 0], ddq[~wave, 0])  # off the oscillation: as measured
    error = np.sqrt(np.mean((out[wave, 0] - follower[wave]) ** 2))
    assert error < 0.2 * 0.5


def test_savitzky_golay_differentiates_a_cubic_exactly():
    t = np.arange(100) * DT_S
    x = 0.3 * t ** 3 - t ** 2 + 2 * t
    inner = slice(cf.SG_WINDOW, -cf.SG_WINDOW)
    assert np.allclose(cf.savitzky_golay(x, DT_S, 1)[inner], (0.9 * t ** 2 - 2 * t + 2)[inner])
    assert np.allclose(cf.savitzky_golay(x, DT_S, 2)[inner], (1.8 * t - 2)[inner])
    shifted = cf.savitzky_golay(x, DT_S, 0, shift_s=0.005)
    assert np.allclose(shifted[inner], (0.3 * (t - 0.005) ** 3 - (t - 0.005) ** 2
                                        + 2 * (t - 0.005))[inner])


# -- the protocol --------------------------------------------------------------------------
def test_protocol_segments_cover_the_range_at_their_speeds(knee_scene):
    rom = cal._anatomical_rom(knee_scene)
    ranges = cp.protocol_ranges(knee_scene, rom)
    (joint, (low, high)), = ranges.items()
    assert joint == "knee_flexion_r"
    # The knee's exercises span 20-85 deg, its rest 90: widened by 15, inside the workspace
    # box (5-120), 2 deg short of either end.
    assert math.degrees(low) == pytest.approx(7.0)
    assert math.degrees(high) == pytest.approx(103.0)
    settings = cp.ProtocolSettings(repetitions=3)
    protocol = cp.build_protocol(knee_scene, ranges, rom, DT_S, settings)
    i = list(knee_scene.exercised_joints).index(joint)
    ramps = [s for s in protocol.segments if s.kind == "ramp"]
    assert len(ramps) == 2 * 3  # both ways, 3 repetitions
    for ramp in ramps:
        angles = ramp.patient_q_rad[:, i]
        start, end = (low, high) if angles[-1] > angles[0] else (high, low)
        assert angles[-1] == pytest.approx(end, abs=1e-12)
        assert 0 < abs(angles[0] - start) <= settings.ramp_speed_rad_s * DT_S * (1 + 1e-9)
        steps = np.abs(np.diff(angles)) / DT_S
        assert steps.max() <= settings.ramp_speed_rad_s * (1 + 1e-9)
        assert steps.max() > 0.9 * settings.ramp_speed_rad_s
    for speed in settings.stretch_speeds_rad_s:
        stretches = [s for s in protocol.segments if s.kind == "stretch"
                     and s.speed_rad_s == speed]
        assert len(stretches) == 2 * 3
        for stretch in stretches:
            angles = stretch.patient_q_rad[:, i]
            start, end = (low, high) if angles[-1] > angles[0] else (high, low)
            assert angles[-1] == pytest.approx(end, abs=1e-12)
            first_step = 0.5 * settings.stretch_acceleration_rad_s2 * DT_S ** 2
            assert abs(angles[0] - start) == pytest.approx(first_step, rel=1e-9)
            peak = np.abs(np.diff(angles)).max() / DT_S
            assert 0.95 * speed < peak <= speed * (1 + 1e-9)
    # The other exercised joints never move in a ramp or a stretch.
    for segment in protocol.segments:
        if segment.kind in ("ramp", "stretch"):
            others = np.delete(segment.patient_q_rad, i, axis=1)
            assert np.ptp(others, axis=0).max() == 0.0
    assert [t.shape for t in protocol.robot_targets_rad] == [
        (len(s.patient_q_rad), knee_scene.n_robot_joints) for s in protocol.segments]
    # The oscillations: per centre and frequency one, between the ramps and the stretches.
    waves = [s for s in protocol.segments if s.kind == "oscillation"]
    assert len(waves) == len(cp.OSCILLATION_CENTRES) * len(cp.OSCILLATION_FREQUENCIES_HZ)
    kinds = [s.kind for s in protocol.segments]
    last_ramp = max(k for k, kind in enumerate(kinds) if kind == "ramp")
    first_stretch = kinds.index("stretch")
    assert last_ramp < kinds.index("oscillation") and \
        max(k for k, kind in enumerate(kinds) if kind == "oscillation") < first_stretch
    # The stretches start at the end nearer rest (90 deg: the high one here).
    first = protocol.segments[first_stretch].patient_q_rad[:, i]
    assert first[-1] == pytest.approx(low, abs=1e-12) and first[0] > high - 0.01
    centres = sorted({round(float(w.patient_q_rad[-1, i]), 12) for w in waves})
    assert centres == pytest.approx([low + f * (high - low) for f in cp.OSCILLATION_CENTRES],
                                    abs=1e-12)


def test_oscillation_profile_starts_and_ends_at_rest():
    dt = 0.002
    for frequency in cp.OSCILLATION_FREQUENCIES_HZ:
        angles = cp.oscillation_profile(0.5, 0.1, frequency, dt)
        steady = max(2, math.ceil(cp.OSCILLATION_STEADY_S * frequency))
        assert len(angles) == round((steady + 2) / frequency / dt)
        assert angles[-1] == pytest.approx(0.5, abs=1e-12)
        assert np.abs(angles - 0.5).max() == pytest.approx(0.1, rel=1e-3)
        speed = np.diff(np.concatenate([[0.5], angles])) / dt
        peak = 2 * np.pi * frequency * 0.1
        assert abs(speed[0]) < 1e-3 * peak and abs(speed[-1]) < 1e-2 * peak
        assert np.abs(speed).max() == pytest.approx(peak, rel=1e-2)


def test_stretch_profile_is_trapezoidal():
    angles = cp.stretch_profile(0.0, 2.0, 3.0, 30.0, 0.001)
    speed = np.diff(np.concatenate([[0.0], angles])) / 0.001
    assert angles[-1] == pytest.approx(2.0)
    assert speed.max() == pytest.approx(3.0, rel=1e-6)
    assert np.abs(np.diff(speed)).max() / 0.001 <= 30.0 * (1 + 1e-6)


def test_unknown_joint_is_named(knee_scene):
    rom = cal._anatomical_rom(knee_scene)
    with pytest.raises(UsageError, match="'ankle_dorsiflexion_r'"):
        cp.protocol_ranges(knee_scene, rom, joints=["ankle_dorsiflexion_r"])


def test_range_outside_the_patient_is_named(knee_scene):
    low, high = cal._anatomical_rom(knee_scene)
    i = list(knee_scene.exercised_joints).index("knee_flexion_r")
    high = high.copy()
    high[i] = math.radians(90.0)  # a contracted knee
    with pytest.raises(UsageError, match=r"knee_flexion_r \[10, 100\].*range of motion"):
        cp.protocol_ranges(knee_scene, (low, high), ranges_deg={"knee_flexion": (10, 100)})
    with pytest.raises(UsageError, match=r"\[10, 130\].*workspace"):
        cp.protocol_ranges(knee_scene, cal._anatomical_rom(knee_scene),
                           ranges_deg={"knee_flexion": (10, 130)})


def test_ramps_stay_where_the_cuff_can_hold_the_limb(knee_scene):
    """The ramps are narrowed to where holding the limb needs at most 70 % of the limit; a
    limit the resting limb already exceeds is refused, naming the joint."""
    rom = cal._anatomical_rom(knee_scene)
    ranges = cp.protocol_ranges(knee_scene, rom)
    assert cal.within_force(knee_scene, ranges, 1000.0) == ranges
    home = knee_scene.home_qpos[knee_scene.exercised_qpos_adr]
    (low, high), = ranges.values()
    i = list(knee_scene.exercised_joints).index("knee_flexion_r")
    pose = home.copy()
    forces = []
    for angle in (low, high):
        pose[i] = angle
        forces.append(cal.holding_force_n(knee_scene, pose))
    limit = (max(forces) - 1.0) / cal.HOLDING_SHARE  # the heavier end no longer fits
    (narrow_low, narrow_high), = cal.within_force(knee_scene, ranges, limit).values()
    assert (narrow_low, narrow_high) != (low, high)
    assert low <= narrow_low < narrow_high <= high
    with pytest.raises(UsageError, match="knee_flexion_r"):
        cal.within_force(knee_scene, ranges, 1.0)


class ForceBackend:
    """A backend whose cuff force on the limb is the first joint target [N] (x axis)."""

    control_dt_s = DT_S
    joint_names = ("a",)

    def __init__(self) -> None:
        self.target = np.zeros(1)
        self.time_s = 0.0

    def command(self, q_target_rad: np.ndarray) -> None:
        self.target = np.asarray(q_target_rad, dtype=float)
        self.time_s += DT_S

    def state(self) -> RobotState:
        return RobotState(self.time_s, self.target.copy(), np.zeros(1),
                          patient_q_rad=np.zeros(1), patient_dq_rad_s=np.zeros(1))

    def cuff_force_vector_n(self) -> np.ndarray:
        return np.array([-self.target[0], 0.0, 0.0])  # on the robot: the limb feels +x

    def stop(self) -> None:
        pass

    def healthy(self) -> bool:
        return True


def test_an_oscillation_predicted_above_the_limit_is_skipped():
    """After a ramp peaking at 10 N and an oscillation at 1 rad/s peaking at 40 N, one at
    2 rad/s predicts 10 + 30 x 2^2 = 130 N: above a 100 N limit it is skipped (and only it);
    one at 1.2 rad/s (53 N) runs."""
    def segment(kind: str, speed: float, peak_n: float) -> cp.ProtocolSegment:
        return cp.ProtocolSegment(kind, "a", speed, 0, np.zeros((5, 1)), "a/0"), \
            np.full((5, 1), peak_n)

    parts = [segment("ramp", 0.1, 10.0), segment("oscillation", 1.0, 40.0),
             segment("oscillation", 2.0, 40.0), segment("oscillation", 1.2, 40.0),
             segment("hold", 0.0, 10.0)]
    protocol = cp.Protocol(("a",), {"a": (0.0, 1.0)}, {"a": (0.0, 1.0)}, DT_S,
                           [p[0] for p in parts], [p[1] for p in parts])
    recording = cp.run_protocol(ForceBackend(), protocol, np.zeros(1), 100.0)
    assert recording.skipped_blocks == ["a/0 oscillation at 2.00 rad/s"]
    assert sorted(set(recording.segment.tolist())) == [0, 1, 3, 4]
    assert recording.stopped_reason == ""
    assert np.allclose(recording.cuff_force_n[:, 0], np.repeat([10.0, 40.0, 40.0, 10.0], 5))


def test_ramps_stay_clear_of_the_leg_rest(knee_scene):
    """The knee's foot rests near the leg rest: its ramps stop CONTACT_MARGIN_RAD short of
    where the foot comes within the clearance; a range in contact throughout is refused."""
    import mujoco

    ranges = cp.protocol_ranges(knee_scene, cal._anatomical_rom(knee_scene))
    (low, high), = ranges.values()
    (clear_low, clear_high), = cal.contact_free(knee_scene, ranges).values()
    assert clear_low == low and clear_high < high
    model = knee_scene.model
    data = mujoco.MjData(model)
    i = list(knee_scene.exercised_joints).index("knee_flexion_r")
    foot, rest = model.geom("foot_r").id, model.geom("leg_rest").id

    def distance(angle: float) -> float:
        data.qpos[:] = knee_scene.home_qpos
        data.qpos[knee_scene.exercised_qpos_adr[i]] = angle
        knee_scene.follow_coupled_joints(data.qpos)
        mujoco.mj_kinematics(model, data)
        return mujoco.mj_geomDistance(model, data, foot, rest, 1.0, None)

    assert distance(clear_high) >= cal.CONTACT_CLEARANCE_M
    beyond = clear_high + cal.CONTACT_MARGIN_RAD + math.radians(1.0) + cp.KNOT_SPACING_RAD
    assert distance(beyond) < cal.CONTACT_CLEARANCE_M
    touching = {"knee_flexion_r": (math.radians(100.0), math.radians(115.0))}
    with pytest.raises(UsageError, match="knee_flexion_r comes within"):
        cal.contact_free(knee_scene, touching)


@pytest.mark.parametrize(("field", "value"), [("repetitions", 0), ("ramp_speed_rad_s", 2.0),
                                              ("stretch_speeds_rad_s", (3.0, 1.0))])
def test_bad_settings_are_named(field, value):
    with pytest.raises(UsageError, match=field):
        cp.ProtocolSettings(**{field: value})


# -- files ---------------------------------------------------------------------------------
def test_bad_patient_files_are_named(tmp_path):
    path = tmp_path / "patient.json"
    path.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(DataError, match="not a patient file"):
        cal.load_patient(path)
    path.write_text(json.dumps({"format": cal.PATIENT_FORMAT, "profile": {"height_m": 9.0},
                                "condition": {}}))
    with pytest.raises(DataError, match="height_m"):
        cal.load_patient(path)
    with pytest.raises(DataError, match="not a calibration recording"):
        cp.Recording.load(path)


def test_a_session_stopped_before_any_joint_moved_is_refused(knee_scene, tmp_path):
    rows = 40
    rest = knee_scene.home_qpos[knee_scene.exercised_qpos_adr].copy()
    recording = cp.Recording(
        time_s=np.arange(rows) * DT_S, patient_q_rad=np.repeat(rest[None], rows, axis=0),
        patient_dq_rad_s=np.zeros((rows, 3)), cuff_force_n=np.zeros((rows, 3)),
        target_q_rad=np.repeat(rest[None], rows, axis=0), segment=np.zeros(rows, dtype=int),
        segments=[("move", "knee_flexion_r", 0.07, 0, "")],
        exercised_joints=knee_scene.exercised_joints, joints=("knee_flexion_r",),
        ranges_rad={"knee_flexion_r": (0.2, 1.5)},
        patient_rom_rad={"knee_flexion_r": (0.0, 2.3)}, rest_q_rad=rest,
        stopped_reason="cuff force 140 N above 130 N")
    path = tmp_path / "session.npz"
    recording.save(path)
    loaded = cp.Recording.load(path)
    assert np.array_equal(loaded.patient_q_rad, recording.patient_q_rad)
    assert loaded.segments == recording.segments
    with pytest.raises(DataError, match="cuff force 140 N"):
        cf.joint_signals(loaded, knee_scene)


# -- a round trip on a simulated patient -----------------------------------------------------
def run_cli(argv: list[str]) -> int:
    from rehabbot.cli.calibrate import add_calibrate_parser

    parser = argparse.ArgumentParser()
    add_calibrate_parser(parser.add_subparsers())
    args = parser.parse_args(argv)
    return args.func(args)


@pytest.mark.slow
def test_round_trip_on_a_spastic_arm(tmp_path):
    """The CLI calibrates a simulated MAS-2 arm with a contracture and sensor noise; the fit
    finds its grade, its stiffness within 10 % and its gravity within 5 %, and gym.make takes
    the patient; fitting the recorded session again gives the same patient."""
    env_kwargs = {"condition": {"spasticity_mas": "2", "stiffness_scale": 1.5}}
    out, log = tmp_path / "patient.json", tmp_path / "session.npz"
    assert run_cli(["calibrate", "rehab-reach-v2", "--env-kwargs", json.dumps(env_kwargs),
                    "--noise-seed", "0", "--repetitions", "1", "--log", str(log),
                    "--out", str(out)]) == 0
    document = json.loads(out.read_text())
    assert document["condition"]["spasticity_mas"] == "2"
    truth = {"shoulder_flexion_r": 3.0, "elbow_flexion_r": 1.5}  # nominal x 1.5
    for name, stiffness in truth.items():
        joint = document["calibration"]["joints"][name]
        assert abs(joint["stiffness_nm_per_rad"] / stiffness - 1) < 0.1
        assert joint["vaf"] > 0.8
    assert abs(document["calibration"]["gravity_scale"] - 1) < 0.05
    assert abs(document["condition"]["stiffness_scale"] / 1.5 - 1) < 0.1
    kwargs = cal.load_patient(out)
    env = gym.make("rehabbot/rehab-reach-v2", **kwargs)
    assert env.unwrapped.config.condition.spasticity_mas == "2"
    env.close()
    # The recorded force is the one the limb feels: at rest it carries the limb's weight
    # and the spring (the opposite sign would double the error instead).
    recording = cp.Recording.load(log)
    backend = cal.simulator_backend("rehab-reach-v2", env_kwargs)
    signals = cf.joint_signals(recording, backend.env.scene)[1]
    rows = cal.gravity_rows(signals)
    expected = cal.model_gravity_nm(backend.env.scene, signals.q_all_rad[rows],
                                    "elbow_flexion_r") + 1.5 * (signals.q_rad[rows]
                                                                - signals.rest_rad)
    slope = float(expected @ signals.tau_nm[rows] / (expected @ expected))
    assert abs(slope - 1) < 0.1
    again = tmp_path / "again.json"
    assert run_cli(["calibrate", "--from-log", str(log), "--out", str(again)]) == 0
    assert json.loads(again.read_text())["condition"] == document["condition"]
