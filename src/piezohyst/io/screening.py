"""A record checked before it is trusted: isolated outliers and holes in the time axis.

A DAQ record can hold a sample logged at 10 kV by an ADC glitch, or a second
of samples it dropped. Trusted blindly, one glitch sets a model's voltage
limits and trained slew (and so every compensator's safety limits), and a hole
bends the leakage. :class:`Screener` reads a record block by block (memory
grows only with what it finds) and :func:`screen` an array record; both give a
:class:`Screen` that names each finding by its row and column.

The rules, from noise statistics
--------------------------------
A sample is an *isolated outlier* when it stands out of both its neighbours
on the same side by more than

- :data:`NOISE_REACH` times the column's noise (:func:`noise_level`): over
  10^4-10^5 samples of Gaussian noise, the highest and lowest sample lie 8.6-9.5
  RMS apart, and a sample must also clear both neighbours, so white noise gives
  no false alarm in any record of practical length;
- :data:`LOCAL_REACH` times the steps just beyond its neighbours: a sampled
  sine's crest clears its neighbours by less than the steps beside them, a
  triangle's corner by as much (1x), a staircase's step by nothing on one side,
  so none of them is an outlier, while a glitch stands out of calm neighbours;
- :data:`NOISE_REACH` times the column's resolution (its smallest nonzero step),
  so a quantised record's flicker of one code is not an outlier.

Two or more bad samples in a row are not isolated: they are left as they are
(the steps beside each are as large as the glitch). The first and last samples
have one neighbour each, so a glitch there cannot be told from a step: they
are not judged.

An interval longer than :data:`HOLE_FACTOR` times the median one is a *hole*:
two samples or more missing. A non-uniform record (a logger's jitter, samples
taken on events) has intervals up to about twice its median, and one missing
sample (twice the interval) changes nothing a model can see.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray

__all__ = [
    "HOLE_FACTOR",
    "LOCAL_REACH",
    "NOISE_REACH",
    "Hole",
    "Outlier",
    "Screen",
    "Screener",
    "noise_level",
    "screen",
    "smoothed",
]

NOISE_REACH = 10.0
LOCAL_REACH = 4.0
HOLE_FACTOR = 3.0
#: findings named in a message; the rest are counted
SHOWN = 5

#: Savitzky-Golay smoothing, 7 points, quadratic: exact on cubics, so what it leaves of a
#: smooth input is its noise (times sqrt(1 - 7/21): the centre weight is 7/21)
_SMOOTH = np.array([-2.0, 3.0, 6.0, 7.0, 6.0, 3.0, -2.0]) / 21.0


def noise_level(x: ArrayLike) -> float:
    """A signal's noise (RMS, its units), from what a 7-point quadratic smoothing leaves,
    by its median absolute deviation (steps, corners and glitches are outliers there).

    A smooth input leaves little: from a 70 V sine sampled at 1 kHz it estimates 0.001 V
    at 10 Hz, 0.41 V at 50 Hz and 4.3 V at 100 Hz (6 % of the amplitude), which then
    counts as noise.

    Parameters
    ----------
    x : array_like, shape (N,)

    Returns
    -------
    float
        0 for fewer than 7 samples or a quantised input whose codes rarely change.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> round(noise_level(np.linspace(0, 100, 20000) + rng.normal(0, 0.5, 20000)), 1)
    0.5
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size < _SMOOTH.size:
        return 0.0
    left = x[3:-3] - np.convolve(x, _SMOOTH, mode="valid")
    mad = float(np.median(np.abs(left - np.median(left))))
    return 1.4826 * mad / math.sqrt(1.0 - 7.0 / 21.0)


def smoothed(x: ArrayLike) -> FloatArray:
    """The 7-point quadratic smoothing :func:`noise_level` measures against (its first and
    last three samples as they are).

    Parameters
    ----------
    x : array_like, shape (N,)

    Returns
    -------
    ndarray, shape (N,)
    """
    x = np.asarray(x, dtype=np.float64)
    out = x.copy()
    if x.size >= _SMOOTH.size:
        out[3:-3] = np.convolve(x, _SMOOTH, mode="valid")
    return out


