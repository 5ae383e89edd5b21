"""The ``rehabbot`` command line: train, evaluate, plot and render policies on the registered
environments; list, view and snapshot the simulation scenes.

Examples::

    rehabbot list                                  # the registered env ids
    rehabbot train rehab-reach-v0 --algo sac --timesteps 200000 --seeds 0 1 2
    rehabbot evaluate runs/rehab-reach-v0/sac/seed0/model.zip expert random
    rehabbot plot runs/rehab-reach-v0               # Figs. 3-6 of the paper for your runs
    rehabbot render expert --env rehab-reach-v0 --out expert.mp4
    rehabbot bench                                 # env step throughput vs raw physics
    rehabbot scenes
    rehabbot view upper_right                      # interactive, until the window is closed
    rehabbot view upper_right --seconds 5          # step 5 s of physics in real time, then exit
    rehabbot snapshot upper_right --out front.png --width 1280 --height 720
    rehabbot snapshot upper_right --out tall.png --profile-height 1.95 --profile-mass 95
    rehabbot view upper_right --menagerie ~/mujoco_menagerie   # real UR5e meshes (optional)

Exit codes: 0 success, 1 runtime failure (no display, unwritable file, missing optional
dependency, corrupt model), 2 bad usage (unknown env id, algorithm, scene or camera, invalid
patient profile, image too large), 130 training interrupted (a checkpoint was saved).

Heavy imports (``mujoco``, Stable-Baselines3, matplotlib) happen inside the command functions
so that ``rehabbot --help`` stays fast.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import threading
import time
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rehabbot.models.scene import Scene

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2

VIEWER_FRAME_RATE_HZ = 60.0
DEFAULT_WIDTH_PX = 640
DEFAULT_HEIGHT_PX = 480


class CliError(Exception):
    """An error reported to the user as one line, with an exit code."""

    def __init__(self, message: str, exit_code: int = EXIT_FAILURE) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def has_display() -> bool:
    """Whether a window can be opened: always off Linux, else DISPLAY/WAYLAND_DISPLAY set."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def use_headless_gl_by_default() -> None:
    """Pick EGL for offscreen rendering on a Linux machine without a display.

    Only takes effect if ``MUJOCO_GL`` is unset and ``mujoco`` has not been imported yet
    (MuJoCo chooses its OpenGL backend at import time).
    """
    if not has_display() and "mujoco" not in sys.modules:
        os.environ.setdefault("MUJOCO_GL", "egl")


# --------------------------------------------------------------------------- scene loading


def _profile_from_args(args: argparse.Namespace) -> Any:
    """A ``PatientProfile`` from the ``--profile-*`` flags, or ``None`` if none were given."""
    given = {
        "height_m": args.profile_height,
        "mass_kg": args.profile_mass,
        "sex": args.profile_sex,
    }
    given = {key: value for key, value in given.items() if value is not None}
    if not given:
        return None
    from rehabbot.models import PatientProfile

    return PatientProfile(**given)


def _load_scene(args: argparse.Namespace) -> Scene:
    """Build the scene named by ``args.scene``; usage errors become :class:`CliError`."""
    from rehabbot.models import PRESETS, build_scene

    if args.scene not in PRESETS:
        raise CliError(
            f"unknown scene {args.scene!r}; valid scenes: {', '.join(sorted(PRESETS))}",
            EXIT_USAGE,
        )
    try:
        profile = _profile_from_args(args)
        options = {}
        if getattr(args, "menagerie", None) is not None:
            options["menagerie_dir"] = args.menagerie
        return build_scene(args.scene, profile=profile, weight_level=args.weight_level,
                           **options)
    except ValueError as err:
        raise CliError(str(err), EXIT_USAGE) from err


# --------------------------------------------------------------------------- commands


def cmd_scenes(args: argparse.Namespace) -> int:
    """Print every scene preset with its one-line description."""
    from rehabbot.models import PRESETS

    width = max((len(name) for name in PRESETS), default=0)
    for name, description in PRESETS.items():
        print(f"{name:<{width}}  {description}")
    return EXIT_OK


def cmd_snapshot(args: argparse.Namespace) -> int:
    """Render one offscreen image of a scene and write it as PNG."""
    scene = _load_scene(args)
    from rehabbot.rendering import render_rgb, save_png

    camera = args.camera
    if camera is None and scene.camera_names:
        camera = scene.camera_names[0]
    data = scene.make_data()
    try:
        image = render_rgb(
            scene.model, data, camera, width_px=args.width, height_px=args.height
        )
    except ValueError as err:
        raise CliError(str(err), EXIT_USAGE) from err
    except RuntimeError as err:
        raise CliError(f"rendering failed: {err}") from err
    try:
        path = save_png(args.out, image)
    except ImportError as err:
        raise CliError(str(err)) from err
    except OSError as err:
        raise CliError(f"cannot write {args.out}: {err.strerror or err}") from err
    print(path)
    return EXIT_OK


