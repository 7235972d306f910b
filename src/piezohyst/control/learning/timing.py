r"""The loop's lag measured on the first trial after the lead-in, where the model holds none.

A model identified without input dynamics (``piezohyst fit``'s default on a record that
cannot tell a lag from hysteresis) has absorbed the amplifier's lag at the record's own
rates, and not beyond them: behind a 4 ms amplifier a 40 Hz scan's commands arrive 45
degrees late, its third harmonic 72 degrees, and a law that assumes no lag learns those
harmonics slowly or not at all (0.5-5.7 % width after 10 trials on the plants of
``benchmarks/default_path.py``). The lead-in's probe measures the loop's phase with sines
of 0.2 % of the span, too weak to size the lag on a capacitor whose small-signal response
is not the amplifier's (:mod:`.probe`; docs/benchmarks.md). The first trial after the
lead-in is a record at the scan's own rate and full amplitude: its readings against the
model's prediction from its commands, each command through a first-order lag
(:func:`periodic_lag`, the trial's periodic steady state), find the lag that explains the
trial (:func:`trial_lag`). It is kept where it removes at least :data:`EXPLAINED` of the
trial's misfit variance (a lag the trial shows, not a polish of the model's hysteresis
error) and lies inside the search. The learner then runs a copy of the model that holds the
lag (:func:`timed`): the next trial's commands invert it, and the law is chosen on that
trial, as for a model identified with its lag (the trial that measured it is a second
lead-in, not learned from). How sure: the lag measured again with each fifth of the trial
left out (a jackknife over :data:`BLOCKS` blocks), the spread of those as a 95 % half-width.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from copy import deepcopy
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...model.dynamics import InputDynamics, filter_response

FloatArray = np.ndarray

__all__ = ["BLOCKS", "EXPLAINED", "MAX_LAG", "TrialLag", "periodic_lag", "timed", "trial_lag"]

#: the longest lag searched (s): amplifiers and sensor filters, as the fit's own search
MAX_LAG = 0.05
#: the share of the trial's misfit variance a lag must remove to be kept (chosen before any
#: trial was scored with it: a lag that halves the misfit is what the trial shows)
EXPLAINED = 0.5
#: blocks of the trial the jackknife leaves out one at a time, for the lag's spread
BLOCKS = 5


@dataclass(frozen=True)
class TrialLag:
    """A first-order lag measured on a trial.

    Attributes
    ----------
    lag : float
        s.
    misfit, left : float
        RMS of the trial's readings against the model's prediction (offset-free, desired
        units), without the lag and with it.
    spread : float
        s, the 95 % half-width of the lag from a jackknife over :data:`BLOCKS` blocks of the
        trial (Student's t with ``BLOCKS - 1`` degrees of freedom); NaN where too few
        readings to split.
    trial : int
        The trial it was measured on (-1: not said).
    """

    lag: float
    misfit: float
    left: float
    spread: float = math.nan
    trial: int = -1

    def describe(self) -> str:
        """What the learner says of it: the lag, how sure, where measured, what it explains.

        Returns
        -------
        str
        """
        sure = f" (+- {self.spread * 1e3:.2g} ms over the trial's fifths, 95 %)"
        return (
            f"the model holds a {self.lag * 1e3:.3g} ms lag"
            + (sure if math.isfinite(self.spread) else "")
            + f" measured on trial {self.trial}, not learned from (the model given holds none; "
            f"the lag explains {self.explained:.0%} of that trial's misfit)"
        )

    @property
    def explained(self) -> float:
        """The share of the misfit's variance the lag removes."""
        return 1.0 - (self.left / self.misfit) ** 2 if self.misfit > 0 else 0.0


def periodic_lag(v: FloatArray, tau: float, sample_rate: float) -> FloatArray:
    """``v`` repeated forever through a first-order lag ``tau`` (s) of held samples, the lag
    :class:`~piezohyst.model.dynamics.InputDynamics` applies and the harmonic law inverts:
    one period of the steady state, exactly (its response at each harmonic of the period,
    :func:`~piezohyst.model.dynamics.filter_response`).

    Parameters
    ----------
    v : ndarray
        One period.
    tau : float
        s; 0 returns a copy.
    sample_rate : float
        Hz.

    Returns
    -------
    ndarray

    Examples
    --------
    >>> import numpy as np
    >>> k = np.arange(1000)
    >>> v = np.sin(2 * np.pi * 10 * k / 1000)
    >>> u = periodic_lag(v, 1 / (2 * np.pi * 10), 1000.0)   # the corner near 10 Hz
    >>> round(float(np.ptp(u) / np.ptp(v)), 3)                 # about 1 / sqrt(2)
    0.707
    """
    if tau <= 0:
        return np.array(v, dtype=np.float64)
    f = np.fft.rfftfreq(v.size, 1.0 / sample_rate)
    h = filter_response(0.0, tau, 1.0 / sample_rate, f)
    return np.fft.irfft(np.fft.rfft(v) * h, n=v.size)


def timed(model: Any, lag: float, sample_rate: float) -> Any:
    """A copy of a fitted ``model`` that holds a first-order lag of ``lag`` s before its
    input (held samples at ``sample_rate`` Hz, as :class:`~piezohyst.InputDynamics` applies
    it); the model itself is not changed.

    Parameters
    ----------
    model : HysteresisModel
        Fitted, without input dynamics.
    lag : float
        s.
    sample_rate : float
        Hz.

    Returns
    -------
    HysteresisModel
    """
    copy = deepcopy(model)
    copy.set_params(input_dynamics="first-order")
    dyn = InputDynamics("first-order", tau=float(lag), sample_interval=1.0 / sample_rate)
    copy.take_fit(input_dynamics=dyn)
    return copy


def trial_lag(
    respond: Callable[[FloatArray], FloatArray],
    commands: FloatArray,
    measured: FloatArray,
    usable: FloatArray,
    sample_rate: float,
) -> TrialLag | None:
    """The first-order lag between a trial's commands and its readings that the model,
    run after itself (``respond``), explains best; None where it explains less than
    :data:`EXPLAINED` of the misfit or lies at the search's end.

    Parameters
    ----------
    respond : callable
        Commands (one trial) -> the model's output in the readings' units.
    commands, measured : ndarray
        The trial's commands (V) and readings (desired units; their offset is free).
    usable : ndarray of bool
        The readings to compare.
    sample_rate : float
        Hz.

    Returns
    -------
    TrialLag or None
    """
    from scipy.optimize import minimize_scalar
    from scipy.stats import t as student

    if usable.sum() < 3:
        return None
    top = min(MAX_LAG, 0.1 * commands.size / sample_rate)
    dt = 1.0 / sample_rate

    def misfit(tau: float, keep: FloatArray) -> float:
        """RMS of the readings against the model through the lag, offset-free."""
        r = (measured - respond(periodic_lag(commands, tau, sample_rate)))[keep]
        return float(np.std(r))

    def best(keep: FloatArray, lo: float, hi: float) -> tuple[float, float]:
        """The lag that fits the ``keep`` readings best in [lo, hi], and its misfit."""
        found = minimize_scalar(misfit, bounds=(lo, hi), args=(keep,), method="bounded",
                                options={"xatol": 0.01 * dt})  # fmt: skip
        return float(found.x), float(found.fun)

    tau, left = best(usable, 0.0, top)
    lag = TrialLag(tau, misfit(0.0, usable), left)
    if not math.isfinite(lag.left) or lag.lag > top - dt or lag.explained < EXPLAINED:
        return None
    rows = np.flatnonzero(usable)
    if rows.size < 10 * BLOCKS:
        return lag
    parts = []
    for block in np.array_split(rows, BLOCKS):  # each fifth left out, searched near the lag
        keep = usable.copy()
        keep[block] = False
        parts.append(best(keep, 0.5 * tau, min(2.0 * tau, top))[0])
    jack = np.asarray(parts)
    half = float(student.ppf(0.975, BLOCKS - 1)) * math.sqrt(
        (BLOCKS - 1) / BLOCKS * float(np.sum((jack - jack.mean()) ** 2))
    )
    return replace(lag, spread=half)