@dataclass(frozen=True)
class Outlier:
    """One isolated outlier.

    Attributes
    ----------
    row : int
        Its data row, 1-based (the first sample is row 1; a file's header lines not
        counted), as every message of piezohyst counts rows.
    column : str
    value : float
        As recorded (in the column's standard unit).
    replacement : float
        The mean of its two neighbours, what a fit uses instead.
    """

    row: int
    column: str
    value: float
    replacement: float


@dataclass(frozen=True)
class Hole:
    """A hole in the time axis: samples the DAQ did not record.

    Attributes
    ----------
    row : int
        The data row (1-based) of the first sample after the hole.
    time : float
        The time (s) of the last sample before it.
    length : float
        The time missing (s): the interval less one median interval.
    """

    row: int
    time: float
    length: float


@dataclass(frozen=True)
class Screen:
    """What a record's check found.

    Attributes
    ----------
    outliers : tuple of Outlier
    holes : tuple of Hole
    noise : dict
        Each column's noise level (RMS, its units).
    interval : float
        The median sample interval (s; NaN without times).
    """

    outliers: tuple[Outlier, ...] = ()
    holes: tuple[Hole, ...] = ()
    noise: dict[str, float] = field(default_factory=dict)
    interval: float = math.nan

    def replacements(self, column: str) -> dict[int, float]:
        """The 0-based sample index -> replacement of each outlier of ``column``.

        Parameters
        ----------
        column : str

        Returns
        -------
        dict
        """
        return {o.row - 1: o.replacement for o in self.outliers if o.column == column}

    def cleaned(self, column: str, values: FloatArray, start: int = 0) -> FloatArray:
        """``values`` (the samples from 0-based index ``start`` on) with the outliers of
        ``column`` replaced; the array itself when there are none there.

        Parameters
        ----------
        column : str
        values : ndarray
        start : int, default 0

        Returns
        -------
        ndarray
        """
        rows = [(i - start, v) for i, v in self.replacements(column).items()]
        rows = [(i, v) for i, v in rows if 0 <= i < values.size]
        if not rows:
            return values
        out = values.copy()
        for i, v in rows:
            out[i] = v
        return out

    def outlier_message(
        self, where: str, units: Mapping[str, str | None], *, arrays: bool = False
    ) -> str:
        """One line naming the outliers (the first :data:`SHOWN`, then a count).

        Parameters
        ----------
        where : str
            The record, for the message (a file's path, or "the record").
        units : mapping
            Each column's unit, for the values.
        arrays : bool, default False
            Name a sample by its 0-based index in the array (``x[1234]``), not
            by its 1-based data row and column (a file's).

        Returns
        -------
        str
        """
        n = len(self.outliers)
        shown = _listing([
            f"{f'{o.column}[{o.row - 1}]' if arrays else f'row {o.row} column {o.column!r}'} "
            f"{o.value:.6g}{_unit(units.get(o.column))} (neighbours {o.replacement:.6g})"
            for o in self.outliers
        ])  # fmt: skip
        return (
            f"{where}: {n} isolated outlier{'s' if n > 1 else ''} (a sample standing out of "
            f"both neighbours by over {NOISE_REACH:g}x the column's noise): {shown}; kept out "
            "of the fit, its voltage range and slew (replaced by its neighbours' mean); keep "
            "them with keep_outliers=True (--keep-outliers)"
        )

    def hole_message(self, where: str, *, arrays: bool = False) -> str:
        """One line naming the holes in the time axis (the first :data:`SHOWN`, then a count).

        Parameters
        ----------
        where : str
        arrays : bool, default False
            Name the sample after the hole by its 0-based index (``t[8000]``), not
            by its 1-based data row.

        Returns
        -------
        str
        """
        n = len(self.holes)
        shown = _listing([
            f"before {f't[{h.row - 1}]' if arrays else f'row {h.row}'} ({h.length:.4g} s "
            f"missing after t = {h.time:.6g} s)"
            for h in self.holes
        ])  # fmt: skip
        return (
            f"{where}: {n} hole{'s' if n > 1 else ''} in the time axis (an interval over "
            f"{HOLE_FACTOR:g}x the median {self.interval:.4g} s): {shown}; the model holds its "
            "state across and integrates leakage over the real time, but what the actuator did "
            "there is unknown"
        )


