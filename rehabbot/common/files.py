"""Files that are complete or absent: every write goes to a temporary name in the same
folder and is renamed into place, so an interrupted job never leaves a half-written file
under its final name. New files get the usual permissions (``0666`` minus the umask).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from rehabbot.common.errors import OutputError


def temp_path(path: Path) -> Path:
    """A hidden temporary name beside ``path`` (unique per process)."""
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def _fsync_dir(directory: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _produce_then_rename(path: Path, tmp: Path, produce: Callable[[Path], Any]) -> None:
    """Let ``produce(tmp)`` write the temporary file, flush it to disk, rename it to
    ``path``; remove it if anything fails (interruptions included)."""
    try:
        produce(tmp)
        with open(tmp, "rb+") as stream:
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    _fsync_dir(path.parent)


def atomic_write(path: Path, write: Callable[[io.BufferedWriter], Any]) -> None:
    """Write ``path`` through ``write(stream)`` via a temporary file and ``os.replace``."""
    path = Path(path)

    def produce(tmp: Path) -> None:
        with open(tmp, "wb") as stream:
            write(stream)

    _produce_then_rename(path, temp_path(path), produce)


def atomic_save(path: Path, save: Callable[[str], Any]) -> None:
    """Like :func:`atomic_write` for writers that take a file name (``save(tmp_name)``); the
    temporary name keeps ``path``'s suffix, which some writers read to pick a format."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    _produce_then_rename(path, tmp, lambda name: save(str(name)))


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write(path, lambda stream: stream.write(text.encode("utf-8")))


def atomic_write_json(path: Path, data: Mapping[str, Any], **dumps: Any) -> None:
    """Write ``data`` as indented JSON to ``path`` atomically."""
    atomic_write_text(path, json.dumps(data, indent=2, **dumps) + "\n")


def make_dirs(path: Path) -> Path | None:
    """``mkdir -p path``; returns the topmost folder it created (None if all existed)."""
    path = Path(path)
    missing = []
    probe = path
    while not probe.exists() and probe.parent != probe:
        missing.append(probe)
        probe = probe.parent
    path.mkdir(parents=True, exist_ok=True)
    return missing[-1] if missing else None


def check_writable_dir(path: Path, what: str = "output folder") -> None:
    """Raise :class:`OutputError` naming ``path`` unless files can be written in it.

    The folder is created if needed and a probe file written and removed; folders created
    only for the probe are removed again, so a failed check leaves nothing behind.
    """
    path = Path(path)
    created = None
    try:
        if path.exists() and not path.is_dir():
            raise OSError(f"{path} exists and is not a directory")
        created = make_dirs(path)
        probe = temp_path(path / "write-probe")
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as err:
        if created is not None:
            import shutil

            shutil.rmtree(created, ignore_errors=True)
        reason = err.strerror or str(err)
        raise OutputError(f"cannot write to {what} {str(path)!r}: {reason}") from err
    if created is not None:
        import shutil

        shutil.rmtree(created, ignore_errors=True)
