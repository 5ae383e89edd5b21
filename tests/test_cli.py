"""Tests for the ``rehabbot`` command line (``rehabbot.cli``)."""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from rehabbot.cli import main
from rehabbot.cli.scenes import VIEWER_FRAME_RATE_HZ

imageio = pytest.importorskip("imageio.v3", reason='snapshot tests need "rehabbot[video]"')

SCENE = "upper_right"
WIDTH_PX, HEIGHT_PX = 200, 150


@pytest.fixture(scope="module")
def presets() -> dict[str, str]:
    from rehabbot.sim import PRESETS

    return dict(PRESETS)


def _snapshot(tmp_path: Path, name: str, *extra: str) -> Path:
    out = tmp_path / name
    code = main(
        ["snapshot", SCENE, "--out", str(out), "--width", str(WIDTH_PX),
         "--height", str(HEIGHT_PX), *extra]
    )
    assert code == 0
    return out


# --------------------------------------------------------------------------- help / scenes


def test_help_does_not_import_scene_builders() -> None:
    code = (
        "import sys\n"
        "from rehabbot.cli import main\n"
        "try:\n"
        "    main(['--help'])\n"
        "except SystemExit as exc:\n"
        "    assert exc.code == 0\n"
        "heavy = [m for m in ('rehabbot.sim.scene', 'rehabbot.envs.rendering', 'mujoco',\n"
        "                     'torch', 'matplotlib') if m in sys.modules]\n"
        "print('HEAVY', heavy)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=True
    )
    assert "snapshot" in result.stdout and "view" in result.stdout
    assert "HEAVY []" in result.stdout


def test_scenes_lists_every_preset_with_description(capsys, presets) -> None:
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(presets)
    for line, (name, description) in zip(lines, presets.items(), strict=True):
        assert line.split()[0] == name
        assert line.rstrip().endswith(description)


def test_missing_command_is_a_usage_error(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main([])
    assert exc.value.code == 2


# --------------------------------------------------------------------------- snapshot


def test_snapshot_writes_png_of_requested_size(tmp_path: Path, capsys) -> None:
    out = _snapshot(tmp_path, "shot.png")
    assert capsys.readouterr().out.strip() == str(out)
    image = imageio.imread(out)
    assert image.shape[:2] == (HEIGHT_PX, WIDTH_PX)
    assert image.dtype == np.uint8
    # Not uniform: many distinct colours and real contrast.
    assert image[..., :3].std() > 10.0
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) > 50


@pytest.mark.slow
def test_snapshot_cameras_differ(tmp_path: Path) -> None:
    from rehabbot.sim import build_scene

    cameras = build_scene(SCENE).camera_names
    assert cameras, "scene must define at least one camera"
    default = imageio.imread(_snapshot(tmp_path, "default.png"))
    first = imageio.imread(_snapshot(tmp_path, "first.png", "--camera", cameras[0]))
    np.testing.assert_array_equal(default, first)  # the first camera is the default
    if len(cameras) > 1:
        other = imageio.imread(_snapshot(tmp_path, "other.png", "--camera", cameras[1]))
        assert np.abs(other.astype(int) - default.astype(int)).mean() > 5.0


def test_snapshot_profile_flags_change_the_patient(tmp_path: Path) -> None:
    default = imageio.imread(_snapshot(tmp_path, "default.png"))
    tall = imageio.imread(
        _snapshot(tmp_path, "tall.png", "--profile-height", "1.95", "--profile-mass", "100")
    )
    changed = np.any(default != tall, axis=-1).mean()
    assert changed > 0.01, "a much bigger patient must look different"


def test_unknown_scene_exits_2_and_lists_presets(tmp_path: Path, capsys, presets) -> None:
    code = main(["snapshot", "no_such_scene", "--out", str(tmp_path / "x.png")])
    assert code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "no_such_scene" in err
    for name in presets:
        assert name in err
    assert not (tmp_path / "x.png").exists()


def test_unknown_camera_exits_2_and_lists_cameras(tmp_path: Path, capsys) -> None:
    code = main(["snapshot", SCENE, "--out", str(tmp_path / "x.png"), "--camera", "nope"])
    assert code == 2
    err = capsys.readouterr().err
    from rehabbot.sim import build_scene

    for camera in build_scene(SCENE).camera_names:
        assert camera in err
    assert not (tmp_path / "x.png").exists()


def _usage_error(argv: list[str], capsys) -> str:
    """``main(argv)`` refused by argparse (exit 2); its one-line message."""
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


def test_image_larger_than_offscreen_buffer_is_a_usage_error(tmp_path: Path, capsys) -> None:
    err = _usage_error(["snapshot", SCENE, "--out", str(tmp_path / "x.png"), "--width",
                        "100000"], capsys)
    assert "--width" in err and "1,280" in err and "'100000'" in err


