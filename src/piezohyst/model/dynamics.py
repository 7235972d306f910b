"""Input dynamics: what lies between the logged command and the hysteresis.

An amplifier driving a capacitive load, or a DAQ that logs the *commanded*
voltage, puts a lag between the voltage in the record and the voltage on
the piezo. At one drive frequency a lag widens the loop exactly like
hysteresis does; at another it does not, so a rate-independent model that
absorbed a lag is wrong the moment the frequency changes. An
:class:`InputDynamics` — a delay (integer and fractional samples) and/or a
first-order lag — turns the command ``x`` into the piezo voltage ``u`` that
the hysteresis model sees; models identify it jointly with the hysteresis
(``input_dynamics=`` on every model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._kernels import signal as S
from .._validation import FloatArray
from ..errors import ParameterError

__all__ = ["KINDS", "InputDynamics", "OutputDynamics", "ResponseInterval", "filter_response"]

KINDS = ("none", "delay", "first-order", "delay+first-order")


@dataclass(frozen=True)
class ResponseInterval:
    """The input dynamics' response at one frequency, and how sure it is.

    Attributes
    ----------
    frequency : float
        Hz.
    gain, phase : float
        The identified values' gain and phase lag (degrees).
    gain_range, phase_range : tuple of float
        Their range over the confidence region (NaN when unknown).
    width : float
        The largest loop width (fraction of the span) that a compensator
        built on the identified values leaves for a truth inside the region.
    """

    frequency: float
    gain: float
    phase: float
    gain_range: tuple[float, float]
    phase_range: tuple[float, float]
    width: float

    def __str__(self) -> str:
        lo, hi = self.phase_range
        return (
            f"at {self.frequency:g} Hz: gain {self.gain:.3f}, phase lag {self.phase:.1f}° "
            f"(95 % {lo:.1f}-{hi:.1f}°), loop width from this uncertainty <= "
            f"{100 * self.width:.2g} %"
        )


def filter_response(delay: Any, tau: Any, dt: float, frequency: Any) -> Any:
    """The discrete filter's response: linear-interpolated delay, then a held-input lag.

    Parameters
    ----------
    delay, tau : float or array_like
        Delay and lag (s).
    dt : float
        Sample interval (s).
    frequency : float or array_like
        Frequency (Hz).

    Returns
    -------
    complex or ndarray of complex
        The filter's gain and phase at each frequency.
    """
    f = np.asarray(frequency, dtype=np.float64)
    d = np.asarray(delay, dtype=np.float64)
    tt = np.asarray(tau, dtype=np.float64)
    if dt <= 0:
        return np.ones(np.broadcast(f, d, tt).shape, dtype=complex)
    z1 = np.exp(-2j * np.pi * f * dt)  # z^-1
    samples = d / dt
    whole = np.floor(samples + 1e-9)
    frac = np.maximum(samples - whole, 0.0)
    h = z1**whole * ((1.0 - frac) + frac * z1)
    with np.errstate(divide="ignore", over="ignore"):
        e = np.where(tt > 0, np.exp(-dt / np.where(tt > 0, tt, 1.0)), 0.0)
    return h * (1.0 - e) / (1.0 - e * z1)


@dataclass(frozen=True)
class InputDynamics:
    """A delay and a first-order lag between command and piezo voltage.

    Attributes
    ----------
    kind : str
        One of ``"none"``, ``"delay"``, ``"first-order"``, ``"delay+first-order"``.
    tau : float
        First-order lag time constant (s); 0 for none.
    delay : float
        Pure delay (s); 0 for none. Applied in samples of ``sample_interval``
        (integer part exact, fraction by linear interpolation): the record is
        assumed uniformly sampled.
    sample_interval : float
        The training record's median sample interval (s).
    covariance : tuple of float
        The 2x2 covariance (s², row-major over ``(delay, tau)``) of the
        identified values, from the profile of the model's own fit (see
        :func:`~piezohyst.model.fit_dynamics.profile_dynamics`); ``()`` when unknown
        (stated by hand, or a file from before 0.9). A parameter the kind
        lacks has zero variance.

    Notes
    -----
    A DAC that ramps between commands (first-order hold) instead of holding
    each one (staircase) is covered exactly: a lag of ramps equals the same
    lag of held commands after a delay of ``1 - c / (1 - e)`` samples
    (``e = exp(-dt/tau)``, ``c = 1 - (tau/dt)(1 - e)``; half a sample for
    ``tau >> dt``), which is how the linearly interpolated delay acts. So
    ``"delay+first-order"`` (or ``"auto"``) fits either DAC.

    Examples
    --------
    >>> dyn = InputDynamics("delay", delay=0.002, sample_interval=0.001)
    >>> u, _ = dyn.apply([0.0, 1.0, 2.0, 3.0], dt=[0.0, 1e-3, 1e-3, 1e-3])
    >>> u.tolist()
    [0.0, 0.0, 0.0, 1.0]
    """

    kind: str = "none"
    tau: float = 0.0
    delay: float = 0.0
    sample_interval: float = 0.0
    covariance: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            msg = f"input dynamics kind must be one of {KINDS}. Got {self.kind!r}."
            raise ParameterError(msg)
        for name in ("tau", "delay", "sample_interval"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                msg = f"input dynamics {name!r} must be a finite number >= 0 (s). Got {value!r}."
                raise ParameterError(msg)
        if self.delay > 0 and self.sample_interval <= 0:
            msg = "a delay needs the record's sample interval (s) to count its samples"
            raise ParameterError(msg)
        cov = self.covariance
        if cov and (len(cov) != 4 or not all(math.isfinite(c) for c in cov)):
            msg = f"input dynamics covariance must be 4 finite numbers (2x2, s^2). Got {cov!r}."
            raise ParameterError(msg)

    @property
    def active(self) -> bool:
        """True when the command is changed at all."""
        return self.tau > 0 or self.delay > 0

    @property
    def delay_samples(self) -> float:
        """The delay in samples of ``sample_interval``."""
        return self.delay / self.sample_interval if self.delay > 0 else 0.0

    def _split(self) -> tuple[int, float]:
        d = self.delay_samples
        whole = math.floor(d + 1e-9)
        return whole, max(d - whole, 0.0)

    def rest_state(self, x0: float) -> FloatArray:
        """The filter resting at command ``x0`` (every delayed and lagged value there).

        Parameters
        ----------
        x0 : float
            The command it rests at (V).

        Returns
        -------
        ndarray
            ``[unused, lag, head, ring of the last inputs]``, all at ``x0``.
        """
        whole, _ = self._split()
        state = np.full(3 + whole + 2, float(x0))
        state[0] = 0.0
        state[2] = 0.0
        return state

    def apply(
        self, x: Any, dt: Any, state: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """The piezo voltage for commands ``x`` held over sample intervals ``dt``.

        Parameters
        ----------
        x : array_like, shape (N,)
            Commands (input units).
        dt : array_like, shape (N,)
            Each sample's interval (s; the first of a record is 0).
        state : ndarray, optional
            From :meth:`rest_state` or an earlier call (updated in place);
            default at rest at ``x[0]``.

        Returns
        -------
        tuple of ndarray
            ``u`` and the state.
        """
        xs = np.ascontiguousarray(x, dtype=np.float64)
        ds = np.ascontiguousarray(dt, dtype=np.float64)
        st = self.rest_state(float(xs[0]) if xs.size else 0.0) if state is None else state
        out = np.empty_like(xs)
        if not self.active:
            out[:] = xs
            return out, st
        whole, frac = self._split()
        if st.size != 3 + whole + 2:
            msg = f"the input dynamics state must hold {3 + whole + 2} values. Got {st.size}."
            raise ParameterError(msg)
        S.input_filter(xs, ds, whole, frac, float(self.tau), float(self.sample_interval), st, out)
        return out, st

    def response(self, frequency: Any) -> Any:
        """The complex response from command to piezo voltage at ``frequency`` (Hz).

        The discrete filter the model applies (delay interpolated linearly,
        the lag exact for a held command) at the training sample interval;
        1 for no dynamics.

        Parameters
        ----------
        frequency : float or array_like

        Returns
        -------
        complex ndarray
        """
        return filter_response(self.delay, self.tau, self.sample_interval, frequency)

    def stderr(self) -> tuple[float, float]:
        """Standard errors (s) of ``(delay, tau)``; NaN when unknown.

        Returns
        -------
        tuple of float
        """
        if not self.covariance:
            return math.nan, math.nan
        c = self.covariance
        return math.sqrt(max(c[0], 0.0)), math.sqrt(max(c[3], 0.0))

    def response_interval(self, frequency: float, level: float = 0.95) -> ResponseInterval:
        """What the identified dynamics do at ``frequency`` (Hz), with their uncertainty.

        Over the joint confidence region of ``(delay, tau)`` at ``level``
        (an ellipse from :attr:`covariance`, kept to non-negative values):
        the gain and phase lag's range, and the loop width a compensator
        built on the identified values would leave if the truth were
        anywhere in it, ``max |sin(phase - phase identified)|`` (a line seen
        through a phase error ``p`` becomes an ellipse of width ``sin p`` of
        its span). NaN ranges when the covariance is unknown.

        Parameters
        ----------
        frequency : float
            The scan frequency (Hz).
        level : float, default 0.95

        Returns
        -------
        ResponseInterval
        """
        f = float(frequency)
        if not (math.isfinite(f) and f > 0):
            msg = f"frequency must be a finite number > 0 (Hz). Got {frequency!r}."
            raise ParameterError(msg)
        nominal = complex(self.response(f))
        gain0, phase0 = abs(nominal), -math.degrees(np.angle(nominal))
        if not self.active:  # no dynamics: nothing uncertain
            return ResponseInterval(f, gain0, phase0, (gain0, gain0), (phase0, phase0), 0.0)
        if not self.covariance:  # stated by hand, or an older file: unknown
            nan = (math.nan, math.nan)
            return ResponseInterval(f, gain0, phase0, nan, nan, math.nan)
        from scipy.stats import chi2

        cov = np.array(self.covariance).reshape(2, 2)
        vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
        radius = math.sqrt(float(chi2.ppf(level, 2)))
        angles = np.linspace(0.0, 2 * np.pi, 73)
        unit = np.stack([np.cos(angles), np.sin(angles)])
        scale = np.sqrt(np.maximum(vals, 0.0))[:, None]
        ring = vecs @ (scale * unit) * radius
        pts = np.concatenate([ring, 0.5 * ring, np.zeros((2, 1))], axis=1)
        delay = np.maximum(self.delay + pts[0], 0.0)
        tau = np.maximum(self.tau + pts[1], 0.0)
        h = filter_response(delay, tau, self.sample_interval, np.full(delay.size, f))
        gain = np.abs(h)
        phase = -np.degrees(np.unwrap(np.angle(h)))
        miss = np.abs(np.sin(np.radians(phase - phase0)))
        return ResponseInterval(
            f, gain0, phase0, (float(gain.min()), float(gain.max())),
            (float(phase.min()), float(phase.max())), float(miss.max()),
        )  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """``kind``, ``tau`` (s), ``delay`` (s), ``sample_interval`` (s), ``covariance`` (s²).

        Returns
        -------
        dict
        """
        return {
            "kind": self.kind,
            "tau": self.tau,
            "delay": self.delay,
            "sample_interval": self.sample_interval,
            "covariance": list(self.covariance),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> InputDynamics:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict
            The kind, time constant, delay and sample interval (s), and the covariance
            where the fit gave one.

        Returns
        -------
        InputDynamics
        """
        return cls(
            str(data.get("kind", "none")),
            float(data.get("tau", 0.0)),
            float(data.get("delay", 0.0)),
            float(data.get("sample_interval", 0.0)),
            tuple(float(c) for c in data.get("covariance", ())),
        )


