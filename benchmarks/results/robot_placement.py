"""How well each robot's stand placement serves each limb: the evidence behind a robot's
``base_offset_m`` (``docs/physics.md``, "Placing a robot").

For every robot, scene and patient height, the limb's whole workspace box (the patient poses of
:data:`rehabbot.tasks.workspace.WORKSPACE_DEG`, every 5 degrees) is solved by the robot's IK the
way the env does when it derives its setpoint bounds (each pose from its nearest solved
neighbour, :func:`rehabbot.tasks.workspace.workspace_robot_angles`), and the table reports:

* ``reached``: poses solved on the home branch (to 1 mm, no joint jumping more than 0.6 rad
  from its neighbour) out of all; a pose left out narrows the setpoint bounds;
* ``margin``: the smallest distance of any solved joint angle to its joint's range [rad];
* ``contacts``: solved poses where a robot geom presses more than 2 mm into the patient or the
  furniture;
* ``torque at home``: the largest share of a joint's torque limit used to hold the limb at
  home at weight level 4, and which joint.

A scene the robot cannot reach at home (the env refuses it) is marked ``refused``.

Usage::

    python benchmarks/results/robot_placement.py [--robots ur5e fr3] [--heights 1.4 1.6 1.75 2.0]
                                         [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from rehabbot.common.text_tables import markdown_table
from rehabbot.sim import PatientProfile, build_scene
from rehabbot.sim.robots import ROBOT_NAMES
from rehabbot.tasks.workspace import solve_workspace, workspace_grid_deg

# (scene preset, its options, the limb whose workspace box is swept)
SCENES = (("upper_right", {}, "arm"), ("hip", {}, "hip"), ("knee", {}, "knee"))
HEIGHTS_M = (1.4, 1.6, 1.75, 2.0)
MASS_KG = 75.0
MAX_ERROR_M, MAX_JUMP_RAD, CONTACT_DEPTH_M = 1e-3, 0.6, 2e-3


def sweep_workspace(scene, limb: str) -> dict:
    """Solve ``limb``'s workspace box in ``scene`` as the env does; count and measure."""
    handle = scene.robots[0]
    low, high = handle.robot.joint_low_rad(), handle.robot.joint_high_rad()
    grid = workspace_grid_deg(scene, limb)
    robot_geoms = set(handle.geom_ids.tolist())
    others = set(scene.patient_geom_ids.tolist()) | set(scene.furniture_geom_ids.tolist())
    reached, margin, contacts = 0, np.inf, 0
    for q, data in solve_workspace(scene, grid, MAX_JUMP_RAD, MAX_ERROR_M):
        reached += 1
        margin = min(margin, float(np.min(np.minimum(q - low, high - q))))
        mujoco.mj_forward(scene.model, data)
        pressed = any(((c.geom1 in robot_geoms and c.geom2 in others)
                       or (c.geom2 in robot_geoms and c.geom1 in others))
                      and c.dist < -CONTACT_DEPTH_M for c in data.contact[:data.ncon])
        contacts += int(pressed)
    return {"reached": reached, "poses": len(grid), "margin_rad": margin,
            "contacts": contacts}


def home_torque_share(scene) -> tuple[float, int]:
    """The largest share of a joint's torque limit holding the limb at home, and its joint."""
    data = scene.make_data()
    handle = scene.robots[0]
    share = np.abs(data.qfrc_actuator[handle.dof_adr]) / handle.robot.torque_limits()
    return float(share.max()), int(share.argmax()) + 1


def measure(robots: Sequence[str], heights: Sequence[float]) -> list[dict]:
    rows = []
    for robot in robots:
        for preset, options, limb in SCENES:
            for height in heights:
                profile = PatientProfile(height, MASS_KG, "male")
                row = {"robot": robot, "scene": preset, "height_m": height}
                try:
                    scene = build_scene(preset, profile=profile, robot=robot, **options)
                except ValueError as err:
                    rows.append({**row, "refused": str(err)})
                    continue
                row.update(sweep_workspace(scene, limb))
                scene.set_weight_level(4)
                row["torque_share"], row["torque_joint"] = home_torque_share(scene)
                rows.append(row)
    return rows


def results_markdown(rows: Sequence[dict]) -> str:
    """The rows as a Markdown table (:mod:`rehabbot.common.text_tables`); a refused scene's cells
    are ``-``."""
    cells: list[list[str | None]] = []
    for r in rows:
        head = [r["robot"], r["scene"], f"{r['height_m']:.2f}"]
        if "refused" in r:
            cells.append([*head, "refused", None, None, None])
            continue
        cells.append([*head, f"{r['reached']}/{r['poses']}", f"{r['margin_rad']:.2f}",
                      str(r["contacts"]),
                      f"{100 * r['torque_share']:.0f} % (joint {r['torque_joint']})"])
    return markdown_table(["robot", "scene", "height [m]", "reached", "margin [rad]", "contacts",
                           "torque at home, level 4"], cells)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=list(ROBOT_NAMES), metavar="NAME",
                        help=f"robots (default: {' '.join(ROBOT_NAMES)})")
    parser.add_argument("--heights", nargs="+", type=float, default=list(HEIGHTS_M),
                        metavar="M", help="patient heights [m] (75 kg, male)")
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write the rows")
    args = parser.parse_args(argv)
    unknown = [name for name in args.robots if name not in ROBOT_NAMES]
    if unknown:
        print(f"unknown robot(s) {', '.join(unknown)}; valid: {', '.join(ROBOT_NAMES)}",
              file=sys.stderr)
        return 2
    rows = measure(args.robots, args.heights)
    print(results_markdown(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
