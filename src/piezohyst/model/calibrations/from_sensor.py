r"""From charge to position: the sensor once, then metres from the charge alone.

At zero stress the strain follows the electric displacement, S = g·D (eq. 6-7),
so once the map from the capacitor's charge to the displacement is known, a
compensator that linearises voltage → charge linearises voltage → position,
and the position sensor can go. :func:`calibrate_gain` identifies that map
from one record with a displacement sensor (voltage, charge and displacement
sampled together):

* the charge the map starts from is the capacitor's: the measured charge with
  the model's growth removed (eq. 19), so leaked charge moves nothing;
* the map is a polynomial in the charge, of the lowest order the record's
  evidence supports: linear ``g`` unless a curvature term's coefficient is
  many standard errors from zero (an electrostrictive part, S ∝ D², on
  semi-bipolar drive or near the coercive field); never curved by default;
* a sensor delay (whole samples; a sensor's lag is absorbed by the delay that
  fits best) if the record shows one, and an offset (the sensor's zero);
* a mechanical mode between the charge and the displacement (a bender's first bending
  mode, a stage's flexure: the charge does not ring, the sensor does) where the record
  shows one ringing: a resonance (damping at most :data:`MODE_ZETA_MAX`; a sensor's own
  low-pass is a delay, not a mode) that takes at least :data:`MODE_SHARE` of the misfit
  away, on strong evidence;
* standard errors from a covariance that allows for correlated residuals
  (Newey-West), so the uncertainty stated is not that of white noise.

The :class:`OutputMap` states its uncertainty at any charge
(:meth:`OutputMap.stderr`), the charge range it was calibrated on (beyond it,
it extends linearly from the range's edge and says so with an
:class:`~piezohyst.errors.ExtrapolationWarning`), whether it is monotone there
(on bipolar drive past the coercive field it is not: the butterfly), and saves
as JSON with a schema and a checksum, like a model file.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import FloatArray, as_signal, as_time, same_length
from ...errors import (
    InsufficientDataError,
    ParameterError,
    warn,
)
from ..dynamics import OutputDynamics
from .output_map import (
    EVIDENCE,
    MAX_DELAY,
    MAX_ORDER,
    MIN_SAMPLES,
    SATURATED_SHARE,
    OutputMap,
    model_fingerprint,
)

#: The most damped mode taken as one (a resonance that overshoots); a sensor's low-pass
#: filter fits as a delay instead
MODE_ZETA_MAX = 0.3
#: The share of the map's squared misfit a mode must take away to be kept (beside the
#: evidence), so that a long record's noise cannot buy a mode that does not matter
MODE_SHARE = 0.1
#: The damping ratios the mode's search starts from
MODE_ZETAS = (0.01, 0.02, 0.04, 0.08, 0.15, 0.3)
#: A mode found within this factor of the searched band's ends is not kept: there the fit
#: bends the filter to stand in for something else (a sensor's low-pass whose delay is not
#: a whole number of samples comes out as a 400 Hz "mode" at 1 kHz, the band's top)
EDGE = 1.05

__all__ = ["calibrate_gain"]


def _newey_west(x: FloatArray, e: FloatArray) -> tuple[FloatArray, int]:
    """The least-squares coefficients' covariance robust to correlated residuals, and the
    lag it spans (until the residuals' autocorrelation is lost in the noise)."""
    n = e.size
    rule = math.ceil(4.0 * (n / 100.0) ** (2.0 / 9.0))
    ec = e - e.mean()
    denom = float(ec @ ec) or 1e-300
    cap = max(rule, min(n // 20, 2000))
    lag = rule
    limit = 2.0 / math.sqrt(n)
    for k in range(1, cap + 1):
        if abs(float(ec[k:] @ ec[:-k]) / denom) < limit:
            lag = max(rule, k)
            break
    else:
        lag = cap
    xe = x * e[:, None]
    s = xe.T @ xe
    for k in range(1, lag + 1):
        g = xe[k:].T @ xe[:-k]
        s += (1.0 - k / (lag + 1.0)) * (g + g.T)
    bread = np.linalg.inv(x.T @ x)
    return bread @ s @ bread, lag


def calibrate_gain(
    model: Any,
    voltage: ArrayLike,
    charge: ArrayLike,
    displacement: ArrayLike,
    t: ArrayLike,
    *,
    max_order: int = MAX_ORDER,
    evidence: float = EVIDENCE,
    max_delay: float = MAX_DELAY,
    output_unit: str = "m",
    output_dynamics: str = "auto",
) -> OutputMap:
    """Identify the map from the capacitor's charge to the displacement (eq. 6-7) from a
    record with a displacement sensor: the one step that needs the sensor.

    Parameters
    ----------
    model : HysteresisModel
        Fitted on voltage → charge (its growth terms are removed from ``charge``).
    voltage, charge, displacement, t : array_like, shape (N,)
        Sampled together: V, C, the sensor's reading (``output_unit``) and s.
    max_order : int, default 3
        Highest polynomial order tried; a term is kept only on evidence.
    evidence : float, default 5
        ``|coefficient / standard error|`` a curvature term needs.
    max_delay : float, default 0.05
        Longest sensor delay searched (s).
    output_unit : str, default "m"
    output_dynamics : {"auto", "none", "second-order"}, default "auto"
        A mechanical mode between the charge and the displacement: kept where the record
        shows one ringing ("auto", on evidence: see the module's notes), never, or always.

    Returns
    -------
    OutputMap

    Raises
    ------
    InsufficientDataError
        Too short a record, a sensor that does not move or sits at its limit.
    """
    v = as_signal(voltage, "voltage")
    q = as_signal(charge, "charge")
    s = as_signal(displacement, "displacement")
    same_length(v, q, "voltage", "charge")
    same_length(v, s, "voltage", "displacement")
    ts = as_time(t, v.size, required=True, owner="calibrate_gain")
    assert ts is not None  # required
    if not callable(getattr(model, "remove_growth", None)):
        msg = f"calibrate_gain needs a fitted piezohyst model. Got {type(model).__name__}."
        raise ParameterError(msg)
    if isinstance(max_order, bool) or not isinstance(max_order, int) or not 1 <= max_order <= 5:
        msg = f"'max_order' must be an int in [1, 5]. Got {max_order!r}."
        raise ParameterError(msg)
    if output_dynamics not in ("auto", "none", "second-order"):
        msg = (
            f"'output_dynamics' must be 'auto', 'none' or 'second-order'. Got {output_dynamics!r}."
        )
        raise ParameterError(msg)
    if v.size < MIN_SAMPLES:
        msg = (
            f"calibrate_gain needs at least {MIN_SAMPLES} samples to tell the map from the "
            f"sensor's noise. Got {v.size}."
        )
        raise InsufficientDataError(msg)
    qc = np.asarray(model.remove_growth(v, q, t=ts), dtype=np.float64)  # eq. 19
    _check_sensor(s, qc, output_unit)
    dt = float(np.median(np.diff(ts)))
    d_max = int(min(round(max_delay / dt), v.size // 20))
    lo, hi = float(qc.min()), float(qc.max())
    if not hi - lo > 1e-12 * max(abs(lo), abs(hi), 1e-300):
        msg = "the capacitor charge never moves: nothing maps it to a displacement"
        raise InsufficientDataError(msg)
    center, scale = 0.5 * (lo + hi), 0.5 * (hi - lo)
    leak = _leak_columns(v, q, ts)  # what the displacement tells the model's growth from

    mode = OutputDynamics()

    def design(delay: int, order: int) -> tuple[FloatArray, FloatArray]:
        u = (qc[: qc.size - delay] - center) / scale
        x = np.column_stack([u**k for k in range(order + 1)] + [leak[: u.size]])
        return _through(mode, x), s[delay:]

    # the delay that fits best with the richest map (a delay is a shift, not a shape)
    sse = []
    for d in range(d_max + 1):
        x, y = design(d, max_order)
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        r = y - x @ coef
        sse.append(float(r @ r) / r.size)
    delay = int(np.argmin(sse))
    found: dict[str, float] = {}
    if output_dynamics != "none":
        x, y = design(delay, max_order)
        mode, strength = _find_mode(x, y, dt, output_dynamics == "second-order", evidence)
        if mode.active:
            found["mode"] = strength
    order = 1
    fits: dict[int, tuple[Any, Any, FloatArray, int]] = {}
    for k in range(1, max_order + 1):
        x, y = design(delay, k)
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        r = y - x @ coef
        cov, lag = _newey_west(x, r)
        fits[k] = (coef, cov, r, lag)
        if k > 1:
            t_top = abs(float(coef[k])) / math.sqrt(max(float(cov[k, k]), 1e-300))
            found[f"order {k}"] = t_top
            if t_top < evidence:
                break
            order = k
    full, full_cov, r, lag = fits[order]
    coef, cov = full[: order + 1], full_cov[: order + 1, : order + 1]
    n = r.size
    rho = _lag1(r)
    n_eff = int(max(2, round(n * (1 - rho) / (1 + rho)))) if rho > 0 else n
    om = OutputMap(
        coefficients=tuple(float(c) for c in coef),
        center=center,
        scale=scale,
        covariance=tuple(tuple(float(c) for c in row) for row in cov),
        charge_range=(lo, hi),
        delay=delay * dt,
        residual=float(math.sqrt(float(r @ r) / n)),
        n_samples=n,
        n_effective=n_eff,
        evidence=found,
        input_unit=getattr(model, "output_unit", "C"),
        output_unit=output_unit,
        model=model_fingerprint(model),
        mode_f0=mode.f0,
        mode_zeta=mode.zeta,
        mode_dt=mode.sample_interval,
    )
    sure = max(abs(c) / math.sqrt(max(float(cov[k, k]), 1e-300)) for k, c in enumerate(coef) if k)
    if sure < evidence:  # no term of the map stands out from its error
        msg = (
            f"the displacement does not follow the charge (gain {om.gain:.3g} ± "
            f"{om.gain_stderr:.2g} {output_unit}/{om.input_unit}, no term beyond "
            f"{evidence:g} standard errors): is the sensor on the actuator, and the right column?"
        )
        raise InsufficientDataError(msg)
    if not om.monotone:
        s_lo, s_hi = om.displacement_range()
        warn(
            f"calibrate_gain: the displacement does not follow the charge one way over the "
            f"record (it turns: the butterfly of bipolar drive past the coercive field); "
            f"displacements in [{s_lo:.4g}, {s_hi:.4g}] {output_unit} are reached on two "
            "branches, and a compensator keeps to the branch the charge is on",
            UserWarning,
        )
    return om


def _through(mode: OutputDynamics, x: FloatArray) -> FloatArray:
    """Every column of a design but the first (the constant) through the mode, each from
    rest at its first value (a unit-gain filter: the map's coefficients stay its own)."""
    if not mode.active:
        return x
    out = x.copy()
    out[:, 1:] = mode.apply_columns(np.ascontiguousarray(x[:, 1:]), mode.rest_state(x[0, 1:]))
    return out


def _find_mode(
    x: FloatArray, y: FloatArray, dt: float, always: bool, evidence: float
) -> tuple[OutputDynamics, float]:
    """The mode that fits the displacement best through the design ``x`` (a grid of
    resonances from the record's length to 0.4 of the sample rate and of damping ratios,
    then refined), and how strong its evidence is (the likelihood ratio's square root,
    with as many independent samples as the residuals' correlation is worth, comparable
    with a coefficient's ``|c / stderr|``). Without ``always`` it is kept only where that is
    at least ``evidence``, the damping at most :data:`MODE_ZETA_MAX`, the squared misfit
    falls by :data:`MODE_SHARE` and the resonance lies inside the band (:data:`EDGE`)."""
    from scipy.optimize import minimize

    def sse(f0: float, zeta: float) -> float:
        if not (f_lo <= f0 <= f_hi and 1e-3 <= zeta <= 1.0):
            return math.inf
        xf = _through(OutputDynamics(f0, zeta, dt), x)
        coef, *_ = np.linalg.lstsq(xf, y, rcond=None)
        r = y - xf @ coef
        return float(r @ r)

    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    r0 = y - x @ coef
    base = float(r0 @ r0)
    f_lo, f_hi = max(2.0, 20.0 / (y.size * dt)), 0.4 / dt
    if not f_hi > f_lo or base == 0.0:
        return OutputDynamics(), 0.0
    grid = {(f, z): sse(f, z) for f in np.geomspace(f_lo, f_hi, 48) for z in MODE_ZETAS}
    (f0, zeta), low = min(grid.items(), key=lambda item: item[1])
    best = minimize(
        lambda p: sse(math.exp(p[0]), math.exp(p[1])), np.log((f0, zeta)), method="Nelder-Mead",
        options={"xatol": 1e-4, "fatol": 1e-9 * base, "maxiter": 400},
    )  # fmt: skip
    if float(best.fun) < low:  # refined; else the grid's point stands
        f0, zeta = (float(math.exp(p)) for p in best.x)
        low = float(best.fun)
    rho = _lag1(r0)
    n_eff = y.size * (1 - rho) / (1 + rho) if rho > 0 else y.size
    strength = math.sqrt(max(n_eff * math.log(base / max(low, 1e-300)), 0.0))
    inside = EDGE * f_lo < f0 < f_hi / EDGE  # at the band's edge it stands in for something
    kept = always or (  # else (a sensor's fractional delay, at the top), not a resonance
        strength >= evidence and zeta <= MODE_ZETA_MAX and low <= (1 - MODE_SHARE) * base and inside
    )
    return (OutputDynamics(f0, zeta, dt), strength) if kept else (OutputDynamics(), strength)


def _leak_columns(v: FloatArray, q: FloatArray, t: FloatArray) -> FloatArray:
    """The leakage shapes the model's growth terms may have missed (the terms of
    :data:`~piezohyst.model.calibrations.leakage.LEAKAGE_TERMS`: ohmic, voltage-dependent, a bias
    current, the reference capacitor's discharge), each integrated by the backward
    rectangle rule the growth terms use (eq. 13) and scaled to its span. The displacement
    does not see leaked charge, so their coefficients take up whatever leakage the charge
    model got wrong, instead of the gain."""
    dt = np.diff(t)
    vs = max(float(np.abs(v).max()), 1e-300)
    cols = []
    for rate in (v, v * np.abs(v) / vs, np.ones_like(v), q - q[0]):
        c = np.concatenate([[0.0], np.cumsum(rate[1:] * dt)])
        span = float(np.ptp(c))
        cols.append(c / span if span > 0 else c)
    return np.column_stack(cols)


def _lag1(r: FloatArray) -> float:
    rc = r - r.mean()
    den = float(rc @ rc)
    return float(rc[1:] @ rc[:-1]) / den if den > 0 else 0.0


def _check_sensor(s: FloatArray, qc: FloatArray, unit: str) -> None:
    """Refuse a sensor reading that cannot calibrate: still, or sitting at its limit while
    the charge moves on (a hold at the top is not saturation: the charge holds too)."""
    span = float(np.ptp(s))
    noise = float(np.median(np.abs(np.diff(s)))) / 0.954 / math.sqrt(2.0)  # robust, per sample
    if not span > 20.0 * noise or span == 0.0:
        msg = (
            f"the displacement barely moves ({span:.3g} {unit} peak to peak against a noise "
            f"of {noise:.2g} {unit}): is the sensor on, and the right column?"
        )
        raise InsufficientDataError(msg)
    tol = 1e-9 * span
    for name, edge in (("top", float(s.max())), ("bottom", float(s.min()))):
        at = np.abs(s - edge) <= tol
        moving = at.any() and float(np.ptp(qc[at])) > 0.05 * float(np.ptp(qc))
        if at.sum() > max(SATURATED_SHARE * s.size, 10) and moving:
            runs = np.flatnonzero(at)
            msg = (
                f"the displacement sensor sits at its {name} reading {edge:.6g} {unit} for "
                f"{int(at.sum())} samples (first at sample {int(runs[0])}): saturated; "
                "calibrate within the sensor's range"
            )
            raise InsufficientDataError(msg)
