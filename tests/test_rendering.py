"""Tests for ``rehabbot.rendering`` (offscreen RGB / segmentation / PNG output)."""

from __future__ import annotations

import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from rehabbot.analysis.images import save_png
from rehabbot.envs import rendering
from rehabbot.envs.rendering import (
    BACKGROUND_ID,
    OffscreenRenderer,
    render_rgb,
    render_segmentation,
)

WIDTH_PX, HEIGHT_PX = 160, 120


@pytest.fixture(scope="module")
def box_world() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """A grey floor, a red box in the middle of the 'front' camera's view and a site.

    The site is large and sits in front of the box's left half so that the segmentation
    mapping (sites are not geoms) is exercised.
    """
    spec = mujoco.MjSpec()
    spec.worldbody.add_light(pos=[0.0, -1.0, 3.0], dir=[0.0, 0.3, -1.0])
    spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2.0, 2.0, 0.1],
        rgba=[0.5, 0.5, 0.5, 1.0],
    )
    body = spec.worldbody.add_body(name="box_body", pos=[0.0, 0.0, 0.3])
    body.add_freejoint()
    body.add_geom(
        name="box", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.2, 0.2, 0.2],
        rgba=[0.9, 0.05, 0.05, 1.0],
    )
    spec.worldbody.add_site(
        name="marker", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.08, 0.0, 0.0],
        pos=[-0.1, -0.5, 0.3], rgba=[0.0, 0.0, 1.0, 1.0],
    )
    # Camera 1.6 m in front of the box, looking along +y at the box.
    spec.worldbody.add_camera(
        name="front", pos=[0.0, -1.6, 0.3], xyaxes=[1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    )
    spec.worldbody.add_camera(
        name="top", pos=[0.0, 0.0, 3.0], xyaxes=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def _geom_id(model: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)


def test_rgb_shape_dtype_and_box_in_centre(box_world) -> None:
    model, data = box_world
    image = render_rgb(model, data, "front", width_px=WIDTH_PX, height_px=HEIGHT_PX)
    assert image.shape == (HEIGHT_PX, WIDTH_PX, 3)
    assert image.dtype == np.uint8
    assert image.std() > 5.0, "image is (nearly) uniform: nothing was drawn"
    centre = image[HEIGHT_PX // 2 - 5 : HEIGHT_PX // 2 + 5, WIDTH_PX // 2 - 5 : WIDTH_PX // 2 + 5]
    red, green, blue = (centre[..., c].astype(float).mean() for c in range(3))
    assert red > 2 * green and red > 2 * blue, "red box should fill the image centre"


def test_camera_by_id_equals_camera_by_name(box_world) -> None:
    model, data = box_world
    by_name = render_rgb(model, data, "top", width_px=WIDTH_PX, height_px=HEIGHT_PX)
    by_id = render_rgb(model, data, 1, width_px=WIDTH_PX, height_px=HEIGHT_PX)
    front = render_rgb(model, data, "front", width_px=WIDTH_PX, height_px=HEIGHT_PX)
    np.testing.assert_array_equal(by_name, by_id)
    assert not np.array_equal(by_name, front), "different cameras must give different images"


def test_free_camera_renders_when_camera_is_none(box_world) -> None:
    model, data = box_world
    image = render_rgb(model, data, None, width_px=WIDTH_PX, height_px=HEIGHT_PX)
    assert image.shape == (HEIGHT_PX, WIDTH_PX, 3)
    assert image.std() > 5.0


def test_segmentation_maps_geoms_and_hides_non_geoms(box_world) -> None:
    model, data = box_world
    seg = render_segmentation(model, data, "front", width_px=WIDTH_PX, height_px=HEIGHT_PX)
    assert seg.shape == (HEIGHT_PX, WIDTH_PX)
    assert seg.dtype == np.int32
    box_id, floor_id = _geom_id(model, "box"), _geom_id(model, "floor")
    # Only real geom ids or background may appear: the site must not leak its site id.
    assert set(np.unique(seg)) <= {BACKGROUND_ID, box_id, floor_id}
    assert seg[HEIGHT_PX // 2, WIDTH_PX // 2 + 10] == box_id
    assert (seg == box_id).sum() > 0.05 * seg.size
    assert (seg == floor_id).sum() > 0, "floor is in the lower part of the front view"
    assert (seg == BACKGROUND_ID).sum() > 0, "sky above the horizon is background"


def test_segmentation_agrees_with_rgb(box_world) -> None:
    model, data = box_world
    with OffscreenRenderer(model, width_px=WIDTH_PX, height_px=HEIGHT_PX) as renderer:
        seg = renderer.segmentation(data, "front")
        rgb = renderer.rgb(data, "front")  # segmentation must not stick to the renderer
    box_pixels = rgb[seg == _geom_id(model, "box")].astype(float)
    assert box_pixels.shape[0] > 100
    assert np.median(box_pixels[:, 0]) > 2 * np.median(box_pixels[:, 1])
    # The site occludes part of the box: those pixels are blue in RGB and background in seg.
    site_pixels = (rgb[..., 2].astype(int) > 2 * rgb[..., 0].astype(int) + 30)
    assert site_pixels.sum() > 20
    assert np.all(seg[site_pixels] == BACKGROUND_ID)


def test_segmentation_follows_state(box_world) -> None:
    model, _ = box_world
    data = mujoco.MjData(model)
    data.qpos[0] = 5.0  # move the free box far out of the front camera's view
    mujoco.mj_forward(model, data)
    seg = render_segmentation(model, data, "front", width_px=WIDTH_PX, height_px=HEIGHT_PX)
    assert not np.any(seg == _geom_id(model, "box"))


def test_too_large_image_is_rejected_with_hint(box_world) -> None:
    model, data = box_world
    too_wide = int(model.vis.global_.offwidth) + 1
    with pytest.raises(ValueError, match="offwidth"):
        render_rgb(model, data, "front", width_px=too_wide, height_px=HEIGHT_PX)
    with pytest.raises(ValueError, match="offheight"):
        render_segmentation(
            model, data, "front", width_px=WIDTH_PX,
            height_px=int(model.vis.global_.offheight) + 1,
        )
    with pytest.raises(ValueError, match="positive"):
        render_rgb(model, data, "front", width_px=0, height_px=HEIGHT_PX)


def test_unknown_camera_lists_available(box_world) -> None:
    model, data = box_world
    with pytest.raises(ValueError, match=r"'front', 'top'"):
        render_rgb(model, data, "nope", width_px=WIDTH_PX, height_px=HEIGHT_PX)
    with pytest.raises(ValueError, match="out of range"):
        render_rgb(model, data, 7, width_px=WIDTH_PX, height_px=HEIGHT_PX)


def test_renderer_is_unusable_after_close(box_world) -> None:
    model, data = box_world
    renderer = OffscreenRenderer(model, width_px=WIDTH_PX, height_px=HEIGHT_PX)
    renderer.close()
    renderer.close()  # idempotent
    with pytest.raises(RuntimeError, match="after close"):
        renderer.rgb(data, "front")


def test_save_png_round_trip(tmp_path: Path, box_world) -> None:
    import imageio.v3 as iio

    model, data = box_world
    image = render_rgb(model, data, "front", width_px=WIDTH_PX, height_px=HEIGHT_PX)
    out = save_png(tmp_path / "nested" / "dir" / "front.png", image)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    np.testing.assert_array_equal(iio.imread(out), image)


def test_save_png_rejects_bad_images(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="uint8"):
        save_png(tmp_path / "a.png", np.zeros((4, 4, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="image"):
        save_png(tmp_path / "b.png", np.zeros((4, 4, 2), dtype=np.uint8))


def test_save_png_without_imageio_explains_extra(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "imageio", None)
    monkeypatch.setitem(sys.modules, "imageio.v3", None)
    with pytest.raises(ImportError, match=r'pip install "rehabbot\[video\]"'):
        save_png(tmp_path / "c.png", np.zeros((4, 4, 3), dtype=np.uint8))
    assert not (tmp_path / "c.png").exists()


def test_geom_id_mapping_only_keeps_geom_objects() -> None:
    raw = np.array(
        [[[3, int(mujoco.mjtObj.mjOBJ_GEOM)], [3, int(mujoco.mjtObj.mjOBJ_SITE)]],
         [[-1, -1], [0, int(mujoco.mjtObj.mjOBJ_GEOM)]]],
        dtype=np.int32,
    )
    np.testing.assert_array_equal(
        rendering.geom_ids_from_segmentation(raw), np.array([[3, -1], [-1, 0]])
    )


def test_headless_glfw_backend_gives_actionable_error(box_world, monkeypatch) -> None:
    model, data = box_world
    fake_glfw_context = type("GLContext", (), {"__module__": "mujoco.glfw"})
    monkeypatch.setattr(mujoco, "GLContext", fake_glfw_context)
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert rendering.gl_backend() == "glfw"
    with pytest.raises(RuntimeError, match="MUJOCO_GL=egl"):
        render_rgb(model, data, "front", width_px=WIDTH_PX, height_px=HEIGHT_PX)


# --------------------------------------------------------------------------- scene presets

MIN_PIXELS = 500


@pytest.mark.slow
def test_default_camera_of_every_preset_sees_robot_and_patient() -> None:
    from rehabbot.sim import PRESETS, build_scene

    pixel_counts = {}
    for preset in PRESETS:
        scene = build_scene(preset)
        data = scene.make_data()
        seg = render_segmentation(scene.model, data, scene.camera_names[0], 320, 240)
        pixel_counts[preset] = (
            int(np.isin(seg, scene.robot_geom_ids).sum()),
            int(np.isin(seg, scene.patient_geom_ids).sum()),
        )
    too_few = {
        preset: counts for preset, counts in pixel_counts.items() if min(counts) < MIN_PIXELS
    }
    assert not too_few, f"(robot, patient) pixels below {MIN_PIXELS}: {too_few}"
