"""MuJoCo's C warnings, handled by us for a block instead of by MuJoCo's default handler.

MuJoCo's default warning handler prints ``WARNING: ...`` on stdout and appends the message
to ``MUJOCO_LOG.TXT`` in the current folder: a library that lets it run leaves a file wherever
it is used. :func:`handling_mujoco_warnings` installs a handler of ours
(``mujoco.set_mju_user_warning``, MuJoCo's documented hook; with one installed MuJoCo neither
prints nor writes its log) for a block: known, harmless messages are dropped, any other is
passed to the handler that was installed before, or issued as a Python
:class:`MujocoWarning` once the block ends (never from inside MuJoCo's C callback).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager

import mujoco


class MujocoWarning(RuntimeWarning):
    """A warning MuJoCo's C code issued inside :func:`handling_mujoco_warnings`."""


@contextmanager
def handling_mujoco_warnings(*dropped: str) -> Iterator[None]:
    """Within the block, MuJoCo's C warnings containing one of ``dropped`` are dropped and any
    other goes to the previous handler (or becomes a :class:`MujocoWarning` after the block);
    nothing is printed and no ``MUJOCO_LOG.TXT`` is written. The previous handler is restored
    on exit (the hook is process-wide: keep the block short)."""
    if not dropped or not all(isinstance(text, str) and text for text in dropped):
        raise ValueError(f"dropped={dropped!r}: give at least one non-empty text")
    previous = mujoco.get_mju_user_warning()
    kept: list[str] = []

    def handle(message: str) -> None:
        if any(text in message for text in dropped):
            return
        if previous is not None:
            previous(message)
        else:
            kept.append(message)

    mujoco.set_mju_user_warning(handle)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)
        for message in kept:
            warnings.warn(f"MuJoCo: {message}", MujocoWarning, stacklevel=3)
