"""The patient's conditions on MyoSuite's muscles (``patient_model="myo"``), beside the rigid
patient's in the same run: isokinetic knee and elbow stretches for every Modified Ashworth
grade (the stretch reflex on the muscles' excitation against the rigid patient's joint
reflex), the held elbow's tremor spectrum, and the scripted expert on every exercise of the
knee and reach ids with each condition (success, forces, the work of the robot, of the
patient and of the muscles, fatigue).

    python benchmarks/results/myo_conditions.py [--seed 0] [--levels 0 2 4]
        [--page docs/results/myo-conditions]

Needs ``pip install "rehabbot[myo]"``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import gymnasium as gym

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.condition_probes import stretch_test, tremor_spectrum
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim.conditions import MAS_GRADES, PatientCondition

INTRO = """MyoSuite's legs and right arm (`myo-sim` 0.2.3) with the conditions of
`PatientCondition` acting on their muscles (`rehabbot.sim.muscle_drive`), measured beside the
rigid patient in this run. The isokinetic stretches release the cuff and move the seated knee
or elbow with a velocity servo through 5-99 % of its range at 100 deg/s, 30-70 % at 5 deg/s
(`benchmarks.common.condition_probes.stretch_test`); the resistance is the reflex's torque
against the motion (on the myo patient, the muscles' active torque). The reflex's one
constant was calibrated on the knee; the elbow rows check it. The tremor rows hold the elbow
still and give the spectral peak of its angle. The expert rows run the
scripted expert on every exercise of the rigid and myo knee and reach ids at the listed
weight levels (means over the episodes). Fatigue acts on muscles only, so it has no rigid
row."""

SPEEDS_DEG_S = (5.0, 100.0)
SWEEPS = {5.0: (0.3, 0.7), 100.0: (0.05, 0.99)}
# name -> condition; every one is feasible on both knees.
CONDITIONS: dict[str, dict] = {
    "healthy, passive": {},
    "MAS 2": {"spasticity_mas": "2"},
    "MAS 4": {"spasticity_mas": "4"},
    "contracture (stiffness x1.3, ROM x0.8)": {"stiffness_scale": 1.3, "rom_scale": 0.8},
    "active, 30 % strength": {"effort": "active_assisted", "strength_fraction": 0.3},
    "active, full strength": {"effort": "active_assisted"},
    "resistive, 3 % effort": {"effort": "resistive", "effort_fraction": 0.03},
    "weak (30 %), resistive 10 %": {"effort": "resistive", "effort_fraction": 0.1,
                                    "strength_fraction": 0.3},
    "active 50 %, fatigue x50": {"effort": "active_assisted", "effort_fraction": 0.5,
                                 "fatigue_scale": 50.0},
    "tremor 5 Hz, 2 N·m": {"tremor_hz": 5.0, "tremor_amplitude_nm": 2.0},
}
TREMOR_HZ = (3.0, 5.0, 8.0, 12.0)
TREMOR_NM = 2.0
TREMOR_SECONDS = 10.0


STRETCHED = (("knee_flexion", "knee"), ("elbow_flexion", "arm"))
KNEE_AND_REACH = ("rehab-knee", "rehab-reach")


def stretch_rows() -> list[dict]:
    rows = []
    for (joint, limb), model, grade, speed in itertools.product(
            STRETCHED, ("rigid", "myo"), MAS_GRADES, SPEEDS_DEG_S):
        result = stretch_test({"spasticity_mas": grade}, joint=joint,
                              limb=limb, speed_deg_s=speed, sweep=SWEEPS[speed],
                              patient_model=model)
        resistance = result.resistance_nm
        rows.append({"joint": joint, "patient_model": model, "mas": grade,
                     "speed_deg_s": speed,
                     "sweep": list(SWEEPS[speed]),
                     "peak_nm": float(resistance.max()),
                     "mean_nm": float(resistance.mean()),
                     "resisted_fraction": result.resisted_fraction(),
                     "dynamometer_mean_nm": float(result.dynamometer_nm.mean()),
                     "speed_mean_deg_s": float(result.velocity_deg_s.mean())})
        print(rows[-1], flush=True)
    return rows


def tremor_rows(seed: int) -> list[dict]:
    rows = []
    for model, frequency in itertools.product(("rigid", "myo"), (*TREMOR_HZ, None)):
        condition = None if frequency is None else {"tremor_hz": frequency,
                                                    "tremor_amplitude_nm": TREMOR_NM}
        spectrum = tremor_spectrum(condition, seconds=TREMOR_SECONDS, seed=seed,
                                   patient_model=model)
        rows.append({"patient_model": model, "tremor_hz": frequency,
                     "amplitude_nm": None if frequency is None else TREMOR_NM, "seed": seed,
                     "peak_hz": spectrum.peak_hz, "rms_deg": spectrum.rms_deg})
        print(rows[-1], flush=True)
    return rows


def expert_rows(seed: int, levels: list[int]) -> list[dict]:
    rows = []
    for base, (name, condition) in itertools.product(KNEE_AND_REACH, CONDITIONS.items()):
        for model, env_id in (("rigid", f"rehabbot/{base}-v2"),
                              ("myo", f"rehabbot/{base}-myo-v2")):
            if model == "rigid" and PatientCondition(**condition).fatigue_scale > 0.0:
                continue
            env = gym.make(env_id, condition=condition)
            expert = ScriptedExpert(env)
            episodes = []
            for exercise in range(len(env.unwrapped.config.exercise_table)):
                for level in levels:
                    obs, info = env.reset(seed=seed, options={"exercise": exercise,
                                                              "weight_level": level})
                    peak = 0.0
                    while True:
                        obs, _reward, terminated, truncated, info = env.step(expert(obs))
                        peak = max(peak, info["interaction_force_n"])
                        if terminated or truncated:
                            break
                    episodes.append({
                        "exercise": exercise, "weight_level": level,
                        "success": bool(info["is_success"]),
                        "stop": info.get("safety_violation"), "peak_force_n": peak,
                        "robot_work_j": info["robot_work_j"],
                        "patient_work_j": info["patient_work_j"],
                        "assistance_ratio": info["assistance_ratio"],
                        "peak_muscle_force_n": info.get("peak_muscle_force_n"),
                        "muscle_work_j": info.get("muscle_work_j"),
                        "muscle_fatigue": info.get("muscle_fatigue")})
            env.close()
            rows.append({"id": env_id.split("/")[1], "condition": name, "fields": condition,
                         "patient_model": model, "seed": seed, "episodes": episodes})
            print(name, model, [(e["success"], round(e["peak_force_n"])) for e in episodes],
                  flush=True)
    return rows


def _mean(episodes: list[dict], key: str) -> float | None:
    values = [e[key] for e in episodes if e[key] is not None]
    return sum(values) / len(values) if values else None


def _cell(value: float | None, digits: int) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_seed_argument(parser)
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 2, 4],
                        help="weight levels of the expert episodes")
    add_page_argument(parser, "docs/results/myo-conditions")
    args = parser.parse_args(argv)
    bad = [level for level in args.levels if level not in range(5)]
    if bad:
        parser.error(f"--levels must be weight levels 0-4, got {bad}")
    command = script_command(__file__, argv)
    announce(command)
    stretches = stretch_rows()
    stretch_table = make_table(
        "stretches", "Isokinetic stretches of the seated knee and elbow (cuff released; "
        "resistance = the reflex's torque against the motion)",
        ["joint", "patient", "MAS", "speed [deg/s]", "peak [N·m]", "mean [N·m]",
         "share of sweep resisted", "dynamometer mean [N·m]"],
        [[r["joint"], r["patient_model"], r["mas"], f"{r['speed_deg_s']:.0f}",
          f"{r['peak_nm']:.2f}", f"{r['mean_nm']:.2f}", f"{100 * r['resisted_fraction']:.0f} %",
          f"{r['dynamometer_mean_nm']:.2f}"] for r in stretches])
    tremors = tremor_rows(args.seed)
    tremor_table = make_table(
        "tremor", f"Tremor ({TREMOR_NM:g} N·m), the elbow held by the robot for "
        f"{TREMOR_SECONDS:g} s (zero actions), seed {args.seed}",
        ["patient", "tremor_hz", "spectral peak [Hz]", "RMS about the trend [deg]"],
        [[r["patient_model"], "none" if r["tremor_hz"] is None else f"{r['tremor_hz']:g}",
          f"{r['peak_hz']:.2f}", f"{r['rms_deg']:.4f}"] for r in tremors])
    experts = expert_rows(args.seed, args.levels)
    expert_table = make_table(
        "expert", f"The scripted expert on every exercise at weight levels {args.levels}, "
        f"seed {args.seed} (means over the episodes)",
        ["id", "condition", "success", "stops", "peak cuff force [N]", "robot work [J]",
         "patient work [J]", "assistance ratio", "peak muscle force [N]", "muscle work [J]",
         "most fatigued muscle at the end"],
        [[r["id"], r["condition"],
          f"{100 * _mean(r['episodes'], 'success'):.0f} %",
          ", ".join(sorted({e["stop"] for e in r["episodes"] if e["stop"]})) or "-",
          f"{max(e['peak_force_n'] for e in r['episodes']):.0f}",
          _cell(_mean(r["episodes"], "robot_work_j"), 2),
          _cell(_mean(r["episodes"], "patient_work_j"), 2),
          _cell(_mean(r["episodes"], "assistance_ratio"), 2),
          _cell(_mean(r["episodes"], "peak_muscle_force_n"), 0),
          _cell(_mean(r["episodes"], "muscle_work_j"), 2),
          _cell(_mean(r["episodes"], "muscle_fatigue"), 3)] for r in experts])
    tables = [stretch_table, tremor_table, expert_table]
    for table in tables:
        print(table_markdown(table), flush=True)
    if args.page is not None:
        write_page(make_document(
            title="Conditions on the musculoskeletal patient's muscles", intro=INTRO,
            command=command, generated_by=__file__, tables=tables,
            machine=describe_machine(), seeds={"episodes": args.seed},
            settings={"levels": args.levels, "speeds_deg_s": list(SPEEDS_DEG_S),
                      "sweeps": {str(k): list(v) for k, v in SWEEPS.items()},
                      "conditions": CONDITIONS},
            data={"stretches": stretches, "tremor": tremors, "expert": experts}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
