"""The calibration fit: a patient's limb from joint angles and cuff forces.

The torque the cuff applies to each calibrated joint is ``tau = J^T F``: the force ``F`` the
cuff applies to the limb (world frame) through the limb's Jacobian at the cuff, computed on
the body model (the scene) at the measured joint angles. On a real robot ``F`` comes from a
force/torque sensor at the cuff and the Jacobian from the calibrated body's kinematics: a
wrong body model biases every torque.

A recording faster than :data:`FIT_PERIOD_S` is first averaged over blocks of whole control
periods that span it (:func:`block_average`): the mean of the force over a block is the mean
of the torque law's terms, and the mean acceleration is the change of speed across the block,
which the derivatives of the block means give; a single sample at the end of a period would
catch the servo between two setpoints, its acceleration below the motion's. Speeds and
accelerations are the derivatives of the (averaged) angles (a Savitzky-Golay filter,
:data:`SG_WINDOW` samples, cubic). Per joint ``j`` the model is the limb's rigid-body and
passive dynamics with the patient's own torque subtracted::

    tau_j = I_j,p q''_j + b_j q'_j + k_j (q_j - q_rest,j) + G_j(q) - tau_patient,j

* ``I_j``: the limb's inertia about the joint (the mass matrix's diagonal entry, armature
  included) and ``b_j`` its passive damping, both fitted on the joint's small oscillations
  (the other joints at rest), with a free term per other exercised joint's acceleration (the
  mass matrix's coupling: the cuff lets them move a little);
* ``k_j``: passive stiffness about the resting posture ``q_rest`` (the posture the session
  starts from);
* ``G_j(q)``: gravity, linear in each rigid part's mass and first moment (4 numbers per
  part, shared by every joint the part hangs from), its regressor from the body model's
  kinematics at the measured angles. The posture changes of the protocol turn the gravity
  torque on a joint but not its spring, which separates ``k`` from gravity;
* ``tau_patient``: the hypothesis' torque: a Modified Ashworth grade's stretch reflex
  (:func:`rehabbot.sim.conditions.reflex_torque_nm`, fed by the speed of
  :data:`~rehabbot.sim.conditions.REFLEX_LATENCY_S` earlier) and, for a resistive patient,
  ``-s S_dir tanh(v / 0.1 rad/s)`` with ``s`` the share of the healthy strength ``S_dir``.

On the ramps, holds and stretches, whose speed follows the command's (a velocity term there
is the servo's as much as the limb's), the speed, acceleration, command speed and coupling
terms are free nuisance terms per joint and kind of motion: those rows weigh only on the
stiffness, gravity and the patient's torque. A joint with no oscillation recorded (a session
stopped before them) is fitted with damping and inertia 0.

Every hypothesis (6 grades x passive or resistive) is a weighted linear least-squares fit over
all calibrated joints at once; the one with the lowest Bayesian information criterion wins.
Joint equations use every quasi-static row (ramps, holds) and the joint's own stretches.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from rehabbot.common.errors import DataError
from rehabbot.deploy.calibration_protocol import Recording
from rehabbot.sim.conditions import (
    MAS_GRADES,
    MAS_REFLEX,
    REFLEX_GAIN_NMS_PER_RAD,
    REFLEX_LATENCY_S,
    healthy_strength_nm,
    reflex_torque_nm,
)
from rehabbot.sim.patient_drive import RESIST_VELOCITY_RAD_S
from rehabbot.sim.scene import Scene

#: Samples of the Savitzky-Golay derivative filter.
SG_WINDOW = 7
RCOND = 1e-10  # singular values of the scaled design below this share of the largest are cut
#: The period the fit works at (faster recordings are block-averaged).
FIT_PERIOD_S = 0.02
SG_ORDER = 3
EFFORT_HYPOTHESES = ("passive", "resistive")
# A resistive fit below this share of the healthy strength is the passive one: so small a
# push, saturated in the speed's sign, is a friction the sensors' noise can mimic, and would
# take its share of the damping.
MIN_EFFORT_SHARE = 0.01
QUASI_STATIC = ("ramp",)  # the rows of other joints' motions a joint's equation uses


def savitzky_golay(x: np.ndarray, dt_s: float, derivative: int, window: int = SG_WINDOW,
                   order: int = SG_ORDER, shift_s: float = 0.0) -> np.ndarray:
    """The ``derivative``-th derivative of the samples ``x`` (period ``dt_s``), ``shift_s``
    seconds before each sample, by a centred least-squares polynomial of ``order`` over
    ``window`` samples (ends: edge-padded)."""
    half = window // 2
    offsets = np.arange(-half, half + 1, dtype=float)
    vander = np.vander(offsets, order + 1, increasing=True)
    at = -shift_s / dt_s
    powers = np.array([math.factorial(i) / math.factorial(i - derivative) * at ** (i - derivative)
                       if i >= derivative else 0.0 for i in range(order + 1)])
    coefficients = powers @ np.linalg.pinv(vander)
    padded = np.concatenate([np.full(half, x[0]), x, np.full(half, x[-1])])
    out = np.convolve(padded, coefficients[::-1], mode="valid")
    return out / dt_s ** derivative


@dataclass
class JointSignals:
    """One calibrated joint's signals (one row per sample of the rows it is fitted on)."""

    joint: str
    q_rad: np.ndarray
    q_all_rad: np.ndarray  # (T, n_exercised) every exercised joint's angle
    dq_rad_s: np.ndarray
    ddq_rad_s2: np.ndarray
    delayed_dq_rad_s: np.ndarray  # the speed REFLEX_LATENCY_S earlier (the reflex's input)
    other_ddq_rad_s2: np.ndarray  # (T, n_exercised - 1) the other exercised joints' accelerations
    command_dq_rad_s: np.ndarray  # the speed of the joint's targets (the commands' own)
    stretch: np.ndarray  # (T,) bool: rows of the joint's own stretches
    oscillation: np.ndarray  # (T,) bool: rows of the joint's own oscillations
    tau_nm: np.ndarray  # the cuff's torque on the joint
    gravity: np.ndarray  # (T, n_gravity) regressor of the shared gravity parameters
    posture: np.ndarray  # (T,) index of the posture of the other joints (inertia column)
    own: np.ndarray  # (T,) bool: rows of the joint's own motion (for VAF)
    rest_rad: float
    rom_rad: tuple[float, float]
    strength_nm: tuple[float, float]  # healthy (positive, negative direction)
    reflex_gain_nms_per_rad: float


