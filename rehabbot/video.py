"""A video of one episode: ``rehabbot render MODEL|expert|random --env ENV --out FILE``.

The env renders offscreen (``rgb_array``) with its overlay: the tool's path in purple, the
active target and the upcoming ones. Every ``frame_every``-th decision is kept (default 2: 25
frames per second of simulated time at the paper's 50 Hz), so the video plays in real time.
``.mp4`` is written with imageio's FFmpeg plugin (``imageio-ffmpeg``), ``.gif`` with Pillow;
both come with ``pip install "rehabbot[video]"``. The file is written under a temporary name
and renamed when complete, so an interrupted render leaves no half-written video.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

import numpy as np

VIDEO_SUFFIXES = (".mp4", ".gif")


def render_episode(spec: str, env_id: str | None, out_path: Path, seed: int = 0,
                   width: int = 640, height: int = 480, camera: str | None = "overview",
                   frame_every: int = 2, env_kwargs: dict | None = None,
                   deterministic: bool = True) -> dict:
    """Render one episode of a policy to ``out_path``; return what happened in it."""
    import gymnasium as gym

    import rehabbot  # noqa: F401  (registers the ids)
    from rehabbot.evaluation import env_for
    from rehabbot.policies import load_policy

    out_path = Path(out_path)
    if out_path.suffix.lower() not in VIDEO_SUFFIXES:
        raise ValueError(f"--out {str(out_path)!r}: the file must end in {VIDEO_SUFFIXES}")
    if frame_every < 1:
        raise ValueError(f"frame_every={frame_every!r} must be >= 1")
    env_id, kwargs = env_for(spec, env_id, env_kwargs)
    env = gym.make(env_id, render_mode="rgb_array", width=width, height=height,
                   camera_name=camera, **kwargs)
    frames = []
    try:
        policy = load_policy(spec, env, seed=seed)
        obs, info = env.reset(seed=seed)
        frames.append(env.render())
        steps, total = 0, 0.0
        while True:
            obs, reward, terminated, truncated, info = env.step(policy.act(obs, deterministic))
            steps += 1
            total += float(reward)
            if steps % frame_every == 0 or terminated or truncated:
                frames.append(env.render())
            if terminated or truncated:
                break
        fps = 1.0 / (env.unwrapped.dt_s * frame_every)
    finally:
        env.close()
    write_video(frames, out_path, fps)
    return {"env_id": env_id, "policy": policy.label, "seed": seed, "steps": steps,
            "return": total, "success": bool(info["is_success"]),
            "safety_violation": info["safety_violation"], "frames": len(frames),
            "fps": fps, "path": str(out_path)}


def write_video(frames: list[np.ndarray], out_path: Path, fps: float) -> None:
    """Write RGB frames to ``.mp4`` or ``.gif`` atomically."""
    try:
        import imageio.v2 as imageio
    except ImportError as err:
        raise RuntimeError('writing videos needs imageio: pip install "rehabbot[video]"') from err
    suffix = out_path.suffix.lower()
    out_path.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp = tempfile.mkstemp(dir=out_path.parent, prefix=f".{out_path.stem}.",
                                   suffix=suffix)
    os.close(handle)
    try:
        if suffix == ".mp4":
            try:
                import imageio_ffmpeg  # noqa: F401
            except ImportError as err:
                raise RuntimeError('writing .mp4 needs imageio-ffmpeg: pip install '
                                   '"rehabbot[video]" (or write a .gif)') from err
            with imageio.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                    macro_block_size=8, ffmpeg_log_level="error") as writer:
                for frame in frames:
                    writer.append_data(frame)
        else:
            imageio.mimsave(tmp, frames, format="GIF", duration=1000.0 / fps, loop=0)
        os.replace(tmp, out_path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def add_render_parser(commands: argparse._SubParsersAction) -> None:
    """The ``rehabbot render`` subcommand."""
    parser = commands.add_parser(
        "render", help="render a video of one episode (tool path drawn in purple)",
        description=__doc__.split("\n\n")[0] + "\n\n" + __doc__.split("\n\n")[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
               "  rehabbot render expert --env rehab-reach-v0 --out expert.mp4\n"
               "  rehabbot render runs/rehab-reach-v0/sac/seed0/model.zip --out sac.gif "
               "--width 480 --height 360")
    parser.add_argument("policy", metavar="MODEL|expert|random",
                        help="a model .zip saved by `rehabbot train`, 'expert' or 'random'")
    parser.add_argument("--env", metavar="ENV",
                        help="env id (default: the model's run manifest; required for expert "
                             "and random)")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE.mp4|FILE.gif",
                        help="video file to write")
    parser.add_argument("--seed", type=int, default=0, metavar="S", help="reset seed (0)")
    parser.add_argument("--width", type=int, default=640, metavar="W", help="pixels (640)")
    parser.add_argument("--height", type=int, default=480, metavar="H", help="pixels (480)")
    parser.add_argument("--camera", default="overview",
                        help="overview, front or side (default: overview)")
    parser.add_argument("--frame-every", type=int, default=2, metavar="K",
                        help="keep every K-th decision as a frame (default: 2, 25 fps)")
    parser.add_argument("--env-kwargs", type=json.loads, default=None, metavar="JSON",
                        help="extra RehabEnv keyword arguments")
    parser.set_defaults(func=cmd_render)


def cmd_render(args: argparse.Namespace) -> int:
    from rehabbot.cli import EXIT_USAGE, CliError
    from rehabbot.policies import PolicyError

    try:
        result = render_episode(args.policy, args.env, args.out, args.seed, args.width,
                                args.height, args.camera, args.frame_every, args.env_kwargs)
    except PolicyError as err:
        raise CliError(str(err)) from err
    except ValueError as err:
        raise CliError(str(err), EXIT_USAGE) from err
    except (RuntimeError, OSError) as err:
        raise CliError(str(err)) from err
    outcome = "success" if result["success"] else (result["safety_violation"] or "time limit")
    print(f"wrote {result['path']}: {result['frames']} frames at {result['fps']:.0f} fps, "
          f"{result['policy']} on {result['env_id']} (seed {result['seed']}): "
          f"{result['steps']} steps, return {result['return']:.1f}, {outcome}")
    return 0
