"""Parsers of binary containers, run by :mod:`piezohyst._isolate` in a child process.

Each takes a path and returns plain data (arrays, strings) that pickle; the libraries
are imported here at the top, so the server process that forks the children has
them loaded once.
"""

from __future__ import annotations

from typing import Any

import h5py
import numpy as np
from scipy.io import loadmat


def hdf5_arrays(path: str) -> dict[str, np.ndarray]:
    """Every numeric dataset of an HDF5 file holding at least one value, by its path."""
    arrays: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as fh:

        def visit(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "biuf" and obj.size >= 1:
                arrays[name] = np.asarray(obj[()])

        fh.visititems(visit)
    return arrays


def mat_arrays(path: str) -> dict[str, Any]:
    """The variables of a MAT file (v4 to v7; v7.3 is HDF5 and read as such)."""
    try:
        data = loadmat(path, squeeze_me=False)
    except NotImplementedError:  # MATLAB v7.3 is HDF5
        return hdf5_arrays(path)
    return {k: v for k, v in data.items() if not k.startswith("__")}


def bank_hdf5(path: str) -> tuple[str, list[str]]:
    """A model bank's HDF5 file: its JSON header and one JSON text per channel."""
    with h5py.File(path, "r") as f:
        return str(f["bank"].asstr()[0]), [str(s) for s in f["channels"].asstr()[:]]
