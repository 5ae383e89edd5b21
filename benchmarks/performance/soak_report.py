"""The soak's report: what each cell found (:class:`CellReport`), the whole run
(:class:`SoakReport`), its table and its JSON file (see ``benchmarks/performance/soak.py``)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.files import atomic_write_text
from rehabbot.common.provenance import package_versions
from rehabbot.common.text_tables import markdown_table
from rehabbot.sim.physics import RULES

END_REASONS = ("success", "truncation", *RULES, "exception", "open")
MIB = 1024 * 1024
WARMUP_STEPS = 1000  # per cell, before the first RSS reading
MAX_CONSECUTIVE_FAILURES = 10  # exceptions in a row without a successful step: give up the cell


def short_id(env_id: str) -> str:
    """``rehabbot/rehab-reach-v0`` -> ``rehab-reach-v0``."""
    return env_id.removeprefix("rehabbot/")


def rss_method() -> str | None:
    """How :func:`rss_mib` measures: ``"statm"`` (current RSS), ``"maxrss"`` (peak) or None."""
    if os.path.exists("/proc/self/statm"):
        return "statm"
    try:
        import resource  # noqa: F401
    except ImportError:
        return None
    return "maxrss"


def rss_mib() -> float | None:
    """Resident memory of this process in MiB (see :func:`rss_method`); None if unknown."""
    try:
        with open("/proc/self/statm", encoding="ascii") as stream:
            return int(stream.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / MIB
    except (OSError, ValueError, IndexError):
        pass
    try:
        import resource
    except ImportError:
        return None
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return maxrss / MIB if sys.platform == "darwin" else maxrss / 1024  # bytes / KiB


@dataclass
class ProcessMemory:
    """RSS of one process running cells: from the first cell's warm-up to its last cell."""

    pid: int
    baseline_mib: float | None = None  # after the warm-up of the first cell it ran
    end_mib: float | None = None  # after its last cell (env closed)
    steps_since_baseline: int = 0
    cells: int = 0

    @property
    def growth_mib(self) -> float | None:
        if self.baseline_mib is None or self.end_mib is None:
            return None
        return self.end_mib - self.baseline_mib

    @property
    def growth_mib_per_million_steps(self) -> float | None:
        growth = self.growth_mib
        if growth is None or self.steps_since_baseline <= 0:
            return None
        return growth / self.steps_since_baseline * 1e6

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "growth_mib": self.growth_mib,
                "growth_mib_per_million_steps": self.growth_mib_per_million_steps}


