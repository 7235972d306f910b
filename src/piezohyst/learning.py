r"""Learning from repetition: iterative learning control on the measured charge.

A scan repeats, and so does what a model gets wrong about it. After each trial (one period
of the trajectory, sent without a pause) the error measured over it corrects the reference
the next trial's compensator inverts:

.. math::

    r_j = d + c_j, \qquad c_{j+1} = Q\,(c_j + \gamma\,L\,e_j),

with :math:`e_j` the desired trajectory minus what was measured: the charge with the
calibrated leakage removed (sensorless), or a sensor's displacement. The inverse model is
the learning law's plant inverse (a change :math:`\delta r` of the reference becomes
:math:`\delta r / (dq/dv)` volts: the model's local slope), :math:`L` inverts a lag the
model does not hold, :math:`Q` is a zero-phase low-pass over the periodic trial, and
:math:`\gamma` is the learning gain. :class:`LearningDesign` holds the choices and the
condition under which the error shrinks from trial to trial; ``docs/realtime.md``
("Learning from repetition") derives them.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from ._validation import check_float
from .compensator import Compensator, Domain
from .dynamics import _response
from .errors import (
    LearningWarning,
    ModelFileError,
    NonFiniteError,
    OutputError,
    ParameterError,
    ShapeError,
)
from .leakage import Leakage
from .metrics import hysteresis_width

FloatArray = np.ndarray

__all__ = ["LearningCompensator", "LearningDesign", "Trial", "design_learning"]

#: Q's shape: |Q(f)| = 1 / (1 + (f / cutoff)^(2 ORDER)), a Butterworth filter of this order
#: run forward and backward (zero phase), here exactly, over the periodic trial
ORDER = 4
#: the largest worst-case trial-to-trial contraction the automatic cutoff accepts
KAPPA = 0.9
#: the phase error (rad) the learning may meet inside its band: 60 degrees
PHASE_LIMIT = math.pi / 3
#: a trial's error counts as grown beyond this many standard errors of its estimate
GROWTH_SIGMAS = 3.0
#: the learning gains the automatic design considers
GAINS = np.array([0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0])
#: trials the automatic design aims at: the error predicted after this many is minimised
HORIZON = 10
#: learning stops halving its gain below the first gain over this
GAIN_FLOOR = 64.0
FORMAT = "piezohyst-learning"


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


@dataclass(frozen=True)
class Trial:
    """What one trial measured and what the learner did with it.

    Attributes
    ----------
    index : int
        0 for the first trial.
    error : float
        RMS error over the desired span (fraction), of the quantity learned
        from: offset-free for the charge (the leakage leaves its zero unknown),
        absolute for a sensor.
    width : float
        Loop width of the measured against the desired (fraction of the span).
    learned : int
        Samples learned from (readings that were NaN, and samples whose command
        was slew-limited into the trajectory, are not).
    gain : float
        The learning gain of the update made after this trial.
    rolled_back : bool
        The error grew over the trial before: that update was undone and the gain halved.
    skipped : bool
        Too few readings (under half the trial): nothing learned.
    leakage_bound : float
        The charge error one trial's leakage uncertainty can build (2 standard
        errors of the calibrated current, over the trial), as a fraction of the
        span; NaN when the leakage is not calibrated, 0 for a sensor.
    """

    index: int
    error: float
    width: float
    learned: int
    gain: float
    rolled_back: bool
    skipped: bool
    leakage_bound: float


def _q(f: FloatArray, cutoff: float) -> FloatArray:
    if math.isinf(cutoff):
        return np.ones_like(f)
    return np.asarray(1.0 / (1.0 + (f / cutoff) ** (2 * ORDER)))


def _l(f: FloatArray, lag: float, dt: float) -> Any:
    if lag <= 0:
        return np.ones(f.shape, dtype=complex)
    return 1.0 / _response(0.0, lag, dt, f)


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


def _periodic_fill(values: FloatArray, ok: FloatArray) -> FloatArray:
    """Values at the samples not ``ok`` interpolated linearly from the others, around the period."""
    if ok.all():
        return values
    n = values.size
    k = np.flatnonzero(ok)
    xs = np.concatenate([k - n, k, k + n])
    ys = np.tile(values[k], 3)
    out = values.copy()
    bad = np.flatnonzero(~ok)
    out[bad] = np.interp(bad, xs, ys)
    return out


def _check_periodic(d: FloatArray) -> None:
    steps = np.abs(np.diff(d))
    jump = abs(float(d[0] - d[-1]))
    largest = float(steps.max()) if steps.size else 0.0
    if jump > 2.0 * largest + 1e-12 * float(np.ptp(d)):
        msg = (
            f"the desired trajectory is not periodic over the trial: it jumps {jump:.4g} from "
            f"its last sample to its first, where its largest step is {largest:.4g}; a trial "
            "must end where the next begins (send whole periods)"
        )
        raise ParameterError(msg)


def _digest(values: Any) -> str:
    return hashlib.sha256(values).hexdigest()[:16]


class LearningCompensator:
    r"""A feedforward compensator that learns from repetition (iterative learning control).

    Each trial is one period of a repeated trajectory, sent right after the
    one before (the actuator's hysteresis and the leakage carry over):
    :meth:`command` gives the trial's voltages, :meth:`learn` takes what was
    measured over it (reading *i* taken at the end of sample *i*, as the
    models are identified) and updates the correction for the next. Learning
    from the charge needs no position sensor: the leakage (calibrated from
    holds, :func:`~piezohyst.calibrate_leakage`) is removed and its zero,
    which the leakage leaves unknown, is not learned. A sensor's
    displacement (``learn(displacement=...)``) is learned with its offset.

    The commands of a trial are the compensator's (:class:`~piezohyst.Compensator`)
    for the reference ``desired + correction``, continuing from the previous
    trial's reference (one period of it, at least 1 s, run first from the
    model's initial state: the same history the actuator has, so a trial's
    commands depend on the correction alone and a saved learner resumes
    exactly). Every command is finite, inside ``[v_min, v_max]`` and within
    the slew limit of the command before it, across trials too.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model; its inverse drives the actuator.
    v_min, v_max : float
        The actuator's limits (V).
    sample_rate : float
        Hz, of the trials.
    leakage : Leakage, optional
        Removed from the measured charge; default the model's growth terms.
    slew_rate, domain, gain, allow_extrapolation
        As for :class:`~piezohyst.Compensator` (``gain``, m per model output
        unit, also turns a sensor's displacement into the model's units).
    lag : float, default 0
        s: a lag the model does not hold, inverted by the learning filter
        (see :func:`design_learning`, with ``lag_tolerance``, ``slope_error``).
    learning_gain : float, default 0.5
    cutoff : float or "auto"
    lag_tolerance, slope_error : float

    Attributes
    ----------
    design : LearningDesign
        The law in use; ``"auto"`` fixes its cutoff after the first trial learned.
    history : list of Trial

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> from piezohyst.simulation import Bench
    >>> rec = ph.simulate(signal="decaying", duration=10.0)
    >>> model = ph.ActivePI(n_operators=8).fit(rec.voltage, rec.charge, t=rec.t)
    >>> lo, hi = np.quantile(model.hysteresis_.predict(rec.voltage), [0.3, 0.7])
    >>> desired = lo + (hi - lo) * (0.5 - 0.5 * np.cos(2 * np.pi * np.arange(100) / 100))
    >>> ilc = ph.LearningCompensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0)
    >>> bench = Bench(seed=1)
    >>> for _ in range(8):
    ...     trial = ilc.learn(bench.run(ilc.command(desired)).charge)
    >>> ilc.history[-1].error < ilc.history[0].error / 3
    True
    """

    def __init__(
        self,
        model: Any,
        *,
        v_min: float,
        v_max: float,
        sample_rate: float,
        leakage: Leakage | None = None,
        slew_rate: float | Literal["trained"] | None = "trained",
        domain: Domain = "charge",
        gain: float | None = None,
        allow_extrapolation: bool = False,
        lag: float = 0.0,
        learning_gain: float | Literal["auto"] = "auto",
        cutoff: float | Literal["auto"] = "auto",
        lag_tolerance: float = 0.25,
        slope_error: float = 0.5,
    ) -> None:
        self.model = model
        self.compensator = Compensator(
            model,
            v_min=v_min,
            v_max=v_max,
            slew_rate=slew_rate,
            sample_rate=sample_rate,
            domain=domain,
            gain=gain,
            allow_extrapolation=allow_extrapolation,
        )
        if leakage is None:
            leakage = Leakage.from_model(model)
        if not isinstance(leakage, Leakage):
            msg = f"'leakage' must be a Leakage (see calibrate_leakage). Got {leakage!r}."
            raise ParameterError(msg)
        self.leakage = leakage
        self.sample_rate = float(sample_rate)
        self.settings: dict[str, Any] = {
            "v_min": float(v_min),
            "v_max": float(v_max),
            "sample_rate": self.sample_rate,
            "slew_rate": slew_rate,
            "domain": domain,
            "gain": gain,
            "allow_extrapolation": bool(allow_extrapolation),
            "lag": float(lag),
            "learning_gain": learning_gain,
            "cutoff": cutoff,
            "lag_tolerance": float(lag_tolerance),
            "slope_error": float(slope_error),
        }
        # checks every design setting now (a one-sample trial stands in for the trajectory)
        design_learning(model, **self._design_args(2))
        self._fingerprint = self._make_fingerprint()
        self.reset()

    # ------------------------------------------------------------------ state
    def _design_args(self, samples: int) -> dict[str, Any]:
        s = self.settings
        return {
            "sample_rate": s["sample_rate"],
            "samples": samples,
            "gain": s["learning_gain"],
            "cutoff": s["cutoff"],
            "lag": s["lag"],
            "lag_tolerance": s["lag_tolerance"],
            "slope_error": s["slope_error"],
        }

    def _make_fingerprint(self) -> str:
        model = json.dumps(self.model.to_dict(), sort_keys=True, default=str).encode()
        rest = json.dumps(
            [self.settings, self.leakage.to_dict()], sort_keys=True, default=str
        ).encode()
        return _digest(model + rest)

    def reset(self) -> None:
        """Forget the trajectory and what was learned; the actuator is taken to sit at the
        model's initial state (the compensator's :meth:`~piezohyst.Compensator.reset`)."""
        self.compensator.reset()
        self._desired: FloatArray | None = None
        self._correction = np.zeros(0)
        self._previous = np.zeros(0)  # the reference correction of the trial before
        self._good: tuple[FloatArray, FloatArray, float] | None = None
        self._pending: FloatArray | None = None
        self._clamped = np.zeros(0, dtype=bool)
        self._last = float(self.compensator.last_command)
        self._leaked = 0.0
        self._gain = 0.5
        self._first = True  # the law is chosen from the first trial learned from
        self.history: list[Trial] = []
        self.design: LearningDesign | None = None

    @property
    def trials(self) -> int:
        """Trials learned from (or skipped) so far."""
        return len(self.history)

    @property
    def rollbacks(self) -> int:
        """Trials whose update was undone because the error grew."""
        return sum(t.rolled_back for t in self.history)

    @property
    def correction(self) -> FloatArray:
        """The correction added to the desired trajectory next trial (a copy; desired units)."""
        return self._correction.copy()

    @property
    def pending(self) -> FloatArray | None:
        """The commands of the trial sent and not yet learned from (a copy), or None."""
        return None if self._pending is None else self._pending.copy()

    @property
    def desired(self) -> FloatArray:
        """The trajectory every trial repeats (a copy; empty before the first command)."""
        return np.zeros(0) if self._desired is None else self._desired.copy()

    @property
    def last_command(self) -> float:
        """The last voltage sent (V)."""
        return self._last

    # --------------------------------------------------------------- commands
    def _set_trajectory(self, desired: ArrayLike) -> FloatArray:
        try:
            d = np.ascontiguousarray(desired, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            msg = f"'desired' must be a 1-D array of numbers ({exc})."
            raise ShapeError(msg) from None
        if d.ndim != 1 or d.size < 8:
            msg = f"'desired' must be a 1-D array of at least 8 samples. Got shape {d.shape}."
            raise ShapeError(msg)
        bad = ~np.isfinite(d)
        if bad.any():
            i = int(np.argmax(bad))
            msg = f"'desired' must be finite: a trial repeats it. Got {d[i]} at index {i}."
            raise NonFiniteError(msg)
        if not np.ptp(d) > 0:
            msg = "'desired' must move: a constant trajectory has nothing to learn."
            raise ParameterError(msg)
        _check_periodic(d)
        if self._desired is None:
            self._desired = d.copy()
            self._correction = np.zeros(d.size)
            self._previous = np.zeros(d.size)
            self.design = design_learning(self.model, **self._design_args(d.size))
        elif d.size != self._desired.size or not np.array_equal(d, self._desired):
            msg = (
                "this learner belongs to another trajectory: every trial repeats the first "
                "(reset() to learn a new one)"
            )
            raise ParameterError(msg)
        return self._desired

    def _commands(self, previous: FloatArray, correction: FloatArray) -> FloatArray:
        """The compensator's commands for ``desired + correction`` after the history of
        ``desired + previous`` (at least 1 s of it, from the model's initial state)."""
        assert self._desired is not None
        d = self._desired
        comp = self.compensator
        comp.reset()
        reps = max(1, math.ceil(self.sample_rate / d.size))
        comp.process(np.tile(d + previous, reps))
        return comp.process(d + correction)

    def command(self, desired: ArrayLike | None = None) -> FloatArray:
        """The voltages of the next trial.

        Parameters
        ----------
        desired : array_like, optional
            One period of the trajectory (model output units, or m with
            ``domain="displacement"``), the same every trial; needed the first
            time. It must end where it begins (checked).

        Returns
        -------
        ndarray
            Commands (V): finite, inside the limits, within the slew limit of
            the last command sent.

        Raises
        ------
        ParameterError
            A trial still waits for its readings (:meth:`learn`), or another trajectory.
        """
        if self._pending is not None:
            msg = (
                f"trial {self.trials} still waits for its readings: call learn() with what was "
                "measured over it before the next command()"
            )
            raise ParameterError(msg)
        if desired is None and self._desired is None:
            msg = "the first command() needs the desired trajectory"
            raise ParameterError(msg)
        if desired is not None:
            self._set_trajectory(desired)
        u = self._commands(self._previous, self._correction)
        clamped = np.zeros(u.size, dtype=bool)
        step, prev = self.compensator.max_step, self._last
        for k in range(u.size):  # into the trajectory from the last command, at the slew limit
            if abs(u[k] - prev) <= step * (1 + 1e-12):
                break
            u[k] = prev + math.copysign(step, u[k] - prev)
            clamped[k] = True
            prev = float(u[k])
        if clamped.any():  # the history differs until the trajectory's extremes wipe it out
            d = self._desired
            assert d is not None
            last = int(np.flatnonzero(clamped)[-1])
            after = np.arange(d.size) > last
            near = 0.01 * float(np.ptp(d))  # within 1 % of an extreme: the memory is wiped
            hi = np.flatnonzero(after & (d >= d.max() - near))
            lo = np.flatnonzero(after & (d <= d.min() + near))
            wiped = max(int(hi[0]) if hi.size else d.size, int(lo[0]) if lo.size else d.size)
            clamped[: wiped + 1] = True
        self._pending, self._clamped = u.copy(), clamped
        self._last = float(u[-1])
        return u

    # ----------------------------------------------------------------- learning
    def learn(
        self, charge: ArrayLike | None = None, *, displacement: ArrayLike | None = None
    ) -> Trial:
        """Learn from what was measured over the trial just sent.

        Parameters
        ----------
        charge : array_like, optional
            The measured charge (model output units), one reading per command;
            NaN where a reading is missing.
        displacement : array_like, optional
            Instead: a displacement sensor's reading (m; needs ``gain``), learned
            with its offset (its zero: the actuator at rest, as the compensator's).

        Returns
        -------
        Trial
            Also appended to :attr:`history`.

        Warns
        -----
        LearningWarning
            The error grew (the update is undone and the gain halved), or too
            few readings to learn from.
        """
        if self._pending is None:
            msg = "learn() needs a trial: call command() and send its voltages first"
            raise ParameterError(msg)
        if (charge is None) == (displacement is None):
            msg = "learn() takes the measured charge or a sensor's displacement (one of them)"
            raise ParameterError(msg)
        sensor = displacement is not None
        raw = charge if charge is not None else displacement
        try:
            y = np.array(raw, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            msg = f"the readings must be numbers ({exc})."
            raise ShapeError(msg) from None
        u, d = self._pending, self._desired
        assert d is not None
        if y.size != u.size:
            msg = f"one reading per command: the trial sent {u.size}, got {y.size} readings"
            raise ShapeError(msg)
        ok = np.isfinite(y) & ~self._clamped
        measured, bound = self._measured(y, u, sensor)
        e = d - measured
        if not sensor:
            e = e - (e[ok].mean() if ok.any() else 0.0)
        index = self.trials
        span = float(np.ptp(d))
        learned = int(ok.sum())
        if learned < d.size // 2:
            warnings.warn(
                f"trial {index}: {learned} of {d.size} readings to learn from (NaN or "
                "slew-limited into the trajectory): nothing learned",
                LearningWarning,
                stacklevel=2,
            )
            trial = Trial(index, math.nan, math.nan, learned, self._gain, False, True, bound)
            self._previous = self._correction  # sent again: the history of the next trial
            self._close(trial)
            return trial
        error = float(np.sqrt(np.mean(e[ok] ** 2))) / span
        width = hysteresis_width(d[ok], measured[ok]) if learned > 2 else math.nan
        e = _periodic_fill(e, ok)
        e = self._anti_windup(e, u, sensor)
        rolled = False
        if self._good is not None and error > self._good[2] * (
            1 + GROWTH_SIGMAS / math.sqrt(learned)
        ):
            rolled = True
            assert self.design is not None
            self._gain = max(self._gain / 2, self.design.gain / GAIN_FLOOR)
            warnings.warn(
                f"trial {index}: the error grew from {self._good[2]:.3%} to {error:.3%}: the "
                f"last update is undone and the learning gain halved to {self._gain:.3g}",
                LearningWarning,
                stacklevel=2,
            )
            base, base_e = self._good[0], self._good[1]
        else:
            base, base_e = self._correction, e
            self._good = (self._correction.copy(), e.copy(), error)
        if self._first:  # the law, chosen from the first trial learned from
            self.design = design_learning(self.model, **self._design_args(d.size), first_error=e)
            self._gain = self.design.gain
            self._first = False
        self._previous = self._correction
        self._correction = self._update(base, base_e, sensor)
        trial = Trial(index, error, width, learned, self._gain, rolled, False, bound)
        self._close(trial)
        return trial

    def _close(self, trial: Trial) -> None:
        self.history.append(trial)
        self._pending = None

    def _measured(self, y: FloatArray, u: FloatArray, sensor: bool) -> tuple[FloatArray, float]:
        """The readings in the desired's units (leakage removed from a charge), and the
        leakage's 95 % bound over the trial (fraction of the span)."""
        d = self._desired
        assert d is not None
        g = self.settings["gain"]
        as_displacement = self.settings["domain"] == "displacement"
        span = float(np.ptp(d))
        if sensor:
            if g is None:
                msg = "learning from a displacement needs the gain (m per model output unit)"
                raise ParameterError(msg)
            return (y if as_displacement else y / g), 0.0
        ok = np.isfinite(y)
        q = _periodic_fill(np.where(ok, y, 0.0), ok) if ok.any() else np.zeros_like(y)
        dt = 1.0 / self.sample_rate
        leaked = self._leaked + np.cumsum(self.leakage.current(u, q) * dt)
        self._leaked = float(leaked[-1])
        sigma = self.leakage.current_stderr(u, q)
        scale = abs(g) if as_displacement and g is not None else 1.0
        bound = 2.0 * float(np.mean(sigma)) * u.size * dt * scale / span
        h = np.where(ok, y, np.nan) - leaked
        return (h * g if as_displacement and g is not None else h), bound

    def _anti_windup(self, e: FloatArray, u: FloatArray, sensor: bool) -> FloatArray:
        """No learning outward where a command sat at a limit (the error there is out of reach)."""
        comp = self.compensator
        g = self.settings["gain"]
        sign = (
            -1.0 if (self.settings["domain"] == "displacement" and g is not None and g < 0) else 1.0
        )
        at_top = u >= comp.v_max - 1e-9 * max(1.0, abs(comp.v_max))
        at_bottom = u <= comp.v_min + 1e-9 * max(1.0, abs(comp.v_min))
        out = e.copy()
        out[at_top & (sign * e > 0)] = 0.0
        out[at_bottom & (sign * e < 0)] = 0.0
        return out

    def _update(self, base: FloatArray, e: FloatArray, sensor: bool) -> FloatArray:
        """``Q (base + gain L e)``, over the periodic trial (the mean kept for a charge)."""
        design = self.design
        assert design is not None
        spectrum = np.fft.rfft(base) + self._gain * design.l() * np.fft.rfft(e)
        if not sensor:
            spectrum[0] = np.fft.rfft(base)[0]  # the charge's zero is not learned
        return np.fft.irfft(design.q() * spectrum, n=base.size)

    # -------------------------------------------------------------------- files
    def to_dict(self) -> dict[str, Any]:
        """The learner's state, JSON-ready (see :meth:`from_dict`).

        Returns
        -------
        dict
        """
        good = None
        if self._good is not None:
            good = {
                "correction": self._good[0].tolist(),
                "error": self._good[1].tolist(),
                "metric": self._good[2],
            }
        return {
            "format": FORMAT,
            "version": 1,
            "fingerprint": self._fingerprint,
            "trajectory": None if self._desired is None else _digest(self._desired.tobytes()),
            "desired": None if self._desired is None else self._desired.tolist(),
            "correction": self._correction.tolist(),
            "previous": self._previous.tolist(),
            "good": good,
            "pending": None if self._pending is None else self._pending.tolist(),
            "clamped": np.flatnonzero(self._clamped).tolist(),
            "last_command": self._last,
            "leaked": self._leaked,
            "gain": self._gain,
            "first": self._first,
            "design": None if self.design is None else asdict(self.design),
            "history": [asdict(t) for t in self.history],
        }

    def restore(self, data: dict[str, Any], where: str = "learning state") -> None:
        """Continue from :meth:`to_dict`'s contents, made with the same model and settings.

        Parameters
        ----------
        data : dict
        where : str
            Named in errors (a file's path).

        Raises
        ------
        ModelFileError
            Another model, other settings, or not a learning state.
        """
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            msg = f"{where}: not a piezohyst learning state"
            raise ModelFileError(msg)
        if data.get("fingerprint") != self._fingerprint:
            msg = (
                f"{where}: made with another model, leakage or settings; a learning state "
                "continues only the run that wrote it"
            )
            raise ModelFileError(msg)
        try:
            self.reset()
            if data["desired"] is not None:
                self._set_trajectory(data["desired"])
                if data["trajectory"] != _digest(self._desired.tobytes()):  # type: ignore[union-attr]
                    raise ValueError("the trajectory's digest does not match its values")
            self._correction = np.array(data["correction"], dtype=np.float64)
            self._previous = np.array(data["previous"], dtype=np.float64)
            good = data["good"]
            if good is not None:
                self._good = (
                    np.array(good["correction"], dtype=np.float64),
                    np.array(good["error"], dtype=np.float64),
                    float(good["metric"]),
                )
            pending = data["pending"]
            self._pending = None if pending is None else np.array(pending, dtype=np.float64)
            n = 0 if self._desired is None else self._desired.size
            self._clamped = np.zeros(n, dtype=bool)
            self._clamped[np.array(data["clamped"], dtype=int)] = True
            self._last = float(data["last_command"])
            self._leaked = float(data["leaked"])
            self._gain = float(data["gain"])
            self._first = bool(data["first"])
            self.design = None if data["design"] is None else LearningDesign(**data["design"])
            self.history = [Trial(**t) for t in data["history"]]
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            self.reset()
            msg = f"{where}: a damaged learning state ({exc})"
            raise ModelFileError(msg) from None

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`to_dict` as JSON, atomically (a reader sees the old file or the new).

        Parameters
        ----------
        path : path

        Returns
        -------
        Path
        """
        return self.save_dict(path, self.to_dict())

    def save_dict(self, path: str | os.PathLike[str], data: dict[str, Any]) -> Path:
        """Write ``data`` (:meth:`to_dict`'s, perhaps with keys added) as JSON, atomically.

        Parameters
        ----------
        path : path
        data : dict

        Returns
        -------
        Path
        """
        return write_atomic(Path(path), json.dumps(data))

    def load(self, path: str | os.PathLike[str]) -> None:
        """Continue from a file :meth:`save` wrote (see :meth:`restore`).

        Parameters
        ----------
        path : path
        """
        p = Path(path)
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            msg = f"{p}: cannot read the learning state ({exc})"
            raise ModelFileError(msg) from None
        self.restore(data, str(p))


def write_atomic(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except OSError as exc:
        msg = f"cannot write {path}: {exc.strerror or exc}"
        raise OutputError(msg) from None
    return path
