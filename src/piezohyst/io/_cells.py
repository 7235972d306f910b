"""Cells of a text table that are not plain numbers: a row of units under the header, a
column of timestamps (the readers of :mod:`piezohyst.io._formats` ask)."""

from __future__ import annotations

import re
from datetime import datetime, timedelta

import numpy as np

from .._validation import FloatArray

__all__ = ["ISO_DATE", "is_timestamp", "timestamps", "units_row"]

ISO_DATE = re.compile(r"^\s*\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}")
BRACKETED = re.compile(r"^\s*(?:\([^()]*\)|\[[^\[\]]*\])\s*$")


def units_row(cells: list[str]) -> bool:
    """A row of units under a header, as oscilloscope and DAQ exports write (PicoScope:
    ``(ms),(V),(V)``): every cell a bracketed unit (or empty, not all)."""
    filled = [c for c in cells if c.strip()]
    return bool(filled) and all(BRACKETED.match(c) for c in filled)


def timestamps(cells: list[str]) -> FloatArray | None:
    """A column of ISO 8601 timestamps (``2026-11-27 10:00:00.125``, a ``T`` between date
    and time, an offset or ``Z`` allowed), as a logger writes its clock: the seconds from the
    first row's (exact to the microsecond; the absolute date is not kept, so float64 loses
    nothing). None where any cell is not one."""
    if not cells or not ISO_DATE.match(cells[0]):
        return None
    try:
        stamps = [datetime.fromisoformat(c.strip().replace("Z", "+00:00")) for c in cells]
        first = stamps[0]
        return np.array([(s - first) / timedelta(microseconds=1) for s in stamps]) * 1e-6
    except (ValueError, TypeError):  # not a timestamp, or naive and aware mixed
        return None


def is_timestamp(cell: str) -> bool:
    """Whether ``cell`` is one timestamp of :func:`timestamps`'s kind."""
    try:
        datetime.fromisoformat(cell.strip().replace("Z", "+00:00"))
    except ValueError:
        return False
    return bool(ISO_DATE.match(cell))
