"""Offscreen rendering helpers that work on any ``mujoco.MjModel`` / ``mujoco.MjData``.

The OpenGL backend is chosen by MuJoCo when ``mujoco`` is first imported, from the
``MUJOCO_GL`` environment variable (``egl`` or ``osmesa`` for headless machines,
``glfw`` when a display is available). Set it before importing anything that imports
``mujoco``.

Typical use (:func:`rehabbot.analysis.images.save_png` writes the file)::

    rgb = render_rgb(model, data, camera="front", width_px=640, height_px=480)
    save_png("front.png", rgb)

For several images of the same model, reuse one :class:`OffscreenRenderer` so the
GL context is created only once::

    with OffscreenRenderer(model, width_px=640, height_px=480) as renderer:
        for name in ("front", "side"):
            save_png(f"{name}.png", renderer.rgb(data, name))
"""

from __future__ import annotations

import os
import sys
from types import TracebackType

import mujoco
import numpy as np

CameraSpec = str | int | None
"""A camera: its name, its id, or ``None``/``-1`` for MuJoCo's default free camera."""

BACKGROUND_ID = -1
"""Value used in segmentation images for pixels not covered by any geom."""



def check_offscreen_size(model: mujoco.MjModel, width_px: int, height_px: int) -> None:
    """Raise ``ValueError`` unless ``width_px`` x ``height_px`` fits the offscreen buffer.

    MuJoCo renders offscreen into a framebuffer of ``model.vis.global_.offwidth`` x
    ``model.vis.global_.offheight`` pixels; larger images cannot be rendered.
    """
    if width_px < 1 or height_px < 1:
        raise ValueError(f"image size must be positive, got {width_px}x{height_px} px")
    buffer_width_px = int(model.vis.global_.offwidth)
    buffer_height_px = int(model.vis.global_.offheight)
    if width_px > buffer_width_px or height_px > buffer_height_px:
        raise ValueError(
            f"requested image {width_px}x{height_px} px exceeds the model's offscreen "
            f"buffer {buffer_width_px}x{buffer_height_px} px; render a smaller image or "
            "enlarge the buffer before compiling the model: "
            f"spec.visual.global_.offwidth = {max(width_px, buffer_width_px)}, "
            f"spec.visual.global_.offheight = {max(height_px, buffer_height_px)} "
            '(MJCF: <visual><global offwidth="..." offheight="..."/></visual>)'
        )


def gl_backend() -> str:
    """The OpenGL backend MuJoCo picked at import (``"egl"``, ``"osmesa"``, ``"glfw"``, ...)."""
    context_class = getattr(mujoco, "GLContext", None)
    module = getattr(context_class, "__module__", "") or ""
    return module.rsplit(".", 1)[-1] if module.startswith("mujoco.") else "unknown"


def check_gl_backend() -> None:
    """Raise a clear ``RuntimeError`` if offscreen rendering cannot work in this process.

    The common failure is a headless Linux machine where ``mujoco`` was imported without
    ``MUJOCO_GL`` set, so MuJoCo chose GLFW, which needs a display.
    """
    if (
        sys.platform.startswith("linux")
        and gl_backend() == "glfw"
        and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    ):
        raise RuntimeError(
            "offscreen rendering needs a display with MuJoCo's GLFW backend, and there is "
            "none; set MUJOCO_GL=egl (or osmesa) in the environment before Python starts"
        )


def camera_names(model: mujoco.MjModel) -> tuple[str, ...]:
    """Names of the model's cameras in id order (unnamed cameras give ``""``)."""
    return tuple(model.camera(i).name for i in range(model.ncam))


