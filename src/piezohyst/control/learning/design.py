r"""The learning law's design: the choice of gain and robustness filter, and the condition
under which the error shrinks from trial to trial (see :mod:`piezohyst.control.learning`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..._validation import check_float
from ...model.dynamics import filter_response
from .probe import Response

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
#: points on the edge of the identified delay and lag's 95 % region where the response is
#: evaluated (with its centre)
ELLIPSE_POINTS = 24
#: with a probe's response, the region is sampled inside too, on rings at these fractions
RINGS = (1 / 3, 2 / 3, 1.0)
#: a timing agrees with the probe where its phase lies within the noise's reach and this
#: (rad, 5 degrees: what a local slope varying along the scan may turn) of the measured one
PROBE_MARGIN = math.radians(5.0)
#: the measured response, within this many standard errors of noise (in any direction of the
#: complex plane: beyond 4, 3e-4 per sine), turns the phase by at most asin(4 stderr); a
#: sine whose noise could reach the response itself (4 stderr >= 1) rules nothing out
PROBE_SIGMAS = 4.0
#: a probe's phase beyond every allowed timing is sized with delays of up to this many samples
#: (in quarter samples) and these first-order lags (s)
DELAYS = 20
TAUS = np.concatenate([[0.0], np.geomspace(1e-5, 1.0, 201)])


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
    :attr:`contraction` :math:`= \max_f \max_{\rho, r}
    |Q(f)(1 - \gamma\rho\, r(f))| < 1`, with :math:`\rho \in
    [1 - s, 1 + s]` (:attr:`slope_error`) and :math:`r(f)` the response of any
    timing the law allows for over the one it assumes: a delay anywhere in
    :math:`\pm` :attr:`timing`, the model's identified lag anywhere in its 95 %
    interval, a stated lag anywhere within its tolerance (:attr:`lag_error`).
    A lag known to 25 % is not a timing error that grows with frequency: its
    phase error stays under 6.4 degrees, its gain error under 25 %.

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
        s: the 95 % bound on the delay error left (the model's identified delay's
        interval, or a stated delay's tolerance, and half a sample for the
        reading's instant).
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
    lag_error : float
        The relative 95 % bound on the model's identified lag (or a lag it was
        given by hand), and a stated ``lag``'s tolerance.
    probed : bool
        Whether the lead-in's probe narrowed the timings allowed for (to those whose
        phase agrees with the loop's measured one).
    probe_phase, probe_frequency : float
        Where the probe's response agrees with no timing allowed for: its phase over the
        one the law assumes (rad; negative: the loop lags) at the sine where they differ
        most, and that sine's frequency (Hz); 0 where one agrees. The condition above then
        does not describe the loop (:meth:`beyond`).
    probe_delay, probe_lag : float
        s, the delay and first-order lag (of the model's own timing) whose phase fits the
        probe's best there (among :data:`DELAYS` quarter samples and :data:`TAUS`): a rough
        size of what the model does not hold.
    model_timed : bool
        Whether the model holds input dynamics of its own: the probe's message then says
        they do not describe the loop, not that they are missing.
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
    lag_error: float = 0.0
    probed: bool = False
    probe_phase: float = 0.0
    probe_frequency: float = 0.0
    probe_delay: float = 0.0
    probe_lag: float = 0.0
    model_timed: bool = False

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

    def beyond(self) -> str:
        """What the probe measured beyond every timing the law allows for ("" where nothing).

        Returns
        -------
        str
        """
        if self.probe_phase == 0.0:
            return ""
        size = (f"; a delay of {self.probe_delay * 1e3:.2g} ms and a lag of "
                f"{self.probe_lag * 1e3:.2g} ms more than the model holds fit it best"
                if self.probe_phase < 0 else "")  # fmt: skip
        return (
            f"the lead-in's probe measured the loop {abs(math.degrees(self.probe_phase)):.0f} "
            f"degrees {'behind' if self.probe_phase < 0 else 'ahead of'} the timing the law "
            f"assumes at {self.probe_frequency:.0f} Hz, beyond every timing it allows for{size}: "
            + (
                "the model's identified input dynamics do not describe this loop (identify "
                "them again on a record of the loop's own rates and amplifier, or state lag=)"
                if self.model_timed
                else "the model does not hold the loop's dynamics (identify them: "
                "input_dynamics='auto', --input-dynamics auto; or state lag=)"
            )
            + ", and the condition does not hold"
        )

    def describe(self) -> str:
        """One paragraph: gain, cutoff, what it allows for, the condition.

        Returns
        -------
        str
        """
        cut = "no filter" if math.isinf(self.cutoff) else f"cutoff {self.cutoff:.4g} Hz"
        lag = f", inverting a {self.lag * 1e3:.3g} ms lag" if self.lag > 0 else ""
        sure = "converges monotonically" if self.contraction < 1 else "may NOT converge"
        lags = f", a lag error of {self.lag_error:.0%}" if self.lag_error > 0 else ""
        lags += " (as the lead-in's probe measured the loop)" if self.probed else ""
        return (
            f"learning gain {self.gain:.3g}, {cut}{lag}; allowing a delay error of "
            f"{self.timing * 1e3:.3g} ms{lags} and a slope error of {self.slope_error:.0%}: "
            f"worst-case contraction {self.contraction:.3f} per trial ({sure}); the learned "
            f"correction carries {self.noise_gain:.2f}x the measurement noise"
            + (f"; but {self.beyond()}" if self.probe_phase else "")
        )


def _q(f: FloatArray, cutoff: float) -> FloatArray:
    if math.isinf(cutoff):
        return np.ones_like(f)
    return np.asarray(1.0 / (1.0 + (f / cutoff) ** (2 * ORDER)))


def _l(f: FloatArray, lag: float, dt: float) -> Any:
    if lag <= 0:
        return np.ones(f.shape, dtype=complex)
    return 1.0 / filter_response(0.0, lag, dt, f)


def _worst(ratios: Any, gain: float, slope_error: float) -> FloatArray:
    """max over the responses allowed for and rho in [1-s, 1+s] of |1 - g rho r|, per harmonic
    (|1 - g rho r|^2 is convex in rho: its ends are the worst)."""
    rho = np.array([1.0 - slope_error, 1.0 + slope_error])[:, None, None]
    return np.asarray(np.max(np.abs(1.0 - gain * rho * ratios[None]), axis=(0, 1)))


def _allowed(
    model: Any, lag: float, tolerance: float, dt: float, f: FloatArray,
    measured: Response | None = None,
) -> tuple[float, float, Any, bool, tuple[float, float, float, float]]:  # fmt: skip
    """The delay error allowed for (s), the lag's relative error, the response of every
    timing allowed for over the one the law assumes: shape (timings, harmonics), whether a
    probe's response narrowed them, and where it agrees with none of them, the phase (rad)
    of the loop's measured response over the assumed one at the sine where it is furthest,
    that sine's frequency (Hz), and the delay and first-order lag that fit the phase best (s;
    else zeros).

    The model's identified delay and lag anywhere in their joint 95 % region (the ellipse of
    their covariance: a delay and a lag the record could not tell apart are anti-correlated),
    or within ``tolerance`` of each when stated by hand; a stated ``lag`` within
    ``tolerance``; and half a sample for the instant a reading stands for (a pure shift).
    With ``measured`` (the lead-in's probe, :mod:`~piezohyst.control.learning.probe`), only
    the delays and lags (identified, or stated by hand) whose phase agrees with the measured
    one at every probed harmonic, within what :data:`PROBE_SIGMAS` standard errors of noise
    can turn it and :data:`PROBE_MARGIN` (the reading's half sample and a stated lag's
    tolerance stay allowed for); all of them where none does."""
    delay = tau = 0.0
    offsets = np.zeros((1, 2))  # (delay, tau) off the model's, s
    dyn = getattr(model, "input_dynamics_", None)
    if dyn is not None and dyn.active:
        delay, tau = dyn.delay, dyn.tau
        if dyn.covariance:
            cov = np.array(dyn.covariance).reshape(2, 2)
            w, v = np.linalg.eigh(cov)  # the 95 % ellipse's axes
            turn = np.linspace(0.0, 2 * np.pi, ELLIPSE_POINTS, endpoint=False)
            unit = np.stack([np.cos(turn), np.sin(turn)], axis=1)
            radii = RINGS if measured is not None else (1.0,)  # inside too, to narrow it
            rings = [1.96 * r * unit * np.sqrt(np.maximum(w, 0.0)) @ v.T for r in radii]
            offsets = np.vstack([offsets, *rings])
        else:  # stated by hand: trusted to the tolerance
            box = np.array([[a, b] for a in (-1, 0, 1) for b in (-1, 0, 1)], dtype=float)
            offsets = box * tolerance * np.array([delay, tau])
    shifts = np.array([-0.5 * dt, 0.0, 0.5 * dt])
    lags = np.unique([lag * (1.0 - tolerance), lag, lag * (1.0 + tolerance)])
    assumed = filter_response(delay, tau, dt, f) * filter_response(0.0, lag, dt, f)
    ratios, rows = [], []
    for d_off, t_off in offsets:
        dyn_r = filter_response(delay, max(tau + t_off, 0.0), dt, f) / assumed
        for shift in shifts:
            for stated in lags:
                ratios.append(np.exp(-2j * np.pi * f * (d_off + shift)) * dyn_r
                              * filter_response(0.0, stated, dt, f))  # fmt: skip
                rows.append((abs(d_off + shift), abs(t_off) / tau if tau > 0 else 0.0,
                             abs(stated - lag) / lag if lag > 0 else 0.0))  # fmt: skip
    table, kept = np.array(ratios), np.ones(len(ratios), dtype=bool)
    narrowed, beyond = False, (0.0, 0.0, 0.0, 0.0)
    centre = shifts.size // 2 * lags.size + lags.size // 2  # no shift, the lag stated
    bound = PROBE_SIGMAS * measured.phase_stderr if measured is not None else np.zeros(0)
    sure = bound < 1.0  # where the response stood out of the noise's reach over it
    if measured is not None and sure.any():
        seen = (measured.ratio * _l(f[measured.bins], lag, dt))[sure]
        off = np.abs(np.angle(table[:, measured.bins[sure]] / seen[None, :]))
        agree = np.all(off <= np.arcsin(bound[sure])[None, :] + PROBE_MARGIN, axis=1)
        per = agree.reshape(offsets.shape[0], -1)  # rows: offsets x shifts x stated lags
        near = per[:, centre]
        # the identified timing's region only: the reading's half sample and a stated lag's
        # tolerance stay allowed for
        if offsets.shape[0] > 1 and near.any() and not near.all():
            kept, narrowed = np.repeat(near, per.shape[1]), True
        if not agree.any():  # the loop's timing is none the law allows for: by how much
            phase = np.angle(seen / table[centre, measured.bins[sure]])
            k = int(np.argmax(np.abs(phase)))
            at = f[measured.bins[sure]]
            delays = np.arange(0.0, DELAYS * dt, 0.25 * dt)
            grid = filter_response(delays[:, None, None], TAUS[None, :, None], dt, at)
            misfit = np.sum(np.abs(grid / np.abs(grid) - np.exp(1j * phase)) ** 2, axis=2)
            i, j = np.unravel_index(int(np.argmin(misfit)), misfit.shape)
            beyond = (float(phase[k]), float(at[k]), float(delays[i]), float(TAUS[j]))
    err = np.array(rows)[kept]
    delay_err = float(np.max(err[:, 0]))
    lag_error = float(max(np.max(err[:, 1]), np.max(err[:, 2])))
    return delay_err, lag_error, table[kept], narrowed, beyond


def _noise_gain(q: FloatArray, gain: float) -> float:
    """RMS over the band of the converged correction's share of white measurement noise."""
    var = gain**2 * q**2 / np.maximum(1.0 - q**2 * (1.0 - gain) ** 2, 1e-300)
    return float(math.sqrt(np.mean(var[1:]))) if q.size > 1 else 0.0


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
    measured: Response | None = None,
) -> LearningDesign:
    """The learning law for a model and a trial (see :class:`LearningDesign`).

    ``"auto"`` settings are chosen from the first trial's error
    (``first_error``): among gains 0.2-1 and cutoffs from the trial's first
    harmonic to Nyquist (or no filter) whose worst case over every timing and
    slope allowed for contracts by at most 0.9 per trial (the contraction),
    the pair that minimises the error predicted after ten trials for an
    actuator at the slow end of the slope's range: the repeatable part of
    each harmonic shrinks by ``Q(1 - gain)`` per trial towards what Q leaves,
    ``(1 - Q) / (1 - Q + Q gain)`` of it, and the noise (read off the upper
    half of the band) adds what the correction carries.
    Without ``first_error``: gain 0.5 and the highest cutoff meeting the condition.

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
        Hz (``inf``: no filter).
    lag : float, default 0
        s: a first-order lag between command and actuator that the model does
        not hold (a rate-independent model behind an amplifier), inverted by L.
    lag_tolerance : float, default 0.25
        How far (relative) a stated lag, or input dynamics stated by hand, may be off.
    slope_error : float, default 0.5
        How far (relative) the model's local slope may be off, in [0, 1).
    first_error : ndarray, optional
        The first trial's error (its offset removed where it is not learned).
    measured : Response, optional
        The loop's response to the lead-in's probe: only the timings it agrees with are
        allowed for (all of them where it agrees with none).

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
    timing, lag_error, ratios, narrowed, beyond = _allowed(model, tau, tol, dt, f, measured)
    if cutoff == "auto":
        cuts = np.concatenate([np.geomspace(rate / samples, rate / 2, 60), [math.inf]])
    else:
        inf = isinstance(cutoff, float) and math.isinf(cutoff) and cutoff > 0  # no filter
        cuts = np.array([math.inf if inf else check_float(cutoff, "cutoff", owner, 0.0, 1e12,
                                                          low_open=True)])  # fmt: skip
    if first_error is None:  # before any trial: the plain gain, the widest band that converges
        gains = gains[np.argmin(np.abs(gains - 0.5))][None]
    power, noise = _spectra(first_error, samples)
    options = []  # (not converging, score, gain, cutoff, Q, contraction)
    for g in gains:
        worst = _worst(ratios, float(g), s)
        for c in cuts:
            q = _q(f, float(c))
            if power is None:  # the widest band that converges
                score = -float(c)
            else:
                score = _predicted(power, noise, q, float(g), 1.0 - s)
            kappa = float(np.max(q[1:] * worst[1:])) if f.size > 1 else 0.0
            late = kappa > KAPPA * (1 + 1e-9)
            options.append((late, kappa if late else score, float(g), float(c), q, kappa))
    _, _, g, cut, q, kappa = min(options, key=lambda o: o[:4])
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
        lag_error=lag_error,
        probed=narrowed,
        probe_phase=beyond[0],
        probe_frequency=beyond[1],
        probe_delay=beyond[2],
        probe_lag=beyond[3],
        model_timed=bool(model.input_dynamics_.active),
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
