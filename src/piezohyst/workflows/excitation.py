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

``multisine`` is for a structure's dynamics (:class:`~piezohyst.StructureModel`): a
random-phase multisine with a line at every multiple of the base frequency up to the band,
around the middle of the range, its peaks flattened (crest-factor reduction) so the range
holds as much power as it can; :data:`PERIODS` periods after one that fades it in, one
that fades it out. For several actuators each plays its own lines (every n-th, interleaved):
at every line one actuator alone moves the structure, so one record separates their
responses (with the same lines on every actuator, one record holds one direction of the
inputs per line, and the responses are told apart only by how smooth they are).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray, check_float
from ..errors import ParameterError

__all__ = ["KINDS", "Excitation", "excitation"]

KINDS = ("identification", "holds", "multifreq", "multisine")
STAIRCASE = (0.0, 0.25, 0.5, 0.75, 1.0, 0.75, 0.5, 0.25, 0.0)
SHORT_STAIRCASE = (0.0, 0.5, 1.0, 0.5, 0.0)
FACTORS = (1.0, 10.0, 40.0)  # loop frequencies, times the base frequency
CYCLES = 20  # loops per frequency: two blocks of ten, the centre's whole swing
MIN_SAMPLES_PER_CYCLE = 20
#: The multisine's steady periods, after one that fades it in and before one that fades it out
PERIODS = 8
#: Its highest line, as a share of the sample rate, unless ``band`` says (below where a
#: DAQ's output filter rolls off)
BAND_SHARE = 0.4
#: The crest-factor reduction's rounds: clip the peaks at :data:`CREST_CLIP` times the RMS,
#: give the lines back their amplitude
CREST_ROUNDS = 200
CREST_CLIP = 1.4


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
    actuators : int
        Columns of ``voltage`` (1: a vector).
    lines : tuple of (float, float, int) or None
        A multisine's lowest and highest line (Hz) and how many each actuator plays.
    crest : float
        A multisine's peak over its RMS, per actuator, the largest (0: not a multisine).
    swing : tuple of (float, float, bool)
        A multisine's middle and peak (V), and whether the slew limit lowered the peak.
    steady : tuple of (int, int)
        A multisine's steady periods, as the samples ``voltage[start:stop]``.
    """

    kind: str
    t: FloatArray
    voltage: FloatArray
    sample_rate: float
    rest: float
    holds: list[tuple[float, float, float]] = field(default_factory=list)
    frequencies: list[float] = field(default_factory=list)
    slew_rate: float = math.inf
    actuators: int = 1
    lines: tuple[float, float, int] | None = None
    crest: float = 0.0
    swing: tuple[float, float, bool] | None = None
    steady: tuple[int, int] | None = None

    @property
    def peak_slew(self) -> float:
        """The fastest change between two samples (V/s)."""
        return float(np.abs(np.diff(self.voltage, axis=0)).max() * self.sample_rate)

    def summary(self) -> str:
        """One line: samples, duration, range, slew, holds and loops."""
        parts = [
            f"{self.kind}: {self.voltage.shape[0]} samples ({self.t[-1]:.4g} s) at "
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
        if self.lines is not None:
            lo, hi, count = self.lines
            nth = {2: "second", 3: "third"}.get(self.actuators, f"{self.actuators}th")
            own = (f"{self.actuators} actuators, each on its own {count} lines (every {nth}, "
                   "interleaved)" if self.actuators > 1 else f"{count} lines")  # fmt: skip
            parts.append(f"{own} from {lo:.4g} to {hi:.4g} Hz, crest factor {self.crest:.3g}")
        if self.swing is not None:
            middle, peak, lowered = self.swing
            parts.append(f"{middle:g} V +- {peak:.4g} V" + (" (the slew limit lowered it)"
                                                            if lowered else ""))  # fmt: skip
        if self.steady is not None:
            a, b = self.steady
            parts.append(f"steady periods from {self.t[a]:.6g} s to {self.t[b - 1]:.6g} s")
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


def multisine(
    period: int, lines: np.ndarray, actuators: int, seed: int
) -> tuple[FloatArray, float]:
    """One period (``period`` samples, ``actuators`` columns) of random-phase multisines,
    actuator ``q`` on ``lines[q::actuators]`` (unit amplitude each), each column's peaks
    flattened by clipping them and giving the lines back their amplitude
    (:data:`CREST_ROUNDS` rounds, the lowest crest factor kept), scaled to a peak of 1.
    Returns it and the largest crest factor (peak over RMS)."""
    rng = np.random.default_rng(seed)
    out = np.empty((period, actuators))
    crest = 0.0
    for q in range(actuators):
        own = lines[q::actuators]
        spec = np.zeros(period // 2 + 1, dtype=complex)
        spec[own] = np.exp(2j * np.pi * rng.random(own.size))
        best, best_crest = None, math.inf
        for _ in range(CREST_ROUNDS):
            x = np.fft.irfft(spec, n=period)
            c = float(np.max(np.abs(x)) / np.sqrt(np.mean(x**2)))
            if c < best_crest:
                best, best_crest = x, c
            level = CREST_CLIP * np.sqrt(np.mean(x**2))
            clipped = np.fft.rfft(np.clip(x, -level, level))
            spec = np.zeros_like(spec)
            spec[own] = np.exp(1j * np.angle(clipped[own]))
        assert best is not None
        out[:, q] = best / np.max(np.abs(best))
        crest = max(crest, best_crest)
    return out, crest


def _multisine_excitation(
    build: _Builder, v_min: float, v_max: float, f0: float, band: float | None,
    periods: int, actuators: int, seed: int,
) -> tuple[FloatArray, dict[str, Any]]:  # fmt: skip
    """The multisine's samples (N, actuators): the builder's move to the middle of the
    range, one period fading in, ``periods`` steady, one fading out; and the
    :class:`Excitation`'s fields that say what it is."""
    fs = build.rate
    period = round(fs / f0)
    top = BAND_SHARE * fs if band is None else band
    if not 0 < top < fs / 2:
        msg = f"the band must be above 0 and below half the sample rate ({fs / 2:g} Hz): {top:g}"
        raise ParameterError(msg)
    k = np.arange(1, math.floor(top * period / fs + 1e-9) + 1)
    k = k[k < period / 2]
    if k.size < 2 * actuators:
        msg = (
            f"a multisine from {fs / period:.4g} Hz to {top:g} Hz holds {k.size} lines: give "
            f"each of the {actuators} actuators two at least (a lower --frequency, or a "
            "wider band)"
        )
        raise ParameterError(msg)
    one, crest = multisine(period, k, actuators, seed)
    # faded in over the first period from the middle (exactly there at its first sample),
    # out over the last to the middle (exactly there at its last)
    fade = 0.5 * (1.0 - np.cos(np.pi * np.arange(period + 1) / period))  # 0 ... 1
    body = np.tile(one, (periods + 2, 1))
    body[:period] *= fade[:-1, None]
    body[-period:] *= fade[:0:-1, None] - fade[0]  # 1 ... 0
    centre, half = 0.5 * (v_min + v_max), 0.5 * (v_max - v_min)
    slope = float(np.max(np.abs(np.diff(body, axis=0)))) * fs
    lowered = half > build.slew / slope
    half = min(half, build.slew / slope)  # the slew limit lowers the amplitude
    build.move(centre)
    head = np.concatenate(build.parts)
    build.parts = [np.array([centre])]  # the builder goes on from the middle
    samples = np.vstack([np.repeat(head[:, None], actuators, axis=1), centre + half * body])
    lines = (float(k[0] * fs / period), float(k[-1] * fs / period), int(k[::actuators].size))
    start = head.size + period
    return samples, {"lines": lines, "crest": crest, "swing": (centre, half, lowered),
                     "steady": (start, start + periods * period)}  # fmt: skip