def _listing(items: list[str]) -> str:
    """The first :data:`SHOWN` items, then how many more."""
    more = len(items) - SHOWN
    return ", ".join(items[:SHOWN]) + (f" and {more} more" if more > 0 else "")


def _unit(unit: str | None) -> str:
    return f" {unit}" if unit else ""


@dataclass
class _Column:
    """One column's carry between blocks: its last samples and what was found so far."""

    tail: FloatArray = field(default_factory=lambda: np.empty(0))
    tail_start: int = 0  # 0-based index of tail[0]; -2 once the front is padded
    padded: bool = False
    done: int = 0  # next 0-based index to judge
    noise: list[float] = field(default_factory=list)
    weights: list[int] = field(default_factory=list)
    resolution: float = math.inf
    found: list[tuple[int, float, float, float]] = field(default_factory=list)


class Screener:
    """Finds isolated outliers and holes in a record read block by block.

    Parameters
    ----------
    columns : sequence of str
        The names of the columns to check (time is checked for holes apart).

    Examples
    --------
    >>> x = np.sin(np.linspace(0, 20, 4000)); x[1234] = 50.0
    >>> s = Screener(["voltage"])
    >>> s.add(0, {"voltage": x[:2000]}); s.add(2000, {"voltage": x[2000:]})
    >>> [(o.row, o.column, o.value) for o in s.finish().outliers]
    [(1235, 'voltage', 50.0)]
    """

    def __init__(self, columns: list[str] | tuple[str, ...]) -> None:
        self._columns = {name: _Column() for name in columns}
        self._t_last = math.nan
        self._intervals: list[tuple[float, int]] = []
        self._gaps: list[tuple[int, float, float]] = []  # (index after, t before, interval)

    def add(
        self, start: int, values: Mapping[str, FloatArray], t: FloatArray | None = None
    ) -> None:
        """Read one block.

        Parameters
        ----------
        start : int
            The 0-based index of the block's first sample in the record.
        values : mapping
            Each column's samples in the block.
        t : ndarray, optional
            The block's times (s).
        """
        for name, col in self._columns.items():
            _feed(col, start, np.asarray(values[name], dtype=np.float64))
        if t is not None and t.size:
            t = np.asarray(t, dtype=np.float64)
            if math.isfinite(self._t_last):  # steps[i] ends at t[i], sample start + i
                steps = np.diff(np.concatenate([[self._t_last], t]))
                before = np.concatenate([[self._t_last], t[:-1]])
                first = start
            else:  # steps[i] ends at t[i + 1]
                steps, before, first = np.diff(t), t[:-1], start + 1
            if steps.size:
                self._intervals.append((float(np.median(steps)), int(steps.size)))
                # candidates against this block's median; judged on the record's at the end
                for i in np.flatnonzero(steps > HOLE_FACTOR * float(np.median(steps))):
                    self._gaps.append((first + int(i), float(before[i]), float(steps[i])))
            self._t_last = float(t[-1])

    def finish(self) -> Screen:
        """What the record holds, judged on the whole record's noise and interval.

        Returns
        -------
        Screen
        """
        outliers: list[Outlier] = []
        noise: dict[str, float] = {}
        for name, col in self._columns.items():
            _feed(col, -1, np.empty(0), final=True)
            level = _weighted_median(col.noise, col.weights)
            noise[name] = level
            bar = NOISE_REACH * max(level, col.resolution if math.isfinite(col.resolution)
                                    else 0.0)  # fmt: skip
            outliers += [
                Outlier(i + 1, name, value, mean)
                for i, value, clear, mean in col.found
                if clear > bar
            ]
        interval = _weighted_median(*zip(*self._intervals, strict=True)) if self._intervals \
            else math.nan  # fmt: skip
        holes = tuple(
            Hole(i + 1, t_before, step - interval)
            for i, t_before, step in self._gaps
            if step > HOLE_FACTOR * interval
        )
        outliers.sort(key=lambda o: (o.row, o.column))
        return Screen(tuple(outliers), holes, noise, interval)


