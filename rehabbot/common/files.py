"""Files that are complete or absent: every write goes to a temporary name in the same
folder and is renamed into place, so an interrupted job never leaves a half-written file
under its final name. New files get the usual permissions (``0666`` minus the umask).
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from rehabbot.common.errors import OutputError, UsageError


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
    ``path``; remove it if anything fails (interruptions included). A failed write (a full
    disk: the writer's OSError names no file) becomes :class:`OutputError` naming ``path``."""
    try:
        produce(tmp)
        with open(tmp, "rb+") as stream:
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, OSError) and not isinstance(err, OutputError):
            raise _output_error(path, err) from err
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


def check_parent_exists(path: Path, what: str = "--out") -> Path:
    """``path`` as a Path whose parent folder exists: a folder a user names is created (its
    last part only), a file written into it, but a missing folder above it is a typo, not
    something to build (``mkdir`` without ``-p``). Defaults of the commands (``runs/...``)
    are not checked by this: they are created with their parents.

    Raises:
        UsageError: the parent folder does not exist, or is not a folder (naming both).
    """
    path = Path(path)
    parent = path.parent
    if not parent.exists():
        raise UsageError(f"{what} {str(path)!r}: its folder {str(parent)!r} does not exist; "
                         "create it first")
    if not parent.is_dir():
        raise UsageError(f"{what} {str(path)!r}: {str(parent)!r} is not a folder")
    return path


# --------------------------------------------------------------------------- checked outputs
# Every output a command hands to a user (video, figure, JSON, trace) is written under a
# temporary name, checked by reading it back, and only then renamed over the earlier file:
# a full disk or a writer that fails silently leaves the earlier good file and no temporary.


def check_output_file(path: Path, suffixes: Sequence[str] = (),
                      what: str = "output file") -> Path:
    """``path`` as a Path, checked before any work starts.

    Raises:
        UsageError: the suffix is not one of ``suffixes`` (when given), or ``path`` is a
            folder.
        OutputError: its folder cannot be created or written.
    """
    path = Path(path)
    allowed = tuple(suffix.lower() for suffix in suffixes)
    if allowed and path.suffix.lower() not in allowed:
        raise UsageError(f"{what} {str(path)!r}: the file must end in {' or '.join(allowed)}")
    if path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a folder, not a file")
    check_writable_dir(path.parent, what=f"folder of {what}")
    return path


