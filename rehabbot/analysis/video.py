"""A video of one episode (``rehabbot render``): the env renders offscreen with its overlay
(the tool's path in purple, the active target and the upcoming ones), every
``frame_every``-th decision (default 2: 25 frames per second of simulated time at the paper's
50 Hz), so the video plays in real time.

Frames go to the writer as they are rendered, so memory stays flat however long the episode:
``.mp4`` through imageio's FFmpeg plugin (``imageio-ffmpeg``), ``.gif`` through Pillow, which
keeps each frame until the end as a 256-colour image (one byte per pixel). Both come with
``pip install "rehabbot[video]"``.

A GIF gets a palette of its own for each frame by default. ``gif_colors=N`` (``rehabbot
render --gif-colors N``) draws every frame's colours from one palette of ``N`` colours chosen
from the whole episode, without dithering: a pixel that does not change keeps its exact
colour, so Pillow stores only the part of each frame that moved, and a rendered scene's file
is several times smaller. The frames are then kept, zlib-compressed, until the palette is
chosen at the end.

The output path (suffix, folder) is checked before the episode starts. The file is written
under a temporary name, re-opened and its frames counted
(:func:`verify_video`), and renamed only then (usual permissions, ``0666`` minus the umask):
an interrupted render, a full disk or a writer that fails silently leaves no half-written
video and keeps an earlier file of the same name.

Software rendering is slow (minutes for seconds of video), so :func:`render_episode` reports
its progress to a ``progress(frames_done, frames_at_most)`` callback after every frame; the
total is the frames of an episode that runs to the time limit (an episode that ends earlier
has fewer).
"""

from __future__ import annotations

import contextlib
import math
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym

from rehabbot.analysis.quiet import make_env, quiet_known_warnings
from rehabbot.common.errors import UsageError
from rehabbot.common.extras import missing_module_message
from rehabbot.common.files import atomic_save_verified, check_output_file
from rehabbot.rl.policies import env_for, load_policy

VIDEO_SUFFIXES = (".mp4", ".gif")
GIF_COLORS_RANGE = (2, 256)
# The palette of gif_colors is chosen from evenly spaced frames of at most this many pixels.
PALETTE_SAMPLE_PIXELS = 4_000_000


def check_video_path(out_path: Path) -> Path:
    """``out_path`` as a Path; :class:`UsageError` unless it ends in .mp4 or .gif."""
    out_path = Path(out_path)
    if out_path.suffix.lower() not in VIDEO_SUFFIXES:
        raise UsageError(f"--out {str(out_path)!r}: the file must end in "
                         f"{' or '.join(VIDEO_SUFFIXES)}")
    return out_path


def check_gif_colors(gif_colors: int | None, out_path: Path) -> None:
    """:class:`UsageError` unless ``gif_colors`` is None, or an integer in [2, 256] for a
    ``.gif``."""
    if gif_colors is None:
        return
    low, high = GIF_COLORS_RANGE
    if isinstance(gif_colors, bool) or not isinstance(gif_colors, int) \
            or not low <= gif_colors <= high:
        raise UsageError(f"gif_colors={gif_colors!r} must be an integer in [{low}, {high}]")
    if Path(out_path).suffix.lower() != ".gif":
        raise UsageError(f"--gif-colors applies to a .gif, not {str(out_path)!r}")


class _FrameWriter:
    """Appends RGB frames to an ``.mp4`` or ``.gif`` file as they come (with ``gif_colors``:
    keeps them compressed, and writes the GIF with one palette on :meth:`close`)."""

    def __init__(self, path: str, fps: float, gif_colors: int | None = None) -> None:
        self._gif = path.lower().endswith(".gif")
        self._palette_gif = _PaletteGif(path, fps, gif_colors) if gif_colors else None
        if self._palette_gif is not None:
            self._file: Any = self._palette_gif
        elif self._gif:
            iio = _imageio()
            self._file: Any = iio.imopen(path, "w", plugin="pillow")
            self._options = {"duration": 1000.0 / fps, "loop": 0, "bits": 8}
        else:
            _imageio_ffmpeg()
            import imageio.v2 as iio2

            self._file = iio2.get_writer(path, format="FFMPEG", mode="I", fps=fps,
                                         codec="libx264", macro_block_size=8,
                                         ffmpeg_log_level="error")
        self.frames = 0

    def append(self, frame: Any) -> None:
        if self._palette_gif is not None:
            self._palette_gif.append(frame)
        elif self._gif:
            self._file.write(frame, is_batch=False, **self._options)
        else:
            self._file.append_data(frame)
        self.frames += 1

    def close(self) -> None:
        """Finish the file (once; a second call does nothing). Whether closing succeeds or
        fails (a full disk), imageio's writer is disarmed so that its ``__del__`` does not
        try again and print the same error after the command has reported it."""
        file, self._file = self._file, None
        if file is None:
            return
        try:
            file.close()
        finally:
            _disarm(file)

    def abort(self) -> None:
        """Close after a failure, keeping the failure as the error: whatever closing the
        half-written file raises is dropped, and nothing is left for ``__del__`` to do."""
        with contextlib.suppress(Exception):
            self.close()