@dataclass
class CellReport:
    """What one cell did and found (see the module docstring for the fields' meaning)."""

    env_id: str
    control_mode: str
    steps_planned: int
    steps: int = 0
    episodes: int = 0
    ends: dict[str, int] = field(default_factory=lambda: dict.fromkeys(END_REASONS, 0))
    status: str = "not_run"  # complete, interrupted, abandoned, crashed or not_run
    wall_s: float = 0.0
    steps_per_s: float | None = None
    reset_seeds: list[int] = field(default_factory=list)  # first reset of each env built
    action_seeds: list[int] = field(default_factory=list)  # action space of each env built
    exceptions: int = 0
    exceptions_by_type: dict[str, int] = field(default_factory=dict)
    exception_examples: list[dict[str, Any]] = field(default_factory=list)
    non_finite: int = 0
    non_finite_by_field: dict[str, int] = field(default_factory=dict)
    non_finite_example: dict[str, Any] | None = None
    obs_outside: int = 0
    obs_outside_example: dict[str, Any] | None = None
    warmup_steps: int = 0
    rss_warmup_mib: float | None = None
    rss_end_mib: float | None = None
    rss_growth_mib: float | None = None
    rss_growth_mib_per_million_steps: float | None = None
    pid: int = 0
    process: dict[str, Any] = field(default_factory=dict)  # ProcessMemory after this cell

    @property
    def name(self) -> str:
        return f"{short_id(self.env_id)}/{self.control_mode}"

    @property
    def problems(self) -> int:
        return self.exceptions + self.non_finite + self.obs_outside

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class SoakReport:
    """The whole soak: the plan, every cell, the processes' memory and the versions."""

    seed: int
    total_steps: int  # requested
    env_ids: list[str]
    control_modes: list[str]
    workers: int
    cells: list[CellReport]
    processes: list[ProcessMemory]
    wall_s: float
    interrupted_by: str | None = None  # SIGINT, SIGTERM or KeyboardInterrupt
    versions: dict[str, str | None] = field(default_factory=package_versions)
    rss_method: str | None = field(default_factory=rss_method)
    command: str = ""
    started_at: str = ""

    @property
    def complete(self) -> bool:
        """The run went through every cell (it was not stopped part-way)."""
        return self.interrupted_by is None

    @property
    def steps(self) -> int:
        return sum(cell.steps for cell in self.cells)

    @property
    def episodes(self) -> int:
        return sum(cell.episodes for cell in self.cells)

    @property
    def exceptions(self) -> int:
        return sum(cell.exceptions for cell in self.cells)

    @property
    def non_finite(self) -> int:
        return sum(cell.non_finite for cell in self.cells)

    @property
    def obs_outside(self) -> int:
        return sum(cell.obs_outside for cell in self.cells)

    @property
    def problems(self) -> int:
        return self.exceptions + self.non_finite + self.obs_outside

    @property
    def rss_growth_mib(self) -> float | None:
        """Sum over the processes of their growth after the first warm-up."""
        growths = [p.growth_mib for p in self.processes if p.growth_mib is not None]
        return sum(growths) if growths else None

    def ends(self) -> dict[str, int]:
        totals: dict[str, int] = {}
        for cell in self.cells:
            for reason, count in cell.ends.items():
                totals[reason] = totals.get(reason, 0) + count
        return totals

    def exit_code(self) -> int:
        """130 (SIGINT, KeyboardInterrupt) or 143 (SIGTERM) if stopped, 1 if a problem was
        found, else 0."""
        if self.interrupted_by == "SIGTERM":
            return 128 + signal.SIGTERM
        if self.interrupted_by is not None:
            return 128 + signal.SIGINT
        return 1 if self.problems else 0

    def to_dict(self) -> dict[str, Any]:
        data = {
            "complete": self.complete,
            "interrupted_by": self.interrupted_by,
            "seed": self.seed,
            "total_steps": self.total_steps,
            "steps": self.steps,
            "episodes": self.episodes,
            "exceptions": self.exceptions,
            "non_finite": self.non_finite,
            "obs_outside": self.obs_outside,
            "ends": self.ends(),
            "wall_s": self.wall_s,
            "steps_per_s": self.steps / self.wall_s if self.wall_s > 0 else None,
            "rss_method": self.rss_method,
            "rss_growth_mib": self.rss_growth_mib,
            "processes": [p.to_dict() for p in self.processes],
            "env_ids": self.env_ids,
            "control_modes": self.control_modes,
            "workers": self.workers,
            "warmup_steps_max": WARMUP_STEPS,
            "seeding": ("the k-th env built in a cell (one more after each exception): first "
                        "reset seeded with reset_seeds[k], action space with action_seeds[k]; "
                        "numpy.random.SeedSequence(seed, spawn_key=(crc32(env_id), crc32(mode), "
                        "purpose, k)).generate_state(1)[0], purpose 0: reset, 1: actions"),
            "command": self.command,
            "started_at": self.started_at,
            "versions": self.versions,
            "cells": [cell.to_dict() for cell in self.cells],
        }
        return _json_safe(data)


