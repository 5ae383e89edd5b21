"""``rehabbot plot RUN_DIR...``: the paper's Figs. 3-6 for the user's own runs and the
patient-side Figs. 7-10 for their evaluations (:mod:`rehabbot.analysis.plotting`). An
evaluation folder that ``rehabbot evaluate`` wrote is drawn from its files, nothing run again;
matplotlib is checked before anything else."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from rehabbot.analysis.figures import (
    DEFAULT_FORMATS,
    DEFAULT_SMOOTH,
    DPI,
    SOURCES,
    SUPPORTED_FORMATS,
)
from rehabbot.cli.errors import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, CliError, bounded_int

MAX_SMOOTH = 1_000_000  # episodes in the rolling mean: more than any run logs
MIN_DPI, MAX_DPI = 50, 600

PLOT_DESCRIPTION = """\
Draw the paper's figures for your own runs:
  Fig. 4  fig4_learning_curves.{png,pdf}    return / length / success vs. env steps,
                                            mean ± std over seeds, one line per algorithm
                                            (one file per env id, suffixed, for several)
  Fig. 5  fig5_kinematics_<label>.{png,pdf} joint velocity, acceleration, jerk vs. time
  Fig. 6  fig6_torques_<label>.{png,pdf}    joint torques with the torque limits
  Fig. 3  fig3_tool_path_<label>.{png,pdf}  3-D tool path with the numbered targets
the patient's side (for every trace that holds it; --no-patient-figures leaves them out):
  Fig. 7  fig7_patient_joints_<label>.*     the patient's joint angles, the prescribed path,
                                            the range-of-motion bounds and the range achieved
                                            against the one prescribed (flagged above 1)
  Fig. 8  fig8_cuff_force_<label>.*         the cuff force, its ISO/TS 15066 limit and where
                                            the force went above it
  Fig. 9  fig9_work_<label>.*               the robot's and the patient's cumulative work on
                                            the limb (> 0: into the limb)
  Fig. 10 fig10_overlay_<env>.*             the controllers evaluated together, over each
                                            other (one per evaluation of 2 policies or more)
a deployment session (what `rehabbot deploy` wrote: its folder, session.json or one episode):
  session_<folder>_ep<k>.*                  joint commands against the measured joints with
                                            the filter's interventions, the cuff force against
                                            its limit, the filter's hold share
<label> is <policy>_<env>. Every title names the patient and condition, every limit line its
value and source; a safety stop is marked with its rule. RUN_DIR may be an evaluation folder
(what `rehabbot evaluate` wrote: drawn from its files, nothing is run again), a training run,
any directory above them (all manifest.json and trace.npz below it are used). A training run
with model.zip whose model no evaluation below the RUN_DIRs has evaluated is evaluated first
(one deterministic episode; the command says so before it starts) unless --no-evaluate is
given."""

PLOT_EPILOG = """\
examples:
  rehabbot plot runs/rehab-reach-v2                  # all algorithms and seeds below it
  rehabbot plot runs/evaluation/rehab-knee-v2/zoo-sac+expert   # what evaluate wrote
  rehabbot plot runs/rehab-reach-v2/sac/seed0 --out figures/
  rehabbot plot runs/a runs/b --smooth 50 --formats png
  rehabbot plot runs --source eval --no-evaluate     # Fig. 4 from eval/evaluations.npz
  rehabbot plot sessions/knee                        # a session of `rehabbot deploy`

exit codes: 0 success, 1 unreadable input file, unwritable output or missing matplotlib,
2 bad usage (missing directory, nothing to plot, bad option value)"""


def add_plot_parser(commands: argparse._SubParsersAction) -> None:
    """Add the ``plot`` subcommand to the ``rehabbot`` parser's subcommands."""
    parser = commands.add_parser(
        "plot",
        help="draw the paper's figures (learning curves, kinematics, torques, tool path) and "
             "the patient's (joint angles, cuff force, work)",
        description=PLOT_DESCRIPTION,
        epilog=PLOT_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", type=Path,
                        help="training run directories, their parents, trace directories or "
                             "deployment sessions")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="output directory; its parent folder must exist (default: "
                             "<first RUN_DIR>/figures)")
    parser.add_argument("--smooth", type=bounded_int(1, MAX_SMOOTH), default=DEFAULT_SMOOTH,
                        metavar="N",
                        help="rolling-mean window of the training curves, in episodes, 1 to "
                             f"{MAX_SMOOTH:,} (default: {DEFAULT_SMOOTH})")
    parser.add_argument("--source", choices=SOURCES, default="train",
                        help="Fig. 4 from the training episodes (monitor files, default) or "
                             "from the deterministic evaluations (eval/evaluations.npz)")
    parser.add_argument("--formats", nargs="+", choices=SUPPORTED_FORMATS,
                        default=list(DEFAULT_FORMATS), metavar="FMT",
                        help="file formats to write: png, pdf, svg (default: png pdf)")
    parser.add_argument("--dpi", type=bounded_int(MIN_DPI, MAX_DPI), default=DPI,
                        metavar="DPI", help=f"resolution of the PNGs, {MIN_DPI} to {MAX_DPI} "
                                            f"(default: {DPI})")
    parser.add_argument("--no-evaluate", dest="evaluate", action="store_false",
                        help="do not evaluate runs that have model.zip but no trace.npz")
    parser.add_argument("--no-patient-figures", dest="patient", action="store_false",
                        help="leave out Figs. 7-10 (the patient's joint angles, cuff force and "
                             "work, the controllers' overlay)")
    parser.set_defaults(func=cmd_plot)