class _PaletteGif:
    """A GIF whose frames share one palette of ``colors`` colours, chosen from the whole
    episode (median cut over evenly spaced frames, no dithering): the frames are kept
    zlib-compressed until :meth:`close` writes the file through Pillow."""

    def __init__(self, path: str, fps: float, colors: int) -> None:
        _imageio()  # Pillow comes with imageio (rehabbot[video])
        self._path, self._duration_ms, self._colors = path, 1000.0 / fps, colors
        self._frames: list[bytes] = []
        self._shape: tuple[int, ...] = ()

    def append(self, frame: Any) -> None:
        import numpy as np

        array = np.ascontiguousarray(frame, dtype=np.uint8)
        self._shape = array.shape
        self._frames.append(zlib.compress(array.tobytes(), 1))

    def _frame(self, index: int) -> Any:
        import numpy as np

        return np.frombuffer(zlib.decompress(self._frames[index]),
                             dtype=np.uint8).reshape(self._shape)

    def close(self) -> None:
        import numpy as np
        from PIL import Image

        count = len(self._frames)
        if count == 0:
            return
        pixels = int(np.prod(self._shape[:2]))
        sample = np.linspace(0, count - 1, max(1, min(count, PALETTE_SAMPLE_PIXELS // pixels)))
        mosaic = Image.fromarray(np.concatenate([self._frame(int(k)) for k in
                                                 np.unique(sample.round())], axis=0))
        palette = mosaic.quantize(self._colors, method=Image.Quantize.MEDIANCUT,
                                  dither=Image.Dither.NONE)
        frames = (Image.fromarray(self._frame(k)).quantize(palette=palette,
                                                            dither=Image.Dither.NONE)
                  for k in range(count))
        first = next(frames)
        first.save(self._path, format="GIF", save_all=True, append_images=frames,
                   duration=self._duration_ms, loop=0)
        self._frames = []


def _disarm(file: Any) -> None:
    """Make ``file.close`` (which imageio's ``__del__`` calls) do nothing, and drop what a
    failed Pillow save still holds (its pending frames)."""
    with contextlib.suppress(AttributeError, TypeError):
        file.images_to_write = []
    with contextlib.suppress(AttributeError, TypeError):
        file.close = lambda: None


def _imageio() -> Any:
    try:
        import imageio.v3 as iio
    except ImportError as err:
        raise RuntimeError(missing_module_message("writing videos", "imageio")) from err
    return iio


def _imageio_ffmpeg() -> Any:
    _imageio()
    try:
        import imageio_ffmpeg
    except ImportError as err:
        raise RuntimeError(missing_module_message("writing .mp4", "imageio_ffmpeg")
                           + " (or write a .gif)") from err
    return imageio_ffmpeg


def check_video_writer(out_path: Path) -> None:
    """:class:`RuntimeError` now, before an episode is rendered, if the writer of
    ``out_path``'s format is not installed."""
    if Path(out_path).suffix.lower() == ".gif":
        _imageio()
    else:
        _imageio_ffmpeg()


def verify_video(path: Path, frames: int, fps: float) -> None:
    """Re-open a written video and check that it holds ``frames`` frames (a GIF: that every
    frame decodes and the frames last as long as ``frames`` at ``fps``; Pillow merges
    identical neighbours). Raises ValueError (or the reader's error) when it does not."""
    path = Path(path)
    if path.suffix.lower() == ".gif":
        _verify_gif(path, frames, fps)
        return
    try:
        read, _seconds = _imageio_ffmpeg().count_frames_and_secs(str(path))
    except RuntimeError as err:  # FFmpeg's whole banner: keep its last line, the reason
        lines = [line.strip() for line in str(err).splitlines() if line.strip()]
        raise ValueError(f"FFmpeg cannot read it: {lines[-1] if lines else err}") from None
    if read != frames:
        raise ValueError(f"{read} frames read back, {frames} written")


def _verify_gif(path: Path, frames: int, fps: float) -> None:
    from PIL import Image

    total_ms = 0.0
    with Image.open(path) as image:
        count = int(getattr(image, "n_frames", 1))
        for index in range(count):
            image.seek(index)
            image.load()
            total_ms += float(image.info.get("duration", 0))
    expected_ms = frames * 1000.0 / fps
    if not 1 <= count <= frames or abs(total_ms - expected_ms) > 10.0 * frames + 1e-6:
        raise ValueError(f"{count} frames lasting {total_ms:.0f} ms read back, {frames} "
                         f"frames lasting {expected_ms:.0f} ms written")


Progress = Callable[[int, int], None]  # (frames done, frames at most)


def frames_at_most(env: gym.Env, frame_every: int) -> int:
    """The frames of an episode of ``env`` that runs to its time limit (reset frame included)."""
    limit = env.spec.max_episode_steps if env.spec is not None else None
    limit = limit or getattr(env.unwrapped, "max_episode_steps", None) or 1000
    return 1 + math.ceil(int(limit) / frame_every)


def _record_episode(env: gym.Env, policy: Any, writer: _FrameWriter, seed: int,
                    frame_every: int, deterministic: bool,
                    progress: Progress | None = None) -> dict[str, Any]:
    at_most = frames_at_most(env, frame_every)
    obs, info = env.reset(seed=seed)
    writer.append(env.render())
    if progress is not None:
        progress(writer.frames, at_most)
    steps, total = 0, 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, deterministic))
        steps += 1
        total += float(reward)
        if steps % frame_every == 0 or terminated or truncated:
            writer.append(env.render())
            if progress is not None:
                done = terminated or truncated
                progress(writer.frames, writer.frames if done else max(at_most, writer.frames))
        if terminated or truncated:
            return {"steps": steps, "total": total, "info": info}


def render_episode(spec: str, env_id: str | None, out_path: Path, seed: int = 0,
                   width: int = 640, height: int = 480, camera: str | None = "overview",
                   frame_every: int = 2, env_kwargs: dict | None = None,
                   deterministic: bool = True, progress: Progress | None = None,
                   gif_colors: int | None = None) -> dict:
    """Render one episode of a policy to ``out_path`` (.mp4 or .gif); return what happened.
    ``gif_colors`` (a .gif only, 2 to 256): one palette of that many colours for every
    frame, a much smaller file (the module's docstring).

    Every argument and the output path are checked before the episode starts
    (:class:`UsageError`, :class:`OutputError`). The video is written under a temporary
    name, re-opened and its frames counted, then renamed over ``out_path``: a full disk or a
    damaged file raises :class:`OutputError` and leaves an earlier ``out_path`` as it was.
    ``progress`` (optional) is called after every frame with the frames done and the frames
    at most (equal on the last frame).
    """
    out_path = check_output_file(check_video_path(out_path), VIDEO_SUFFIXES, "--out")
    if isinstance(frame_every, bool) or not isinstance(frame_every, int) or frame_every < 1:
        raise UsageError(f"frame_every={frame_every!r} must be an integer >= 1")
    check_gif_colors(gif_colors, out_path)
    check_video_writer(out_path)
    env_id, kwargs = env_for([spec], env_id, env_kwargs)
    env = make_env(env_id, render_mode="rgb_array", width=width, height=height,
                   camera_name=camera, **kwargs)
    result: dict[str, Any] = {}
    try:
        with quiet_known_warnings():
            policy = load_policy(spec, env, seed=seed)
        fps = 1.0 / (env.unwrapped.dt * frame_every)
        out_path.parent.mkdir(parents=True, exist_ok=True)

        def write(tmp: str) -> None:
            writer = _FrameWriter(tmp, fps, gif_colors)
            try:
                result.update(_record_episode(env, policy, writer, seed, frame_every,
                                              deterministic, progress))
            except BaseException:
                writer.abort()
                raise
            writer.close()
            result["frames"] = writer.frames

        atomic_save_verified(out_path, write,
                             lambda tmp: verify_video(tmp, result["frames"], fps))
    finally:
        env.close()
    info = result["info"]
    return {"env_id": env_id, "policy": policy.label, "seed": seed, "steps": result["steps"],
            "return": result["total"], "success": bool(info["is_success"]),
            "safety_violation": info["safety_violation"], "frames": result["frames"],
            "fps": fps, "path": str(out_path)}
