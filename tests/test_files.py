"""Files are complete or absent: rehabbot.common.files writes through a temporary name."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from rehabbot.common.errors import OutputError
from rehabbot.common.files import atomic_save, atomic_write, atomic_write_json, check_writable_dir


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "manifest.json"
    atomic_write_json(path, {"steps": 1})
    old = path.read_text()

    def write_half_then_fail(stream) -> None:
        stream.write(b'{"steps": ')
        raise KeyboardInterrupt  # an interruption mid-write

    with pytest.raises(KeyboardInterrupt):
        atomic_write(path, write_half_then_fail)
    assert path.read_text() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["manifest.json"]


def test_save_by_name_keeps_the_suffix_and_gets_the_usual_permissions(tmp_path: Path) -> None:
    names = []

    def save(name: str) -> None:
        names.append(name)
        Path(name).write_bytes(b"frames")

    umask = os.umask(0o022)
    try:
        atomic_save(tmp_path / "episode.mp4", save)
    finally:
        os.umask(umask)
    assert names[0].endswith(".mp4") and Path(names[0]).name.startswith(".")
    assert (tmp_path / "episode.mp4").read_bytes() == b"frames"
    assert stat.S_IMODE((tmp_path / "episode.mp4").stat().st_mode) == 0o644
    assert [p.name for p in tmp_path.iterdir()] == ["episode.mp4"]


def test_an_unwritable_folder_is_named_and_nothing_is_left_behind(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(OutputError, match="file/out"):
        check_writable_dir(blocker / "out")
    check_writable_dir(tmp_path / "new" / "deep")  # creates and removes its probe folders
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]
