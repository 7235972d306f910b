"""Input checks shared by the public functions (never called from kernels)."""

from __future__ import annotations

import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import NonFiniteError, ParameterError, ShapeError, TimeAxisError

FloatArray = NDArray[np.float64]

PIECE = 1 << 16  # samples checked at a time (temporaries of 64 kB, whatever the record)


def as_signal(values: ArrayLike, name: str, *, allow_empty: bool = False) -> FloatArray:
    """Return ``values`` as a finite, contiguous, 1-D float64 array."""
    try:
        arr = np.ascontiguousarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        msg = f"'{name}' must be a 1-D array of numbers. Got {type(values).__name__} ({exc})."
        raise ShapeError(msg) from None
    if arr.ndim == 2 and 1 in arr.shape:
        arr = np.ascontiguousarray(arr.reshape(-1))
    if arr.ndim != 1:
        msg = f"'{name}' must be a 1-D array. Got an array of shape {arr.shape}."
        raise ShapeError(msg)
    if arr.size == 0 and not allow_empty:
        msg = f"'{name}' must not be empty. Got 0 samples."
        raise ShapeError(msg)
    for a in range(0, arr.size, PIECE):  # in pieces: no temporary the size of the record
        ok = np.isfinite(arr[a : a + PIECE])
        if not ok.all():
            first = a + int(np.argmin(ok))
            count = int(np.count_nonzero(~np.isfinite(arr)))
            msg = (
                f"'{name}' must be finite. Got {arr[first]} at index {first} "
                f"({count} non-finite values in all)."
            )
            raise NonFiniteError(msg)
    return arr


def same_length(a: FloatArray, b: FloatArray, name_a: str, name_b: str) -> None:
    """Raise :class:`ShapeError` unless ``a`` and ``b`` have equal length."""
    if a.size != b.size:
        msg = f"'{name_a}' and '{name_b}' must have the same length. Got {a.size} and {b.size}."
        raise ShapeError(msg)


def as_time(t: ArrayLike | None, n: int, *, required: bool, owner: str) -> FloatArray | None:
    """Check a time vector (s): finite, strictly increasing, ``n`` samples long."""
    if t is None:
        if required:
            msg = (
                f"{owner} is rate dependent and needs the sample times: pass t= "
                "(an array of time stamps in s, one per sample). Got t=None."
            )
            raise TimeAxisError(msg)
        return None
    arr = as_signal(t, "t", allow_empty=True)
    if arr.size != n:
        msg = f"'t' must have one time stamp per sample ({n}). Got {arr.size}."
        raise ShapeError(msg)
    for a in range(0, arr.size - 1, PIECE):
        seg = arr[a : a + PIECE + 1]
        bad = seg[1:] <= seg[:-1]
        if bad.any():
            i = a + int(np.argmax(bad)) + 1
            msg = (
                "'t' must be strictly increasing. Got "
                f"t[{i - 1}]={float(arr[i - 1])!r} followed by t[{i}]={float(arr[i])!r}."
            )
            raise TimeAxisError(msg)
    return arr


def check_int(value: object, name: str, owner: str, low: int, high: int) -> int:
    """Check an int parameter in ``[low, high]``, sklearn-style message."""
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Integral)
        or not low <= int(value) <= high
    ):
        msg = (
            f"The '{name}' parameter of {owner} must be an int in [{low}, {high}]. "
            f"Got {value!r} instead."
        )
        raise ParameterError(msg)
    return int(value)


def check_float(
    value: object, name: str, owner: str, low: float, high: float, *, low_open: bool = False
) -> float:
    """Check a real parameter in ``[low, high]`` (or ``(low, high]``)."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if ok:
        v = float(value)  # type: ignore[arg-type]
        ok = np.isfinite(v) and (v > low if low_open else v >= low) and v <= high
    if not ok:
        bracket = "(" if low_open else "["
        msg = (
            f"The '{name}' parameter of {owner} must be a float in {bracket}{low}, {high}]. "
            f"Got {value!r} instead."
        )
        raise ParameterError(msg)
    return float(value)  # type: ignore[arg-type]


def frozen(a: ArrayLike) -> np.ndarray:
    """``a`` as a read-only, C-contiguous float64 array: a view where it is one already, a
    copy only where it is not contiguous (or not float64).

    numba compiles a kernel once per type of its arguments, and a read-only array (a fitted
    core's frozen parameters, a column read zero-copy from a file) or a strided slice is
    another type than a writeable contiguous one: a kernel's inputs passed through this
    have one type wherever they come from, so each compiles once (about 2 s), not once per
    caller (the specializations the tests compile went from 74 to 61 with it).

    Examples
    --------
    >>> import numpy as np
    >>> x = np.arange(3.0)
    >>> v = frozen(x)
    >>> v.flags.writeable, np.shares_memory(v, x), x.flags.writeable
    (False, True, True)
    """
    arr = np.ascontiguousarray(a, dtype=np.float64)
    if arr.flags.writeable:
        arr = arr.view()
        arr.flags.writeable = False
    return arr
