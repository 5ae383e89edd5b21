"""``rehabbot render MODEL|expert|aan|random --out FILE.mp4|.gif``: a video of one episode with
the tool's path in purple and the targets (:mod:`rehabbot.analysis.video`), with a progress
line on stderr (frames done of at most, elapsed, estimated time left)."""

from __future__ import annotations

import argparse
from pathlib import Path

from rehabbot.cli import limits
from rehabbot.cli.errors import (
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    bounded_int,
    cli_command,
    env_kwargs_object,
)

RENDER_KWARGS = ("render_mode", "width", "height", "camera_name")  # set by render itself


def add_render_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``render`` to the ``rehabbot`` subcommands."""
    parser = commands.add_parser(
        "render", help="render a video of one episode (tool path drawn in purple)",
        description="A video of one episode: the tool's path in purple, the active target and "
                    "the upcoming ones. Every --frame-every-th decision becomes a frame "
                    "(default 2: 25 fps, real time at 50 Hz). Frames are streamed to the file: "
                    ".mp4 through FFmpeg (imageio-ffmpeg), .gif through Pillow; both come with "
                    'pip install "rehabbot[video]". The output path is checked before the '
                    "episode starts; the file is written under a temporary name, re-opened "
                    "and its frames counted, and appears only when complete and readable: a "
                    "failure (a full disk) exits 1 and keeps an earlier file of that name. "
                    "Software rendering is slow (minutes for a few seconds of video): a "
                    "progress line on stderr says how many frames are done of at most how "
                    "many, the time elapsed and the time left. Needs pip install "
                    '"rehabbot[video]" (and, for a model zip, the library that trained it: '
                    '"rehabbot[train]" for Stable-Baselines3, "rehabbot[jax]" for SBX).',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
               "  rehabbot render expert --env rehab-reach-v2 --out expert.mp4\n"
               "  rehabbot render zoo:rehab-reach-v1/ppo --out ppo.mp4\n"
               "  rehabbot render runs/rehab-reach-v2/sac/seed0/model.zip --out sac.gif "
               "--width 480 --height 360")
    parser.add_argument("policy", metavar="MODEL|zoo:ENV/ALGO|expert|aan|random",
                        help="a model .zip saved by `rehabbot train`, an agent shipped in the "
                             "zoo (zoo:rehab-reach-v1/ppo), 'expert' (scripted expert), 'aan' "
                             "(assist-as-needed controller) or 'random'")
    parser.add_argument("--env", metavar="ENV",
                        help="env id (default: the model's run manifest or the zoo agent's "
                             "env; required for expert, aan and random)")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE.mp4|FILE.gif",
                        help="video file to write (its folder must exist)")
    parser.add_argument("--seed", type=limits.seed, default=0, metavar="S",
                        help=f"reset seed (default: 0; 0 <= S <= {limits.MAX_SEED})")
    parser.add_argument("--width", type=limits.width_px, default=640, metavar="W",
                        help=f"pixels (default 640, at most {limits.MAX_IMAGE_WIDTH_PX})")
    parser.add_argument("--height", type=limits.height_px, default=480, metavar="H",
                        help=f"pixels (default 480, at most {limits.MAX_IMAGE_HEIGHT_PX})")
    parser.add_argument("--camera", default="overview",
                        help="overview, front or side (default: overview)")
    parser.add_argument("--frame-every", type=limits.frame_every, default=2, metavar="K",
                        help="keep every K-th decision as a frame (default: 2, 25 fps; "
                             f"at most {limits.MAX_FRAME_EVERY})")
    parser.add_argument("--gif-colors", type=bounded_int(2, 256), default=None, metavar="N",
                        help="a .gif with one palette of N colours (2 to 256) for every frame, "
                             "several times smaller (default: a palette per frame)")
    parser.add_argument("--env-kwargs", type=env_kwargs_object, default=None, metavar="JSON",
                        help="extra RehabEnv keyword arguments (not render_mode, width, "
                             "height or camera_name: render sets them)")
    parser.set_defaults(func=cmd_render)


@cli_command
def cmd_render(args: argparse.Namespace) -> int:
    """Run ``rehabbot render``."""
    from rehabbot.cli.needs import policy_modules, require, video_modules
    from rehabbot.common.files import check_parent_exists

    require("rehabbot render", video_modules(args.out), policy_modules(args.policy))
    check_parent_exists(args.out)
    from rehabbot.analysis.video import render_episode
    from rehabbot.cli.progress import ProgressLine
    from rehabbot.cli.threads import one_torch_thread

    taken = [key for key in RENDER_KWARGS if key in (args.env_kwargs or {})]
    if taken:
        raise CliError(f"--env-kwargs: {', '.join(taken)} cannot be given to render (it "
                       "renders rgb_array frames; use --width, --height and --camera)",
                       EXIT_USAGE)
    one_torch_thread([args.policy])
    result = render_episode(args.policy, args.env, args.out, args.seed, args.width,
                            args.height, args.camera, args.frame_every, args.env_kwargs,
                            progress=ProgressLine("rehabbot render"),
                            gif_colors=args.gif_colors)
    outcome = "success" if result["success"] else (result["safety_violation"] or "time limit")
    print(f"wrote {result['path']}: {result['frames']} frames at {result['fps']:.3g} fps, "
          f"{result['policy']} on {result['env_id']} (seed {result['seed']}): "
          f"{result['steps']} steps, return {result['return']:.1f}, {outcome}")
    return EXIT_OK
