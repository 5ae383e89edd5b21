"""The calibration round trip: simulated patients of known limbs, calibrated with sensor
noise, their fitted numbers against the simulator's own.

For every env id, body and Modified Ashworth grade (0, 1, 1+, 2, 3, 4), the simulator backend
(:mod:`rehabbot.deploy.simulator`) holds a patient with that body and grade (and, for every
other patient, a contracture: ``stiffness_scale`` 1.5); ``rehabbot.deploy.calibration``
runs its protocol on it, adds Gaussian sensor noise (encoders ``1e-3`` rad, each cuff force
component 1 N, from a seeded generator per patient) and fits. The truth is the simulated
model's own values (:func:`rehabbot.deploy.calibration.simulated_truth`): the joints'
stiffness and damping, the limb's inertia about the joint at rest (the mass matrix's
diagonal), the gravity torque (the model's bias force at rest), the grade.

The floors: stiffness and damping within 10 %, inertia within 20 %, at least 80 % of
the torque's variance accounted for (VAF), the grade exact for at least 80 % of the patients.

Usage::

    python benchmarks/deploy/calibration_roundtrip.py [--ids ID ...] [--bodies N]
        [--seed 0] [--page docs/results/calibration]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, add_seed_argument, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)

DEFAULT_IDS = ("rehab-reach-v2", "rehab-knee-v2")
GRADES = ("0", "1", "1+", "2", "3", "4")
FLOORS = {"stiffness": 0.10, "damping": 0.10, "inertia": 0.20, "vaf": 0.80, "mas": 0.80}
INTRO = """Simulated patients of known limbs (an env id's scene, a body of the envelope's test
cohort, a Modified Ashworth grade, every other one with a contracture), calibrated by
`rehabbot.deploy.calibration` on the simulator backend with sensor noise (encoders 1e-3 rad,
cuff force 1 N per component), the fitted numbers against the simulated model's own. The
floors: stiffness and damping within 10 %, inertia within 20 %, VAF at least 80 %,
the grade exact for at least 80 % of the patients; a cell that misses its floor is marked
**bold**."""


def bodies_of(env_id: str, count: int) -> list[Any]:
    """The first ``count`` bodies of the envelope's test cohort for ``env_id``'s limb."""
    from rehabbot.envs.registration import ENV_SPECS
    from rehabbot.sim.envelope import envelope_bodies

    limb = ENV_SPECS[env_id][0]["limb"]
    return list(envelope_bodies("test", limb))[:count]


def calibrate_one(env_id: str, profile: Any, grade: str, stiffness_scale: float,
                  seed: int) -> dict[str, Any]:
    """One patient's round trip: its truth, its fit, their relative errors."""
    import dataclasses

    from rehabbot.deploy import calibration as cal

    condition = {"spasticity_mas": grade, "stiffness_scale": stiffness_scale}
    backend = cal.simulator_backend(env_id, {"profile": dataclasses.asdict(profile),
                                             "condition": condition})
    start = time.perf_counter()
    result = cal.calibrate(backend, backend.env.scene, noise_rng=np.random.default_rng(seed))
    seconds = time.perf_counter() - start
    truth = cal.simulated_truth(backend, result)
    gravity = cal.gravity_error(backend.env.scene, result)
    joints = {}
    for name, fitted in result.joint_table().items():
        true = truth["joints"][name]
        joints[name] = {
            "truth": true, "fit": {k: fitted[k] for k in true},
            "error": {k.split("_")[0]: fitted[k] / true[k] - 1 for k in true},
            "vaf": fitted["vaf"], "gravity_error": gravity[name]}
    backend.close()
    return {"env_id": env_id, "profile": dataclasses.asdict(profile), "grade": grade,
            "stiffness_scale": stiffness_scale, "seed": seed,
            "fitted_grade": result.fit.spasticity_mas, "fitted_effort": result.fit.effort,
            "fitted_profile": dataclasses.asdict(result.profile),
            "fitted_condition": result.condition.to_dict(), "joints": joints,
            "stopped_reason": result.recording.stopped_reason,
            "skipped_blocks": result.recording.skipped_blocks, "seconds": seconds}


def _cell(value: float, floor: float, percent: bool = True, above: bool = False) -> str:
    text = f"{100 * value:+.0f} %" if percent and not above else f"{100 * value:.1f} %"
    missed = value < floor if above else abs(value) > floor
    return f"**{text}**" if missed else text