@dataclass(frozen=True)
class OutputDynamics:
    r"""A mechanical mode between the hysteresis and the measured displacement (Hammerstein).

    :math:`H(s) = \omega_0^2 / (s^2 + 2\zeta\omega_0 s + \omega_0^2)`, unit gain
    at DC, discretised exactly for an input held over each sample of
    ``sample_interval``. Identified from displacement records with
    ``output_dynamics="second-order"``; charge has no mechanical mode.

    Attributes
    ----------
    f0 : float
        Resonance (Hz); 0 for none.
    zeta : float
        Damping ratio.
    sample_interval : float
        The sample interval it is discretised for (s).

    Examples
    --------
    >>> mode = OutputDynamics(100.0, 0.05, 1e-3)
    >>> y, _ = mode.apply(np.ones(2000))
    >>> round(float(y[-1]), 6)       # unit gain at DC
    1.0
    """

    f0: float = 0.0
    zeta: float = 0.0
    sample_interval: float = 0.0

    def __post_init__(self) -> None:
        for name in ("f0", "zeta", "sample_interval"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                msg = f"output dynamics {name!r} must be a finite number >= 0. Got {value!r}."
                raise ParameterError(msg)
        if self.f0 > 0 and (self.sample_interval <= 0 or self.zeta <= 0):
            msg = "a mode needs its damping ratio (> 0) and the sample interval (s)"
            raise ParameterError(msg)

    @property
    def active(self) -> bool:
        """True for a mode at all."""
        return self.f0 > 0

    def matrices(self) -> tuple[FloatArray, FloatArray]:
        """The exact discretisation (``ad``, ``bd``) of the state (position, velocity).

        Returns
        -------
        tuple of ndarray
        """
        from scipy.linalg import expm

        w = 2.0 * math.pi * self.f0
        a = np.array([[0.0, 1.0], [-w * w, -2.0 * self.zeta * w]])
        b = np.array([0.0, w * w])
        aug = np.zeros((3, 3))
        aug[:2, :2] = a * self.sample_interval
        aug[:2, 2] = b * self.sample_interval
        e = expm(aug)
        return np.ascontiguousarray(e[:2, :2]), np.ascontiguousarray(e[:2, 2])

    def rest_state(self, values: Any) -> FloatArray:
        """At rest at ``values`` (one per column): position there, velocity 0.

        Parameters
        ----------
        values : array_like, shape (p,)

        Returns
        -------
        ndarray, shape (2, p)
        """
        v = np.atleast_1d(np.asarray(values, dtype=np.float64))
        return np.vstack([v, np.zeros_like(v)])

    def apply_columns(self, u: FloatArray, state: FloatArray) -> FloatArray:
        """Every column of ``u`` (m x p) through the mode; ``state`` (2 x p) updated.

        Parameters
        ----------
        u : ndarray, shape (m, p)
        state : ndarray, shape (2, p)

        Returns
        -------
        ndarray, shape (m, p)
        """
        ad, bd = self._cached()
        out = np.empty_like(u)
        S.mode_filter(np.ascontiguousarray(u), ad, bd, state, out)
        return out

    def apply(self, y: Any, state: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
        """One signal through the mode (state at rest at its first value by default).

        Parameters
        ----------
        y : array_like, shape (N,)
        state : ndarray, shape (2, 1), optional

        Returns
        -------
        tuple of ndarray
            The output and the state.
        """
        ys = np.ascontiguousarray(y, dtype=np.float64)
        st = self.rest_state([ys[0] if ys.size else 0.0]) if state is None else state
        if not self.active:
            return ys.copy(), st
        return self.apply_columns(ys[:, None], st)[:, 0], st

    def unapply(self, y: Any) -> FloatArray:
        """The input held over each sample that the mode turns into ``y`` exactly, from rest
        at ``y[0]`` (as :meth:`apply` starts).

        The discrete mode's inverse, run forward: sample ``k``'s input is what moves the
        position from ``y[k-1]`` to ``y[k]``, and the velocity follows from it. Stable: its
        pole is the held mode's sampling zero, inside the unit circle but near -1 for a mode
        well below the sample rate (-0.968 for 150 Hz at 1 kHz), so noise near half the
        sample rate is amplified and rings on; a fit low-passes the output first where the
        sampling reaches far above the mode. What a core that does not filter its columns
        through the mode is fitted to (:attr:`~piezohyst.model.cores.base.Core.takes_mode`).

        Parameters
        ----------
        y : array_like, shape (N,)
            The mode's output (a displacement record).

        Returns
        -------
        ndarray, shape (N,)

        Examples
        --------
        >>> mode = OutputDynamics(150.0, 0.05, 1e-3)
        >>> u = np.sin(np.linspace(0.0, 20.0, 400))
        >>> y, _ = mode.apply(u)
        >>> bool(np.allclose(mode.unapply(y), u, rtol=0.0, atol=1e-9))
        True
        """
        ys = np.ascontiguousarray(y, dtype=np.float64)
        if not self.active or ys.size < 2:
            return ys.copy()
        ad, bd = self._cached()
        u = np.empty_like(ys)
        S.mode_unfilter(ys, ad, bd, u)
        return u

    def invert(self, desired: FloatArray, before: FloatArray, after: FloatArray) -> FloatArray:
        """The input that makes the mode follow ``desired``: y + 2ζ/ω y' + y''/ω².

        The input held over a sample acts, on average, half a sample before its
        end, so each input is the continuous inverse evaluated there, from
        differences of the trajectory: it needs the two desired values before
        the block (``before``, the last two already used) and one after
        (``after``, the preview; extrapolated when empty). Error of order
        (ω Δt)².

        Parameters
        ----------
        desired : ndarray, shape (N,)
        before : ndarray, shape (2,)
            The two desired values before the block (NaN: none yet, taken as the first
            one known: ``[NaN, a]`` is ``[a, a]``).
        after : ndarray
            Desired values after the block.

        Returns
        -------
        ndarray, shape (N,)
        """
        if not self.active or desired.size == 0:
            return desired.copy()
        nxt = float(after[0]) if after.size else math.nan
        e = np.concatenate([np.asarray(before, dtype=np.float64), desired, [nxt]])
        dt = self.sample_interval
        w = 2.0 * math.pi * self.f0
        k = np.arange(desired.size) + 2  # e[k] is desired[k - 2]
        # a value not known (NaN: before the first, a held sample, no preview) is taken as the
        # nearest known one, per sample as the C step does: ``[NaN, a]`` before is ``[a, a]``,
        # and an unknown next value extrapolates the last two linearly
        cur = e[k]
        b1 = np.where(np.isfinite(e[k - 1]), e[k - 1], cur)
        b0 = np.where(np.isfinite(e[k - 2]), e[k - 2], b1)
        ahead = np.where(np.isfinite(e[k + 1]), e[k + 1], 2.0 * cur - b1)
        mid = 0.5 * (cur + b1)
        d1 = (cur - b1) / dt
        d2 = ((ahead - cur) - (b1 - b0)) / (2.0 * dt * dt)
        return np.asarray(mid + 2.0 * self.zeta / w * d1 + d2 / (w * w))

    def invert_one(self, cur: float, e1: float, e2: float, nxt: float) -> float:
        """:meth:`invert` of one value in floats: the same operations in the same order (a
        loop's ``step`` equals its ``process`` to the bit), without arrays.

        Parameters
        ----------
        cur : float
            The desired value.
        e1, e2 : float
            The one before it and the one before that (NaN: not known).
        nxt : float
            The next one (NaN: extrapolated).

        Returns
        -------
        float
        """
        b1 = e1 if math.isfinite(e1) else cur
        b0 = e2 if math.isfinite(e2) else b1
        ahead = nxt if math.isfinite(nxt) else 2.0 * cur - b1
        dt = self.sample_interval
        w = 2.0 * math.pi * self.f0
        mid = 0.5 * (cur + b1)
        d1 = (cur - b1) / dt
        d2 = ((ahead - cur) - (b1 - b0)) / (2.0 * dt * dt)
        return mid + 2.0 * self.zeta / w * d1 + d2 / (w * w)

    def _cached(self) -> tuple[FloatArray, FloatArray]:
        key = (self.f0, self.zeta, self.sample_interval)
        hit = _MATRICES.get(key)
        if hit is None:
            hit = _MATRICES[key] = self.matrices()
        return hit

    def to_dict(self) -> dict[str, Any]:
        """``f0`` (Hz), ``zeta``, ``sample_interval`` (s).

        Returns
        -------
        dict
        """
        return {"f0": self.f0, "zeta": self.zeta, "sample_interval": self.sample_interval}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> OutputDynamics:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict
            ``f0`` (Hz; 0: no mode), ``zeta`` and ``sample_interval`` (s).

        Returns
        -------
        OutputDynamics
        """
        return cls(
            float(data.get("f0", 0.0)),
            float(data.get("zeta", 0.0)),
            float(data.get("sample_interval", 0.0)),
        )


_MATRICES: dict[tuple[float, float, float], tuple[FloatArray, FloatArray]] = {}
