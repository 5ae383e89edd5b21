"""Groundwork for the musculoskeletal patient: what MyoSuite's models give us.

Loads the models of the installed ``myo-sim`` package (``pip install myo-sim==0.2.3``; nothing
is copied into this repository) through ``myo_sim.build.compose.build_spec`` and measures:

1. **Passive joint torque against angle** of the elbow (``myoarm_r``, joint
   ``elbow_flexion_r``) and the knee (``myolegs``, ``knee_angle_r``) with every muscle at zero
   excitation and zero activation, gravity off: the joint is set to each angle (the joints
   coupled to it by polynomial joint equalities, as MyoLeg's knee translations are, follow
   their polynomials), ``mj_forward`` runs, and the torque is ``qfrc_actuator`` (the muscles'
   passive force through their moment arms) plus ``qfrc_passive`` (joint springs) at that
   joint's DoF, in N m. A rising magnitude at the ends of the range is the passive
   force-length curve the rigid patient's contracture model imitates.
2. **Physics throughput**: ``mj_step`` per second of each myo model at its default state
   against the rigid patient's knee and reach scenes at their home state
   (``rehabbot.sim.build_scene``; the robot holds its setpoints),
   measured in the same run, best of the repeats.

Usage::

    python benchmarks/probes/myo_models.py [--steps 2000] [--repeats 3] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.machine import describe_machine
from rehabbot.common.text_tables import text_table

# (myo-sim model, joint) pairs whose passive torque-angle curves are measured.
CURVES = (("myoarm_r", "elbow_flexion_r"), ("myolegs", "knee_angle_r"))
CURVE_POINTS = 9
THROUGHPUT_MODELS = ("myoarm_r", "myolegs")
RIGID_PRESETS = ("knee", "upper_right")


def build_myo_model(name: str) -> mujoco.MjModel:
    """Compile myo-sim's ``name`` (a ``myo_sim.build.compose`` registry name), quietly."""
    from rehabbot.sim.myo_patient import MyoModelMissingError, build_myo_spec

    try:
        return build_myo_spec(name).compile()
    except MyoModelMissingError as err:
        raise SystemExit(str(err)) from err


def _coupled_joints(model: mujoco.MjModel, joint_id: int) -> list[tuple[int, np.ndarray]]:
    """(dependent joint id, polynomial coefficients) of the active joint equalities that make
    a joint follow ``joint_id``."""
    coupled = []
    for eq in range(model.neq):
        if (model.eq_type[eq] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj2id[eq] == joint_id
                and model.eq_active0[eq]):
            coupled.append((int(model.eq_obj1id[eq]), np.array(model.eq_data[eq, :5])))
    return coupled


def passive_torque_curve(model: mujoco.MjModel, joint: str,
                         points: int = CURVE_POINTS) -> list[dict[str, float]]:
    """Passive torque [N m] at ``points`` angles across ``joint``'s range (see the module)."""
    data = mujoco.MjData(model)
    model.opt.gravity[:] = 0.0
    joint_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
    if joint_id < 0:
        raise SystemExit(f"no joint {joint!r} in the model")
    qadr, dof = model.jnt_qposadr[joint_id], model.jnt_dofadr[joint_id]
    low, high = model.jnt_range[joint_id]
    coupled = _coupled_joints(model, joint_id)
    rows = []
    for angle in np.linspace(low, high, points):
        mujoco.mj_resetData(model, data)
        data.ctrl[:] = 0.0
        if model.na:
            data.act[:] = 0.0
        data.qpos[qadr] = angle
        for dependent, coefficients in coupled:
            data.qpos[model.jnt_qposadr[dependent]] = float(
                np.polyval(coefficients[::-1], angle))
        mujoco.mj_forward(model, data)
        rows.append({"angle_deg": math.degrees(angle),
                     "muscle_torque_nm": float(data.qfrc_actuator[dof]),
                     "joint_torque_nm": float(data.qfrc_passive[dof]),
                     "total_torque_nm": float(data.qfrc_actuator[dof] + data.qfrc_passive[dof])})
    return rows


def steps_per_second(model: mujoco.MjModel, data: mujoco.MjData, steps: int,
                     repeats: int) -> float:
    """Best ``mj_step`` rate of ``repeats`` timed runs of ``steps`` after a warm-up."""
    for _ in range(min(steps, 200)):
        mujoco.mj_step(model, data)
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(model, data)
        best = min(best, time.perf_counter() - start)
    return steps / best


def throughput_rows(steps: int, repeats: int) -> list[dict[str, Any]]:
    from rehabbot.sim import build_scene

    rows = []
    for preset in RIGID_PRESETS:
        scene = build_scene(preset)
        rows.append({"model": f"rigid patient: {preset}", "nv": int(scene.model.nv),
                     "muscles": 0, "steps_per_s": steps_per_second(
                         scene.model, scene.make_data(), steps, repeats)})
    for name in THROUGHPUT_MODELS:
        model = build_myo_model(name)
        muscles = int(np.sum(model.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE))
        rows.append({"model": f"myo-sim: {name}", "nv": int(model.nv), "muscles": muscles,
                     "steps_per_s": steps_per_second(model, mujoco.MjData(model), steps,
                                                     repeats)})
    baseline = rows[0]["steps_per_s"]
    for row in rows:
        row["x_rigid_knee"] = row["steps_per_s"] / baseline
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", type=Path, help="write the measurements to this file")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.repeats < 1:
        parser.error(f"--steps and --repeats must be >= 1, got {args.steps}, {args.repeats}")
    result: dict[str, Any] = {"machine": describe_machine(), "curves": {}}
    for model_name, joint in CURVES:
        rows = passive_torque_curve(build_myo_model(model_name), joint)
        result["curves"][f"{model_name}:{joint}"] = rows
        print(f"\npassive torque of {joint} ({model_name}), zero excitation, no gravity")
        print(text_table(["angle [deg]", "muscles [N m]", "joint [N m]", "total [N m]"],
                         [[f"{r['angle_deg']:.1f}", f"{r['muscle_torque_nm']:.3f}",
                           f"{r['joint_torque_nm']:.3f}", f"{r['total_torque_nm']:.3f}"]
                          for r in rows]))
    rows = throughput_rows(args.steps, args.repeats)
    result["throughput"] = rows
    print(f"\nphysics throughput, best of {args.repeats} x {args.steps} steps "
          f"({result['machine']})")
    print(text_table(["model", "nv", "muscles", "steps/s", "x rigid knee"],
                     [[r["model"], r["nv"], r["muscles"], f"{r['steps_per_s']:.0f}",
                       f"{r['x_rigid_knee']:.2f}"] for r in rows]))
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
