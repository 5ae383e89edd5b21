"""Every figure of the paper that the data under some folders supports (:func:`plot_all`):
Fig. 4 from the training runs, Figs. 5, 6 and 3 from every evaluated episode (``trace.npz``).

================================  ===========  ==============================================
file                              figure       content
================================  ===========  ==============================================
``fig4_learning_curves``          Fig. 4       episode return, episode length and success rate
                                               versus environment steps: one line per
                                               algorithm (mean over seeds) with a ± std band
``fig5_kinematics_<label>``       Fig. 5       joint velocity, acceleration and jerk of the
                                               robot versus time in one evaluated episode
``fig6_torques_<label>``          Fig. 6       actuator torque of each robot joint versus time,
                                               with the torque limits as dashed lines
``fig3_tool_path_<label>``        Fig. 3       3-D tool path (purple) with the numbered targets
                                               in order, robot base frame, equal axes
``fig7_patient_joints_<label>``   (patient)    the patient's joint angles, the prescribed path
                                               and the range-of-motion bounds
``fig8_cuff_force_<label>``       (patient)    the cuff force and its limit
``fig9_work_<label>``             (patient)    the robot's and the patient's work on the limb
``fig10_overlay_<env>``           (patient)    the controllers evaluated together, over each
                                               other: joint angles, cuff force, robot work
================================  ===========  ==============================================

Figs. 7-10 (:mod:`rehabbot.analysis.patient_figures`, :mod:`rehabbot.analysis.overlay_figure`)
are drawn for every trace that holds the patient's data (every trace ``rehabbot evaluate``
writes now), Fig. 10 once per evaluation of two policies or more; ``patient=False`` leaves them
out.

An evaluation folder (what ``rehabbot evaluate`` wrote) is plotted from its files: nothing is
run again. A training run with ``model.zip`` is evaluated first (one episode) only when no
trace is found for its model: neither in its own ``evaluation/`` nor in an evaluation among the
plotted paths whose ``evaluation.json`` names the run.

``<label>`` is the trace's policy and the short env name (``sac-seed0_rehab-reach-v0``),
sanitised for file names. When runs of several env ids are plotted together, Fig. 4 is one
figure per env id, ``fig4_learning_curves_<env-short>``.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

from rehabbot.analysis.figures import (
    DEFAULT_FORMATS,
    DEFAULT_SMOOTH,
    DPI,
    SOURCES,
    build_kinematics,
    build_tool_path,
    build_torques,
    check_formats,
    save_figure,
)
from rehabbot.analysis.learning_curves import build_learning_curves, load_runs
from rehabbot.analysis.overlay_figure import OVERLAY_PREFIX, build_overlay, overlay_groups
from rehabbot.analysis.patient_figures import PATIENT_FIGURES, has_patient_data
from rehabbot.analysis.traces import find_traces, load_trace, sanitize
from rehabbot.common.extras import install_hint
from rehabbot.envs.registration import env_short_name
from rehabbot.rl import runs as run_files


def _unique_label(label: str, used: set[str]) -> str:
    candidate, k = label, 2
    while candidate in used:
        candidate, k = f"{label}-{k}", k + 1
    used.add(candidate)
    return candidate


def _ensure_trace(run_dir: Path) -> Path:
    """Evaluate the run's final model once (:func:`.evaluation.ensure_trace`)."""
    try:
        from rehabbot.analysis.evaluation import ensure_trace
    except ImportError as err:
        raise ImportError(
            f"evaluating {run_dir} for Figs. 3, 5, 6 needs the training extras "
            f"({install_hint('stable_baselines3')}): {err}; or pass --no-evaluate"
        ) from err
    return Path(ensure_trace(run_dir)).resolve()


def evaluated_runs(trace_paths: Sequence[Path]) -> set[Path]:
    """The training run folders that the evaluations beside ``trace_paths`` name (their
    ``evaluation.json``'s ``policy.run_dir``, resolved), so that a run evaluated together with
    other policies is not evaluated again alone."""
    named: set[Path] = set()
    for trace_path in trace_paths:
        report = Path(trace_path).parent / "evaluation.json"
        try:
            run_dir = json.loads(report.read_text(encoding="utf-8"))["policy"]["run_dir"]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # no report beside the trace (or not one of ours): nothing named
        if isinstance(run_dir, str) and run_dir:
            named.add(Path(run_dir).resolve())
    return named