def resolve_camera(model: mujoco.MjModel, camera: CameraSpec) -> int:
    """Turn a camera name/id/``None`` into a camera id (``-1`` = default free camera).

    Raises:
        ValueError: if the name is unknown or the id is out of range; the message
            lists the model's cameras.
    """
    if camera is None:
        return -1
    if isinstance(camera, str):
        camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if camera_id < 0:
            raise ValueError(
                f"unknown camera {camera!r}; available cameras: "
                f"{', '.join(repr(n) for n in camera_names(model)) or '(none)'}"
            )
        return int(camera_id)
    camera_id = int(camera)
    if not -1 <= camera_id < model.ncam:
        raise ValueError(
            f"camera id {camera_id} out of range; model has {model.ncam} camera(s) "
            "(use -1 or None for the free camera)"
        )
    return camera_id


def geom_ids_from_segmentation(segmentation: np.ndarray) -> np.ndarray:
    """Map MuJoCo's ``(H, W, 2)`` ``(objid, objtype)`` image to ``(H, W)`` geom ids.

    Pixels showing anything other than a geom (background, sites, tendons, ...)
    become :data:`BACKGROUND_ID`.
    """
    if segmentation.ndim != 3 or segmentation.shape[2] != 2:
        raise ValueError(f"expected an (H, W, 2) segmentation image, got {segmentation.shape}")
    object_ids = segmentation[..., 0]
    object_types = segmentation[..., 1]
    is_geom = object_types == int(mujoco.mjtObj.mjOBJ_GEOM)
    return np.where(is_geom, object_ids, BACKGROUND_ID).astype(np.int32)


class OffscreenRenderer:
    """A reusable offscreen renderer for one model and one image size.

    Wraps :class:`mujoco.Renderer`; use it as a context manager (or call
    :meth:`close`) so the GL context is released deterministically.

    Raises:
        ValueError: if the image does not fit the model's offscreen buffer.
        RuntimeError: if no OpenGL context can be created (see :func:`check_gl_backend`).
    """

    def __init__(self, model: mujoco.MjModel, width_px: int = 640, height_px: int = 480) -> None:
        check_offscreen_size(model, width_px, height_px)
        check_gl_backend()
        self.model = model
        self.width_px = width_px
        self.height_px = height_px
        self._renderer: mujoco.Renderer | None = mujoco.Renderer(
            model, height=height_px, width=width_px
        )

    def _active(self) -> mujoco.Renderer:
        if self._renderer is None:
            raise RuntimeError("OffscreenRenderer used after close()")
        return self._renderer

    def rgb(self, data: mujoco.MjData, camera: CameraSpec = None) -> np.ndarray:
        """Render a colour image, shape ``(height_px, width_px, 3)``, dtype ``uint8``."""
        renderer = self._active()
        renderer.disable_segmentation_rendering()
        renderer.update_scene(data, camera=resolve_camera(self.model, camera))
        return np.asarray(renderer.render(), dtype=np.uint8)

    def segmentation(self, data: mujoco.MjData, camera: CameraSpec = None) -> np.ndarray:
        """Render geom ids per pixel, shape ``(height_px, width_px)``, dtype ``int32``.

        Background and non-geom objects are :data:`BACKGROUND_ID` (``-1``).
        """
        renderer = self._active()
        renderer.enable_segmentation_rendering()
        try:
            renderer.update_scene(data, camera=resolve_camera(self.model, camera))
            raw = renderer.render()
        finally:
            renderer.disable_segmentation_rendering()
        return geom_ids_from_segmentation(raw)

    def close(self) -> None:
        """Release the GL context; safe to call more than once."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def render_rgb(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    camera: CameraSpec = None,
    width_px: int = 640,
    height_px: int = 480,
) -> np.ndarray:
    """Render one colour image ``(height_px, width_px, 3)`` ``uint8`` from ``camera``."""
    with OffscreenRenderer(model, width_px=width_px, height_px=height_px) as renderer:
        return renderer.rgb(data, camera)


def render_segmentation(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    camera: CameraSpec = None,
    width_px: int = 640,
    height_px: int = 480,
) -> np.ndarray:
    """Render one ``(height_px, width_px)`` ``int32`` image of geom ids (``-1`` = none)."""
    with OffscreenRenderer(model, width_px=width_px, height_px=height_px) as renderer:
        return renderer.segmentation(data, camera)
