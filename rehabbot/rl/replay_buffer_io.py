"""Replay-buffer checkpoints that hold only what was collected.

Stable-Baselines3 pickles the whole replay buffer, preallocated to ``buffer_size`` (1e6 by
default): a 400-step SAC run wrote a 220 MB checkpoint. Here only the filled rows are saved,
as plain arrays in an ``.npz`` (no pickle), and loaded back into the model's own buffer, which
SB3 allocates when it loads the checkpoint. The buffer's position and wrap-around are kept,
so sampling after a resume sees exactly the transitions it saw before.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import DataError

FORMAT_VERSION = 1
ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def filled_rows(buffer: Any) -> int:
    """How many rows of ``buffer`` hold transitions."""
    return int(buffer.buffer_size if buffer.full else buffer.pos)


def save_replay_buffer(model: Any, stream: io.BufferedIOBase | str | Path) -> None:
    """Write the filled part of ``model.replay_buffer`` to ``stream`` (``.npz``)."""
    buffer = model.replay_buffer
    rows = filled_rows(buffer)
    arrays = {name: getattr(buffer, name)[:rows] for name in ARRAYS
              if getattr(buffer, name, None) is not None}
    np.savez(stream, format_version=np.array(FORMAT_VERSION),
             buffer_size=np.array(buffer.buffer_size), pos=np.array(buffer.pos),
             full=np.array(buffer.full), **arrays)


def load_replay_buffer(model: Any, path: str | Path) -> int:
    """Fill ``model.replay_buffer`` from a file of :func:`save_replay_buffer`; returns the
    number of transitions loaded.

    Raises:
        DataError: the file is not such a file, or does not fit the model's buffer (size,
            number of envs, observation or action shape); the message names the file.
    """
    buffer = model.replay_buffer
    try:
        with np.load(path, allow_pickle=False) as data:
            if int(data["format_version"]) != FORMAT_VERSION:
                raise ValueError(f"format version {int(data['format_version'])}, expected "
                                 f"{FORMAT_VERSION}")
            size, pos, full = int(data["buffer_size"]), int(data["pos"]), bool(data["full"])
            arrays = {name: data[name] for name in ARRAYS if name in data.files}
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise DataError(f"cannot load replay buffer {path}: {type(err).__name__}: {err} "
                        "(delete it to resume with an empty buffer)") from err
    rows = size if full else pos
    if size != buffer.buffer_size:
        raise DataError(f"cannot load replay buffer {path}: it holds a buffer of {size} "
                        f"transitions, the model's has {buffer.buffer_size}")
    for name in ARRAYS:
        target = getattr(buffer, name, None)
        if target is None:
            continue
        source = arrays.get(name)
        if source is None or source.shape != (rows, *target.shape[1:]):
            got = None if source is None else source.shape
            raise DataError(f"cannot load replay buffer {path}: {name} has shape {got}, "
                            f"expected {(rows, *target.shape[1:])}")
        target[:rows] = source
    buffer.pos, buffer.full = pos, full
    return rows * buffer.n_envs