def suffixed_temp_path(path: Path) -> Path:
    """A hidden temporary name beside ``path`` that keeps its suffix (unique per process)."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


def _output_error(path: Path, err: BaseException) -> OutputError:
    reason = getattr(err, "strerror", None) or str(err) or type(err).__name__
    return OutputError(f"cannot write {str(path)!r}: {reason}; the earlier file, if any, "
                       "is kept")


def _remove_quietly(paths: Iterable[Path]) -> None:
    for tmp in paths:
        with contextlib.suppress(OSError):
            tmp.unlink()


def _produce_checked(path: Path, tmp: Path, produce: Callable[[Path], Any],
                     verify: Callable[[Path], Any] | None) -> None:
    """``produce(tmp)``, flush it to disk, ``verify(tmp)``; an OSError or a failed check
    becomes :class:`OutputError` naming ``path``."""
    try:
        produce(tmp)
        with open(tmp, "rb+") as stream:
            os.fsync(stream.fileno())
    except OSError as err:
        raise _output_error(path, err) from err
    if verify is None:
        return
    try:
        verify(tmp)
    except Exception as err:  # any reader's complaint means the file is not good
        reason = f"the file read back is damaged ({type(err).__name__}: {err})"
        raise OutputError(f"cannot write {str(path)!r}: {reason}; the earlier file, if any, "
                          "is kept") from err


def atomic_save_verified(path: Path, save: Callable[[str], Any],
                         verify: Callable[[Path], Any]) -> None:
    """Like :func:`atomic_save`, and ``verify(tmp)`` reads the file back before the rename
    (it raises when the file is damaged); the earlier ``path`` survives any failure.

    Raises:
        OutputError: the write failed (a full disk) or the file read back is damaged.
    """
    atomic_save_all({Path(path): save}, {Path(path): verify})


def atomic_save_all(saves: Mapping[Path, Callable[[str], Any]],
                    verifies: Mapping[Path, Callable[[Path], Any]] | None = None) -> None:
    """Write several files together: each ``saves[path](tmp_name)`` writes a temporary
    (keeping the suffix), ``verifies[path](tmp)`` checks it, and only when every one is
    written and checked are they renamed into place. A failure leaves every earlier file
    as it was (never a new one beside an old one) and no temporary.

    Raises:
        OutputError: a write failed or a file read back is damaged.
    """
    checks = {Path(path): verify for path, verify in (verifies or {}).items()}
    temps = {Path(path): suffixed_temp_path(Path(path)) for path in saves}
    try:
        for raw, save in saves.items():
            path = Path(raw)
            _produce_checked(path, temps[path], lambda name, save=save: save(str(name)),
                             checks.get(path))
        for path, tmp in temps.items():
            os.replace(tmp, path)
    except OutputError:
        _remove_quietly(temps.values())
        raise
    except OSError as err:  # a rename failed
        _remove_quietly(temps.values())
        raise _output_error(path, err) from err
    except BaseException:
        _remove_quietly(temps.values())
        raise
    for folder in {path.parent for path in temps}:
        _fsync_dir(folder)


def remove_tree(path: Path) -> None:
    """Delete ``path`` without ever following a symbolic link: a link (to a file or a
    folder) is removed as a link, a folder's links inside it too, and nothing they point to
    is touched. Missing ``path``: nothing to do."""
    import shutil

    path = Path(path)
    if path.is_symlink() or (path.exists() and not path.is_dir()):
        path.unlink()
    elif path.is_dir():
        shutil.rmtree(path)  # does not follow links inside the tree (fd-based on Linux)


def remove_contents(folder: Path, keep: tuple[str, ...] = ()) -> None:
    """Delete everything in ``folder`` except the names in ``keep``, never following a
    symbolic link (:func:`remove_tree`).

    Raises:
        OutputError: ``folder`` is itself a symbolic link (nothing is deleted).
    """
    folder = Path(folder)
    if folder.is_symlink():
        raise OutputError(f"refusing to empty {folder}: it is a symbolic link (to "
                          f"{folder.readlink()})")
    if not folder.is_dir():
        return
    for child in folder.iterdir():
        if child.name not in keep:
            remove_tree(child)


class FolderLockedError(OutputError):
    """Another process holds the lock of a folder (:func:`lock_folder`)."""


class FolderLock:
    """An exclusive ``flock`` on ``folder/name`` that holds this process's pid; the kernel
    releases it when the process ends, however it ends, so a killed process never leaves a
    lock that blocks."""

    def __init__(self, folder: Path, name: str) -> None:
        self.path = Path(folder) / name
        self._fd: int | None = None

    def acquire(self, what: str = "folder") -> FolderLock:
        """Take the lock, or raise :class:`FolderLockedError` naming the folder and the pid of
        the process that holds it."""
        import fcntl

        if self.path.is_symlink():
            raise OutputError(f"refusing lock file {self.path}: it is a symbolic link")
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as err:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            os.close(fd)
            raise FolderLockedError(f"{what} {self.path.parent} is being written by another "
                                    f"process (pid {holder}); wait for it to end or stop it "
                                    "first") from err
        except BaseException:
            os.close(fd)
            raise
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        """Let go of the lock (the file stays: removing it would race with a new holder)."""
        if self._fd is not None:
            fd, self._fd = self._fd, None
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            os.close(fd)

    def __enter__(self) -> FolderLock:
        return self.acquire() if self._fd is None else self

    def __exit__(self, *_exc: object) -> None:
        self.release()


# --------------------------------------------------------------------------- write errors


def unnamed_write_error(err: BaseException) -> bool:
    """An OSError of a writer that names no file (a full disk: ``file.write`` raises
    ``[Errno 28]`` without a name), not one of ours (:class:`OutputError` names its file)."""
    return isinstance(err, OSError) and not isinstance(err, OutputError) \
        and err.filename is None


def naming_write_errors(func: Callable[..., Any], path: Path) -> Callable[..., Any]:
    """``func``, with an OSError that names no file raised as :class:`OutputError` naming
    ``path``, the file ``func`` writes (Stable-Baselines3's monitor and evaluation logs)."""

    @functools.wraps(func)
    def call(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except OSError as err:
            if not unnamed_write_error(err):
                raise
            raise OutputError(f"cannot write {str(path)!r}: {err.strerror or err}") from err

    return call
