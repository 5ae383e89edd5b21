"""Rendering of a RehabEnv: offscreen RGB and depth images, MuJoCo's passive viewer for
``render_mode="human"``, and the overlay of the paper's Fig. 3 (the tool's path in purple,
the active target, the upcoming targets faintly).

The env owns one :class:`EnvRendering`; it records the tool's path only when a render mode is
set, so that an env that never renders does no rendering work per step.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import mujoco
import numpy as np

from rehabbot.envs import overlay


class EnvRendering:
    """Renderer, viewer and tool trace of one env."""

    def __init__(self, model: mujoco.MjModel, render_mode: str | None, width: int,
                 height: int, camera_name: str | None, max_steps: int, dt_s: float,
                 base_pos: np.ndarray, base_rot: np.ndarray) -> None:
        self.model = model
        self.render_mode = render_mode
        self.width, self.height = width, height
        self.camera_name = camera_name
        self.dt_s = dt_s
        self.base_pos, self.base_rot = base_pos, base_rot
        self.trace = np.zeros((max_steps + 1, 3))
        self.trace_len = 0
        self._renderer: mujoco.Renderer | None = None
        self._viewer = None
        self._viewer_threads: set[threading.Thread] = set()
        self._last_frame_s = 0.0
        if render_mode in ("rgb_array", "depth_array"):
            from rehabbot.envs.rendering import check_offscreen_size

            check_offscreen_size(model, width, height)

    # -- the tool's path -------------------------------------------------------------------
    def clear_trace(self) -> None:
        self.trace_len = 0

    def record(self, tool_world_m: np.ndarray) -> None:
        """Append the tool's position (world frame) to the trace (a sliding window)."""
        if self.trace_len >= len(self.trace):
            self.trace[:-1] = self.trace[1:]
            self.trace_len = len(self.trace) - 1
        self.trace[self.trace_len] = tool_world_m
        self.trace_len += 1

    def decorate(self, scene: mujoco.MjvScene, targets_base_m: np.ndarray, index: int) -> None:
        """Draw the trace, the active target ``index`` and the upcoming ones into ``scene``."""
        world = self.base_pos + targets_base_m @ self.base_rot.T
        upcoming = world[index + 1:]
        overlay.draw_task(scene, self.trace[:self.trace_len], world[index],
                          upcoming if len(upcoming) else None)

    # -- images ----------------------------------------------------------------------------
    def offscreen(self, data: mujoco.MjData, depth: bool, targets_base_m: np.ndarray,
                  index: int) -> np.ndarray:
        if self._renderer is None:
            from rehabbot.envs.rendering import check_gl_backend

            check_gl_backend()  # a clear error on a headless machine without MUJOCO_GL=egl
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
        renderer = self._renderer
        camera = -1 if self.camera_name is None else self.camera_name
        renderer.update_scene(data, camera)
        if depth:
            renderer.enable_depth_rendering()
            image = renderer.render()
            renderer.disable_depth_rendering()
            return image
        self.decorate(renderer.scene, targets_base_m, index)
        return renderer.render()

    def human(self, data: mujoco.MjData, targets_base_m: np.ndarray, index: int) -> None:
        if self._viewer is None:
            import mujoco.viewer

            if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                         or os.environ.get("WAYLAND_DISPLAY")):
                raise RuntimeError("render_mode='human' opens MuJoCo's viewer, which needs a "
                                   "display (DISPLAY is not set); use render_mode='rgb_array' "
                                   "on a headless machine, or run under xvfb-run (Gymnasium's "
                                   "check_env: pass skip_render_check=True)")
            before = set(threading.enumerate())
            self._viewer = mujoco.viewer.launch_passive(self.model, data, show_left_ui=False,
                                                        show_right_ui=False)
            self._viewer_threads = set(threading.enumerate()) - before
            if self.camera_name is not None:
                self._viewer.cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
                self._viewer.cam.fixedcamid = self.model.camera(self.camera_name).id
            self._last_frame_s = time.perf_counter()
        viewer = self._viewer
        if not viewer.is_running():
            return
        with viewer.lock():
            viewer.user_scn.ngeom = 0
            self.decorate(viewer.user_scn, targets_base_m, index)
        viewer.sync()
        # Keep to real time: one decision per dt.
        idle_s = self.dt_s - (time.perf_counter() - self._last_frame_s)
        if idle_s > 0:
            time.sleep(idle_s)
        self._last_frame_s = time.perf_counter()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
            for thread in self._viewer_threads:
                if thread is not threading.current_thread():
                    thread.join(10.0)
            self._viewer_threads = set()

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_renderer"] = None
        state["_viewer"] = None
        state["_viewer_threads"] = set()
        return state
