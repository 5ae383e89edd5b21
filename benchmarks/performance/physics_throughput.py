"""Raw physics throughput of every scene preset, against a robot-only baseline.

For each preset the scene is built at its home pose with the robot holding its home
setpoints, warmed up, and then ``mujoco.mj_step`` is timed with ``time.perf_counter``.
``ncon``/``nefc`` are the contact count and constraint rows at the home pose.
The baseline is the bare UR5e (``rehabbot.sim.robots.ur5e.build_ur5e_spec``) holding the same
joint angles, so the ``x baseline`` column shows what the patient, the straps and the
contacts cost relative to the robot alone, measured in the same run on the same machine.
``--robots ur5e fr3`` measures every preset with each robot (rows ``<preset>/<robot>`` for
robots other than the UR5e), against the same UR5e baseline.

Usage::

    python benchmarks/performance/physics_throughput.py [--steps 5000] [--warmup 500]
        [--repeats 3] [--presets NAME ...] [--robots NAME ...] [--json FILE]
        [--page docs/results/NAME]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine

BASELINE_NAME = "robot_only"
INTRO = """Raw `mujoco.mj_step` rate of every scene preset at its home pose, the robot holding
its home setpoints (best of the timed repeats after a warm-up), against the bare robot holding
the same joint angles, measured in the same run: the `x baseline` column is what the patient,
the straps and the contacts cost relative to the robot alone. `ncon`/`nefc` are the contacts
and constraint rows at the home pose; `<preset>/fr3` rows hold the FR3 instead of the UR5e."""


@dataclass
class ThroughputRow:
    """One line of the benchmark table."""

    name: str
    nq: int
    nv: int
    ncon_at_rest: int
    nefc_at_rest: int
    timestep_s: float
    steps_per_s: float
    realtime_factor: float
    ratio_to_baseline: float = float("nan")


def measure_steps_per_s(
    model: mujoco.MjModel, data: mujoco.MjData, steps: int, warmup: int, repeats: int
) -> float:
    """Best-of-``repeats`` ``mj_step`` rate over ``steps`` steps, after ``warmup`` steps.

    The controls in ``data.ctrl`` are left untouched, so the robot keeps its setpoints.
    """
    for _ in range(warmup):
        mujoco.mj_step(model, data)
    best_s = float("inf")
    for _ in range(repeats):
        start_s = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(model, data)
        best_s = min(best_s, time.perf_counter() - start_s)
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        raise RuntimeError(f"simulation diverged (non-finite state) at t={data.time:.3f} s")
    return steps / best_s


def make_row(
    name: str, model: mujoco.MjModel, data: mujoco.MjData, steps: int, warmup: int, repeats: int
) -> ThroughputRow:
    """Measure one model whose ``data`` is at rest at its home pose (``mj_forward`` done)."""
    ncon_at_rest, nefc_at_rest = int(data.ncon), int(data.nefc)
    steps_per_s = measure_steps_per_s(model, data, steps, warmup, repeats)
    timestep_s = float(model.opt.timestep)
    return ThroughputRow(
        name=name,
        nq=int(model.nq),
        nv=int(model.nv),
        ncon_at_rest=ncon_at_rest,
        nefc_at_rest=nefc_at_rest,
        timestep_s=timestep_s,
        steps_per_s=steps_per_s,
        realtime_factor=steps_per_s * timestep_s,
    )


def joint_angles_by_name(model: mujoco.MjModel, data: mujoco.MjData) -> dict[str, float]:
    """Angles of all hinge/slide joints, keyed by joint name."""
    angles = {}
    for joint_id in range(model.njnt):
        joint = model.joint(joint_id)
        if joint.type[0] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            angles[joint.name] = float(data.qpos[joint.qposadr[0]])
    return angles


def robot_only_model(home_angles_rad: dict[str, float]) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The bare UR5e at the given joint angles, its servos holding them.

    Robot joints are matched to ``home_angles_rad`` by name, allowing for a prefix the
    scene may have added (e.g. ``robot/elbow``); unmatched joints stay at 0.
    """
    from rehabbot.sim.robots.ur5e import JOINT_NAMES, build_ur5e_spec

    model = build_ur5e_spec().compile()
    data = mujoco.MjData(model)
    for joint_name in JOINT_NAMES:
        matches = [v for k, v in home_angles_rad.items() if k.endswith(joint_name)]
        angle_rad = matches[0] if len(matches) == 1 else 0.0
        joint = model.joint(joint_name)
        data.qpos[joint.qposadr[0]] = angle_rad
        servo_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{joint_name}_servo")
        if servo_id >= 0:
            data.ctrl[servo_id] = angle_rad
    mujoco.mj_forward(model, data)
    return model, data


