"""Scene tour: render every scene preset and run its scripted exercise sweep.

Usage::

    python benchmarks/probes/scene_tour.py --out runs/scenes

For every preset in :data:`rehabbot.sim.PRESETS` this writes one PNG per camera
(``DIR/<preset>_<camera>.png``), runs :func:`rehabbot.sim.scripted_sweep.run_sweep` and prints one
line saying which patient joints the robot moved, e.g.::

    upper_right: elbow_flexion_r moved 92.1 deg, shoulder_flexion_r 55.0 deg; \
max cuff error 2.1 mm; within ROM: yes

and finally writes ``DIR/summary.json`` with those numbers. The exit code is 1 if any
sweep produced non-finite state or left the patient's range of motion.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rehabbot.cli.display import use_headless_gl_by_default

if TYPE_CHECKING:
    from rehabbot.sim.scene import Scene

DEFAULT_DURATION_S = 10.0
MIN_REPORTED_MOTION_DEG = 1.0
MAX_REPORTED_JOINTS = 6


@dataclass
class PresetReport:
    """What the scene tour did and measured for one preset."""

    preset: str
    images: list[str] = field(default_factory=list)
    exercised_joint_range_deg: dict[str, float] = field(default_factory=dict)
    max_cuff_error_m: float = math.nan
    within_rom: bool = False
    finite: bool = False
    max_rom_excess_deg: float = math.nan
    max_robot_torque_nm: float = math.nan

    @property
    def ok(self) -> bool:
        """The sweep stayed finite and inside the patient's range of motion."""
        return self.finite and self.within_rom

    def summary_line(self) -> str:
        """The one-line human summary printed by the scene tour."""
        moved = sorted(
            (
                (name, deg)
                for name, deg in self.exercised_joint_range_deg.items()
                if deg >= MIN_REPORTED_MOTION_DEG
            ),
            key=lambda item: item[1],
            reverse=True,
        )[:MAX_REPORTED_JOINTS]
        if moved:
            first_name, first_deg = moved[0]
            parts = [f"{first_name} moved {first_deg:.1f} deg"]
            parts += [f"{name} {deg:.1f} deg" for name, deg in moved[1:]]
            motion = ", ".join(parts)
        else:
            motion = f"no joint moved more than {MIN_REPORTED_MOTION_DEG:.0f} deg"
        line = (
            f"{self.preset}: {motion}; max cuff error {self.max_cuff_error_m * 1e3:.1f} mm; "
            f"within ROM: {'yes' if self.within_rom else 'NO'}"
        )
        if not self.finite:
            line += "; NON-FINITE STATE"
        return line

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable form (plain floats/bools; NaN becomes ``null``)."""
        def number(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        return {
            "images": list(self.images),
            "exercised_joint_range_deg": {
                name: float(deg) for name, deg in self.exercised_joint_range_deg.items()
            },
            "max_cuff_error_m": number(self.max_cuff_error_m),
            "within_rom": bool(self.within_rom),
            "finite": bool(self.finite),
            "max_rom_excess_deg": number(self.max_rom_excess_deg),
            "max_robot_torque_nm": number(self.max_robot_torque_nm),
        }


def render_cameras(
    scene: Scene, preset: str, out_dir: Path, width_px: int, height_px: int
) -> list[str]:
    """Render the scene at its home pose from every camera; returns the PNG file names."""
    from rehabbot.analysis.images import save_png
    from rehabbot.envs.rendering import OffscreenRenderer

    data = scene.make_data()
    written: list[str] = []
    with OffscreenRenderer(scene.model, width_px=width_px, height_px=height_px) as renderer:
        for camera in scene.camera_names:
            path = save_png(out_dir / f"{preset}_{camera}.png", renderer.rgb(data, camera))
            written.append(path.name)
    return written


def run_preset(
    preset: str, out_dir: Path, duration_s: float, width_px: int, height_px: int
) -> PresetReport:
    """Build one preset, render its cameras and run its exercise sweep."""
    from rehabbot.sim import build_scene
    from rehabbot.sim.scripted_sweep import run_sweep

    scene = build_scene(preset)
    report = PresetReport(preset=preset)
    report.images = render_cameras(scene, preset, out_dir, width_px, height_px)
    result = run_sweep(scene, duration_s=duration_s)
    report.exercised_joint_range_deg = {
        str(name): float(deg) for name, deg in result.exercised_joint_range_deg.items()
    }
    report.max_cuff_error_m = float(result.max_cuff_error_m)
    report.within_rom = bool(result.within_rom)
    report.finite = bool(result.finite)
    report.max_rom_excess_deg = float(result.max_rom_excess_deg)
    report.max_robot_torque_nm = float(result.max_robot_torque_nm)
    return report


def write_summary(path: Path, reports: Sequence[PresetReport], duration_s: float) -> None:
    """Write ``summary.json``: sweep duration plus one entry per preset."""
    summary = {
        "duration_s": duration_s,
        "presets": {report.preset: report.to_json() for report in reports},
    }
    path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")


def build_parser() -> argparse.ArgumentParser:
    """Command-line options of the scene tour."""
    parser = argparse.ArgumentParser(
        prog="python benchmarks/probes/scene_tour.py",
        description="Render every scene preset and run its scripted exercise sweep.",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    parser.add_argument(
        "--duration", type=float, default=DEFAULT_DURATION_S, metavar="S",
        help=f"simulated seconds per sweep (default: {DEFAULT_DURATION_S})",
    )
    parser.add_argument("--width", type=int, default=640, metavar="W", help="image width [px]")
    parser.add_argument("--height", type=int, default=480, metavar="H", help="image height [px]")
    parser.add_argument(
        "--presets", nargs="+", metavar="NAME", help="only these presets (default: all)"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the scene tour; returns 0 if every sweep was finite and within ROM, else 1 (2: usage)."""
    args = build_parser().parse_args(argv)
    use_headless_gl_by_default()
    from rehabbot.sim import PRESETS

    presets = list(args.presets or PRESETS)
    unknown = [name for name in presets if name not in PRESETS]
    if unknown:
        print(
            f"unknown preset(s) {', '.join(unknown)}; valid: {', '.join(PRESETS)}",
            file=sys.stderr,
        )
        return 2
    out_dir: Path = args.out
    out_dir.mkdir(parents=True, exist_ok=True)

    reports = []
    for preset in presets:
        report = run_preset(preset, out_dir, args.duration, args.width, args.height)
        print(report.summary_line(), flush=True)
        reports.append(report)
    summary_path = out_dir / "summary.json"
    write_summary(summary_path, reports, args.duration)
    print(f"wrote {len(reports)} preset(s) to {out_dir} (summary: {summary_path})")
    return 0 if all(report.ok for report in reports) else 1


if __name__ == "__main__":
    sys.exit(main())
