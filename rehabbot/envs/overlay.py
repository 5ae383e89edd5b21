"""Decorations drawn on top of a rendered scene: the tool's path as a purple trace and the
active target as a marker (paper Fig. 3). Works on any ``mujoco.MjvScene``: the offscreen
renderer's scene and the passive viewer's ``user_scn`` alike."""

from __future__ import annotations

import itertools

import mujoco
import numpy as np

TRACE_RGBA = np.array([0.55, 0.1, 0.8, 1.0], dtype=np.float32)  # purple
TARGET_RGBA = np.array([0.1, 0.85, 0.3, 0.6], dtype=np.float32)
UPCOMING_RGBA = np.array([0.1, 0.85, 0.3, 0.18], dtype=np.float32)
TRACE_WIDTH_M = 0.006
TARGET_RADIUS_M = 0.025
MAX_TRACE_SEGMENTS = 400

_IDENTITY = np.eye(3).reshape(9)
_NO_SIZE = np.zeros(3)


def _next_geom(scene: mujoco.MjvScene) -> mujoco.MjvGeom | None:
    if scene.ngeom >= scene.maxgeom:
        return None
    geom = scene.geoms[scene.ngeom]
    scene.ngeom += 1
    return geom


def add_sphere(scene: mujoco.MjvScene, pos: np.ndarray, radius_m: float,
               rgba: np.ndarray) -> None:
    """Append a sphere (no collision, not in the model) to ``scene``."""
    geom = _next_geom(scene)
    if geom is not None:
        mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_SPHERE, np.array([radius_m, 0, 0]),
                            np.asarray(pos, dtype=float), _IDENTITY, rgba)


def add_trace(scene: mujoco.MjvScene, points: np.ndarray, width_m: float = TRACE_WIDTH_M,
              rgba: np.ndarray = TRACE_RGBA, max_segments: int = MAX_TRACE_SEGMENTS) -> None:
    """Append a polyline through ``points`` (n, 3) as capsules, at most ``max_segments``."""
    n = len(points)
    if n < 2:
        return
    stride = max(1, int(np.ceil((n - 1) / max_segments)))
    idx = np.arange(0, n, stride)
    if idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    for a, b in itertools.pairwise(idx):
        geom = _next_geom(scene)
        if geom is None:
            return
        mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, _NO_SIZE, _NO_SIZE,
                            _IDENTITY, rgba)
        mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, width_m,
                             points[a].astype(float), points[b].astype(float))


def draw_task(scene: mujoco.MjvScene, trace_world: np.ndarray, target_world: np.ndarray | None,
              upcoming_world: np.ndarray | None = None) -> None:
    """The tool trace, the active target and (faintly) the upcoming targets."""
    if upcoming_world is not None:
        for pos in upcoming_world:
            add_sphere(scene, pos, 0.6 * TARGET_RADIUS_M, UPCOMING_RGBA)
    if target_world is not None:
        add_sphere(scene, target_world, TARGET_RADIUS_M, TARGET_RGBA)
    add_trace(scene, trace_world)
