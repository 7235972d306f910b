r"""The lead-in's probe: small sines whose response measures the loop's timing.

The learning law allows for every timing the model's identification could not rule out
(:func:`~piezohyst.control.learning.design.design_learning`). A model identified on slow
records knows its lag poorly at the harmonics a fast scan needs: on the two-state capacitor
behind a 4 ms amplifier, ``ActivePI`` with identified dynamics states its delay to
:math:`\pm 1.2` ms (95 %), 123 degrees at 200 Hz, where the loop's measured phase error was
one degree. The lead-in trial, which is not learned from, can carry a few small sines
(:data:`AMPLITUDE` of the trajectory's span each, at :data:`FREQUENCIES` harmonics of the
trial that are not harmonics of the scan); the next trial repeats the lead-in's reference
without them, so the difference of the two trials' readings is the loop's response to the
sines (the hysteresis and the scan's own harmonics are the same in both; a slow drift is
fitted out by a cubic). Its phase at each sine, with its standard error from the fit's
residual, rules out the timings it disagrees with (:class:`Response`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FloatArray = np.ndarray

__all__ = ["AMPLITUDE", "FREQUENCIES", "Response", "probe_bins", "probe_signal", "response",
           "scan_bin"]  # fmt: skip

#: amplitude of each sine, over the trajectory's span: 0.2 % (eight of them: 0.4 % RMS); at
#: 0.1 % noise on 1000 readings, each phase is measured to about 1.5 degrees
AMPLITUDE = 2e-3
#: sines in a probe, spread geometrically from 1.5 times the scan's frequency to 0.4 of the
#: sample rate
FREQUENCIES = 8
#: readings the difference must have, at least, to be fitted (of the trial's)
USABLE = 0.5
#: the drift fitted beside the sines reaches up to the lowest sine's frequency over this
DRIFT = 3.0
#: the scan's harmonics fitted beside the sines, the lowest this many (a slow scan has
#: hundreds, and its error is small there; a 10 Hz scan of 1000 samples has 49)
HARMONICS = 64
#: the start of the lead-in not used (of the trial): the actuator's arrival leaves a transient
#: whose fast part reaches the sines (on the two-state capacitor it doubled their phases'
#: errors when the first 200 ms were used)
SETTLE = 0.2
#: a fit worse conditioned than this measures nothing: over part of the trial (a lead-in the
#: slew limit ramped in, and the samples until its extremes wiped the ramp out) the sines,
#: at odd harmonics of the trial, are sums of the scan's even ones there; on a 4 Hz scan of
#: 500 samples half of them were usable and the condition number was 2e15 (the phases read
#: 175 degrees off, and the learner said the loop was late), 6 over the whole trial
CONDITION = 1e8


@dataclass(frozen=True)
class Response:
    """The loop's response to the probe: at each sine, the reading's change over the
    reference's (complex: gain and phase), and the phase's standard error (rad).

    Attributes
    ----------
    bins : ndarray of int
        Harmonics of the trial (``numpy.fft.rfftfreq`` indices).
    ratio : complex ndarray
    phase_stderr : ndarray
    """

    bins: np.ndarray
    ratio: np.ndarray
    phase_stderr: FloatArray


def probe_bins(desired: FloatArray) -> np.ndarray:
    """The harmonics of the trial a probe sines at: geometric from 1.5 times the scan's
    fundamental (the strongest harmonic of ``desired``) to 0.4 of the sample rate, none on a
    harmonic of the scan (where the scan's own error sits); empty for a trial too short.

    Parameters
    ----------
    desired : ndarray
        One trial of the trajectory.

    Returns
    -------
    ndarray of int
    """
    n = desired.size
    if n < 64:
        return np.zeros(0, dtype=int)
    k0 = scan_bin(desired)
    top = int(0.4 * n)  # 0.4 of the sample rate, in the trial's harmonics
    low = max(math.ceil(1.5 * k0), 2)
    if top <= low:
        return np.zeros(0, dtype=int)
    bins: list[int] = []
    for k in np.geomspace(low, top, FREQUENCIES):
        b = round(float(k))
        # distinct, off the scan's harmonics (a scan of one cycle a trial has every harmonic:
        # its own error is the same in both trials and falls out of their difference)
        while b in bins or (k0 > 1 and b % k0 == 0):
            b += 1
        if b < n // 2:
            bins.append(b)
    return np.array(bins, dtype=int)


def scan_bin(desired: FloatArray) -> int:
    """The scan's fundamental: the strongest harmonic of the trial's trajectory.

    Parameters
    ----------
    desired : ndarray

    Returns
    -------
    int
    """
    spectrum = np.abs(np.fft.rfft(desired - desired.mean()))
    return int(np.argmax(spectrum[1:])) + 1 if spectrum.size > 1 else 1


def probe_signal(bins: np.ndarray, samples: int, span: float) -> FloatArray:
    """The probe: a sine of :data:`AMPLITUDE` times ``span`` at each harmonic, with Schroeder
    phases (a low crest factor), periodic over the trial.

    Parameters
    ----------
    bins : ndarray of int
    samples : int
    span : float

    Returns
    -------
    ndarray
    """
    k = np.arange(samples)
    out = np.zeros(samples)
    for b, phase in zip(bins, _phases(bins.size), strict=True):
        out += np.cos(2 * math.pi * b * k / samples + phase)
    return AMPLITUDE * span * out


def _phases(m: int) -> FloatArray:
    """Schroeder's phases of ``m`` sines (a low crest factor): the probe's, and its fit's."""
    j = np.arange(m)
    return -math.pi * j * (j + 1) / max(m, 1)


def response(
    with_probe: FloatArray, without: FloatArray, usable: np.ndarray, bins: np.ndarray,
    desired: FloatArray,
) -> Response | None:  # fmt: skip
    """The loop's response to the probe, from the readings of the trial that carried it and of
    the next (the same reference without it), in the desired's units.

    Parameters
    ----------
    with_probe, without : ndarray
        The two trials' readings (NaN where missing).
    usable : ndarray of bool
        Readings that stand for the scan (not the ramp-in).
    bins : ndarray of int
        The probe's harmonics (:func:`probe_bins`).
    desired : ndarray
        The trajectory (its span scales the probe; the trials may differ at its harmonics,
        which are fitted out with the drift).

    Returns
    -------
    Response or None
        None where too few readings are usable, or where they cannot tell the sines from the
        scan's harmonics (:data:`CONDITION`).
    """
    n = with_probe.size
    settled = np.arange(n) >= SETTLE * n  # the arrival's fast transient has decayed
    ok = usable & settled & np.isfinite(with_probe) & np.isfinite(without)
    if bins.size == 0 or ok.sum() < USABLE * n:
        return None
    k = np.flatnonzero(ok)
    x = k / n
    m = bins.size
    columns = []
    for b, phase in zip(bins, _phases(m), strict=True):
        columns += [np.cos(2 * math.pi * b * x + phase), np.sin(2 * math.pi * b * x + phase)]
    # what the lead-in's arrival leaves: a slow drift (creep, relaxation), below a third of the
    # lowest sine; a cosine series over the usable stretch (a drift need not be periodic)
    first, length = int(k[0]), int(k[-1] - k[0] + 1)
    slow = int(2 * length * bins.min() / (DRIFT * n))
    u = (k - first + 0.5) / length
    columns += [np.cos(math.pi * j * u) for j in range(slow + 1)]
    k0 = scan_bin(desired)
    probed = set(bins.tolist())
    scan = [h for h in range(k0, n // 2, k0) if h not in probed][:HARMONICS]
    for h in scan:  # the scan's own harmonics: what else the two trials differ by
        columns += [np.cos(2 * math.pi * h * x), np.sin(2 * math.pi * h * x)]
    a = np.column_stack(columns)
    if np.linalg.cond(a) > CONDITION:  # the stretch cannot tell the sines from the scan's
        return None
    diff = (with_probe - without)[ok]
    coef, *_ = np.linalg.lstsq(a, diff, rcond=None)
    resid = diff - a @ coef
    dof = max(k.size - a.shape[1], 1)
    var = float(resid @ resid) / dof
    cov = var * np.linalg.pinv(a.T @ a)
    amp = AMPLITUDE * float(np.ptp(desired))
    c, s = coef[0 : 2 * m : 2], coef[1 : 2 * m : 2]
    ratio = (c - 1j * s) / amp  # the reading's phasor over the probe's (e^{i w t})
    sd = np.sqrt(np.maximum(np.diag(cov)[: 2 * m], 0.0)).reshape(m, 2).max(axis=1)
    phase_stderr = sd / np.maximum(np.abs(c - 1j * s), 1e-300)
    return Response(bins.copy(), ratio, phase_stderr)