def excitation(
    kind: str = "identification",
    *,
    v_min: float,
    v_max: float,
    sample_rate: float,
    slew_rate: float | None = None,
    frequency: float = 1.0,
    hold: float = 5.0,
    actuators: int = 1,
    band: float | None = None,
    periods: int = PERIODS,
    seed: int = 0,
) -> Excitation:
    """A voltage excitation to play on the rig (see the module's notes for the kinds).

    Parameters
    ----------
    kind : {"identification", "holds", "multifreq", "multisine"}
    v_min, v_max : float
        The actuator's limits (V); the excitation spans them.
    sample_rate : float
        Of the DAQ output (Hz).
    slew_rate : float, optional
        The fastest change allowed (V/s); default none beyond the loops' own
        (moves take a quarter of a base period, at most 1 s). Loop frequencies
        are lowered to keep it, and moves slowed.
    frequency : float, default 1
        The base loop frequency (Hz); a multisine's lowest line and spacing (its period
        is one over it).
    hold : float, default 5
        Each hold's length (s). :func:`~piezohyst.calibrate_leakage` drops the
        first 0.25 s of a hold and needs 1 s; longer holds measure the leakage
        better.
    actuators : int, default 1
        A multisine's columns, each on its own lines (the other kinds drive one).
    band : float, optional
        A multisine's highest line (Hz); default :data:`BAND_SHARE` of the sample rate.
    periods : int, default :data:`PERIODS`
        A multisine's steady periods.
    seed : int, default 0
        A multisine's random phases.

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
    if not isinstance(actuators, int) or not 1 <= actuators <= 64:
        msg = f"'actuators' must be an integer from 1 to 64. Got {actuators!r}."
        raise ParameterError(msg)
    if actuators > 1 and kind != "multisine":
        msg = f"a {kind} excitation drives one actuator: several take --kind multisine"
        raise ParameterError(msg)
    if not isinstance(periods, int) or not 1 <= periods <= 10_000:
        msg = f"'periods' must be an integer from 1 to 10000. Got {periods!r}."
        raise ParameterError(msg)
    rest = float(np.clip(0.0, v_min, v_max))
    build = _Builder(fs, slew, rest, move_time=min(0.25 / f0, 1.0))
    build.hold(min(1.0, hold), settle=True)  # at rest before anything moves
    if kind == "multisine":
        head, said = _multisine_excitation(build, v_min, v_max, f0, band, periods, actuators,
                                           seed)  # fmt: skip
        build.move(rest)
        build.hold(min(1.0, hold), settle=True)
        tail = build.done()[1:]
        v = np.vstack([head, np.repeat(tail[:, None], actuators, axis=1)])
        v = np.clip(v, v_min, v_max)
        v = v[:, 0] if actuators == 1 else v
        t = np.arange(v.shape[0]) / fs
        return Excitation(kind, t, v, fs, rest, slew_rate=slew, actuators=actuators, **said)
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