def results_table(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    cells = []
    for row in rows:
        body = row["profile"]
        for name, joint in row["joints"].items():
            truth, fit, error = joint["truth"], joint["fit"], joint["error"]
            cells.append([
                row["env_id"].split("/")[-1],
                f"{body['height_m']:.2f} m, {body['mass_kg']:.1f} kg, {body['sex']}",
                name, row["grade"],
                row["fitted_grade"] if row["fitted_grade"] == row["grade"]
                else f"**{row['fitted_grade']}**",
                f"{truth['stiffness_nm_per_rad']:.2f} / {fit['stiffness_nm_per_rad']:.2f}",
                _cell(error["stiffness"], FLOORS["stiffness"]),
                f"{truth['damping_nms_per_rad']:.2f} / {fit['damping_nms_per_rad']:.2f}",
                _cell(error["damping"], FLOORS["damping"]),
                f"{truth['inertia_kg_m2']:.3f} / {fit['inertia_kg_m2']:.3f}",
                _cell(error["inertia"], FLOORS["inertia"]),
                f"{100 * joint['gravity_error']:.1f} %",
                _cell(joint["vaf"], FLOORS["vaf"], above=True),
                f"{row['fitted_profile']['mass_kg']:.1f} kg"])
    return make_table(
        "patients", "Per patient and calibrated joint: truth / fit and the fit's error",
        ["id", "body", "joint", "MAS", "fitted MAS", "stiffness [N·m/rad]", "error",
         "damping [N·m·s/rad]", "error", "inertia [kg·m²]", "error", "gravity error",
         "VAF", "fitted mass"],
        cells, align=["left", "left", "left", "center", "center", *["right"] * 9],
        note="Errors are fit / truth - 1. `gravity error`: the RMS of the fitted gravity "
             "torque's error over the joint's quasi-static rows, relative to the model's RMS. "
             "`fitted mass`: from the fitted gravity at the body's own height (the body's "
             "mass is in the `body` column). Bold: outside the floor.")


def summary_table(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    cells = []
    for env_id in sorted({row["env_id"] for row in rows}):
        mine = [row for row in rows if row["env_id"] == env_id]
        joints = [j for row in mine for j in row["joints"].values()]

        def share(key: str, floor: float, joints: list = joints) -> str:
            inside = sum(abs(j["error"][key]) <= floor for j in joints)
            return f"{inside} of {len(joints)}"

        def median(key: str, joints: list = joints) -> str:
            return f"{100 * float(np.median([abs(j['error'][key]) for j in joints])):.0f} %"

        exact = sum(row["fitted_grade"] == row["grade"] for row in mine)
        vaf = sum(j["vaf"] >= FLOORS["vaf"] for j in joints)
        cells.append([env_id.split("/")[-1], str(len(mine)),
                      f"{share('stiffness', FLOORS['stiffness'])} ({median('stiffness')})",
                      f"{share('damping', FLOORS['damping'])} ({median('damping')})",
                      f"{share('inertia', FLOORS['inertia'])} ({median('inertia')})",
                      f"{vaf} of {len(joints)}",
                      f"{exact} of {len(mine)} ({100 * exact / len(mine):.0f} %)"])
    return make_table(
        "summary", "Summary: joints within each floor (median absolute error)",
        ["id", "patients", "stiffness within 10 %", "damping within 10 %",
         "inertia within 20 %", "VAF >= 80 %", "MAS exact"],
        cells, align=["left", *["right"] * 6])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ids", nargs="+", metavar="ID", default=list(DEFAULT_IDS),
                        help=f"one-robot env ids (default: {' '.join(DEFAULT_IDS)})")
    parser.add_argument("--bodies", type=int, default=2,
                        help="bodies of the envelope's test cohort per id (2)")
    add_seed_argument(
        parser, help_text="the first patient's noise seed; each next patient adds 1 (0)")
    add_page_argument(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.bodies < 1:
        parser.error(f"--bodies={args.bodies} must be >= 1")
    import rehabbot  # noqa: F401  (registers the ids)

    ids = [i if "/" in i else f"rehabbot/{i}" for i in args.ids]
    rows, seed = [], args.seed
    for env_id in ids:
        for profile in bodies_of(env_id, args.bodies):
            for k, grade in enumerate(GRADES):
                rows.append(calibrate_one(env_id, profile, grade, 1.5 if k % 2 else 1.0,
                                          seed))
                seed += 1
                row = rows[-1]
                print(f"{env_id} {profile} MAS {grade} -> {row['fitted_grade']} "
                      f"({row['seconds']:.0f} s)", flush=True)
    command = script_command(__file__, argv)
    tables = [summary_table(rows), results_table(rows)]
    for table in tables:
        print(table_markdown(table))
    if args.page is not None:
        notes = [
            "The truth of a joint is the simulated model's: `jnt_stiffness` and `dof_damping` "
            "(the condition's contracture included), the diagonal of the mass matrix at the "
            "resting posture (armature included) and the bias force at rest for gravity.",
            "A patient whose session stopped early (the cuff force reached its limit) or "
            "whose fast stretches were skipped (the slower ones predicted too large a force) "
            "is fitted on what was recorded; the JSON data lists both per patient."]
        write_page(make_document(
            title="Patient calibration: the round trip on simulated patients", intro=INTRO,
            command=command, generated_by=__file__, tables=tables,
            seeds={"first_noise_seed": args.seed, "per_patient": "first + index"},
            settings={"ids": ids, "bodies": args.bodies, "grades": list(GRADES),
                      "encoder_noise_rad": 1e-3, "force_noise_n": 1.0, "floors": FLOORS},
            notes=notes, data={"patients": rows}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