def _json_safe(value: Any) -> Any:
    """JSON-ready copy: NaN/inf as strings, NumPy scalars as Python numbers."""
    if isinstance(value, Mapping):
        return {str(key): _json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(item) for item in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return value


RULE_HEADERS = {"instability": "instab.", "range_of_motion": "ROM", "cuff_force": "cuff force",
                "unintended_contact": "contact"}


def _fmt_mib(value: float | None) -> str:
    return "-" if value is None else f"{value:+.1f}"


def _table_row(label: Sequence[str], steps: int, episodes: int, ends: Mapping[str, int],
               exceptions: int, non_finite: int, outside: int, growth: float | None,
               rate: float | None) -> list[str]:
    other = ends.get("exception", 0) + ends.get("open", 0) + ends.get("terminated", 0)
    cells = [*label, str(steps), str(episodes), str(ends.get("success", 0)),
             str(ends.get("truncation", 0)), *(str(ends.get(rule, 0)) for rule in RULES),
             str(other), str(exceptions), str(non_finite), str(outside), _fmt_mib(growth),
             "-" if rate is None else f"{rate:.0f}"]
    return cells


def format_header(report: SoakReport) -> str:
    """The line above the table: seed, steps, cells, workers and versions."""
    v = report.versions
    n = len(report.cells)
    share = report.total_steps // n if n else 0
    return (f"soak: seed {report.seed}, {report.total_steps} steps = {n} cells x {share}"
            f"{'+' if n and report.total_steps % n else ''}, workers {report.workers}, "
            f"random actions; python {v.get('python')}, rehabbot {v.get('rehabbot')}, "
            f"mujoco {v.get('mujoco')}, gymnasium {v.get('gymnasium')}, numpy {v.get('numpy')}")


def format_table(report: SoakReport) -> str:
    """Markdown table (:mod:`rehabbot.common.text_tables`): one row per cell and a total row."""
    header = ["env", "mode", "steps", "episodes", "success", "trunc.",
              *(RULE_HEADERS.get(rule, rule) for rule in RULES), "other", "exceptions",
              "non-finite", "obs outside", "RSS growth [MiB]", "steps/s"]
    lines = []
    for cell in report.cells:
        mode = cell.control_mode if cell.status == "complete" \
            else f"{cell.control_mode} [{cell.status}]"
        lines.append(_table_row((short_id(cell.env_id), mode), cell.steps, cell.episodes,
                                cell.ends, cell.exceptions, cell.non_finite, cell.obs_outside,
                                cell.rss_growth_mib, cell.steps_per_s))
    rate = report.steps / report.wall_s if report.wall_s > 0 else None
    lines.append(_table_row(("**total**", ""), report.steps, report.episodes, report.ends(),
                            report.exceptions, report.non_finite, report.obs_outside,
                            report.rss_growth_mib, rate))
    return markdown_table(header, lines, align=["left", "left", *["right"] * (len(header) - 2)])


def format_footer(report: SoakReport) -> str:
    """Process memory, wall-clock, the first example of each problem and the verdict."""
    lines = ["other: episodes cut by an exception or still open at the end of the cell; "
             "RSS growth: per cell from its warm-up to its end, total = sum over processes "
             "from the first warm-up to the end"]
    for i, proc in enumerate(report.processes, 1):
        per_million = proc.growth_mib_per_million_steps
        lines.append(
            f"RSS process {i}/{len(report.processes)} (pid {proc.pid}, {proc.cells} cells): "
            f"{_mib(proc.baseline_mib)} after the first warm-up -> {_mib(proc.end_mib)} at the "
            f"end ({_fmt_mib(proc.growth_mib)} MiB over {proc.steps_since_baseline} steps, "
            f"{_fmt_mib(per_million)} MiB per million steps; {report.rss_method})")
    rate = report.steps / report.wall_s if report.wall_s > 0 else 0.0
    lines.append(f"wall-clock: {report.wall_s:.1f} s ({rate:.0f} steps/s overall)")
    for cell in report.cells:
        lines.extend(f"{cell.name}: {line}" for line in _problem_lines(cell))
    if not report.complete:
        lines.append(f"INTERRUPTED by {report.interrupted_by} after {report.steps} of "
                     f"{report.total_steps} steps: partial report (complete: false)")
    elif report.problems:
        lines.append(f"FOUND PROBLEMS: {report.exceptions} exceptions, {report.non_finite} "
                     f"non-finite values, {report.obs_outside} observations outside the space")
    else:
        lines.append(f"OK: {report.steps} steps, no exceptions, non-finite values or "
                     "observations outside the space")
    return "\n".join(lines)


def _mib(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} MiB"


def _problem_lines(cell: CellReport) -> list[str]:
    lines = []
    if cell.exceptions:
        first = cell.exception_examples[0] if cell.exception_examples else {}
        lines.append(f"{cell.exceptions} exceptions {cell.exceptions_by_type}; first: "
                     f"{_example(first)}")
    if cell.non_finite_example is not None:
        lines.append(f"{cell.non_finite} non-finite {cell.non_finite_by_field}; first: "
                     f"{_example(cell.non_finite_example)}")
    if cell.obs_outside_example is not None:
        lines.append(f"{cell.obs_outside} observations outside the space; first: "
                     f"{_example(cell.obs_outside_example)}")
    if cell.status == "abandoned":
        lines.append(f"abandoned after {MAX_CONSECUTIVE_FAILURES} failures in a row")
    return lines


def _example(example: Mapping[str, Any]) -> str:
    return json.dumps(_json_safe(example), separators=(", ", ": "))


def write_report(report: SoakReport, path: Path) -> None:
    """Write the report as JSON, atomically."""
    atomic_write_text(path, json.dumps(report.to_dict(), indent=2) + "\n")


