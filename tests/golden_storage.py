"""A lossless file format for many small tables of numbers: the golden episodes'
(``tests/golden_episodes.py``).

:func:`write` stores ``{key: {name: array}}`` (every array with a leading axis of rows, any
numeric dtype; a name may have another dtype or row shape in another key) and :func:`read`
gives back the same keys, names, dtypes, shapes and bits (NaN payloads included). It is
built for the golden rollouts, whose floats change a little from row to row and whose
integers rarely change:

* the arrays of one name, dtype and row shape are concatenated over the keys that have it
  (nothing is stored for a key without it: no padding);
* each column is stored as the differences of its values' bit patterns from row to row (as
  unsigned integers, wrapping), so that a slowly moving column has equal high bytes;
* those are split into byte planes (every value's first byte, then every second byte, ...),
  so that the compressor sees the equal high bytes side by side;
* the planes and a small JSON layout go into an ``.npz`` (``numpy.savez``, no pickles), and
  the whole of it is compressed with LZMA (the standard library's ``lzma``, the ``.xz``
  format).

The golden episodes take about three quarters of the bytes that ``numpy.savez_compressed``
(zlib, values as they are) takes for the same arrays.
"""

from __future__ import annotations

import io
import json
import lzma
from pathlib import Path

import numpy as np

FORMAT = "golden-storage-1"
LZMA_PRESET = 9 | lzma.PRESET_EXTREME


def _bits_dtype(dtype: np.dtype) -> np.dtype:
    """The little-endian unsigned integer as wide as ``dtype``."""
    return np.dtype(f"<u{dtype.itemsize}")


def encode_columns(values: np.ndarray) -> np.ndarray:
    """``values`` (rows, *shape) as byte planes, ``uint8`` (itemsize, columns, rows): the
    differences of each column's bit patterns from row to row, byte by byte."""
    if values.dtype.kind not in "biuf":
        raise TypeError(f"cannot store an array of dtype {values.dtype} (numbers only)")
    width = int(np.prod(values.shape[1:], dtype=int))
    columns = np.ascontiguousarray(values.reshape(len(values), width).T)
    little = columns.astype(values.dtype.newbyteorder("<"), copy=False)
    bits = little.view(_bits_dtype(values.dtype))
    steps = np.diff(bits, axis=1, prepend=bits.dtype.type(0))  # wraps modulo 2**(8 itemsize)
    planes = steps.view(np.uint8).reshape(*steps.shape, values.dtype.itemsize)
    return np.ascontiguousarray(planes.transpose(2, 0, 1))


def decode_columns(planes: np.ndarray, dtype: np.dtype, shape: tuple[int, ...]) -> np.ndarray:
    """The inverse of :func:`encode_columns`: ``(rows, *shape)`` of ``dtype``."""
    dtype = np.dtype(dtype)
    itemsize, columns, rows = planes.shape
    if itemsize != dtype.itemsize or columns != int(np.prod(shape, dtype=int)):
        raise ValueError(f"byte planes {planes.shape} do not hold rows of {dtype} {shape}")
    bits_dtype = _bits_dtype(dtype)
    steps = np.ascontiguousarray(planes.transpose(1, 2, 0)).view(bits_dtype)[..., 0]
    bits = np.cumsum(steps, axis=1, dtype=bits_dtype)  # wraps as the differences did
    values = bits.view(dtype.newbyteorder("<")).astype(dtype, copy=False)
    return np.ascontiguousarray(values.T).reshape(rows, *shape)


def write(path: Path, tables: dict[str, dict[str, np.ndarray]]) -> int:
    """Store ``tables`` in ``path`` (written whole, then renamed into place); its size in
    bytes."""
    keys = list(tables)
    groups: dict[tuple[str, str, tuple[int, ...]], list[int]] = {}
    for index, key in enumerate(keys):
        for name, values in tables[key].items():
            values = np.asarray(values)
            if values.ndim == 0:
                raise ValueError(f"{key}: {name!r} has no rows (a 0-d array)")
            group = (name, values.dtype.newbyteorder("<").str, values.shape[1:])
            groups.setdefault(group, []).append(index)
    lengths = np.full((len(keys), len(groups)), -1, dtype=np.int64)
    arrays = {}
    fields = []
    for column, ((name, dtype, shape), members) in enumerate(groups.items()):
        parts = []
        for index in members:
            values = np.asarray(tables[keys[index]][name])
            lengths[index, column] = len(values)
            parts.append(values.astype(dtype, copy=False))
        arrays[f"field{column}"] = encode_columns(np.concatenate(parts))
        fields.append({"name": name, "dtype": dtype, "shape": list(shape)})
    layout = {"format": FORMAT, "keys": keys, "fields": fields}
    buffer = io.BytesIO()
    np.savez(buffer, layout=np.array(json.dumps(layout)), lengths=lengths, **arrays)
    packed = lzma.compress(buffer.getvalue(), preset=LZMA_PRESET)
    partial = path.with_name(path.name + ".partial")
    partial.write_bytes(packed)
    partial.replace(path)
    return len(packed)


def read(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """The tables stored in ``path`` by :func:`write`."""
    with np.load(io.BytesIO(lzma.decompress(path.read_bytes())), allow_pickle=False) as data:
        layout = json.loads(str(data["layout"]))
        if layout.get("format") != FORMAT:
            raise ValueError(f"{path} is not in the format {FORMAT!r}: {layout.get('format')!r}")
        lengths = data["lengths"]
        keys = layout["keys"]
        tables: dict[str, dict[str, np.ndarray]] = {key: {} for key in keys}
        for column, field in enumerate(layout["fields"]):
            values = decode_columns(data[f"field{column}"], np.dtype(field["dtype"]),
                                    tuple(field["shape"]))
            start = 0
            for key, length in zip(keys, lengths[:, column].tolist(), strict=True):
                if length >= 0:
                    tables[key][field["name"]] = values[start:start + length]
                    start += length
            if start != len(values):
                raise ValueError(f"{path}: {field['name']!r} holds {len(values)} rows, its "
                                 f"lengths add up to {start}")
    return tables