def plot_all(paths: Sequence[Path | str], out_dir: Path | str, smooth: int = DEFAULT_SMOOTH,
             source: str = "train", formats: Sequence[str] = DEFAULT_FORMATS,
             evaluate: bool = True,
             announce: Callable[[str], None] | None = None,
             patient: bool = True, dpi: int = DPI) -> list[Path]:
    """Every figure that the data under ``paths`` supports; returns the written files.

    Fig. 4 from all runs (skipped with a warning when no run has data yet); Figs. 5, 6 and 3
    for every ``trace.npz`` found, and with ``patient`` (default) the patient-side Figs. 7-9
    for every trace that holds their data and Fig. 10 for every evaluation of two policies or
    more (:func:`.overlay_figure.overlay_groups`). With ``evaluate`` (default), a run that has
    ``model.zip`` but no trace (neither its own nor one of an evaluation found under
    ``paths`` that names it, :func:`evaluated_runs`) first gets one (one deterministic episode
    of its final model, :func:`rehabbot.analysis.evaluation.ensure_trace`), and ``announce``
    is told so before it starts. Traces whose labels coincide get ``-2``, ``-3``, ...
    suffixes instead of overwriting each other. PNGs are drawn at ``dpi``.

    Raises:
        ValueError: a path is missing, holds no runs or traces, or holds a corrupt file.
        OSError: ``out_dir`` cannot be created or written.
    """
    formats = check_formats(formats)
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r} (choose from {', '.join(SOURCES)})")
    if smooth < 1:
        raise ValueError(f"--smooth must be >= 1, got {smooth}")
    runs = load_runs(paths)
    trace_paths = find_traces(paths)
    if evaluate:
        evaluated = evaluated_runs(trace_paths)
        for run in runs:
            if (run.path / run_files.MODEL_NAME).is_file() and not find_traces([run.path]) \
                    and run.path.resolve() not in evaluated:
                if announce is not None:
                    announce(f"{run.path} has no evaluated episode: evaluating its "
                             f"{run_files.MODEL_NAME} on one deterministic episode (seed "
                             f"{run.seed}) into {run.path / run_files.EVALUATION_DIR}; "
                             "--no-evaluate skips this")
                trace_paths.append(_ensure_trace(run.path))
    traces = [load_trace(path) for path in dict.fromkeys(trace_paths)]

    written: list[Path] = []
    if runs:
        try:
            figures = build_learning_curves(runs, smooth=smooth, source=source)
        except ValueError as err:
            warnings.warn(f"Fig. 4 skipped: {err}", stacklevel=2)
            figures = {}
        for env_id, figure in figures.items():
            stem = "fig4_learning_curves"
            if len(figures) > 1:
                stem += f"_{sanitize(env_short_name(env_id))}"
            written += save_figure(figure, out_dir, stem, formats, dpi)
    used: set[str] = set()
    for trace in traces:
        label = _unique_label(trace.label, used)
        written += save_figure(build_kinematics(trace), out_dir, f"fig5_kinematics_{label}",
                               formats, dpi)
        written += save_figure(build_torques(trace), out_dir, f"fig6_torques_{label}", formats,
                               dpi)
        written += save_figure(build_tool_path(trace), out_dir, f"fig3_tool_path_{label}",
                               formats, dpi)
        if patient and has_patient_data(trace):
            for prefix, build in PATIENT_FIGURES:
                written += save_figure(build(trace), out_dir, f"{prefix}_{label}", formats, dpi)
    if patient:
        overlays: set[str] = set()
        for group in overlay_groups([t for t in traces if has_patient_data(t)]):
            env = sanitize(env_short_name(group[0].env_id))
            stem = f"{OVERLAY_PREFIX}_{_unique_label(env, overlays)}"
            written += save_figure(build_overlay(group), out_dir, stem, formats, dpi)
    return written
