"""Figures of merit for hysteresis models and compensation."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_signal, same_length

__all__ = ["CLIP_RUN", "clipped", "hysteresis_width", "nrmse", "rmse", "run_on"]


def rmse(measured: ArrayLike, predicted: ArrayLike) -> float:
    """Root-mean-square error, in the units of the data.

    The errors are divided by their largest magnitude before squaring, so data
    near 1e300 do not overflow and data near 1e-300 do not underflow to a
    perfect score.

    Parameters
    ----------
    measured, predicted : array_like, shape (N,)

    Returns
    -------
    float

    Examples
    --------
    >>> rmse([1e300, 2e300], [1e300, 3e300]) / 1e300
    0.7071067811865476
    """
    a = as_signal(measured, "measured")
    b = as_signal(predicted, "predicted")
    same_length(a, b, "measured", "predicted")
    err = a - b  # the one record-length temporary
    peak = max(float(err.max()), -float(err.min())) if err.size else 0.0
    if peak == 0.0 or not np.isfinite(peak):
        return peak
    err /= peak
    return peak * float(np.sqrt(np.dot(err, err) / err.size))


def nrmse(measured: ArrayLike, predicted: ArrayLike) -> float:
    """RMSE divided by the span (max - min) of ``measured``; 0.01 is 1 %.

    Parameters
    ----------
    measured : array_like, shape (N,)
        The data, whose span normalises the error.
    predicted : array_like, shape (N,)
        The model's output.

    Returns
    -------
    float
        ``inf`` for a constant ``measured``.

    Examples
    --------
    >>> round(nrmse([0.0, 1.0, 2.0], [0.0, 1.0, 2.2]), 12)
    0.057735026919
    """
    a = as_signal(measured, "measured")
    span = float(np.ptp(a))
    return rmse(a, predicted) / span if span > 0 else float("inf")


def hysteresis_width(x: ArrayLike, y: ArrayLike, *, levels: int = 200) -> float:
    """Largest gap between the rising and falling branches, as a fraction of y's span.

    The input range is cut into ``levels`` levels (2 % kept clear of each end,
    where the branches meet). Every monotone run of ``x`` is interpolated at
    the levels it crosses; the rising and falling branches are the means over
    the runs of each direction. A straight line gives 0.

    Parameters
    ----------
    x : array_like
        The input (what was wanted, or the voltage).
    y : array_like
        The output, one per input sample.
    levels : int, default 200
        How many input levels the branches are compared at.

    Returns
    -------
    float
        The largest gap between the branches over the levels, divided by ``y``'s span.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.concatenate([np.linspace(0, 1, 50), np.linspace(1, 0, 50)])
    >>> y = x + np.where(np.arange(100) < 50, 0.0, 0.1)   # falling branch 0.1 above
    >>> round(hysteresis_width(x, y), 3)
    0.091
    """
    xs = as_signal(x, "x")
    ys = as_signal(y, "y")
    same_length(xs, ys, "x", "y")
    lo, hi = float(xs.min()), float(xs.max())
    span_y = float(np.ptp(ys))
    if hi <= lo or span_y == 0:
        return 0.0
    grid = np.linspace(lo + 0.02 * (hi - lo), hi - 0.02 * (hi - lo), levels)
    sums = np.zeros((2, levels))
    counts = np.zeros((2, levels))
    dx = np.diff(xs)
    direction = np.sign(dx)
    k = 0
    while k < dx.size:
        if direction[k] == 0:
            k += 1
            continue
        end = k
        while end + 1 < dx.size and direction[end + 1] in (direction[k], 0):
            end += 1
        seg_x = xs[k : end + 2]
        seg_y = ys[k : end + 2]
        if direction[k] < 0:
            seg_x, seg_y = seg_x[::-1], seg_y[::-1]
        inside = (grid >= seg_x[0]) & (grid <= seg_x[-1])
        row = 0 if direction[k] > 0 else 1
        sums[row, inside] += np.interp(grid[inside], seg_x, seg_y)
        counts[row, inside] += 1
        k = end + 1
    both = (counts[0] > 0) & (counts[1] > 0)
    if not both.any():
        return 0.0
    gap = np.abs(sums[1, both] / counts[1, both] - sums[0, both] / counts[0, both])
    return float(gap.max() / span_y)


#: Samples in a row at a channel's extreme, exactly equal, that count as a clipped run
CLIP_RUN = 3


def clipped(chunks: Iterable[FloatArray]) -> tuple[int, str, float, int, int]:
    """Samples of a channel that sit at its top or bottom in flat runs (a clipped recording).

    A sensor or an ADC at its full scale returns the same value sample after sample; a
    real signal at its extreme does not stay bit-for-bit equal. Counts the samples equal
    to the channel's maximum (or minimum) in runs of at least :data:`CLIP_RUN`, in one
    pass (a new extreme starts the count again).

    Parameters
    ----------
    chunks : iterable of ndarray
        The channel's values in order, chunk by chunk.

    Returns
    -------
    (int, str, float, int, int)
        The larger count (top or bottom), which (``"top"``/``"bottom"``), the level, the
        first such sample (-1 when none) and the number of samples.
    """
    top, bottom = _Runs(-math.inf), _Runs(math.inf)
    row = 0
    for c in chunks:
        if not c.size:
            continue
        hi, lo = float(np.max(c)), float(np.min(c))
        if hi > top.level:
            top = _Runs(hi)
        if lo < bottom.level:
            bottom = _Runs(lo)
        top.feed(c, row)
        bottom.feed(c, row)
        row += c.size
    t, b = top.total(), bottom.total()
    if b[0] > t[0]:
        return b[0], "bottom", bottom.level, b[1], row
    return t[0], "top", top.level, t[1], row


class _Runs:
    """Runs of samples equal to ``level``, fed chunk by chunk (a run may span chunks)."""

    def __init__(self, level: float) -> None:
        self.level = level
        self.count, self.first, self.run, self.run_start = 0, -1, 0, 0

    def _close(self, start: int, length: int) -> None:
        if length >= CLIP_RUN:
            self.count += length
            self.first = start if self.first < 0 else self.first

    def feed(self, c: FloatArray, row: int) -> None:
        edges = np.diff(np.concatenate([[0], (c == self.level).astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        if self.run and not (starts.size and starts[0] == 0):  # the carried run ended
            self._close(self.run_start, self.run)
            self.run = 0
        for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
            carried = a == 0 and self.run
            start, length = (self.run_start, self.run + b) if carried else (row + a, b - a)
            self.run = 0
            if b == c.size:  # it may go on in the next chunk
                self.run, self.run_start = length, start
            else:
                self._close(start, length)

    def total(self) -> tuple[int, int]:
        if self.run:
            self._close(self.run_start, self.run)
            self.run = 0
        return self.count, self.first


def run_on(
    x: ArrayLike, y: ArrayLike, *, swing: float = 0.2, window: float = 0.15
) -> tuple[float, float, int]:
    """How far the output keeps moving the old way after the input turns.

    At every turn of ``x`` that ends a monotone run over at least ``swing`` of its range,
    the output's furthest excursion past its value at the turn, in the direction it was
    moving, while ``x`` comes back by up to ``window`` of its range. A hysteresis whose
    branches rise with the input (every model here) gives 0 (the noise aside); a lag between
    ``x`` and what drives the output, creep, or a law whose branches fall just past a
    reversal give more.

    Parameters
    ----------
    x, y : array_like, shape (N,)
        Input (the piezo's voltage: with a lag identified, the lagged one) and output
        (growth removed).
    swing, window : float
        Fractions of ``x``'s range.

    Returns
    -------
    tuple
        The median excursion as a fraction of ``y``'s span, the median input distance
        from the turn to where it peaks, and the number of turns measured (0: none, and
        NaN for the two figures).

    Examples
    --------
    >>> import numpy as np
    >>> x = np.concatenate([np.linspace(0, 1, 101), np.linspace(0.99, 0, 100)] * 2)
    >>> y = np.concatenate([x[:1], x[:-1]])           # the output a sample late
    >>> share, dx, turns = run_on(x, y)
    >>> round(share, 3), round(dx, 3), turns
    (0.01, 0.01, 3)
    """
    xs = as_signal(x, "x")
    ys = as_signal(y, "y")
    same_length(xs, ys, "x", "y")
    span_x, span_y = float(np.ptp(xs)), float(np.ptp(ys))
    none = (math.nan, math.nan, 0)
    if xs.size < 3 or span_x <= 0 or span_y <= 0:
        return none
    direction = np.sign(np.diff(xs))
    moving = np.flatnonzero(direction != 0)
    if moving.size < 2:
        return none
    turns = moving[1:][direction[moving[1:]] != direction[moving[:-1]]]  # first step back
    shares, dists = [], []
    start = int(moving[0])
    for k in turns:
        d = float(direction[start])
        if d * (xs[k] - xs[start]) >= swing * span_x:
            back = np.abs(xs[k:] - xs[k])
            stop = int(np.argmax(back > window * span_x)) if np.any(back > window * span_x) else 0
            if stop > 1:
                seg = d * (ys[k : k + stop] - ys[k])
                j = int(np.argmax(seg))
                shares.append(max(float(seg[j]), 0.0) / span_y)
                dists.append(float(back[j]))
        start = int(k)
    if not shares:
        return none
    return float(np.median(shares)), float(np.median(dists)), len(shares)
