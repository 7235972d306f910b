"""A record read block by block: the source every fit and run takes, and its summary.

A :data:`Blocks` source is a function that yields ``(x, y, t)`` blocks from the record's
start each time it is called, so a fit can read a file three times (extremes, normal
equations, fit quality) and never hold it whole; :func:`array_blocks` makes one of
arrays in memory.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from .._validation import FloatArray
from ..errors import InsufficientDataError

__all__ = ["BLOCK", "Summary", "array_blocks", "block_dt", "without_time"]

BLOCK = 4096  # samples per block when accumulating or streaming


Triple = tuple[FloatArray, FloatArray, FloatArray | None]
Blocks = Callable[[], Iterable[Triple]]
"""A record that can be read again from its start: each call yields ``(x, y, t)`` blocks."""


def array_blocks(x: FloatArray, y: FloatArray, t: FloatArray | None) -> Blocks:
    """Arrays in memory as a :data:`Blocks` source (views, no copies).

    Parameters
    ----------
    x, y : ndarray
    t : ndarray or None

    Returns
    -------
    callable
    """

    def blocks() -> Iterator[Triple]:
        for lo in range(0, x.size, 1 << 18):
            hi = lo + (1 << 18)
            yield x[lo:hi], y[lo:hi], None if t is None else t[lo:hi]

    return blocks


def without_time(blocks: Blocks) -> Blocks:
    """The same record with its times dropped (for models without rate-dependent terms).

    Parameters
    ----------
    blocks : Blocks

    Returns
    -------
    Blocks
    """
    return lambda: ((x, y, None) for x, y, _ in blocks())


#: the sample strides over which :attr:`Summary.co_move` correlates the changes
MOVE_STRIDES = (1, 8, 64)


@dataclass(frozen=True)
class Summary:
    """What a fit needs to know of a whole record before it reads it again.

    Attributes
    ----------
    n : int
        Samples.
    x_first, x_min, x_max, y_first, y_min, y_max : float
        First value and extremes of input and output.
    t_first, t_last : float
        First and last time (s); NaN without times.
    max_slew_rate : float
        Fastest input change (input units per s); NaN without times.
    max_step : float
        Largest input change from one sample to the next (input units).
    co_move : float
        The correlation of the input's and the output's changes (about zero: a drift does
        not move with the input), the largest over changes across 1, 8 and 64 samples (at
        one sample, noise of both channels from one source can move them together, or
        apart, more than the drive does): near 1 where the output rises with the input,
        negative where it falls at every scale (a sensor counting the other way), near 0
        where it does both (the butterfly of bipolar drive); NaN where either never moves.
    """

    n: int
    x_first: float
    x_min: float
    x_max: float
    y_first: float
    y_min: float
    y_max: float
    t_first: float = float("nan")
    t_last: float = float("nan")
    max_slew_rate: float = float("nan")
    max_step: float = float("nan")
    co_move: float = float("nan")

    @classmethod
    def of(cls, blocks: Blocks) -> Summary:
        """One pass over a record.

        Parameters
        ----------
        blocks : Blocks

        Returns
        -------
        Summary

        Raises
        ------
        InsufficientDataError
            The record is empty.
        """
        n = 0
        x0 = y0 = t0 = t1 = x_last = np.nan
        x_lo = y_lo = np.inf
        x_hi = y_hi = -np.inf
        slew = np.nan
        jump = 0.0
        moves = np.zeros((len(MOVE_STRIDES), 3))  # per stride: sums of dx dy, dx^2, dy^2
        tail_x = tail_y = np.zeros(0)  # the last samples before the block, for the strides
        for x, y, t in blocks():
            if x.size == 0:
                continue
            if n == 0:
                x0, y0 = float(x[0]), float(y[0])
                t0 = np.nan if t is None else float(t[0])
            ext_x, ext_y = np.concatenate([tail_x, x]), np.concatenate([tail_y, y])
            for row, stride in enumerate(MOVE_STRIDES):
                dx, dy = ext_x[stride:] - ext_x[:-stride], ext_y[stride:] - ext_y[:-stride]
                done = max(tail_x.size - stride, 0)  # pairs counted with the block before
                dx, dy = dx[done:], dy[done:]
                moves[row] += (float(dx @ dy), float(dx @ dx), float(dy @ dy))
            keep = max(MOVE_STRIDES)
            tail_x, tail_y = ext_x[-keep:].copy(), ext_y[-keep:].copy()
            x_lo, x_hi = min(x_lo, float(x.min())), max(x_hi, float(x.max()))
            if x.size > 1:
                jump = max(jump, float(np.max(np.abs(np.diff(x)))))
            if n > 0:
                jump = max(jump, abs(float(x[0]) - x_last))
            y_lo, y_hi = min(y_lo, float(y.min())), max(y_hi, float(y.max()))
            if t is not None:
                steps = [np.abs(np.diff(x)) / np.diff(t)] if x.size > 1 else []
                if n > 0:  # the step from the previous block
                    steps.append(np.array([abs(x[0] - x_last) / (t[0] - t1)]))
                if steps:
                    fastest = max(float(np.max(s)) for s in steps)
                    slew = fastest if np.isnan(slew) else max(slew, fastest)
                t1 = float(t[-1])
            x_last = float(x[-1])
            n += x.size
        if n == 0:
            msg = "the record holds no samples"
            raise InsufficientDataError(msg)
        both = moves[:, 1] * moves[:, 2]
        moving = both > 0
        co = float(np.max(moves[moving, 0] / np.sqrt(both[moving]))) if moving.any() else np.nan
        return cls(n, x0, x_lo, x_hi, y0, y_lo, y_hi, t0, t1, slew, jump if n > 1 else np.nan, co)

    @property
    def x_range(self) -> FloatArray:
        """``[x_min, x_max]``: what :meth:`~piezohyst.model.terms.Term.bind` and thresholds need."""
        return np.array([self.x_min, self.x_max])


def block_dt(
    t: FloatArray | None, start: int, stop: int, t_previous: float | None
) -> FloatArray | None:
    """Sample intervals (s) of ``t[start:stop]``; the record's first is 0 unless it continues.

    Parameters
    ----------
    t : ndarray or None
        The whole record's times (s); None for a rate-independent model.
    start, stop : int
        The block.
    t_previous : float or None
        Time of the sample before ``t[0]`` when continuing a saved state.

    Returns
    -------
    ndarray or None
    """
    if t is None:
        return None
    dt = np.empty(stop - start)
    if start > 0:
        dt[0] = t[start] - t[start - 1]
    else:
        dt[0] = 0.0 if t_previous is None else t[0] - t_previous
    dt[1:] = np.diff(t[start:stop])
    return dt