def _check_viewer_can_open() -> None:
    """Fail fast (instead of hanging in the viewer thread) when no window can be opened."""
    if not has_display():
        raise CliError(
            "no display found (DISPLAY/WAYLAND_DISPLAY unset); run on a desktop session "
            "or under a virtual display, e.g. `xvfb-run -a rehabbot view ...`"
        )
    try:
        import glfw
    except ImportError as err:
        raise CliError(f"the viewer needs the 'glfw' package: {err}") from err
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ok = glfw.init()
    if not ok:
        reason = "; ".join(str(w.message) for w in caught) or "unknown reason"
        raise CliError(f"cannot open a window (GLFW init failed: {reason})")
    glfw.terminate()


def run_passive_viewer(scene: Scene, seconds: float) -> tuple[float, int]:
    """Step ``seconds`` of physics in real time while showing it in a passive viewer.

    Returns:
        (simulated time [s], number of viewer frames synced). Stops early if the user
        closes the window.
    """
    import mujoco
    import mujoco.viewer

    model = scene.model
    data = scene.make_data()
    timestep_s = float(model.opt.timestep)
    total_steps = math.ceil(seconds / timestep_s - 1e-9)
    frame_period_s = 1.0 / VIEWER_FRAME_RATE_HZ
    start_time_s = float(data.time)
    steps_done = 0
    frames = 0
    threads_before = set(threading.enumerate())
    try:
        with mujoco.viewer.launch_passive(model, data) as viewer:
            wall_start_s = time.perf_counter()
            while steps_done < total_steps and viewer.is_running():
                frame_start_s = time.perf_counter()
                # Keep simulated time one step ahead of wall-clock time since the start.
                elapsed_steps = int((frame_start_s - wall_start_s) / timestep_s) + 1
                due_steps = min(total_steps, elapsed_steps)
                with viewer.lock():
                    while steps_done < due_steps:
                        mujoco.mj_step(model, data)
                        steps_done += 1
                viewer.sync()
                frames += 1
                idle_s = frame_period_s - (time.perf_counter() - frame_start_s)
                if idle_s > 0 and steps_done < total_steps:
                    time.sleep(idle_s)
    finally:
        _join_viewer_threads(threads_before)
    return float(data.time) - start_time_s, frames


def _join_viewer_threads(threads_before: set[threading.Thread], timeout_s: float = 10.0) -> None:
    """Wait for the viewer's render thread to finish tearing down after ``close()``.

    ``Handle.close()`` only *requests* the exit; if the interpreter shuts down while the
    (daemon) render thread is still releasing its OpenGL resources, the process can crash.
    """
    for thread in set(threading.enumerate()) - threads_before:
        if thread is not threading.current_thread():
            thread.join(timeout_s)


def cmd_view(args: argparse.Namespace) -> int:
    """Open MuJoCo's interactive viewer on a scene."""
    if args.seconds is not None and not args.seconds > 0:
        raise CliError(f"--seconds must be positive, got {args.seconds}", EXIT_USAGE)
    scene = _load_scene(args)
    _check_viewer_can_open()
    if args.seconds is None:
        import mujoco.viewer

        mujoco.viewer.launch(scene.model, scene.make_data())
        return EXIT_OK
    simulated_s, frames = run_passive_viewer(scene, args.seconds)
    print(f"viewed {args.scene}: simulated {simulated_s:.2f} s, {frames} viewer frames")
    return EXIT_OK


def cmd_list(args: argparse.Namespace) -> int:
    """Print the registered env ids with their limb, task, spaces and description (each env
    is built once, so the spaces shown are the real ones)."""
    import gymnasium as gym

    import rehabbot  # noqa: F401  (registers the ids)
    from rehabbot.registration import ENV_SPECS

    rows = [("id", "limb", "side", "task", "action", "observation", "description")]
    for env_id, (kwargs, description) in ENV_SPECS.items():
        env = gym.make(env_id)
        act, obs = env.action_space, env.observation_space
        env.close()
        rows.append((env_id, kwargs["limb"], kwargs["side"], kwargs["task_type"],
                     f"Box({float(act.low[0]):.5f}, {float(act.high[0]):.5f}, {act.shape})",
                     f"Box({obs.shape})", description))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]) - 1)]
    for row in rows:
        cells = [cell.ljust(width) for cell, width in zip(row[:-1], widths, strict=True)]
        print("  ".join([*cells, row[-1]]))
    return EXIT_OK


