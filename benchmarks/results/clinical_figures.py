"""The figures of docs/clinical-evaluation.md: Figs. 7-9 of the assist-as-needed controller's
episode and the overlay (Fig. 10) of the three controllers evaluated together, on the supine
hip exercise of a patient with MAS 3 spasticity, drawn by the commands a user runs:

    rehabbot evaluate expert aan random --env rehab-hip-v2 --episodes 1 \\
        --env-kwargs '{"condition": {"spasticity_mas": "3"}}' --out TMP/evaluation
    rehabbot plot TMP/evaluation --formats png --dpi 100 --out TMP/figures

    python benchmarks/results/clinical_figures.py [--out docs/images/clinical]

Only the figures the page shows are kept (each well under 150 KB); their sizes are printed.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import script_command
from rehabbot.cli import main as rehabbot

ENV = "rehab-hip-v2"
ENV_KWARGS = '{"condition": {"spasticity_mas": "3"}}'
POLICIES = ("expert", "aan", "random")
DPI = 100
# what the page shows: (file rehabbot plot writes, name on the page)
SHOWN = (("fig7_patient_joints_aan_rehab-hip-v2.png", "fig7_patient_joints.png"),
         ("fig8_cuff_force_aan_rehab-hip-v2.png", "fig8_cuff_force.png"),
         ("fig9_work_aan_rehab-hip-v2.png", "fig9_work.png"),
         ("fig10_overlay_rehab-hip-v2.png", "fig10_overlay.png"))
MAX_BYTES = 150_000


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/images/clinical"),
                        help="folder of the page's figures (default: docs/images/clinical)")
    args = parser.parse_args(argv)
    print(f"command: {script_command(__file__, argv)}",
          flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        evaluation, figures = Path(tmp) / "evaluation", Path(tmp) / "figures"
        code = rehabbot(["evaluate", *POLICIES, "--env", ENV, "--episodes", "1",
                         "--env-kwargs", ENV_KWARGS, "--out", str(evaluation)])
        if code == 0:
            code = rehabbot(["plot", str(evaluation), "--formats", "png", "--dpi", str(DPI),
                             "--out", str(figures)])
        if code != 0:
            return code
        args.out.mkdir(parents=True, exist_ok=True)
        for written, shown in SHOWN:
            target = args.out / shown
            shutil.copyfile(figures / written, target)
            size = target.stat().st_size
            print(f"{target}: {size / 1000:.0f} kB")
            if size > MAX_BYTES:
                print(f"{target} is over {MAX_BYTES / 1000:.0f} kB", file=sys.stderr)
                return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
