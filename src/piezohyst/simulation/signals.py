"""Excitation signals for identification and validation (V over s).

Every function returns ``(t, v)``: time stamps (s) from 0 at ``rate`` (Hz)
and the voltage (V). Unipolar signals run 0..``amplitude`` like the paper's
140 V drive; ``bipolar`` runs -amplitude..+amplitude.
"""

from __future__ import annotations

import numpy as np

from .._validation import FloatArray, check_float
from ..errors import ParameterError

__all__ = ["SIGNALS", "make_signal"]


def _time(duration: float, rate: float) -> FloatArray:
    n = round(duration * rate)
    return np.arange(n, dtype=np.float64) / rate


def fixed(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Quasi-static raised cosine 0..amplitude at one amplitude (paper Fig. 7 left)."""
    t = _time(duration, rate)
    return 0.5 * amplitude * (1.0 - np.cos(2 * np.pi * frequency * t))


def multi(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Raised cosine whose amplitude steps down and up again: minor loops (Fig. 7 right)."""
    t = _time(duration, rate)
    cycle = np.floor(t * frequency).astype(int)
    levels = np.array([1.0, 0.8, 0.6, 0.4, 0.6, 0.8])
    envelope = levels[cycle % levels.size]
    return np.asarray(0.5 * amplitude * envelope * (1.0 - np.cos(2 * np.pi * frequency * t)))


def bipolar(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Sine -amplitude..+amplitude starting at 0 V."""
    t = _time(duration, rate)
    return amplitude * np.sin(2 * np.pi * frequency * t)


def triangle(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Triangle 0..amplitude (constant |dV/dt|), the usual ferroelectric test wave."""
    t = _time(duration, rate)
    phase = (t * frequency) % 1.0
    return amplitude * (1.0 - np.abs(2.0 * phase - 1.0))


def two_rate(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Equal raised-cosine loops at ``frequency`` then at ``frequency / 4``.

    Hysteresis is rate independent, leakage is not: the same loops run four
    times slower carry four times the leaked charge, which pins R apart from
    the hysteresis.
    """
    t = _time(duration, rate)
    fast_end = duration / 5.0  # one fifth of the time fast, the rest four times slower
    phase = np.where(
        t < fast_end, frequency * t, frequency * fast_end + 0.25 * frequency * (t - fast_end)
    )
    return 0.5 * amplitude * (1.0 - np.cos(2 * np.pi * phase))


def hold(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Raised-cosine loops with a hold at the top and bottom of every cycle.

    During a hold the hysteresis output stands still while leakage keeps
    integrating, so the growth is seen on its own.
    """
    t = _time(duration, rate)
    period = 1.0 / frequency
    ramp = 0.25 * period  # rising and falling parts take a quarter period each
    phase = t % period
    rise = np.clip(phase / ramp, 0, 1)
    fall = np.clip((phase - 0.5 * period) / ramp, 0, 1)
    shape = 0.5 * (1 - np.cos(np.pi * rise)) - 0.5 * (1 - np.cos(np.pi * fall))
    return amplitude * shape


def decaying(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Loops that decay towards a centre that moves, repeating every two blocks of ~10 s.

    Each block holds whole cycles (about 10 s): the loops start full range
    and decay to 15 % of what the centre allows; the centre moves smoothly
    between 25 % and 75 % of ``amplitude`` over two blocks, so the signal
    repeats exactly (after the first cycle, which rises from 0) and stays
    continuous. Minor loops of many sizes at several
    places in the major loop: where a PI model's congruent minor loops differ
    most from a real actuator's.
    """
    t = _time(duration, rate)
    block = max(1, round(10.0 * frequency)) / frequency  # whole cycles: sin = 0 at the edges
    centre = 0.5 - 0.25 * np.sin(np.pi * t / block)
    decay = 0.15 + 0.85 * np.exp(-3.0 * (t % block) / block)
    reach = np.minimum(centre, 1.0 - centre) * decay
    rise = 0.5 * (1 - np.cos(np.pi * np.clip(t * frequency, 0.0, 1.0)))  # from 0 in one cycle
    return np.asarray(amplitude * rise * (centre + reach * np.sin(2 * np.pi * frequency * t)))


_LEVELS = np.array([1.0, 0.0, 0.5, 1.0, 0.25, 0.75, 0.0, 1.0, 0.5, 0.0, 0.75, 0.25, 1.0, 0.0])


def levels(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Moves between several levels (fractions of amplitude), each followed by a hold.

    Every move takes half a period (raised cosine), every hold the other half.
    Holds at several voltages tell leakage that grows with voltage (or a
    constant bias current) apart from ohmic leakage, which holds at 0 V and the
    top alone cannot (see ``docs/bench.md``).
    """
    t = _time(duration, rate)
    period = 1.0 / frequency
    seg = np.floor(t / period).astype(int)
    phase = (t % period) / (0.5 * period)
    frm = _LEVELS[(seg - 1) % _LEVELS.size]
    frm[seg == 0] = 0.0
    to = _LEVELS[seg % _LEVELS.size]
    move = 0.5 * (1 - np.cos(np.pi * np.clip(phase, 0.0, 1.0)))
    return np.asarray(amplitude * (frm + (to - frm) * move))


def multifreq(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Thirds of the record at ``frequency``, 10x and 40x it, loops decaying in each third.

    For identifying rate dependence (an amplifier's lag, sensor filters): at
    one frequency lag and hysteresis cannot be told apart, at several they can.
    Each third holds whole cycles (raised cosines from 0) whose amplitude
    decays from ``amplitude`` to 30 % of it, so the record is continuous.
    """
    t = _time(duration, rate)
    out = np.zeros_like(t)
    third = duration / 3.0
    start = 0.0
    for factor in (1.0, 10.0, 40.0):
        f = frequency * factor
        cycles = max(1, int(third * f))
        stop = start + cycles / f
        seg = (t >= start) & (t < stop)
        tau = t[seg] - start
        decay = 0.3 + 0.7 * np.exp(-3.0 * tau / (stop - start))
        loops = 0.5 * (1 - np.cos(2 * np.pi * f * tau))
        out[seg] = amplitude * decay * loops
        start = stop
    return out


_STAIRCASE = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 0.75, 0.5, 0.25, 0.0])


def staircase(amplitude: float, frequency: float, duration: float, rate: float) -> FloatArray:
    """Holds at 0, 25, 50, 75, 100, 75, 50, 25, 0 % of ``amplitude``, ``1/frequency`` s each.

    The record for a leakage calibration (:func:`~piezohyst.calibrate_leakage`):
    every level is held once on the way up and once on the way down, which
    tells a leak that depends on the charge (the charge amplifier's own
    discharge) from one that depends on the voltage. Each hold starts with a
    raised-cosine move of a tenth of it (at most 0.5 s); the pattern repeats.
    """
    t = _time(duration, rate)
    period = 1.0 / frequency
    seg = np.floor(t / period).astype(int)
    to = _STAIRCASE[seg % _STAIRCASE.size]
    frm = _STAIRCASE[(seg - 1) % _STAIRCASE.size]
    frm[seg == 0] = 0.0
    move = min(0.5, 0.1 * period)
    phase = np.clip((t - seg * period) / move, 0.0, 1.0)
    return np.asarray(amplitude * (frm + (to - frm) * 0.5 * (1 - np.cos(np.pi * phase))))


SIGNALS = {
    "fixed": fixed,
    "decaying": decaying,
    "multi": multi,
    "bipolar": bipolar,
    "triangle": triangle,
    "two-rate": two_rate,
    "hold": hold,
    "levels": levels,
    "staircase": staircase,
    "multifreq": multifreq,
}


def make_signal(
    name: str,
    *,
    amplitude: float = 140.0,
    frequency: float = 0.5,
    duration: float = 20.0,
    rate: float = 1000.0,
) -> tuple[FloatArray, FloatArray]:
    """Time stamps (s) and voltage (V) of the named excitation.

    Parameters
    ----------
    name : str
        One of :data:`SIGNALS`.
    amplitude : float, default 140
        V, the peak.
    frequency : float, default 0.5
        Hz, the base frequency.
    duration : float, default 20
        s.
    rate : float, default 1000
        Hz, the sample rate.

    Returns
    -------
    t, voltage : ndarray

    Raises
    ------
    ParameterError
        An unknown name, a value out of range, fewer than 2 samples.

    Examples
    --------
    >>> t, v = make_signal("triangle", amplitude=100, frequency=1, duration=1, rate=4)
    >>> t.tolist(), v.tolist()
    ([0.0, 0.25, 0.5, 0.75], [0.0, 50.0, 100.0, 50.0])
    """
    if name not in SIGNALS:
        msg = f"The 'signal' parameter must be one of {sorted(SIGNALS)}. Got {name!r} instead."
        raise ParameterError(msg)
    amplitude = check_float(amplitude, "amplitude", "make_signal", 0.0, 1e5, low_open=True)
    frequency = check_float(frequency, "frequency", "make_signal", 0.0, 1e4, low_open=True)
    duration = check_float(duration, "duration", "make_signal", 0.0, 1e6, low_open=True)
    rate = check_float(rate, "rate", "make_signal", 0.0, 1e7, low_open=True)
    if duration * rate < 2:
        msg = f"duration x rate must give at least 2 samples. Got {duration * rate:g}."
        raise ParameterError(msg)
    t = _time(duration, rate)
    return t, SIGNALS[name](amplitude, frequency, duration, rate)