def _weighted_median(values: list[float] | tuple[float, ...], weights: list[int] | tuple[int, ...]
                     ) -> float:  # fmt: skip
    """The median of blocks' estimates, each counted by its samples (0 for none)."""
    if not values:
        return 0.0
    order = np.argsort(values)
    cum = np.cumsum(np.asarray(weights, dtype=np.float64)[order])
    return float(np.asarray(values)[order][int(np.searchsorted(cum, 0.5 * cum[-1]))])


def _feed(col: _Column, start: int, v: FloatArray, final: bool = False) -> None:
    """Judge every sample of ``col`` whose two neighbours on each side are known."""
    if final:
        if col.tail.size == 0:
            return
        p = col.tail
        # the record's last sample, repeated past its end: it has one neighbour only, so a
        # glitch there cannot be told from a step, and it is not judged
        p = np.concatenate([p, np.full(2, p[-1])])
        p0 = col.tail_start
    else:
        if v.size:
            col.noise.append(noise_level(v))
            col.weights.append(int(v.size))
            steps = np.abs(np.diff(v))
            steps = steps[steps > 0]
            if steps.size:
                col.resolution = min(col.resolution, float(steps.min()))
        p = np.concatenate([col.tail, v]) if col.tail.size else v
        p0 = col.tail_start if col.tail.size else start
        if not col.padded:
            if p.size == 0:
                return
            p = np.concatenate([np.full(2, p[0]), p])  # the first sample, repeated (as the last)
            p0 -= 2
            col.padded = True
    lo = max(col.done, p0 + 2)
    hi = p0 + p.size - 3  # the last index with two samples after it
    if hi >= lo:
        i = np.arange(lo - p0, hi - p0 + 1)
        c = p[i]
        d1 = c - p[i - 1]
        d2 = c - p[i + 1]
        clear = np.minimum(np.abs(d1), np.abs(d2))
        beside = np.maximum(np.abs(p[i - 1] - p[i - 2]), np.abs(p[i + 2] - p[i + 1]))
        hit = (d1 * d2 > 0) & (clear > LOCAL_REACH * beside)
        for k in np.flatnonzero(hit):
            j = int(i[k])
            mean = 0.5 * (float(p[j - 1]) + float(p[j + 1]))
            col.found.append((p0 + j, float(p[j]), float(clear[k]), mean))
        col.done = hi + 1
    keep = min(4, p.size)
    col.tail = p[p.size - keep :]
    col.tail_start = p0 + p.size - keep


def screen(columns: Mapping[str, ArrayLike], t: ArrayLike | None = None) -> Screen:
    """Check a record held in memory (see :class:`Screener` and the module's rules).

    Parameters
    ----------
    columns : mapping
        Each column's samples, all of one length.
    t : array_like, optional
        Sample times (s).

    Returns
    -------
    Screen

    Examples
    --------
    >>> t = np.arange(3000) * 1e-3
    >>> v = 70 - 70 * np.cos(2 * np.pi * t); v[100] = 1e4
    >>> keep = (t < 1.0) | (t >= 1.5)
    >>> found = screen({"voltage": v[keep]}, t[keep])
    >>> [o.row for o in found.outliers], [(h.row, round(h.length, 3)) for h in found.holes]
    ([101], [(1001, 0.5)])
    """
    s = Screener(list(columns))
    s.add(0, {k: np.asarray(v, dtype=np.float64) for k, v in columns.items()},
          None if t is None else np.asarray(t, dtype=np.float64))  # fmt: skip
    return s.finish()
