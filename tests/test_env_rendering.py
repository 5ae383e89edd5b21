"""Rendering of ``RehabEnv``: the paper's Listing 1 in MuJoCo's viewer (under Xvfb), the
offscreen ``rgb_array`` / ``depth_array`` modes with their overlay (purple tool trace, green
target marker), cameras, and the errors of misuse."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs import overlay
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.tasks.observation import P_STAR

ROOT = Path(__file__).resolve().parents[1]
LISTING_1 = ROOT / "examples" / "listing1_visualize.py"
ENV_ID = "rehabbot/rehab-reach-v0"
CAMERAS = ("overview", "front", "side")

# The paper's Listing 1, as printed.
PRINTED_LISTING_1 = """\
import gymnasium as gym
import rehabbot # registers env IDs

env = gym.make("rehabbot/rehab-reach-v0",
render_mode="human")
obs, info = env.reset(seed=0)

done = False
while not done:
    action = env.action_space.sample()
    obs, reward, terminated, truncated, info = env.step(action)
    done = terminated or truncated
env.close()
"""


# How long a child process may take before a test calls it hung: only a hang guard, far above
# what a child takes on a loaded machine (a 2-core machine running the suite beside a training
# run takes ten times as long as an idle one).
HANG_GUARD_S = 600


def _headless_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    return env


def _xvfb_run() -> list[str]:
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run not on PATH (apt-get install xvfb): cannot open MuJoCo's viewer")
    return ["xvfb-run", "-a"]


def _assert_clean_exit(result: subprocess.CompletedProcess) -> None:
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-3000:]
    assert "Traceback" not in output, output[-3000:]
    assert "Segmentation fault" not in output, output[-3000:]


# --------------------------------------------------------------------------- pixel helpers


def _purple(image: np.ndarray) -> np.ndarray:
    """Pixels of the trace colour (0.55, 0.1, 0.8) under any lighting: B > R > G, B >> G."""
    r, g, b = (image[..., k].astype(int) for k in range(3))
    return (b > r) & (r > g) & (b - g > 60)


def _green(image: np.ndarray) -> np.ndarray:
    """Strongly green pixels (the target marker is (0.1, 0.85, 0.3), alpha 0.6)."""
    r, g, b = (image[..., k].astype(int) for k in range(3))
    return (g > r + 40) & (g > b + 40)


def _project(env: RehabEnv, camera: str, points_world: np.ndarray) -> np.ndarray:
    """Pinhole projection of world points into ``camera``'s image: (n, 2) (column, row)."""
    model, data = env.model, env.data
    cam = model.camera(camera).id
    rot = data.cam_xmat[cam].reshape(3, 3)
    local = (np.atleast_2d(points_world) - data.cam_xpos[cam]) @ rot  # camera looks along -z
    focal_px = 0.5 * env.config.render.height / np.tan(np.radians(model.cam_fovy[cam]) / 2)
    depth = -local[:, 2]
    assert np.all(depth > 0), "point behind the camera"
    return np.column_stack([0.5 * env.config.render.width + focal_px * local[:, 0] / depth,
                            0.5 * env.config.render.height - focal_px * local[:, 1] / depth])