def _own_warnings(caught: list[warnings.WarningMessage]) -> list[warnings.WarningMessage]:
    """The warnings RehabBot itself gave (third parties' are not shown to users)."""
    package = Path(__file__).resolve().parents[1]
    return [warning for warning in caught
            if Path(warning.filename).resolve().is_relative_to(package)]


def check_matplotlib() -> None:
    """:class:`CliError` (exit 1) with the install line when matplotlib is missing: before
    any run is evaluated or any file read."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as err:
        from rehabbot.common.extras import missing_module_message

        raise CliError(missing_module_message("plotting", "matplotlib")) from err


def cmd_plot(args: argparse.Namespace) -> int:
    """Run ``rehabbot plot``: write the figures, print each path, return 0."""
    from rehabbot.common.errors import UsageError
    from rehabbot.common.files import check_parent_exists

    check_matplotlib()
    from rehabbot.analysis.plotting import plot_all
    from rehabbot.analysis.traces import TRACE_NAME, find_files, find_traces
    from rehabbot.common.errors import OutputError
    from rehabbot.common.files import check_writable_dir
    from rehabbot.rl.runs import MANIFEST_NAME

    run_dirs = [Path(path) for path in args.run_dirs]
    for path in run_dirs:
        if not path.exists():
            raise CliError(f"{path}: no such file or directory", EXIT_USAGE)
    first = run_dirs[0] if run_dirs[0].is_dir() else run_dirs[0].parent
    if args.out is not None:
        try:
            out_dir = check_parent_exists(args.out, "--out")
        except UsageError as err:
            raise CliError(str(err), EXIT_USAGE) from err
    else:
        out_dir = first / "figures"
    if out_dir.exists() and not out_dir.is_dir():
        raise CliError(f"--out {out_dir}: exists and is not a directory", EXIT_USAGE)
    from rehabbot.deploy.session_log import is_session

    sessions = [path for path in run_dirs if is_session(path)]
    run_dirs = [path for path in run_dirs if path not in sessions]
    try:
        runs_or_traces = [path for path in run_dirs
                          if find_files([path], MANIFEST_NAME) or find_traces([path])]
        if len(runs_or_traces) < len(run_dirs):
            bad = next(path for path in run_dirs if path not in runs_or_traces)
            raise CliError(
                f"{bad}: no training runs ({MANIFEST_NAME}) or evaluated episodes "
                f"({TRACE_NAME}) found there", EXIT_USAGE,
            )
        check_writable_dir(out_dir, "--out folder")  # before any run is evaluated
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            written = plot_all(run_dirs, out_dir, smooth=args.smooth, source=args.source,
                               formats=args.formats, evaluate=args.evaluate,
                               patient=args.patient, dpi=args.dpi,
                               announce=lambda text: print(f"rehabbot plot: {text}",
                                                           flush=True)) if run_dirs else []
            if sessions:
                from rehabbot.analysis.session_figures import plot_session

                for session in sessions:
                    written += plot_session(session, out_dir, args.formats, args.dpi)
    except ImportError as err:
        raise CliError(str(err)) from err
    except ValueError as err:
        raise CliError(str(err), EXIT_FAILURE) from err
    except OutputError as err:  # names the file, says the earlier one is kept
        raise CliError(str(err)) from err
    except OSError as err:
        where = err.filename or out_dir
        raise CliError(f"cannot write {where}: {err.strerror or err}") from err
    for warning in _own_warnings(caught):
        print(f"rehabbot plot: warning: {warning.message}", file=sys.stderr)
    if not written:
        raise CliError(f"nothing to plot under {', '.join(map(str, run_dirs))}", EXIT_USAGE)
    for path in written:
        print(path)
    return EXIT_OK
