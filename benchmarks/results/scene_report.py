"""Physical checks of every scene preset, as numbers for the README and release notes.

For each preset: the largest cuff error at reset over a grid of patient profiles and every
weight level, the largest joint drift while holding still for 2 s, and the scripted sweep's
ranges, cuff error and peak robot torque at weight levels 0 and 4.

    python benchmarks/results/scene_report.py [--json FILE]
"""

from __future__ import annotations

import argparse
import itertools
import json
import math

import mujoco
import numpy as np

from rehabbot.sim import PRESETS, PatientProfile, build_scene
from rehabbot.sim.scene import WEIGHT_LEVELS
from rehabbot.sim.scripted_sweep import run_sweep

HEIGHTS_M = (1.45, 1.60, 1.75, 1.90, 2.05)
MASSES_KG = (40.0, 75.0, 110.0, 150.0)
SEXES = ("male", "female")


def report_preset(preset: str) -> dict:
    worst_cuff_m = 0.0
    count = 0
    for height, mass, sex, level in itertools.product(HEIGHTS_M, MASSES_KG, SEXES,
                                                      WEIGHT_LEVELS):
        scene = build_scene(preset, PatientProfile(height, mass, sex), weight_level=level)
        worst_cuff_m = max(worst_cuff_m, float(scene.cuff_errors_m(scene.make_data()).max()))
        count += 1
    drift_deg = 0.0
    for level in WEIGHT_LEVELS:
        scene = build_scene(preset, weight_level=level)
        data = scene.make_data()
        q0 = data.qpos.copy()
        mujoco.mj_step(scene.model, data, nstep=1000)
        drift_deg = max(drift_deg, math.degrees(float(np.max(np.abs(data.qpos - q0)))))
    sweeps = {}
    for level in (0, 4):
        result = run_sweep(build_scene(preset, weight_level=level))
        sweeps[level] = {
            "range_deg": {k: round(v, 1) for k, v in result.exercised_joint_range_deg.items()},
            "max_cuff_error_mm": round(result.max_cuff_error_m * 1000, 2),
            "within_rom": result.within_rom,
            "max_robot_torque_nm": round(result.max_robot_torque_nm, 1),
        }
    return {"profiles_x_levels": count, "max_reset_cuff_error_mm": worst_cuff_m * 1000,
            "max_hold_drift_deg_2s": drift_deg, "sweep": sweeps}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="also write the report to this file")
    args = parser.parse_args()
    report = {preset: report_preset(preset) for preset in PRESETS}
    print(f"{'preset':<16} {'reset cuff [mm]':>15} {'hold drift [deg]':>16}  sweep (level 0 | 4)")
    for preset, row in report.items():
        s0, s4 = row["sweep"][0], row["sweep"][4]
        moved = ", ".join(f"{k} {v}" for k, v in s0["range_deg"].items() if v >= 10)
        print(f"{preset:<16} {row['max_reset_cuff_error_mm']:>15.2e} "
              f"{row['max_hold_drift_deg_2s']:>16.3f}  {moved}; cuff "
              f"{s0['max_cuff_error_mm']} | {s4['max_cuff_error_mm']} mm; peak torque "
              f"{s0['max_robot_torque_nm']} | {s4['max_robot_torque_nm']} N·m; in ROM "
              f"{s0['within_rom'] and s4['within_rom']}")
    print(f"(reset cuff error: max over {row['profiles_x_levels']} profile x weight-level "
          f"combinations per preset; hold: 2 s at every weight level)")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(report, handle, indent=2)


if __name__ == "__main__":
    main()