def cmd_bench(args: argparse.Namespace) -> int:
    """The env step throughput table (:mod:`rehabbot.throughput`)."""
    from rehabbot import throughput

    argv = sys.argv[2:] if len(sys.argv) > 1 and sys.argv[1] == "bench" else []
    code = throughput.run(args, argv)
    if code != EXIT_OK:
        raise CliError("bad benchmark options (see above)", EXIT_USAGE)
    return code


# --------------------------------------------------------------------------- parser


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def _add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="scene preset (see `rehabbot scenes`)")
    group = parser.add_argument_group("patient profile (defaults: the PatientProfile defaults)")
    group.add_argument("--profile-height", type=float, metavar="M", help="body height [m]")
    group.add_argument("--profile-mass", type=float, metavar="KG", help="body mass [kg]")
    group.add_argument("--profile-sex", choices=("male", "female"), help="anthropometric tables")
    parser.add_argument(
        "--weight-level", type=int, default=0, metavar="L",
        help="wrist weight level of the exercise (default: 0, no weight)",
    )
    parser.add_argument(
        "--menagerie", metavar="DIR",
        help="draw the UR5e with the meshes of a local mujoco_menagerie checkout (looks only; "
             "nothing is downloaded)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``rehabbot`` command."""
    parser = argparse.ArgumentParser(
        prog="rehabbot",
        description="RehabBot: a UR5e strapped to a humanoid patient, simulated in MuJoCo. "
                    "Train, evaluate, plot and render RL agents on its therapy exercises.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="a typical session:\n"
               "  rehabbot list\n"
               "  rehabbot train rehab-reach-v0 --algo sac --hyperparams hyperparams/sac.yml "
               "--seeds 0 1 2\n"
               "  rehabbot evaluate runs/rehab-reach-v0/sac/seed0/model.zip expert random\n"
               "  rehabbot plot runs/rehab-reach-v0\n"
               "  rehabbot render runs/rehab-reach-v0/sac/seed0/model.zip --out sac.mp4\n\n"
               "`rehabbot COMMAND --help` describes each command. Exit codes: 0 success, "
               "1 failure, 2 bad usage, 130/143 training interrupted (resumable).",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    from rehabbot.evaluation import add_evaluate_parser
    from rehabbot.plotting import add_plot_parser
    from rehabbot.throughput import add_arguments as add_bench_arguments
    from rehabbot.training import add_train_parser
    from rehabbot.video import add_render_parser

    listing = commands.add_parser("list", help="list the registered env ids")
    listing.set_defaults(func=cmd_list)
    add_train_parser(commands)
    add_evaluate_parser(commands)
    add_plot_parser(commands)
    add_render_parser(commands)
    bench = commands.add_parser(
        "bench", help="env step throughput of every id against the raw physics",
        description="Steps every registered id through gym.make and the same mj_step calls "
                    "on its model, interleaved; prints steps/s and the share of time in "
                    "physics.")
    add_bench_arguments(bench)
    bench.set_defaults(func=cmd_bench)

    scenes = commands.add_parser("scenes", help="list the scene presets")
    scenes.set_defaults(func=cmd_scenes)

    view = commands.add_parser("view", help="open the interactive MuJoCo viewer on a scene")
    _add_scene_arguments(view)
    view.add_argument(
        "--seconds", type=float, metavar="S",
        help="simulate S seconds in real time, then close the viewer and report",
    )
    view.set_defaults(func=cmd_view)

    snapshot = commands.add_parser("snapshot", help="render a scene offscreen to a PNG file")
    _add_scene_arguments(snapshot)
    snapshot.add_argument("--out", required=True, metavar="FILE.png", help="output PNG path")
    snapshot.add_argument("--camera", help="camera name (default: the scene's first camera)")
    snapshot.add_argument("--width", type=_positive_int, default=DEFAULT_WIDTH_PX, metavar="W",
                          help=f"image width [px] (default: {DEFAULT_WIDTH_PX})")
    snapshot.add_argument("--height", type=_positive_int, default=DEFAULT_HEIGHT_PX,
                          metavar="H", help=f"image height [px] (default: {DEFAULT_HEIGHT_PX})")
    snapshot.set_defaults(func=cmd_snapshot)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``rehabbot`` command; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    use_headless_gl_by_default()
    try:
        return int(args.func(args))
    except CliError as err:
        one_line = " ".join(str(err).split())
        print(f"rehabbot: error: {one_line}", file=sys.stderr)
        return err.exit_code


if __name__ == "__main__":
    sys.exit(main())
