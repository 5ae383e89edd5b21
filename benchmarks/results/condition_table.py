"""What each patient condition does, measured in the simulation (docs/conditions.md).

Three tables, in Markdown:

1. **Spasticity**: isokinetic elbow (or knee) stretches for every Modified Ashworth grade at
   5 and 100 deg/s (:func:`benchmarks.common.condition_probes.stretch_test`): the reflex's peak
   and mean resistance, the share of the sweep it resists, and the dynamometer's mean torque
   (the passive joint's at grade 0).
2. **Tremor**: the spectral peak of the held elbow's angle for several tremor frequencies
   (:func:`~benchmarks.common.condition_probes.tremor_spectrum`) and its RMS.
3. **Work on the limb**: the scripted expert and the assist-as-needed controller on every
   exercise of a base -v1 id, for a list of conditions: success, peak cuff force, the robot's
   and the patient's work and the assistance ratio (mean over exercises and weight levels 0, 2
   and 4, seed 0).

Usage::

    python benchmarks/results/condition_table.py [--sections spasticity tremor work]
        [--json FILE] [--page docs/results/conditions]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, script_command
from benchmarks.common.condition_probes import stretch_test, tremor_spectrum
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_text,
    write_page,
)
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.rl.assist_as_needed import AssistAsNeeded
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim.conditions import MAS_GRADES

INTRO = """The measurements behind docs/conditions.md: isokinetic stretches for every Modified
Ashworth grade at 5 and 100 deg/s (the reflex's peak and mean resistance, the share of the
sweep it resists and the dynamometer's mean torque; the passive joint's at grade 0), the
spectral peak and RMS of the held elbow's angle for several tremor frequencies, and the
scripted expert and the assist-as-needed controller on every exercise of a base -v1 id for a
list of conditions (success, peak cuff force, the robot's and the patient's work on the limb
and the assistance ratio)."""
TREMOR_HZ = (3.0, 5.0, 8.0, 12.0)
WORK_LEVELS = (0, 2, 4)
# (label, limb, task_type, condition): the conditions of the work table
WORK_CASES: tuple[tuple[str, str, str, dict], ...] = (
    ("healthy, passive", "arm", "reaching", {}),
    ("MAS 2", "arm", "reaching", {"spasticity_mas": "2"}),
    ("MAS 4", "arm", "reaching", {"spasticity_mas": "4"}),
    ("tremor 5 Hz, 1 N·m", "arm", "reaching", {"tremor_hz": 5.0, "tremor_amplitude_nm": 1.0}),
    ("active, strength 0.1", "arm", "reaching",
     {"effort": "active_assisted", "strength_fraction": 0.1}),
    ("active, strength 0.3", "arm", "reaching",
     {"effort": "active_assisted", "strength_fraction": 0.3}),
    ("active, strength 0.6", "arm", "reaching",
     {"effort": "active_assisted", "strength_fraction": 0.6}),
    ("healthy, passive", "knee", "trajectory", {}),
    ("active, strength 0.1", "knee", "trajectory",
     {"effort": "active_assisted", "strength_fraction": 0.1}),
    ("resistive, 10 %", "knee", "trajectory", {"effort": "resistive", "effort_fraction": 0.1}),
    ("stiffness x3, ROM x0.7", "knee", "trajectory", {"stiffness_scale": 3.0, "rom_scale": 0.7}),
)


def spasticity_rows(joint: str, limb: str) -> list[dict]:
    rows = []
    for grade in MAS_GRADES:
        for speed in (5.0, 100.0):
            sweep = (0.05, 0.95) if speed > 50 else (0.3, 0.7)
            result = stretch_test({"spasticity_mas": grade}, joint=joint, limb=limb,
                                  speed_deg_s=speed, sweep=sweep)
            resistance = result.resistance_nm
            rows.append({"joint": joint, "grade": grade, "speed_deg_s": speed,
                         "peak_resistance_nm": float(resistance.max()),
                         "mean_resistance_nm": float(resistance.mean()),
                         "resisted_fraction": result.resisted_fraction(),
                         "dynamometer_mean_nm": float(np.abs(result.dynamometer_nm).mean()),
                         "measured_speed_deg_s": float(result.velocity_deg_s.mean())})
    return rows


def tremor_rows() -> list[dict]:
    rows = []
    for hz in TREMOR_HZ:
        spectrum = tremor_spectrum({"tremor_hz": hz, "tremor_amplitude_nm": 1.0}, seed=0)
        rows.append({"tremor_hz": hz, "peak_hz": spectrum.peak_hz, "rms_deg": spectrum.rms_deg})
    quiet = tremor_spectrum(None, seed=0)
    rows.append({"tremor_hz": 0.0, "peak_hz": quiet.peak_hz, "rms_deg": quiet.rms_deg})
    return rows


def _episode(env: RehabEnv, controller, exercise: int, level: int) -> dict:
    obs, info = env.reset(seed=0, options={"exercise": exercise, "weight_level": level})
    peak = 0.0
    for _ in range(1000):
        obs, _, terminated, truncated, info = env.step(controller.predict(obs)[0])
        peak = max(peak, info["interaction_force_n"])
        if terminated or truncated:
            break
    return {"success": bool(info["is_success"]), "violation": info["safety_violation"],
            "peak_force_n": peak, "robot_work_j": info["robot_work_j"],
            "patient_work_j": info["patient_work_j"],
            "assistance_ratio": info["assistance_ratio"]}


def work_rows() -> list[dict]:
    rows = []
    for label, limb, task_type, condition in WORK_CASES:
        env = RehabEnv(limb=limb, task_type=task_type, condition=condition, reward="progress")
        for name, make in (("expert", ScriptedExpert), ("aan", AssistAsNeeded)):
            controller = make(env)
            episodes = [_episode(env, controller, e, lv) for e in range(len(env.targets))
                        for lv in WORK_LEVELS]
            rows.append({"condition": label, "limb": limb, "task_type": task_type,
                         "controller": name,
                         "success_rate": float(np.mean([e["success"] for e in episodes])),
                         "stops": sorted({e["violation"] for e in episodes} - {None}),
                         **{key: float(np.nanmean([e[key] for e in episodes]))
                            for key in ("peak_force_n", "robot_work_j", "patient_work_j",
                                        "assistance_ratio")}})
        env.close()
    return rows


def spasticity_table(rows: list[dict]) -> dict[str, Any]:
    return make_table(
        "spasticity", "Isokinetic stretches (cuff released; resistance = the reflex's torque "
        "against the motion)",
        ["joint", "MAS", "speed [deg/s]", "peak [N·m]", "mean [N·m]", "share of sweep resisted",
         "dynamometer mean [N·m]"],
        [[r["joint"], r["grade"], f"{r['speed_deg_s']:.0f}", f"{r['peak_resistance_nm']:.2f}",
          f"{r['mean_resistance_nm']:.2f}", f"{100 * r['resisted_fraction']:.0f} %",
          f"{r['dynamometer_mean_nm']:.2f}"] for r in rows])


def tremor_table(rows: list[dict]) -> dict[str, Any]:
    return make_table(
        "tremor", "Tremor, elbow held by the robot for 10 s (zero actions), seed 0",
        ["tremor_hz", "spectral peak [Hz]", "RMS about the trend [deg]"],
        [[f"{r['tremor_hz']:g}" if r["tremor_hz"] else "none", f"{r['peak_hz']:.2f}",
          f"{r['rms_deg']:.4f}"] for r in rows])


def work_table(rows: list[dict]) -> dict[str, Any]:
    return make_table(
        "work", f"Work on the limb: every exercise at weight levels {list(WORK_LEVELS)}, seed 0 "
        "(means over episodes)",
        ["limb", "condition", "controller", "success", "stops", "peak cuff force [N]",
         "robot work [J]", "patient work [J]", "assistance ratio"],
        [[r["limb"], r["condition"], r["controller"], f"{100 * r['success_rate']:.0f} %",
          ", ".join(r["stops"]) or "-", f"{r['peak_force_n']:.0f}", f"{r['robot_work_j']:.2f}",
          f"{r['patient_work_j']:.2f}", f"{r['assistance_ratio']:.2f}"] for r in rows])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sections", nargs="+", default=["spasticity", "tremor", "work"],
                        choices=["spasticity", "tremor", "work"])
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    add_page_argument(parser, "docs/results/conditions")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    command = script_command(__file__, argv)
    out: dict = {"command": command}
    tables = []
    if "spasticity" in args.sections:
        out["spasticity"] = spasticity_rows("elbow_flexion", "arm") + spasticity_rows(
            "knee_flexion", "knee")
        tables.append(spasticity_table(out["spasticity"]))
        print(table_text(tables[-1]) + "\n", flush=True)
    if "tremor" in args.sections:
        out["tremor"] = tremor_rows()
        tables.append(tremor_table(out["tremor"]))
        print(table_text(tables[-1]) + "\n", flush=True)
    if "work" in args.sections:
        out["work"] = work_rows()
        tables.append(work_table(out["work"]))
        print(table_text(tables[-1]) + "\n", flush=True)
    print(f"({time.perf_counter() - started:.0f} s)")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(out, handle, indent=2)
    if args.page is not None:
        write_page(make_document(
            title="What each patient condition does, measured in the simulation", intro=INTRO,
            command=command, generated_by=__file__, tables=tables, seeds={"episodes": 0},
            settings={"sections": args.sections, "work_levels": list(WORK_LEVELS),
                      "tremor_hz": list(TREMOR_HZ)}, data=out), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