def run_benchmark(
    presets: Sequence[str], steps: int, warmup: int, repeats: int,
    robots: Sequence[str] = ("ur5e",),
) -> list[ThroughputRow]:
    """Benchmark the presets (with each robot) and the robot-only baseline; baseline first."""
    from rehabbot.sim import build_scene

    scene_rows = []
    home_angles_rad: dict[str, float] = {}
    for robot in robots:
        for preset in presets:
            scene = build_scene(preset, robot=robot)
            data = scene.make_data()
            if not home_angles_rad and robot == "ur5e":
                home_angles_rad = joint_angles_by_name(scene.model, data)
            name = preset if robot == "ur5e" else f"{preset}/{robot}"
            scene_rows.append(make_row(name, scene.model, data, steps, warmup, repeats))
    model, data = robot_only_model(home_angles_rad)
    baseline = make_row(BASELINE_NAME, model, data, steps, warmup, repeats)
    rows = [baseline, *scene_rows]
    for row in rows:
        row.ratio_to_baseline = row.steps_per_s / baseline.steps_per_s
    return rows


def results_table(rows: Sequence[ThroughputRow]) -> dict[str, Any]:
    """The rows as a results-document table; ``x baseline`` is each rate over the robot-only
    rate measured in the same run."""
    return make_table(
        "throughput", "mj_step throughput per scene preset, against the robot alone",
        ["preset", "nq", "nv", "ncon@rest", "nefc@rest", "dt [ms]", "steps/s", "x realtime",
         "x baseline"],
        [[row.name, row.nq, row.nv, row.ncon_at_rest, row.nefc_at_rest,
          f"{row.timestep_s * 1e3:.2f}", f"{row.steps_per_s:.0f}",
          f"{row.realtime_factor:.1f}", f"{row.ratio_to_baseline:.2f}"] for row in rows],
        align=["left", *["right"] * 8],
        note=f"`{BASELINE_NAME}`: the bare UR5e holding the same joint angles (the baseline). "
             "`x baseline` is a ratio measured in the same run on the same machine and is the "
             "figure to compare across machines; absolute rates depend on the machine.")


def build_parser() -> argparse.ArgumentParser:
    """Command-line options of the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000, help="timed steps per repeat")
    parser.add_argument("--warmup", type=int, default=500, help="untimed steps first")
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats; best is kept")
    parser.add_argument("--presets", nargs="+", metavar="NAME", help="default: all presets")
    parser.add_argument("--robots", nargs="+", metavar="NAME", default=["ur5e"],
                        help="robots to put in each preset (default: ur5e)")
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write results as JSON")
    add_page_argument(parser, "docs/results/physics-throughput")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and print the table; returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.steps < 1 or args.warmup < 0 or args.repeats < 1:
        print("--steps and --repeats must be >= 1, --warmup >= 0", file=sys.stderr)
        return 2
    from rehabbot.sim import PRESETS

    presets = list(args.presets or PRESETS)
    unknown = [name for name in presets if name not in PRESETS]
    if unknown:
        print(f"unknown preset(s) {', '.join(unknown)}; valid: {', '.join(PRESETS)}",
              file=sys.stderr)
        return 2
    from rehabbot.sim.robots import ROBOT_NAMES

    unknown = [name for name in args.robots if name not in ROBOT_NAMES]
    if unknown:
        print(f"unknown robot(s) {', '.join(unknown)}; valid: {', '.join(ROBOT_NAMES)}",
              file=sys.stderr)
        return 2
    rows = run_benchmark(presets, args.steps, args.warmup, args.repeats, args.robots)
    print(
        f"mujoco {mujoco.__version__}, python {platform.python_version()}, "
        f"{platform.machine()}; {args.steps} steps x best of {args.repeats} "
        f"after {args.warmup} warm-up steps"
    )
    table = results_table(rows)
    print(table_markdown(table))
    if args.page is not None:
        document = make_document(
            title="Physics throughput of every scene preset",
            intro=INTRO, command=script_command(__file__, argv),
            generated_by=__file__, tables=[table], machine=describe_machine(),
            settings={"steps": args.steps, "warmup": args.warmup, "repeats": args.repeats,
                      "robots": list(args.robots), "presets": presets},
            data={"rows": [asdict(row) for row in rows]})
        write_page(document, args.page)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        payload = {
            "mujoco_version": mujoco.__version__,
            "python_version": platform.python_version(),
            "machine": platform.machine(),
            "steps": args.steps,
            "warmup": args.warmup,
            "repeats": args.repeats,
            "robots": list(args.robots),
            "rows": [asdict(row) for row in rows],
        }
        args.json.write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
