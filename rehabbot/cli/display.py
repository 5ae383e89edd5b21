"""Whether a window can be opened, and the headless OpenGL default for offscreen rendering."""

from __future__ import annotations

import os
import sys


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