def test_invalid_profile_is_a_usage_error(tmp_path: Path, capsys) -> None:
    err = _usage_error(["snapshot", SCENE, "--out", str(tmp_path / "x.png"),
                        "--profile-height", "9"], capsys)
    assert "--profile-height" in err and "[1.2, 2.2]" in err


def test_an_out_below_a_file_is_a_usage_error_with_one_line(tmp_path: Path, capsys) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    code = main(["snapshot", SCENE, "--out", str(blocker / "shot.png"), "--width", "64",
                 "--height", "48"])
    assert code == 2
    err = capsys.readouterr().err
    assert str(blocker / "shot.png") in err and "is not a folder" in err
    assert len(err.strip().splitlines()) == 1


# --------------------------------------------------------------------------- view


def test_view_without_display_fails_fast(monkeypatch, capsys) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    assert main(["view", SCENE, "--seconds", "1"]) == 1
    assert "xvfb-run" in capsys.readouterr().err


def test_view_rejects_non_positive_seconds(capsys) -> None:
    assert "--seconds" in _usage_error(["view", SCENE, "--seconds", "0"], capsys)


@pytest.fixture(scope="module")
def xvfb_display() -> Iterator[str]:
    """Start a private Xvfb server; yields its DISPLAY value (e.g. ``":99"``)."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb not on PATH (apt-get install xvfb) - cannot test the viewer")
    read_fd, write_fd = os.pipe()
    # -displayfd: Xvfb picks a free display number and writes it to the pipe when ready.
    server = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    try:
        with os.fdopen(read_fd) as pipe:
            number = pipe.readline().strip()
        if not number.isdigit():
            pytest.skip("Xvfb failed to start")
        yield f":{number}"
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()


@pytest.mark.slow
def test_view_steps_physics_in_the_viewer(xvfb_display: str) -> None:
    env = {**os.environ, "DISPLAY": xvfb_display}
    env.pop("WAYLAND_DISPLAY", None)
    result = subprocess.run(
        [sys.executable, "-m", "rehabbot", "view", SCENE, "--seconds", "1"],
        capture_output=True, text=True, timeout=600, env=env,
    )
    assert result.returncode == 0, result.stderr
    match = re.search(
        rf"viewed {SCENE}: simulated (\d+\.\d+) s, (\d+) viewer frames", result.stdout
    )
    assert match, result.stdout
    simulated_s, frames = float(match.group(1)), int(match.group(2))
    assert simulated_s >= 0.99
    assert simulated_s < 1.1
    # Paced by the wall clock: the first frame steps once and each later one what the clock
    # says is due, so a paced second has 2 frames or more however loaded the machine (an
    # unpaced run has one); a frame lasts at least 1/60 s, so there are at most 60 + 1.
    assert 2 <= frames <= math.ceil(VIEWER_FRAME_RATE_HZ * 1.0) + 1, \
        f"{frames} viewer frames in 1 s of real-time simulation"


# --------------------------------------------------------------------------- scene tour


def test_scene_tour_renders_cameras_and_summarises_sweep(tmp_path: Path, capsys) -> None:
    import json

    from benchmarks.probes import scene_tour
    from rehabbot.sim import build_scene

    code = scene_tour.main(
        ["--out", str(tmp_path), "--presets", SCENE, "--duration", "1",
         "--width", "160", "--height", "120"]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    for camera in build_scene(SCENE).camera_names:
        image = imageio.imread(tmp_path / f"{SCENE}_{camera}.png")
        assert image.shape[:2] == (120, 160) and image.std() > 10.0
    summary = json.loads((tmp_path / "summary.json").read_text())
    entry = summary["presets"][SCENE]
    moved = entry["exercised_joint_range_deg"]
    assert max(moved.values()) > 10.0, "the sweep must move the exercised joints"
    assert entry["finite"] is True and entry["within_rom"] is True
    assert 0.0 <= entry["max_cuff_error_m"] < 0.05
    # The printed line reports the joint that moved most, with the same number.
    top_joint = max(moved, key=moved.get)
    assert f"{SCENE}: {top_joint} moved {moved[top_joint]:.1f} deg" in out
    assert f"max cuff error {entry['max_cuff_error_m'] * 1e3:.1f} mm" in out


def test_scene_tour_rejects_unknown_preset(tmp_path: Path, capsys) -> None:
    from benchmarks.probes import scene_tour

    assert scene_tour.main(["--out", str(tmp_path), "--presets", "bogus"]) == 2
    assert "upper_right" in capsys.readouterr().err
