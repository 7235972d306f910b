"""Parsers of binary containers, run by :mod:`piezohyst.io._isolate` in a helper process.

The helper is a fresh interpreter that loads this file by its path, not the package: it
imports NumPy, then SciPy's MAT reader or h5py as a request needs them, and nothing of
piezohyst (so neither numba nor the user's own script). It answers requests on its
standard input and output, each message an 8-byte little-endian length and a pickle: a
request ``(parser name, path)``, an answer ``(True, result)`` or ``(False, exception)``.
Every result is plain data. The caller imports this module for :func:`send` and
:func:`receive` alone, so nothing heavy is imported at its top.
"""

from __future__ import annotations

import os
import pickle
import signal
import struct
import sys
from collections.abc import Callable
from typing import IO, Any

import numpy as np


def _numeric(arrays: dict[str, Any]) -> dict[str, np.ndarray]:
    """The numeric arrays holding at least one value (structs, cells and text left out)."""
    out = {}
    for name, value in arrays.items():
        arr = np.asarray(value) if isinstance(value, np.ndarray) else None
        if arr is not None and arr.dtype.kind in "biuf" and arr.size >= 1:
            out[name] = arr
    return out


#: a dataset's text attribute that states its unit (NeXus and most writers: ``units``)
UNIT_ATTRIBUTES = ("units", "unit", "unit_string")


def hdf5_arrays(path: str) -> dict[str, Any]:
    """Every numeric dataset of an HDF5 file holding at least one value, by its path, every
    numeric attribute as ``path@name`` (``@name`` for the file's own), and the unit a
    dataset's ``units`` attribute states as the text ``path@unit``."""
    import h5py

    arrays: dict[str, Any] = {}
    units: dict[str, str] = {}
    with h5py.File(path, "r") as fh:

        def attributes(name: str, obj: Any) -> None:
            for key, value in obj.attrs.items():
                arrays[f"{name}@{key}"] = np.asarray(value) if np.isscalar(value) else value
                text = np.asarray(value).reshape(-1)[:1]
                if key.lower() in UNIT_ATTRIBUTES and text.size and text.dtype.kind in "SUO":
                    word = text[0].decode("latin-1") if isinstance(text[0], bytes) else text[0]
                    if isinstance(word, str) and word.strip():
                        units[f"{name}@unit"] = word.strip()

        def visit(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "biuf" and obj.size >= 1:
                arrays[name] = np.asarray(obj[()])
            attributes(name, obj)

        attributes("", fh)
        fh.visititems(visit)
    return {**_numeric(arrays), **units}


def mat_arrays(path: str) -> dict[str, Any]:
    """The numeric variables of a MAT file (v4 to v7; v7.3 is HDF5 and read as such), and
    each text ``NAME_unit`` variable as a string."""
    from scipy.io import loadmat

    try:
        data = loadmat(path, squeeze_me=False)
    except NotImplementedError:  # MATLAB v7.3 is HDF5
        return hdf5_arrays(path)
    variables: dict[str, Any] = {}
    for name, value in data.items():
        if not name.startswith("__"):
            _flatten(name, value, variables)
    units = {  # 'voltage_unit': 'V', as piezohyst writes them
        k.rpartition("/")[2] if "/" in k else k: str(np.asarray(v).reshape(-1)[0])
        for k, v in variables.items()
        if k.endswith("_unit") and isinstance(v, np.ndarray) and v.dtype.kind == "U" and v.size
    }
    return {**_numeric(variables), **units}


#: A matrix with at most this many rows or columns holds signals (one per column or row)
MAX_SIGNALS = 64


def _flatten(name: str, value: Any, out: dict[str, Any]) -> None:
    """A MAT variable as 1-D arrays: a struct's fields as ``name/field`` (nested structs
    deeper: MATLAB's ``save`` of a struct of signals), a matrix of signals as ``name/0``,
    ``name/1``... (one per column, or per row when they lie in rows), anything else as is."""
    arr = value if isinstance(value, np.ndarray) else None
    if arr is None:
        return
    if arr.dtype.names and arr.size == 1:  # a 1x1 struct
        for field in arr.dtype.names:
            _flatten(f"{name}/{field}", arr[field].reshape(-1)[0], out)
        return
    if arr.dtype.kind == "O" and arr.size == 1:  # a struct field holds its value in a cell
        _flatten(name, arr.reshape(-1)[0], out)
        return
    if arr.dtype.kind in "biuf" and arr.ndim == 2 and min(arr.shape) > 1:
        signals = arr if arr.shape[0] >= arr.shape[1] else arr.T  # samples down the rows
        if signals.shape[1] <= MAX_SIGNALS:
            for j in range(signals.shape[1]):
                out[f"{name}/{j}"] = np.ascontiguousarray(signals[:, j])
            return
    out[name] = arr


def bank_hdf5(path: str) -> tuple[str, list[str]]:
    """A model bank's HDF5 file: its JSON header and one JSON text per channel."""
    import h5py

    with h5py.File(path, "r") as f:
        return str(f["bank"].asstr()[0]), [str(s) for s in f["channels"].asstr()[:]]


def crash(path: str) -> None:
    """Dies as compiled code does on a damaged file (the tests check it is reported)."""
    os.kill(os.getpid(), signal.SIGSEGV)


PARSERS: dict[str, Callable[[str], Any]] = {
    "hdf5_arrays": hdf5_arrays,
    "mat_arrays": mat_arrays,
    "bank_hdf5": bank_hdf5,
    "crash": crash,
}


def send(stream: IO[bytes], obj: object) -> None:
    """One message: its length, then its pickle."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack("<Q", len(data)))
    stream.write(data)
    stream.flush()


def receive(stream: IO[bytes]) -> Any:
    """One message; EOFError when the other side has gone."""
    head = stream.read(8)
    if len(head) < 8:
        raise EOFError
    (size,) = struct.unpack("<Q", head)
    data = stream.read(size)
    if len(data) < size:
        raise EOFError
    return pickle.loads(data)


def serve() -> None:
    """Answer requests until the standard input closes (the caller has gone)."""
    inp, out = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # a stray print must not corrupt the answers
    while True:
        try:
            name, path = receive(inp)
        except EOFError:
            return
        try:
            answer: tuple[bool, Any] = (True, PARSERS[name](path))
        except Exception as exc:  # raised again in the caller
            answer = (False, exc)
        try:
            send(out, answer)
        except Exception as exc:  # an exception that does not pickle: its text
            send(out, (False, RuntimeError(f"{type(exc).__name__}: {exc}")))
