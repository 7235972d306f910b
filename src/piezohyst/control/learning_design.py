r"""The learning law's design: the choice of gain and robustness filter, and the condition
under which the error shrinks from trial to trial (see :mod:`piezohyst.control.learning`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from .._validation import check_float
from ..model.dynamics import filter_response

FloatArray = np.ndarray

__all__ = ["LearningDesign", "design_learning"]

#: Q's shape: |Q(f)| = 1 / (1 + (f / cutoff)^(2 ORDER)), a Butterworth filter of this order
#: run forward and backward (zero phase), here exactly, over the periodic trial
ORDER = 4
#: the largest worst-case trial-to-trial contraction the automatic design accepts
KAPPA = 0.9
#: the learning gains the automatic design considers
GAINS = np.array([0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0])
#: trials the automatic design aims at: the error predicted after this many is minimised
HORIZON = 10


@dataclass(frozen=True)
class LearningDesign:
    r"""The learning law's settings and why they converge.

    For a periodic trial of ``samples`` samples the error's spectrum at each
    harmonic ``f`` evolves, to first order, as
    :math:`E_{j+1} = Q(f)\,(1 - \gamma\,\rho\,e^{i\theta})\,E_j` (plus what
    Q leaves unlearned), where :math:`\rho` is the actuator's local slope over
    the model's (the compensator's residual gain) and :math:`\theta` the phase
    error of the timing left after the compensator and :math:`L`. The error
    shrinks monotonically (in the mean-square sense, trial after trial) when
    :attr:`contraction` :math:`= \max_f \max_{\rho, |\theta| \le \theta(f)}
    |Q(f)(1 - \gamma\rho e^{i\theta})| < 1`, with :math:`\rho \in
    [1 - s, 1 + s]` (:attr:`slope_error`) and :math:`\theta(f) = \min(2\pi f
    \Delta, \pi)` (:attr:`timing`).

    Attributes
    ----------
    gain : float
        :math:`\gamma`, the fraction of the error learned per trial (now: halved
        after every rolled-back trial).
    cutoff : float
        Hz, where :math:`|Q| = 1/2`; ``inf``: no filter.
    lag : float
        s, the first-order lag :math:`L` inverts (one the model does not hold; 0: none).
    timing : float
        s, :math:`\Delta`: the 95 % bound on the timing error left (the model's
        identified delay and lag's interval, a stated lag's tolerance, and half
        a sample for the reading's instant).
    slope_error : float
        :math:`s`, the relative error of the model's local slope allowed for.
    contraction : float
        The worst-case factor above (< 1: monotone convergence).
    noise_gain : float
        RMS of the measurement noise the converged correction carries into the
        output, over the noise's own RMS: :math:`\sqrt{\mathrm{mean}_f\,
        \gamma^2 |Q|^2 / (1 - |Q|^2 (1 - \gamma)^2)}` for white noise.
    noise : float
        RMS of the first trial's measurement noise (the desired's units; from the
        upper half of its spectrum); NaN before a trial was learned. A trial's
        error counts as grown only above what this noise and the noise the
        correction carries leave.
    predicted : float
        The RMS error predicted after ten trials for a nominal actuator (the
        desired's units; see :func:`design_learning`); NaN before a trial was learned.
    sample_rate : float
    samples : int
        Samples per trial.
    """

    gain: float
    cutoff: float
    lag: float
    timing: float
    slope_error: float
    contraction: float
    noise_gain: float
    predicted: float
    noise: float
    sample_rate: float
    samples: int

    def frequencies(self) -> FloatArray:
        """The harmonics of the trial (Hz), as :func:`numpy.fft.rfftfreq` gives them.

        Returns
        -------
        ndarray
        """
        return np.fft.rfftfreq(self.samples, 1.0 / self.sample_rate)

    def q(self) -> FloatArray:
        """:math:`Q` at each harmonic (real: zero phase).

        Returns
        -------
        ndarray
        """
        return _q(self.frequencies(), self.cutoff)

    def l(self) -> Any:  # noqa: E743 - the learning filter's name in every ILC text
        """:math:`L` at each harmonic: the inverse of the stated lag (1 without one).

        Returns
        -------
        complex ndarray
        """
        return _l(self.frequencies(), self.lag, 1.0 / self.sample_rate)

    def describe(self) -> str:
        """One paragraph: gain, cutoff, what it allows for, the condition.

        Returns
        -------
        str
        """
        cut = "no filter" if math.isinf(self.cutoff) else f"cutoff {self.cutoff:.4g} Hz"
        lag = f", inverting a {self.lag * 1e3:.3g} ms lag" if self.lag > 0 else ""
        sure = "converges monotonically" if self.contraction < 1 else "may NOT converge"
        return (
            f"learning gain {self.gain:.3g}, {cut}{lag}; allowing a timing error of "
            f"{self.timing * 1e3:.3g} ms and a slope error of {self.slope_error:.0%}: "
            f"worst-case contraction {self.contraction:.3f} per trial ({sure}); the learned "
            f"correction carries {self.noise_gain:.2f}x the measurement noise"
        )


def _q(f: FloatArray, cutoff: float) -> FloatArray:
    if math.isinf(cutoff):
        return np.ones_like(f)
    return np.asarray(1.0 / (1.0 + (f / cutoff) ** (2 * ORDER)))


def _l(f: FloatArray, lag: float, dt: float) -> Any:
    if lag <= 0:
        return np.ones(f.shape, dtype=complex)
    return 1.0 / filter_response(0.0, lag, dt, f)


def _contraction(
    f: FloatArray, q: FloatArray, gain: float, timing: float, slope_error: float
) -> float:
    """max over f, rho in [1-s, 1+s], |theta| <= theta(f) of |Q (1 - g rho e^{i theta})|."""
    theta = np.minimum(2 * np.pi * f * timing, np.pi)
    worst = np.zeros_like(f)
    for rho in (1.0 - slope_error, 1.0 + slope_error):  # |1 - g rho e^{it}|^2 is convex in rho
        worst = np.maximum(worst, np.abs(1.0 - gain * rho * np.exp(1j * theta)))
    return float(np.max(q[1:] * worst[1:])) if f.size > 1 else 0.0


def _noise_gain(q: FloatArray, gain: float) -> float:
    """RMS over the band of the converged correction's share of white measurement noise."""
    var = gain**2 * q**2 / np.maximum(1.0 - q**2 * (1.0 - gain) ** 2, 1e-300)
    return float(math.sqrt(np.mean(var[1:]))) if q.size > 1 else 0.0


def _timing(model: Any, lag: float, tolerance: float, dt: float) -> float:
    """The 95 % bound on the timing error the learning meets (s)."""
    bound = 0.5 * dt  # the instant within the sample the reading stands for
    dyn = getattr(model, "input_dynamics_", None)
    if dyn is not None and dyn.active:
        if dyn.covariance:
            c = dyn.covariance  # (delay, tau): the phase error at low frequency follows their sum
            bound += 1.96 * math.sqrt(max(c[0] + c[3] + 2.0 * c[1], 0.0))
        else:  # stated by hand: trusted to the stated lag's tolerance
            bound += tolerance * (dyn.tau + dyn.delay)
    return bound + tolerance * lag


def design_learning(
    model: Any,
    *,
    sample_rate: float,
    samples: int,
    gain: float | Literal["auto"] = "auto",
    cutoff: float | Literal["auto"] = "auto",
    lag: float = 0.0,
    lag_tolerance: float = 0.25,
    slope_error: float = 0.5,
    first_error: FloatArray | None = None,
) -> LearningDesign:
    """The learning law for a model and a trial (see :class:`LearningDesign`).

    ``"auto"`` settings are chosen from the first trial's error
    (``first_error``): among gains 0.2-1 and cutoffs from the trial's first
    harmonic to Nyquist (or no filter) whose worst-case contraction is at
    most 0.9, the pair that minimises the error predicted after ten trials
    for a nominal actuator (the model right to first order): the repeatable
    part of each harmonic shrinks by ``Q(1 - gain)`` per trial towards what Q
    leaves, ``(1 - Q) / (1 - Q + Q gain)`` of it, and the noise (read off the
    upper half of the band) adds what the correction carries. Without
    ``first_error``: gain 0.5 and the highest cutoff meeting the condition.

    Parameters
    ----------
    model : HysteresisModel
        Its input dynamics' interval sets the timing error allowed for.
    sample_rate : float
        Hz.
    samples : int
        Samples per trial.
    gain : float or "auto"
        The learning gain, in (0, 1].
    cutoff : float or "auto"
        Hz.
    lag : float, default 0
        s: a first-order lag between command and actuator that the model does
        not hold (a rate-independent model behind an amplifier), inverted by L.
    lag_tolerance : float, default 0.25
        How far (relative) a stated lag, or input dynamics stated by hand, may be off.
    slope_error : float, default 0.5
        How far (relative) the model's local slope may be off, in [0, 1).
    first_error : ndarray, optional
        The first trial's error (its offset removed where it is not learned).

    Returns
    -------
    LearningDesign
    """
    owner = "LearningCompensator"
    rate = check_float(sample_rate, "sample_rate", owner, 0.0, math.inf, low_open=True)
    gains = GAINS if gain == "auto" else np.array([check_float(gain, "learning_gain", owner, 0.0,
                                                               1.0, low_open=True)])  # fmt: skip
    tau = check_float(lag, "lag", owner, 0.0, 10.0)
    tol = check_float(lag_tolerance, "lag_tolerance", owner, 0.0, 1.0)
    s = check_float(slope_error, "slope_error", owner, 0.0, 0.99)
    dt = 1.0 / rate
    f = np.fft.rfftfreq(samples, dt)
    timing = _timing(model, tau, tol, dt)
    if cutoff == "auto":
        cuts = np.concatenate([np.geomspace(rate / samples, rate / 2, 60), [math.inf]])
    else:
        inf = isinstance(cutoff, float) and math.isinf(cutoff) and cutoff > 0  # no filter
        cuts = np.array([math.inf if inf else check_float(cutoff, "cutoff", owner, 0.0, 1e12,
                                                          low_open=True)])  # fmt: skip
    if first_error is None:  # before any trial: the plain gain, the widest band that converges
        gains = gains[np.argmin(np.abs(gains - 0.5))][None]
    power, noise = _spectra(first_error, samples)
    options = []  # (not converging, score, gain, cutoff, contraction)
    for g in gains:
        for c in cuts:
            q = _q(f, float(c))
            kappa = _contraction(f, q, float(g), timing, s)
            if power is None:  # the widest band that converges
                score = -float(c)
            else:
                score = _predicted(power, noise, q, float(g), 1.0 - s)
            late = kappa > KAPPA
            options.append((late, kappa if late else score, float(g), float(c), kappa))
    _, _, g, cut, kappa = min(options)
    q = _q(f, cut)
    predicted = math.nan
    if power is not None:
        predicted = math.sqrt(2 * _predicted(power, noise, q, g, 1.0 - s)) / samples  # Parseval
    return LearningDesign(
        gain=g,
        cutoff=cut,
        lag=tau,
        timing=timing,
        slope_error=s,
        contraction=kappa,
        noise_gain=_noise_gain(q, g),
        predicted=predicted,
        noise=math.sqrt(noise / samples) if power is not None else math.nan,
        sample_rate=rate,
        samples=int(samples),
    )


def _predicted(power: FloatArray, noise: float, q: FloatArray, g: float, rho: float) -> float:
    """The error power after HORIZON trials of an actuator whose slope is ``rho`` times the
    model's: what Q leaves of the repeatable part, what the trials have not yet removed, and
    the noise the correction carries."""
    left = (1 - q) / np.maximum(1 - q + q * g * rho, 1e-300)
    after = left + (q * (1 - g * rho)) ** HORIZON * (1 - left)
    carried = (g * rho) ** 2 * q**2 / np.maximum(1 - q**2 * (1 - g * rho) ** 2, 1e-300)
    return float(np.sum(power[1:] * after[1:] ** 2) + noise * np.sum(carried[1:]))


def _spectra(error: FloatArray | None, samples: int) -> tuple[FloatArray | None, float]:
    """The repeatable power of each harmonic of a trial's error, and the noise's per harmonic
    (from the upper half of the band: a Rayleigh variable's median); (None, 0) without one."""
    if error is None:
        return None, 0.0
    spec = np.abs(np.fft.rfft(error - error.mean())) ** 2
    upper = spec[spec.size // 2 :]
    noise = float(np.median(upper)) / math.log(2.0) if upper.size >= 8 else 0.0
    return np.maximum(spec - noise, 0.0), noise
