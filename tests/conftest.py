"""Shared pytest configuration.

``MUJOCO_GL`` must be set before ``mujoco`` is first imported: MuJoCo picks its
OpenGL backend at import time. EGL renders offscreen without a display.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
