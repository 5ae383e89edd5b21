"""``rehabbot scenes``, ``view`` and ``snapshot``: list, look at and render the scene presets
(no env, no task: the robot strapped to the patient at the home state)."""

from __future__ import annotations

import argparse
import math
import threading
import time
import warnings
from typing import TYPE_CHECKING, Any

from rehabbot.cli import limits
from rehabbot.cli.display import has_display
from rehabbot.cli.errors import EXIT_OK, EXIT_USAGE, CliError

if TYPE_CHECKING:
    from rehabbot.sim.scene import Scene

VIEWER_FRAME_RATE_HZ = 60.0
DEFAULT_WIDTH_PX = 640
DEFAULT_HEIGHT_PX = 480


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
    from rehabbot.sim.patient import PatientProfile

    return PatientProfile(**given)


def _load_scene(args: argparse.Namespace) -> Scene:
    """Build the scene named by ``args.scene``; usage errors become :class:`CliError`."""
    from rehabbot.sim import PRESETS, build_scene

    if args.scene not in PRESETS:
        raise CliError(
            f"unknown scene {args.scene!r}; valid scenes: {', '.join(sorted(PRESETS))}",
            EXIT_USAGE,
        )
    try:
        profile = _profile_from_args(args)
        options = {"robot": args.robot, "patient_model": args.patient_model}
        if getattr(args, "menagerie", None) is not None:
            options["menagerie_dir"] = args.menagerie
        return build_scene(args.scene, profile=profile, weight_level=args.weight_level,
                           **options)
    except ValueError as err:
        raise CliError(str(err), EXIT_USAGE) from err


def cmd_scenes(args: argparse.Namespace) -> int:
    """Print every scene preset with its one-line description."""
    from rehabbot.sim import PRESETS

    width = max((len(name) for name in PRESETS), default=0)
    for name, description in PRESETS.items():
        print(f"{name:<{width}}  {description}")
    return EXIT_OK


def cmd_snapshot(args: argparse.Namespace) -> int:
    """Render one offscreen image of a scene and write it as PNG."""
    from rehabbot.cli.needs import GIF_MODULES, require
    from rehabbot.common.errors import UsageError
    from rehabbot.common.files import check_parent_exists

    require("rehabbot snapshot", GIF_MODULES)  # imageio writes the PNG
    try:
        check_parent_exists(args.out)
    except UsageError as err:
        raise CliError(str(err), EXIT_USAGE) from err
    scene = _load_scene(args)
    from rehabbot.analysis.images import save_png
    from rehabbot.envs.rendering import render_rgb

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
    scene = _load_scene(args)
    _check_viewer_can_open()
    if args.seconds is None:
        import mujoco.viewer

        mujoco.viewer.launch(scene.model, scene.make_data())
        return EXIT_OK
    simulated_s, frames = run_passive_viewer(scene, args.seconds)
    print(f"viewed {args.scene}: simulated {simulated_s:.2f} s, {frames} viewer frames")
    return EXIT_OK


def _add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="scene preset (see `rehabbot scenes`)")
    group = parser.add_argument_group("patient profile (defaults: the PatientProfile defaults)")
    group.add_argument("--profile-height", type=limits.library_float("height_m"), metavar="M",
                       help="body height [m] (the range of PatientProfile)")
    group.add_argument("--profile-mass", type=limits.library_float("mass_kg"), metavar="KG",
                       help="body mass [kg] (the range of PatientProfile)")
    group.add_argument("--profile-sex", choices=("male", "female"), help="anthropometric tables")
    parser.add_argument(
        "--weight-level", type=limits.library_int("weight_level"), default=0, metavar="L",
        help="wrist weight level of the exercise (default: 0, no weight)",
    )
    parser.add_argument(
        "--robot", default="ur5e", metavar="NAME",
        help="the robot on each cuff: ur5e (default, the paper's) or fr3 (Franka Research 3)",
    )
    parser.add_argument(
        "--patient-model", choices=("rigid", "myo"), default="rigid",
        help="the patient's body: rigid (default) or myo (MyoSuite's musculoskeletal legs; "
             "hip and knee scenes, default profile; pip install \"rehabbot[myo]\")",
    )
    parser.add_argument(
        "--menagerie", metavar="DIR",
        help="draw the UR5e with the meshes of a local mujoco_menagerie checkout (looks only; "
             "nothing is downloaded)",
    )


def add_scene_parsers(commands: argparse._SubParsersAction) -> None:
    """Add ``scenes``, ``view`` and ``snapshot`` to the ``rehabbot`` subcommands."""
    scenes = commands.add_parser("scenes", help="list the scene presets")
    scenes.set_defaults(func=cmd_scenes)

    view = commands.add_parser("view", help="open the interactive MuJoCo viewer on a scene")
    _add_scene_arguments(view)
    view.add_argument(
        "--seconds", type=limits.view_seconds, metavar="S",
        help="simulate S seconds in real time, then close the viewer and report (0 < S <= "
             f"{limits.MAX_VIEW_SECONDS:g})",
    )
    view.set_defaults(func=cmd_view)

    snapshot = commands.add_parser(
        "snapshot", help="render a scene offscreen to a PNG file",
        description='Render a scene offscreen to a PNG file. Needs pip install "rehabbot[video]" '
                    "(imageio writes the PNG).")
    _add_scene_arguments(snapshot)
    snapshot.add_argument("--out", required=True, metavar="FILE.png",
                          help="output PNG path (its folder must exist)")
    snapshot.add_argument("--camera", help="camera name (default: the scene's first camera)")
    snapshot.add_argument("--width", type=limits.width_px, default=DEFAULT_WIDTH_PX,
                          metavar="W", help=f"image width [px] (default: {DEFAULT_WIDTH_PX}, "
                                            f"at most {limits.MAX_IMAGE_WIDTH_PX})")
    snapshot.add_argument("--height", type=limits.height_px, default=DEFAULT_HEIGHT_PX,
                          metavar="H", help=f"image height [px] (default: {DEFAULT_HEIGHT_PX}, "
                                            f"at most {limits.MAX_IMAGE_HEIGHT_PX})")
    snapshot.set_defaults(func=cmd_snapshot)
