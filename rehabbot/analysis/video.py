"""A video of one episode (``rehabbot render``): the env renders offscreen with its overlay
(the tool's path in purple, the active target and the upcoming ones), every
``frame_every``-th decision (default 2: 25 frames per second of simulated time at the paper's
50 Hz), so the video plays in real time.

Frames go to the writer as they are rendered, so memory stays flat however long the episode:
``.mp4`` through imageio's FFmpeg plugin (``imageio-ffmpeg``), ``.gif`` through Pillow, which
keeps each frame until the end as a 256-colour image (one byte per pixel). Both come with
``pip install "rehabbot[video]"``. The file is written under a temporary name and renamed
when complete (usual permissions, ``0666`` minus the umask), so an interrupted render leaves
no half-written video.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym

from rehabbot.common.errors import UsageError
from rehabbot.common.files import atomic_save
from rehabbot.rl.policies import env_for, load_policy

VIDEO_SUFFIXES = (".mp4", ".gif")


def check_video_path(out_path: Path) -> Path:
    """``out_path`` as a Path; :class:`UsageError` unless it ends in .mp4 or .gif."""
    out_path = Path(out_path)
    if out_path.suffix.lower() not in VIDEO_SUFFIXES:
        raise UsageError(f"--out {str(out_path)!r}: the file must end in "
                         f"{' or '.join(VIDEO_SUFFIXES)}")
    return out_path


class _FrameWriter:
    """Appends RGB frames to an ``.mp4`` or ``.gif`` file as they come."""

    def __init__(self, path: str, fps: float) -> None:
        try:
            import imageio.v3 as iio
        except ImportError as err:
            raise RuntimeError('writing videos needs imageio: pip install "rehabbot[video]"'
                               ) from err
        self._gif = path.lower().endswith(".gif")
        if self._gif:
            self._file = iio.imopen(path, "w", plugin="pillow")
            self._options = {"duration": 1000.0 / fps, "loop": 0, "bits": 8}
        else:
            try:
                import imageio_ffmpeg  # noqa: F401
            except ImportError as err:
                raise RuntimeError('writing .mp4 needs imageio-ffmpeg: pip install '
                                   '"rehabbot[video]" (or write a .gif)') from err
            import imageio.v2 as iio2

            self._file = iio2.get_writer(path, format="FFMPEG", mode="I", fps=fps,
                                         codec="libx264", macro_block_size=8,
                                         ffmpeg_log_level="error")
        self.frames = 0

    def append(self, frame: Any) -> None:
        if self._gif:
            self._file.write(frame, is_batch=False, **self._options)
        else:
            self._file.append_data(frame)
        self.frames += 1

    def close(self) -> None:
        self._file.close()


def render_episode(spec: str, env_id: str | None, out_path: Path, seed: int = 0,
                   width: int = 640, height: int = 480, camera: str | None = "overview",
                   frame_every: int = 2, env_kwargs: dict | None = None,
                   deterministic: bool = True) -> dict:
    """Render one episode of a policy to ``out_path`` (.mp4 or .gif); return what happened.

    Every argument is checked before the episode starts (:class:`UsageError`).
    """
    out_path = check_video_path(out_path)
    if isinstance(frame_every, bool) or not isinstance(frame_every, int) or frame_every < 1:
        raise UsageError(f"frame_every={frame_every!r} must be an integer >= 1")
    env_id, kwargs = env_for([spec], env_id, env_kwargs)
    env = gym.make(env_id, render_mode="rgb_array", width=width, height=height,
                   camera_name=camera, **kwargs)
    result: dict[str, Any] = {}
    try:
        policy = load_policy(spec, env, seed=seed)
        fps = 1.0 / (env.unwrapped.dt * frame_every)
        out_path.parent.mkdir(parents=True, exist_ok=True)

        def write(tmp: str) -> None:
            writer = _FrameWriter(tmp, fps)
            try:
                obs, info = env.reset(seed=seed)
                writer.append(env.render())
                steps, total = 0, 0.0
                while True:
                    obs, reward, terminated, truncated, info = env.step(
                        policy.act(obs, deterministic))
                    steps += 1
                    total += float(reward)
                    if steps % frame_every == 0 or terminated or truncated:
                        writer.append(env.render())
                    if terminated or truncated:
                        break
            finally:
                writer.close()
            result.update(steps=steps, total=total, info=info, frames=writer.frames)

        atomic_save(out_path, write)
    finally:
        env.close()
    info = result["info"]
    return {"env_id": env_id, "policy": policy.label, "seed": seed, "steps": result["steps"],
            "return": result["total"], "success": bool(info["is_success"]),
            "safety_violation": info["safety_violation"], "frames": result["frames"],
            "fps": fps, "path": str(out_path)}
