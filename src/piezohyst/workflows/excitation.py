"""Excitations to play on a real rig: the voltage a lab loads into its own DAQ software,
records the response to, and fits (``piezohyst excite``).

Every excitation starts and ends at rest (0 V, or the limit nearer to it), stays inside
``[v_min, v_max]``, never changes faster than the slew limit, and is sized from the
actuator's range and the sample rate. Its parts:

* **holds**: the staircase 0, 25, 50, 75, 100, 75, 50, 25, 0 % of the range, each level
  held ``hold`` s: reached from below and from above, so a leakage calibration
  (:func:`~piezohyst.calibrate_leakage`) tells a leak that follows the voltage from
  one that follows the charge;
* **loops**: one full-range cycle, then loops that decay to 15 % of what a centre allows,
  the centre moving between 25 % and 75 % of the range: minor loops of many sizes at
  many places of the major loop;
* several **frequencies**: the loops again at 10 and 40 times the base frequency (as far
  as the slew limit and 20 samples per cycle allow): at one frequency an amplifier's
  lag and hysteresis cannot be told apart.

``identification`` is holds at 0, 50, 100, 50 and 0 %, then the loops at the base
frequency and at 10 times it; ``holds`` is the staircase alone; ``multifreq`` the
loops at every frequency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._validation import FloatArray, check_float
from ..errors import ParameterError

__all__ = ["KINDS", "Excitation", "excitation"]

KINDS = ("identification", "holds", "multifreq")
STAIRCASE = (0.0, 0.25, 0.5, 0.75, 1.0, 0.75, 0.5, 0.25, 0.0)
SHORT_STAIRCASE = (0.0, 0.5, 1.0, 0.5, 0.0)
FACTORS = (1.0, 10.0, 40.0)  # loop frequencies, times the base frequency
CYCLES = 20  # loops per frequency: two blocks of ten, the centre's whole swing
MIN_SAMPLES_PER_CYCLE = 20


@dataclass(frozen=True)
class Excitation:
    """A voltage excitation and what it holds.

    Attributes
    ----------
    kind : str
    t, voltage : ndarray
        Time (s, from 0) and command (V).
    sample_rate : float
        Hz.
    rest : float
        The voltage it starts and ends at (V).
    holds : list of (float, float, float)
        Each hold's start and stop (s) and voltage (V).
    frequencies : list of float
        The loops' frequencies (Hz).
    slew_rate : float
        The limit it keeps (V/s; inf: none asked for).
    """

    kind: str
    t: FloatArray
    voltage: FloatArray
    sample_rate: float
    rest: float
    holds: list[tuple[float, float, float]] = field(default_factory=list)
    frequencies: list[float] = field(default_factory=list)
    slew_rate: float = math.inf

    @property
    def peak_slew(self) -> float:
        """The fastest change between two samples (V/s)."""
        return float(np.abs(np.diff(self.voltage)).max() * self.sample_rate)

    def summary(self) -> str:
        """One line: samples, duration, range, slew, holds and loops."""
        parts = [
            f"{self.kind}: {self.voltage.size} samples ({self.t[-1]:.4g} s) at "
            f"{self.sample_rate:g} Hz, [{self.voltage.min():g}, {self.voltage.max():g}] V, "
            f"from and to {self.rest:g} V, peak slew {self.peak_slew:.4g} V/s"
        ]
        if self.holds:
            levels = sorted({round(v, 9) for _, _, v in self.holds})
            length = min(b - a for a, b, _ in self.holds)
            at = ", ".join(f"{v:g}" for v in levels)
            parts.append(f"{len(self.holds)} holds of {length:.3g} s at {at} V")
        if self.frequencies:
            parts.append(f"loops at {', '.join(f'{f:.3g}' for f in self.frequencies)} Hz")
        return "; ".join(parts)


class _Builder:
    """Segments joined by moves, sample by sample at one rate."""

    def __init__(self, rate: float, slew: float, rest: float, move_time: float) -> None:
        self.rate = rate
        self.slew = slew
        self.move_time = move_time
        self.parts: list[FloatArray] = [np.array([rest])]
        self.holds: list[tuple[float, float, float]] = []

    @property
    def now(self) -> float:
        return float(self.parts[-1][-1])

    @property
    def samples(self) -> int:
        return sum(p.size for p in self.parts)

    def move(self, to: float) -> None:
        """A raised cosine to ``to``: its peak slope, pi/2 * step / duration, within the limit."""
        step = to - self.now
        if step == 0.0:
            return
        duration = max(self.move_time, 0.5 * math.pi * abs(step) / self.slew)
        n = max(2, math.ceil(duration * self.rate))
        s = np.arange(1, n + 1) / n
        path = self.now + step * 0.5 * (1.0 - np.cos(np.pi * s))
        path[-1] = to  # exactly: a level, a limit, the rest voltage
        self.parts.append(path)

    def hold(self, seconds: float, *, settle: bool = False) -> None:
        n = max(1, round(seconds * self.rate))
        start = self.samples / self.rate
        self.parts.append(np.full(n, self.now))
        if not settle:
            self.holds.append((start, start + n / self.rate, self.now))

    def loops(self, f: float, lo: float, hi: float) -> float:
        """One full-range cycle, then :data:`CYCLES` loops around a centre that swings once
        over them; at ``f`` or just below it, a whole number of samples per cycle (so
        every cycle ends where it began). Returns the frequency played."""
        per_cycle = math.ceil(self.rate / f - 1e-9)
        f = self.rate / per_cycle
        span = hi - lo
        self.move(lo + 0.5 * span)
        first = np.arange(1, per_cycle + 1) / self.rate
        self.parts.append(lo + span * (0.5 + 0.5 * np.sin(2 * np.pi * f * first)))
        block = CYCLES / 2 / f
        t = np.arange(1, CYCLES * per_cycle + 1) / self.rate
        centre = 0.5 - 0.25 * np.sin(np.pi * t / block)
        decay = 0.15 + 0.85 * np.exp(-3.0 * (t % block) / block)
        reach = np.minimum(centre, 1.0 - centre) * decay
        self.parts.append(lo + span * (centre + reach * np.sin(2 * np.pi * f * t)))
        self.parts[-2][-1] = self.parts[-1][-1] = lo + 0.5 * span  # sin(2 pi k) is not 0
        return f

    def done(self) -> FloatArray:
        return np.concatenate(self.parts)


def excitation(
    kind: str = "identification",
    *,
    v_min: float,
    v_max: float,
    sample_rate: float,
    slew_rate: float | None = None,
    frequency: float = 1.0,
    hold: float = 5.0,
) -> Excitation:
    """A voltage excitation to play on the rig (see the module's notes for the kinds).

    Parameters
    ----------
    kind : {"identification", "holds", "multifreq"}
    v_min, v_max : float
        The actuator's limits (V); the excitation spans them.
    sample_rate : float
        Of the DAQ output (Hz).
    slew_rate : float, optional
        The fastest change allowed (V/s); default none beyond the loops' own
        (moves take a quarter of a base period, at most 1 s). Loop frequencies
        are lowered to keep it, and moves slowed.
    frequency : float, default 1
        The base loop frequency (Hz).
    hold : float, default 5
        Each hold's length (s). :func:`~piezohyst.calibrate_leakage` drops the
        first 0.25 s of a hold and needs 1 s; longer holds measure the leakage
        better.

    Returns
    -------
    Excitation

    Raises
    ------
    ParameterError
        Limits that are not a range, a rate or frequency out of range, a slew
        limit too low to reach the range in a minute.
    """
    if kind not in KINDS:
        msg = f"The kind of excitation must be one of {', '.join(KINDS)}. Got {kind!r}."
        raise ParameterError(msg)
    v_min = check_float(v_min, "v_min", "excitation", -1e5, 1e5)
    v_max = check_float(v_max, "v_max", "excitation", -1e5, 1e5)
    if not v_max > v_min:
        msg = f"v_max must be above v_min. Got [{v_min:g}, {v_max:g}] V."
        raise ParameterError(msg)
    fs = check_float(sample_rate, "sample_rate", "excitation", 0.0, 1e7, low_open=True)
    f0 = check_float(frequency, "frequency", "excitation", 0.0, 1e4, low_open=True)
    hold = check_float(hold, "hold", "excitation", 0.0, 3600.0, low_open=True)
    span = v_max - v_min
    if f0 > fs / MIN_SAMPLES_PER_CYCLE:
        msg = (
            f"a {f0:g} Hz loop has fewer than {MIN_SAMPLES_PER_CYCLE} samples per cycle at "
            f"{fs:g} Hz; lower the frequency or raise the sample rate"
        )
        raise ParameterError(msg)
    slew = math.inf if slew_rate is None else float(slew_rate)
    if not slew >= span / 60.0:
        msg = (
            f"a slew limit of {slew_rate} V/s is below the range over a minute "
            f"({span / 60.0:.3g} V/s); give it in V/s"
        )
        raise ParameterError(msg)
    rest = float(np.clip(0.0, v_min, v_max))
    build = _Builder(fs, slew, rest, move_time=min(0.25 / f0, 1.0))
    build.hold(min(1.0, hold), settle=True)  # at rest before anything moves
    if kind in ("identification", "holds"):
        for level in STAIRCASE if kind == "holds" else SHORT_STAIRCASE:
            build.move(v_min + level * span)
            build.hold(hold)
    frequencies: list[float] = []
    if kind in ("identification", "multifreq"):
        for factor in FACTORS[:2] if kind == "identification" else FACTORS:
            # the loops' peak slope: pi f span (a full-range sine), and under 10 % more
            # from the moving centre and the decay; and 20 samples per cycle
            f = min(f0 * factor, slew / (1.1 * math.pi * span), fs / MIN_SAMPLES_PER_CYCLE)
            if not frequencies or f > frequencies[-1] * 1.5:
                frequencies.append(build.loops(f, v_min, v_max))
    build.move(rest)
    build.hold(min(1.0, hold), settle=True)
    v = np.clip(build.done(), v_min, v_max)
    t = np.arange(v.size) / fs
    return Excitation(kind, t, v, fs, rest, build.holds, frequencies, slew)