def _pixel_distance(mask: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """For every pixel of ``mask``: distance (px) from its centre to the nearest point."""
    rows, cols = np.nonzero(mask)
    centres = np.column_stack([cols + 0.5, rows + 0.5])
    return np.min(np.linalg.norm(centres[:, None, :] - points_px[None, :, :], axis=-1), axis=1)


# --------------------------------------------------------------------------- Listing 1


def test_listing1_example_is_the_papers_listing_verbatim() -> None:
    source = LISTING_1.read_text()
    assert source.endswith(PRINTED_LISTING_1)
    header = source[: -len(PRINTED_LISTING_1)]
    # Only a docstring and comments precede the listing.
    code_lines = [line for line in header.splitlines()
                  if line.strip() and not line.lstrip().startswith("#")]
    assert code_lines and code_lines[0].startswith('"""') and code_lines[-1].endswith('"""')
    assert "xvfb-run" in header


@pytest.mark.slow
def test_listing1_runs_as_printed_under_xvfb() -> None:
    """The paper's Listing 1, unmodified, opens the viewer and runs one full episode of random
    actions in real time (<= 1000 steps of 20 ms), then closes cleanly."""
    env = _headless_env()
    env.pop("MUJOCO_GL", None)  # as a user runs it: the passive viewer picks GLFW itself
    result = subprocess.run([*_xvfb_run(), sys.executable, str(LISTING_1)], cwd=ROOT,
                            capture_output=True, text=True, timeout=HANG_GUARD_S, env=env)
    _assert_clean_exit(result)


HUMAN_SHORT_EPISODE = """
import threading, time
import numpy as np, gymnasium as gym, rehabbot
from rehabbot.envs import overlay
from rehabbot.rl.experts import ScriptedExpert

real_sleep, slept = time.sleep, []
def counted_sleep(seconds):  # what the pacing sleeps (the viewer's threads sleep too)
    if threading.current_thread() is threading.main_thread():
        slept.append(seconds)
    real_sleep(seconds)
time.sleep = counted_sleep

env = gym.make("rehabbot/rehab-reach-v0", render_mode="human", camera_name="front")
base = env.unwrapped
obs, info = env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
viewer = base._rendering._viewer
assert viewer is not None and viewer.is_running(), "reset() must open the viewer"
print("CAMERA", int(viewer.cam.type), int(viewer.cam.fixedcamid),
      base.model.camera("front").id)
expert = ScriptedExpert(env)
steps = 50
slept.clear()
start = time.perf_counter()
for _ in range(steps):
    obs, reward, terminated, truncated, info = env.step(expert.predict(obs)[0])
elapsed = time.perf_counter() - start
print("ELAPSED", elapsed, steps * base.dt_s)
print("SLEPT", sum(slept))
scn = viewer.user_scn
rgba = np.array([scn.geoms[i].rgba for i in range(scn.ngeom)])
print("TRACE_GEOMS", int(np.sum(np.all(np.isclose(rgba, overlay.TRACE_RGBA), axis=1))))
print("TARGET_GEOMS", int(np.sum(np.all(np.isclose(rgba, overlay.TARGET_RGBA), axis=1))))
threads = set(base._rendering._viewer_threads)
env.close()
env.close()
print("CLOSED", base._rendering._viewer is None, any(t.is_alive() for t in threads))
"""


@pytest.mark.slow
def test_human_mode_shows_overlay_in_viewer_at_real_time() -> None:
    """50 expert steps in the passive viewer (Xvfb): the fixed camera is used, the user scene
    holds the trace and one active target, the loop keeps real time, and close() twice ends
    the viewer's threads."""
    result = subprocess.run([*_xvfb_run(), sys.executable, "-c", HUMAN_SHORT_EPISODE],
                            cwd=ROOT, capture_output=True, text=True, timeout=HANG_GUARD_S,
                            env=_headless_env())
    _assert_clean_exit(result)
    lines = {line.split()[0]: line.split()[1:] for line in result.stdout.splitlines() if line}
    cam_type, cam_id, front_id = map(int, lines["CAMERA"])
    assert cam_type == int(mujoco.mjtCamera.mjCAMERA_FIXED) and cam_id == front_id
    elapsed_s, simulated_s = map(float, lines["ELAPSED"])
    assert elapsed_s >= 0.9 * simulated_s, "human mode must not run faster than real time"
    # ... nor wait longer: it sleeps what is left of each step's dt after the step's work, less
    # than dt a step however loaded the machine (the time the work takes is the machine's).
    slept_s = float(lines["SLEPT"][0])
    assert slept_s < simulated_s, f"slept {slept_s} s in {simulated_s} s of simulated time"
    assert int(lines["TRACE_GEOMS"][0]) >= 40  # one capsule per recorded step (51 points)
    assert int(lines["TARGET_GEOMS"][0]) == 1
    assert lines["CLOSED"] == ["True", "False"]


HUMAN_NO_DISPLAY = """
import gymnasium as gym, rehabbot
env = gym.make("rehabbot/rehab-reach-v0", render_mode="human")
try:
    env.reset(seed=0)
except RuntimeError as err:
    print("RUNTIME_ERROR", err)
else:
    print("NO_ERROR")
env.close()
print("CLOSED")
"""


def test_human_mode_without_display_raises_runtime_error_mentioning_xvfb() -> None:
    result = subprocess.run([sys.executable, "-c", HUMAN_NO_DISPLAY], cwd=ROOT,
                            capture_output=True, text=True, timeout=120, env=_headless_env())
    _assert_clean_exit(result)
    assert "RUNTIME_ERROR" in result.stdout, result.stdout
    assert "xvfb" in result.stdout and "DISPLAY" in result.stdout
    assert "rgb_array" in result.stdout
    assert "CLOSED" in result.stdout


# --------------------------------------------------------------------------- rgb_array


@pytest.mark.parametrize(("width", "height"), [(320, 240), (161, 97)])
def test_rgb_array_is_uint8_of_the_requested_size(width: int, height: int) -> None:
    env = gym.make(ENV_ID, render_mode="rgb_array", width=width, height=height)
    env.reset(seed=0)
    image = env.render()
    env.close()
    assert isinstance(image, np.ndarray)
    assert image.dtype == np.uint8
    assert image.shape == (height, width, 3)
    assert image.std() > 10.0, "the image must show a scene, not a blank buffer"


def test_rgb_frames_are_fresh_arrays_and_deterministic() -> None:
    env = gym.make(ENV_ID, render_mode="rgb_array", width=160, height=120)
    obs, _ = env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    first = env.render()
    kept = first.copy()
    again = env.render()
    # Rendering twice draws the same frame: decorations do not pile up between calls.
    np.testing.assert_array_equal(first, again)
    expert = ScriptedExpert(env)
    for _ in range(30):
        obs, *_ = env.step(expert.predict(obs)[0])
    moved = env.render()
    np.testing.assert_array_equal(first, kept)  # an earlier frame is not overwritten
    assert np.any(moved != first), "the robot moved: the frame must change"
    env.close()


@pytest.fixture(scope="module")
def expert_run():
    """The front camera at 640x480 after 100 scripted-expert steps of exercise 0: the env,
    its last observation, the frame rendered at reset and the tool flange's world positions
    (reset and every step)."""
    env = gym.make(ENV_ID, render_mode="rgb_array", width=640, height=480, camera_name="front")
    base = env.unwrapped
    tool_site = base.handle.tool_site_id
    obs, _ = env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    at_reset = env.render()
    tool_path = [base.data.site_xpos[tool_site].copy()]
    expert = ScriptedExpert(env)
    for _ in range(100):
        obs, _, terminated, truncated, _ = env.step(expert.predict(obs)[0])
        assert not (terminated or truncated)
        tool_path.append(base.data.site_xpos[tool_site].copy())
    yield env, obs, at_reset, np.array(tool_path)
    env.close()


def test_trace_is_drawn_in_purple_along_the_tool_path(expert_run, monkeypatch) -> None:
    env, _, at_reset, tool_path = expert_run
    base = env.unwrapped
    image = env.render()
    purple = _purple(image)
    assert _purple(at_reset).sum() <= 2, "no trace at reset (a single point)"
    assert purple.sum() >= 50, f"only {purple.sum()} trace pixels after 100 steps"
    # The purple pixels come from the overlay, not from the scene ...
    monkeypatch.setattr(overlay, "add_trace", lambda *args, **kwargs: None)
    assert _purple(env.render()).sum() <= 2
    # ... and lie on the projection of the tool flange's path.
    assert np.ptp(tool_path, axis=0).max() > 0.1, "the expert must move the tool"
    distance_px = _pixel_distance(purple, _project(base, "front", tool_path))
    assert np.mean(distance_px < 3.0) > 0.9, np.percentile(distance_px, [50, 90, 100])


def test_active_target_marker_is_drawn_where_the_target_projects(expert_run,
                                                                 monkeypatch) -> None:
    env, obs, _, _ = expert_run
    base = env.unwrapped
    body = base.handle.base_body_id
    # The active target (observation p*, base frame) in world coordinates.
    target_world = base.data.xpos[body] + base.data.xmat[body].reshape(3, 3) @ obs[P_STAR]
    centre_px = _project(base, "front", target_world)[0]
    render = base.config.render
    assert 0 <= centre_px[0] < render.width and 0 <= centre_px[1] < render.height

    def green_near_target(image: np.ndarray) -> int:
        green = _green(image)
        return int(np.sum(_pixel_distance(green, centre_px[None]) < 10.0)) if green.any() else 0

    with_marker = green_near_target(env.render())
    monkeypatch.setattr(overlay, "add_sphere", lambda *args, **kwargs: None)
    without_marker = green_near_target(env.render())
    assert with_marker >= 40, f"{with_marker} green pixels at the active target"
    assert without_marker <= 2


@pytest.mark.slow
def test_cameras_give_different_images() -> None:
    images = {}
    for camera in CAMERAS:
        env = gym.make(ENV_ID, render_mode="rgb_array", width=160, height=120,
                       camera_name=camera)
        env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
        images[camera] = env.render().astype(int)
        env.close()
    for i, a in enumerate(CAMERAS):
        for b in CAMERAS[i + 1:]:
            assert np.abs(images[a] - images[b]).mean() > 5.0, (a, b)
    # The default camera is "overview". Mesa's software rasteriser has, once in CI, shaded a
    # handful of pixels of the same scene differently, so the images are compared by their
    # mean difference (different cameras differ by more than 5 per pixel).
    env = gym.make(ENV_ID, render_mode="rgb_array", width=160, height=120)
    env.reset(seed=0, options={"exercise": 0, "weight_level": 0})
    assert env.unwrapped.config.camera_name == "overview"
    assert np.abs(env.render().astype(int) - images["overview"]).mean() < 0.05
    env.close()


@pytest.mark.parametrize("render_mode", [None, "rgb_array", "human"])
def test_unknown_camera_name_raises_and_lists_valid_names(render_mode) -> None:
    with pytest.raises(ValueError, match="no_such_camera") as err:
        RehabEnv(render_mode=render_mode, camera_name="no_such_camera")
    for camera in CAMERAS:
        assert camera in str(err.value)


# --------------------------------------------------------------------------- depth_array


def test_depth_array_is_metric_distance_from_the_camera() -> None:
    width, height = 81, 61
    env = RehabEnv(render_mode="depth_array", width=width, height=height, camera_name="front")
    env.reset(seed=0)
    depth = env.render()
    assert isinstance(depth, np.ndarray)
    assert depth.shape == (height, width)
    assert np.issubdtype(depth.dtype, np.floating)
    assert np.all(np.isfinite(depth))
    assert depth.min() > 0.05
    model, data = env.model, env.data
    far_m = model.stat.extent * model.vis.map.zfar
    scene = depth < 0.99 * far_m  # pixels that show geometry; the rest is sky at the far plane
    assert scene.mean() > 0.5
    assert depth[scene].max() < 50.0
    np.testing.assert_allclose(depth[~scene], far_m, rtol=0.01)

    # Cast a ray through a grid of pixel centres: the depth image holds the distance along the
    # optical axis to the first visible geom.
    cam = model.camera("front").id
    rot = data.cam_xmat[cam].reshape(3, 3)
    focal_px = 0.5 * height / np.tan(np.radians(model.cam_fovy[cam]) / 2)
    visible_groups = np.array([1, 1, 1, 0, 0, 0], dtype=np.uint8)
    geom_id = np.zeros(1, dtype=np.int32)
    errors_m = []
    for row in range(2, height, 6):
        for col in range(2, width, 6):
            local = np.array([col + 0.5 - 0.5 * width, 0.5 * height - row - 0.5, -focal_px])
            direction = rot @ (local / np.linalg.norm(local))
            hit_m = mujoco.mj_ray(model, data, data.cam_xpos[cam], direction, visible_groups,
                                  1, -1, geom_id)
            if hit_m < 0:
                continue
            along_axis_m = hit_m * focal_px / np.linalg.norm(local)
            errors_m.append(abs(depth[row, col] - along_axis_m))
    errors_m = np.array(errors_m)
    assert len(errors_m) > 50
    assert np.median(errors_m) < 0.01 and np.mean(errors_m < 0.03) > 0.9, errors_m
    env.close()


# --------------------------------------------------------------------------- misuse


def test_render_without_render_mode_warns_and_returns_none() -> None:
    env = RehabEnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    env.close()
    wrapped = gym.make(ENV_ID)
    wrapped.reset(seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert wrapped.render() is None
    assert any("render_mode" in str(w.message) for w in caught)
    wrapped.close()


@pytest.mark.parametrize("render_mode", ["rgb", "Human", "depth", ""])
def test_invalid_render_mode_raises_value_error(render_mode: str) -> None:
    with pytest.raises(ValueError, match="render_mode"):
        RehabEnv(render_mode=render_mode)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Gymnasium warns before the env raises
        with pytest.raises(ValueError, match="render_mode"):
            gym.make(ENV_ID, render_mode=render_mode)


@pytest.mark.parametrize("render_mode", ["rgb_array", "depth_array"])
@pytest.mark.parametrize(("width", "height"), [(2000, 480), (640, 1000), (4096, 4096)])
def test_image_larger_than_offscreen_buffer_raises_value_error(render_mode, width,
                                                               height) -> None:
    with pytest.raises(ValueError, match="offscreen buffer") as err:
        RehabEnv(render_mode=render_mode, width=width, height=height)
    assert f"{width}x{height}" in str(err.value)


@pytest.mark.parametrize("render_mode", ["rgb_array", "depth_array"])
def test_close_twice_is_a_noop_and_render_after_close_raises(render_mode: str) -> None:
    env = gym.make(ENV_ID, render_mode=render_mode, width=64, height=48)
    env.reset(seed=0)
    assert env.render() is not None
    env.close()
    env.close()
    assert env.unwrapped._rendering._renderer is None
    with pytest.raises(RuntimeError, match="close"):
        env.render()
    # Closing an env that never rendered is fine too (no wrappers: Gymnasium's order
    # enforcer would refuse render() before reset()).
    unused = RehabEnv(render_mode=render_mode, width=64, height=48)
    unused.close()
    unused.close()
    with pytest.raises(RuntimeError, match="close"):
        unused.render()