@dataclass
class JointFit:
    """The fitted numbers of one joint."""

    joint: str
    stiffness_nm_per_rad: float
    damping_nms_per_rad: float
    inertia_kg_m2: tuple[float, ...]  # (the others at their resting posture,)
    vaf: float
    rms_residual_nm: float
    range_reached_rad: tuple[float, float]


@dataclass
class Fit:
    """The winning hypothesis and its numbers."""

    spasticity_mas: str
    effort: str
    effort_share: float
    joints: dict[str, JointFit]
    gravity_params: np.ndarray
    scores: dict[str, float] = field(default_factory=dict)  # hypothesis -> BIC

    def predicted_gravity(self, signals: JointSignals) -> np.ndarray:
        """The fitted gravity torque on ``signals``' joint at its rows."""
        return signals.gravity @ self.gravity_params


# -- signals from a recording ----------------------------------------------------------------
def block_average(recording: Recording, period_s: float = FIT_PERIOD_S) -> Recording:
    """``recording`` averaged over consecutive blocks of ``round(period_s / dt)`` rows (the
    last, incomplete block dropped): the time, angles, speeds, forces and targets are the
    block's means; the segment is the one of the block's middle row. A recording at
    ``period_s`` or slower is returned as it is."""
    import dataclasses

    if len(recording.time_s) < 2:
        return recording
    dt = float(np.median(np.diff(recording.time_s)))
    factor = round(period_s / dt) if dt > 0 else 1
    if factor <= 1:
        return recording
    blocks = len(recording.time_s) // factor

    def mean(x: np.ndarray) -> np.ndarray:
        x = x[:blocks * factor]
        return x.reshape(blocks, factor, *x.shape[1:]).mean(axis=1)

    return dataclasses.replace(
        recording, time_s=mean(recording.time_s), patient_q_rad=mean(recording.patient_q_rad),
        patient_dq_rad_s=mean(recording.patient_dq_rad_s),
        cuff_force_n=mean(recording.cuff_force_n), target_q_rad=mean(recording.target_q_rad),
        segment=recording.segment[factor // 2:blocks * factor:factor].copy())


def joint_signals(recording: Recording, scene: Scene) -> list[JointSignals]:
    """Per calibrated joint, its signals from ``recording`` on the body model ``scene``; a
    joint the session stopped before moving is left out. A recording faster than
    :data:`FIT_PERIOD_S` is block-averaged first (:func:`block_average`)."""
    recording = block_average(recording)
    if len(recording.time_s) < 4 * SG_WINDOW:
        raise DataError(f"calibration: the recording holds {len(recording.time_s)} samples; "
                        f"the fit needs at least {4 * SG_WINDOW}")
    model = scene.model
    exercised = list(scene.exercised_joints)
    if list(recording.exercised_joints) != exercised:
        raise DataError(f"calibration: the recording's joints {list(recording.exercised_joints)}"
                        f" are not the body model's {exercised}")
    dt = float(np.median(np.diff(recording.time_s)))
    lag = recording.force_lag_s
    q, dq, ddq = (np.column_stack([savitzky_golay(recording.patient_q_rad[:, i], dt, d,
                                                  shift_s=lag)
                                   for i in range(len(exercised))]) for d in (0, 1, 2))
    ddq = _follower_accelerations(recording, q, dq, ddq)
    delayed = np.column_stack([np.interp(recording.time_s - REFLEX_LATENCY_S,
                                         recording.time_s, dq[:, i], left=0.0)
                               for i in range(len(exercised))])
    command = np.vstack([np.zeros((1, len(exercised))),
                         np.diff(recording.target_q_rad, axis=0) / dt])
    joints = list(recording.joints)
    dofs = [int(model.joint(j).dofadr[0]) for j in joints]
    groups = _rigid_groups(model, [model.joint(j).id for j in joints])
    tau, gravity = _torques_and_gravity(scene, q,
                                        recording.cuff_force_n, joints, dofs, groups)
    kinds = np.array([recording.segments[s][0] for s in recording.segment])
    movers = np.array([recording.segments[s][1] for s in recording.segment])
    postures = _posture_index(recording)
    profile = scene.profile
    out = []
    for n, joint in enumerate(joints):
        i = exercised.index(joint)
        own = (movers == joint) & np.isin(kinds, ("ramp", "stretch", "hold", "oscillation"))
        if own.sum() < 4 * SG_WINDOW:  # a session stopped before this joint's motions
            continue
        rows = own | np.isin(kinds, QUASI_STATIC)
        base = joint.rsplit("_", 1)[0]
        out.append(JointSignals(
            joint=joint, q_rad=q[rows, i], q_all_rad=q[rows], dq_rad_s=dq[rows, i],
            ddq_rad_s2=ddq[rows, i],
            delayed_dq_rad_s=delayed[rows, i],
            other_ddq_rad_s2=np.delete(ddq[rows], i, axis=1),
            command_dq_rad_s=command[rows, i], stretch=(own & (kinds == "stretch"))[rows],
            oscillation=(own & (kinds == "oscillation"))[rows],
            tau_nm=tau[rows, n], gravity=gravity[n][rows],
            posture=np.where(own, postures, 0)[rows], own=own[rows],
            rest_rad=float(recording.rest_q_rad[i]),
            rom_rad=recording.patient_rom_rad[joint],
            strength_nm=healthy_strength_nm(base, profile.mass_kg, profile.sex),
            reflex_gain_nms_per_rad=REFLEX_GAIN_NMS_PER_RAD[base]))
    if not out:
        raise DataError("calibration: the recording holds no joint's own motions (the "
                        f"session stopped: {recording.stopped_reason or 'no reason given'})")
    return out


def _follower_accelerations(recording: Recording, q: np.ndarray, dq: np.ndarray,
                            ddq: np.ndarray) -> np.ndarray:
    """``ddq`` with, on each oscillation, the other exercised joints' accelerations replaced
    by their least-squares fit on the moving joint's angle, speed and acceleration (and a
    constant): the joints the cuff lets follow a little move at the oscillation's frequency,
    an acceleration far below the encoders' noise once differentiated twice, and their
    coupling torque is a large share of the damping's."""
    out = ddq.copy()
    exercised = list(recording.exercised_joints)
    bounds = np.flatnonzero(np.diff(recording.segment)) + 1
    for rows in np.split(np.arange(len(recording.segment)), bounds):
        kind, joint = recording.segments[int(recording.segment[rows[0]])][:2]
        if kind != "oscillation" or joint not in exercised or len(rows) < 8:
            continue
        i = exercised.index(joint)
        basis = np.column_stack([np.ones(len(rows)), q[rows, i] - q[rows, i].mean(),
                                 dq[rows, i], ddq[rows, i]])
        others = [k for k in range(len(exercised)) if k != i]
        fit, *_ = np.linalg.lstsq(basis, ddq[np.ix_(rows, others)], rcond=None)
        out[np.ix_(rows, others)] = basis @ fit
    return out


def _posture_index(recording: Recording) -> np.ndarray:
    """Per row: the posture of the other joints in the protocol's block of the row (the
    number after the block's ``/``: 0 is the resting posture; 0 outside blocks)."""
    per_segment = [int(block.rsplit("/", 1)[1]) if block else 0
                   for *_, block in recording.segments]
    return np.array([per_segment[s] for s in recording.segment], dtype=int)


def _rigid_groups(model: mujoco.MjModel, joint_ids: Sequence[int]) -> list[list[int]]:
    """The rigid parts hanging from the calibrated joints: lists of bodies that move together
    (a body with a joint starts a part; a body without one belongs to its parent's)."""
    first = min(int(model.jnt_bodyid[j]) for j in joint_ids)
    root = int(model.body_rootid[first])
    parts: dict[int, list[int]] = {}
    for body in range(model.nbody):
        if int(model.body_rootid[body]) != root or not _descends(model, body, first):
            continue
        head = body
        while model.body_jntnum[head] == 0 and head != first:
            head = int(model.body_parentid[head])
        parts.setdefault(head, []).append(body)
    return list(parts.values())


def _descends(model: mujoco.MjModel, body: int, ancestor: int) -> bool:
    while body > 0:
        if body == ancestor:
            return True
        body = int(model.body_parentid[body])
    return ancestor == 0


def _torques_and_gravity(scene: Scene, q: np.ndarray, force: np.ndarray, joints: list[str],
                         dofs: list[int], groups: list[list[int]]
                         ) -> tuple[np.ndarray, list[np.ndarray]]:
    """The cuff's torques (T, n_joints) and, per joint, the gravity regressor (T, 4 x parts):
    per part, its first moment (3, in the part's frame) and its mass."""
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = scene.home_qpos
    site = scene.robots[0].patient_cuff_site_id
    jac = np.zeros((3, model.nv))
    g = model.opt.gravity.copy()
    joint_ids = [model.joint(j).id for j in joints]
    tau = np.zeros((len(q), len(joints)))
    gravity = [np.zeros((len(q), 4 * len(groups))) for _ in joints]
    for t in range(len(q)):
        data.qpos[scene.exercised_qpos_adr] = q[t]
        scene.follow_coupled_joints(data.qpos)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_jacSite(model, data, jac, None, site)
        tau[t] = jac[:, dofs].T @ force[t]
        for n, jid in enumerate(joint_ids):
            axis = data.xanchor[jid], data.xaxis[jid]
            lever = np.cross(g, axis[1])
            for p, part in enumerate(groups):
                head = part[0]
                if not _descends(model, head, int(model.jnt_bodyid[jid])):
                    continue
                rot = data.xmat[head].reshape(3, 3)
                gravity[n][t, 4 * p:4 * p + 3] = -(rot.T @ lever)
                gravity[n][t, 4 * p + 3] = -float((data.xpos[head] - axis[0]) @ lever)
    return tau, gravity


# -- the fit ---------------------------------------------------------------------------------
def reflex_column(signals: JointSignals, grade: str) -> np.ndarray:
    """The grade's stretch-reflex torque on the joint at every row."""
    reflex = MAS_REFLEX[grade]
    low, high = signals.rom_rad
    return np.array([reflex_torque_nm(reflex, signals.reflex_gain_nms_per_rad, v, q, low, high)
                     for v, q in zip(signals.delayed_dq_rad_s, signals.q_rad, strict=True)])


def resist_column(signals: JointSignals) -> np.ndarray:
    """The resistive push per unit share, as it appears in the cuff torque (it adds)."""
    push = np.tanh(signals.dq_rad_s / RESIST_VELOCITY_RAD_S)
    pos, neg = signals.strength_nm
    return push * np.where(push > 0, neg, pos)


def _design(signals: Sequence[JointSignals], effort: str) -> tuple[np.ndarray, list[tuple]]:
    """The stacked regressor and the meaning of each column: per joint its physics (damping,
    inertia and the coupling to the other joints' accelerations on the oscillations;
    stiffness everywhere), then the nuisance terms (on the ramps and holds, per posture, and
    on the stretches: a free velocity, acceleration, command and coupling term), then the
    shared gravity and share."""
    n_gravity = signals[0].gravity.shape[1]
    per_joint = []
    for n, s in enumerate(signals):
        wave = s.oscillation
        others = range(s.other_ddq_rad_s2.shape[1])
        cols: list[tuple[tuple, np.ndarray]] = [
            (("damping", n), np.where(wave, s.dq_rad_s, 0.0)),
            (("stiffness", n), s.q_rad - s.rest_rad),
            (("inertia", n, 0), np.where(wave, s.ddq_rad_s2, 0.0))]
        cols += [(("coupling", n, k), np.where(wave, s.other_ddq_rad_s2[:, k], 0.0))
                 for k in others]
        still = ~s.stretch & ~wave
        cols += [(("slow velocity", n), np.where(still, s.dq_rad_s, 0.0)),
                 (("slow command", n), np.where(still, s.command_dq_rad_s, 0.0))]
        for p in range(int(s.posture.max()) + 1):
            mask = s.own & still & (s.posture == p)
            cols.append((("slow acceleration", n, p), np.where(mask, s.ddq_rad_s2, 0.0)))
            cols += [(("slow coupling", n, p, k), np.where(mask, s.other_ddq_rad_s2[:, k], 0.0))
                     for k in others]
        fast = s.stretch
        cols += [(("stretch velocity", n), np.where(fast, s.dq_rad_s, 0.0)),
                 (("stretch acceleration", n), np.where(fast, s.ddq_rad_s2, 0.0)),
                 (("stretch command", n), np.where(fast, s.command_dq_rad_s, 0.0))]
        cols += [(("stretch coupling", n, k), np.where(fast, s.other_ddq_rad_s2[:, k], 0.0))
                 for k in others]
        per_joint.append(cols)
    columns = [name for cols in per_joint for name, _ in cols]
    columns += [("gravity", k) for k in range(n_gravity)]
    if effort == "resistive":
        columns.append(("share",))
    blocks = []
    offset = 0
    for n, s in enumerate(signals):
        block = np.zeros((len(s.q_rad), len(columns)))
        for k, (_, values) in enumerate(per_joint[n]):
            block[:, offset + k] = values
        offset += len(per_joint[n])
        g0 = len(columns) - n_gravity - (effort == "resistive")
        block[:, g0:g0 + n_gravity] = s.gravity
        if effort == "resistive":
            block[:, -1] = resist_column(s)
        blocks.append(block)
    return np.vstack(blocks), columns


def fit_hypothesis(signals: Sequence[JointSignals], grade: str, effort: str,
                   weights: Sequence[float]) -> tuple[np.ndarray, list[tuple], float, int]:
    """Weighted least squares of one hypothesis: (parameters, columns, weighted SSE, rows)."""
    design, columns = _design(signals, effort)
    target = np.concatenate([s.tau_nm + reflex_column(s, grade) for s in signals])
    w = np.concatenate([np.full(len(s.q_rad), weights[n]) for n, s in enumerate(signals)])
    scale = np.linalg.norm(design, axis=0)
    scale[scale == 0] = 1.0
    params, *_ = np.linalg.lstsq(design * w[:, None] / scale, target * w, rcond=RCOND)
    params = params / scale
    if effort == "resistive" and params[-1] < MIN_EFFORT_SHARE:  # no effort at all
        params = np.append(fit_hypothesis(signals, grade, "passive", weights)[0], 0.0)
    residual = (target - design @ params) * w
    return params, columns, float(residual @ residual), len(target)


def fit_signals(signals: Sequence[JointSignals],
                grades: Sequence[str] = MAS_GRADES,
                efforts: Sequence[str] = EFFORT_HYPOTHESES) -> Fit:
    """Fit every hypothesis to ``signals`` and keep the best (module docstring)."""
    weights = _noise_weights(signals)
    # An exact fit leaves round-off for a residual: below this share of the torques' own
    # sum of squares, residuals count as equal (then the fewer parameters win).
    floor = 1e-20 * sum(float((s.tau_nm * w) @ (s.tau_nm * w))
                        for s, w in zip(signals, weights, strict=True))
    best = None
    scores = {}
    for grade in grades:
        for effort in efforts:
            params, columns, sse, rows = fit_hypothesis(signals, grade, effort, weights)
            bic = rows * math.log(max(sse, floor, 1e-300) / rows) \
                + len(params) * math.log(rows)
            scores[f"{grade}/{effort}"] = bic
            if best is None or bic < best[0]:
                best = (bic, grade, effort, params, columns)
    assert best is not None
    _, grade, effort, params, columns = best
    return _fit_result(signals, grade, effort, params, columns, scores)


def _noise_weights(signals: Sequence[JointSignals]) -> list[float]:
    """1 / each joint's residual spread under the passive, grade-0 model (robust: the
    median absolute residual), so a joint with a longer lever arm weighs no more."""
    params, _, _, _ = fit_hypothesis(signals, "0", "passive", [1.0] * len(signals))
    design, _ = _design(signals, "passive")
    residual = np.concatenate([s.tau_nm for s in signals]) - design @ params
    weights, start = [], 0
    for s in signals:
        part = residual[start:start + len(s.q_rad)]
        start += len(s.q_rad)
        spread = 1.4826 * float(np.median(np.abs(part - np.median(part))))
        weights.append(1.0 / max(spread, 1e-9))
    return weights


def _fit_result(signals: Sequence[JointSignals], grade: str, effort: str, params: np.ndarray,
                columns: list[tuple], scores: dict[str, float]) -> Fit:
    n_gravity = signals[0].gravity.shape[1]
    g0 = len(columns) - n_gravity - (effort == "resistive")
    design, _ = _design(signals, effort)
    predicted_all = design @ params
    joints, start = {}, 0
    for n, s in enumerate(signals):
        rows = slice(start, start + len(s.q_rad))
        start += len(s.q_rad)
        mine = {c: params[k] for k, c in enumerate(columns) if len(c) > 1
                and c[0] != "gravity" and c[1] == n}
        inertia = (float(mine[("inertia", n, 0)]),)
        predicted = predicted_all[rows] - reflex_column(s, grade)
        own = s.own
        error = s.tau_nm[own] - predicted[own]
        variance = float(np.var(s.tau_nm[own]))
        reached = s.q_rad[own]
        joints[s.joint] = JointFit(
            joint=s.joint, stiffness_nm_per_rad=float(mine[("stiffness", n)]),
            damping_nms_per_rad=float(mine[("damping", n)]), inertia_kg_m2=inertia,
            vaf=1.0 - float(np.var(error)) / variance if variance > 0 else 0.0,
            rms_residual_nm=float(np.sqrt(np.mean(error ** 2))),
            range_reached_rad=(float(reached.min()), float(reached.max())))
    return Fit(spasticity_mas=grade, effort=effort,
               effort_share=float(params[-1]) if effort == "resistive" else 0.0,
               joints=joints, gravity_params=params[g0:g0 + n_gravity], scores=scores)
