"""Which patient profiles each scene supports: builds ``RehabEnv`` for every limb, side and a
grid of heights, masses and both sexes (random weight levels, so every level is checked) and
counts the profiles it refuses (:mod:`rehabbot.feasibility`), by reason.

    python benchmarks/results/profile_envelope.py [--robot ur5e] [--workers 2]
        [--out runs/envelope.json]

Prints a Markdown table: per limb and side, the refused share of the grid, the reasons, and the
lowest height from which every profile up to a given mass is accepted.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from rehabbot.common.text_tables import markdown_table

HEIGHTS_M = tuple(float(h) for h in np.round(np.arange(1.20, 2.2001, 0.05), 2))
MASSES_KG = (30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 100.0, 120.0, 140.0, 160.0, 180.0, 200.0)
SEXES = ("male", "female")
COMBOS = tuple(itertools.product(("arm", "hip", "knee"), ("right", "left")))
MASS_CAPS_KG = (100.0, 140.0, 200.0)
# Refusal reasons by a phrase of their message (rehabbot.tasks.feasibility), most specific
# first: the torque and cuff-force messages both say "at rest".
REASONS = {"cannot reach": "robot cannot reach the cuff", "setpoint bounds":
           "target outside the setpoint bounds", "torque limit": "robot joint saturated at rest",
           "touches": "robot touches the body at home", "cuff carries": "cuff force at rest"}


def survey(combo: tuple[str, str], robot: str = "ur5e") -> list[dict]:
    """One row per profile of the grid for ``combo`` = (limb, side), with ``robot``."""
    from rehabbot.envs.rehab_env import RehabEnv

    limb, side = combo
    rows = []
    for h, m, sex in itertools.product(HEIGHTS_M, MASSES_KG, SEXES):
        reason = message = None
        try:
            RehabEnv(limb=limb, side=side, robot=robot,
                     profile={"height_m": h, "mass_kg": m, "sex": sex})
        except ValueError as err:
            message = str(err)
            reason = refusal_reason(message)
        rows.append({"limb": limb, "side": side, "height_m": h, "mass_kg": m, "sex": sex,
                     "refused": reason, "message": message})
    return rows


def refusal_reason(message: str) -> str:
    """The :data:`REASONS` class of a refusal message (the message itself if none fits)."""
    return next((v for k, v in REASONS.items() if k in message), message)


def lowest_supported_height(rows: list[dict], mass_cap_kg: float) -> float | None:
    """The lowest grid height from which every profile up to ``mass_cap_kg`` is accepted."""
    for h in HEIGHTS_M:
        if all(r["refused"] is None for r in rows
               if r["height_m"] >= h and r["mass_kg"] <= mass_cap_kg):
            return h
    return None


def table(rows: list[dict]) -> str:
    """Per limb and side: the refused share, the reasons, and the lowest height from which
    every profile up to each mass cap is accepted (Markdown, :mod:`rehabbot.common.text_tables`)."""
    cells = []
    for limb, side in COMBOS:
        mine = [r for r in rows if r["limb"] == limb and r["side"] == side]
        refused = [r for r in mine if r["refused"]]
        reasons = sorted({r["refused"] for r in refused})
        heights = [f"{h:.2f} m" if (h := lowest_supported_height(mine, c)) is not None
                   else "never" for c in MASS_CAPS_KG]
        cells.append([limb, side, f"{len(refused)}/{len(mine)}", "; ".join(reasons) or "-",
                      *heights])
    return markdown_table(["limb", "side", "refused", "reasons",
                           *(f"all accepted from (mass ≤ {c:.0f} kg)" for c in MASS_CAPS_KG)],
                          cells)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="ur5e", help="the robot (default: ur5e)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None, help="write every row as JSON")
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error(f"--workers {args.workers} must be >= 1")
    with ProcessPoolExecutor(args.workers) as pool:
        rows = [r for part in pool.map(functools.partial(survey, robot=args.robot), COMBOS)
                for r in part]
    print(f"robot {args.robot}; grid: heights {HEIGHTS_M[0]}-{HEIGHTS_M[-1]} m every 0.05 m, "
          f"masses {', '.join(f'{m:.0f}' for m in MASSES_KG)} kg, both sexes; every weight level")
    print(table(rows))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
