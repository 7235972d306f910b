"""The leakage identified from constant-voltage holds: :func:`find_holds` finds them in a
record, :func:`calibrate_leakage` measures the charge's slope on each (after it settles) and
fits the terms the holds can tell apart (:class:`~.leakage.Leakage` holds the result)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..._kernels import signal as S
from ..._validation import FloatArray, as_signal, as_time, same_length
from ...errors import InsufficientDataError, ParameterError, warn
from .leakage import LEAKAGE_TERMS, Hold, Leakage

__all__ = ["calibrate_leakage", "find_holds"]


def find_holds(
    t: ArrayLike,
    v: ArrayLike,
    *,
    tolerance: float | None = None,
    min_duration: float = 1.0,
    settle: float = 0.25,
) -> list[tuple[int, int]]:
    """Stretches where the voltage stays constant, without their settling start.

    Parameters
    ----------
    t, v : array_like, shape (N,)
        Times (s) and voltages.
    tolerance : float, optional
        How far the voltage may wander from the hold's first sample; default
        0.1 % of the record's span (a DAC's or monitor's noise).
    min_duration : float, default 1.0
        Shortest hold kept (s), counted after the settling.
    settle : float, default 0.25
        Fraction of each hold dropped at its start, where creep and the
        amplifier still settle after the step.

    Returns
    -------
    list of (start, stop)
        Sample ranges ``start:stop``.
    """
    ts = as_time(t, np.size(v), required=True, owner="find_holds")
    x = as_signal(v, "v")
    assert ts is not None
    tol = 1e-3 * float(np.ptp(x)) if tolerance is None else float(tolerance)
    if not 0.0 <= settle < 1.0:
        msg = f"'settle' must be a fraction in [0, 1). Got {settle!r}."
        raise ParameterError(msg)
    edges = np.empty(x.size + 1, dtype=np.int64)
    count = S.constant_runs(x, tol, edges)
    holds = []
    for k, j in itertools.pairwise(edges[: count + 1]):
        if j - k >= 3:
            first = k + math.ceil(settle * (j - k))
            if j - first >= 3 and ts[j - 1] - ts[first] >= min_duration:
                holds.append((int(first), int(j)))
    return holds


#: Trims tried at a hold's start (fractions), shortest first: the first whose slope agrees
#: with the hold's last 40 % is kept, so a hold still settling loses more
TRIMS = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5)
#: The calibrated current's relative standard error above which a warning names longer holds
#: (and beyond 10 %, the calibration refuses)
CURRENT_RTOL = 0.03


def calibrate_leakage(
    t: ArrayLike,
    v: ArrayLike,
    q: ArrayLike,
    *,
    terms: Sequence[str] = LEAKAGE_TERMS,
    select: bool = True,
    holds: Sequence[tuple[int, int]] | None = None,
    tolerance: float | None = None,
    min_duration: float = 1.0,
    settle: float | str = "auto",
    scale: float | None = None,
    input_unit: str = "V",
    output_unit: str = "C",
) -> Leakage:
    r"""Fit the leakage current from the charge's slope on constant-voltage holds.

    On each hold the slope of a straight line through the charge is the
    current there, with its standard error; the terms of
    :math:`G_0 v + G_1 v|v|/s + i_b - q/\tau` are fitted to those currents,
    each weighted by its precision. The physics is kept: a conductance (at 0 V
    and at the top, :math:`G_0 + G_1`) or a discharge is never negative.
    With ``select`` the terms are chosen by evidence: of every subset the holds
    can determine, the one with the lowest Bayesian information criterion (the
    misfit in the holds' standard errors, plus ln(holds) per term); while holds
    still settle, every voltage term is kept and no discharge is chosen. The
    result carries the coefficients' covariance (:meth:`Leakage.stderr`,
    :meth:`Leakage.current_stderr`), and one that also counts the terms the choice
    left out, for the charge over a scan (:meth:`Leakage.charge_stderr`); a current
    less sure than 3 % at a hold's voltage gets a warning naming the hold length
    that would do, and beyond
    10 % the calibration refuses, as it does for settling holds all reached
    from one side. The
    discharge term needs holds at one voltage with different charges (reached
    from below and from above); the others need as many voltage levels as
    terms. A hold's slope is uncertain by about ``noise * sqrt(12 / samples) /
    duration``: a few long holds beat many short ones.

    Parameters
    ----------
    t, v, q : array_like, shape (N,)
        Times (s), voltages and measured charge.
    terms : sequence of str, default all
        Of ``"conductance"``, ``"quadratic"``, ``"bias"``, ``"discharge"``.
    select : bool, default True
        Choose among ``terms`` by evidence; False fits them all.
    holds : sequence of (start, stop), optional
        The holds as sample ranges; default found by :func:`find_holds`.
    tolerance, min_duration
        Passed to :func:`find_holds`.
    settle : float or "auto", default "auto"
        The fraction of each hold dropped at its start, where creep and the
        amplifier still settle; "auto" chooses it per hold from
        :data:`TRIMS`: the shortest whose slope agrees with the hold's last 40 %.
    scale : float, optional
        :math:`s`; default the largest ``|v|`` of the record.
    input_unit, output_unit : str
        Units of ``v`` and ``q``.

    Returns
    -------
    Leakage
        With the holds used, the fit's RMS residual and the covariance.

    Raises
    ------
    ParameterError
        Unknown terms.
    InsufficientDataError
        Too few holds, or holds at too few distinct voltages, to determine
        the requested terms; or a current too uncertain to stand behind.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(12000) / 1000.0
    >>> v = np.repeat([0.0, 50.0, 100.0], 4000)
    >>> q = np.cumsum((2e-9 * v + 1e-11) * 1e-3)
    >>> leak = calibrate_leakage(t, v, q, terms=("conductance", "bias"), select=False)
    >>> round(leak.conductance / 1e-9, 6), round(leak.bias / 1e-11, 6), len(leak.holds)
    (2.0, 1.0, 3)
    """
    chosen = tuple(terms)
    unknown = [name for name in chosen if name not in LEAKAGE_TERMS]
    if unknown or not chosen or len(set(chosen)) != len(chosen):
        msg = f"'terms' must be distinct names from {LEAKAGE_TERMS}. Got {chosen!r} instead."
        raise ParameterError(msg)
    x = as_signal(v, "v")
    y = as_signal(q, "q")
    same_length(x, y, "v", "q")
    ts = as_time(t, x.size, required=True, owner="calibrate_leakage")
    assert ts is not None
    s = float(np.max(np.abs(x))) if scale is None else float(scale)
    s = s if s > 0 else 1.0
    auto = isinstance(settle, str)
    if auto and settle != "auto":
        msg = f"'settle' must be a fraction in [0, 1) or 'auto'. Got {settle!r}."
        raise ParameterError(msg)
    if holds is None:
        ranges = find_holds(ts, x, tolerance=tolerance, min_duration=min_duration,
                            settle=0.0 if auto else float(settle))  # fmt: skip
    else:
        ranges = [(int(a), int(b)) for a, b in holds]
    found = []
    settling = 0  # holds whose charge had not settled when they ended
    for a, b in ranges:
        if not 0 <= a < b <= x.size or b - a < 3:
            msg = f"a hold must be a range start:stop of at least 3 samples. Got {a}:{b}."
            raise ParameterError(msg)
        gap = 0.0
        if auto and holds is None:
            a, gap = _settled_start(ts, y, a, b)
        if gap > 0.0:  # a charge still settling: its end slope, and what may be left of it
            slope, stderr = _steady_slope(ts, y, a, b)
            # what is left after the hold: for a relaxation slower than the hold, more than
            # it moved within it; twice that (measured on the relaxing plants of
            # piezohyst.simulation.PLANTS: it then holds the truth to 3 standard errors)
            stderr = math.hypot(stderr, 2.0 * gap)
        else:
            slope, stderr = _slope(ts, y, a, b)
        settling += gap > 0.0
        found.append(Hold(a, b, float(x[a:b].mean()), float(y[a:b].mean()), slope, stderr,
                          float(ts[b - 1] - ts[a])))  # fmt: skip
    span = float(np.ptp(x)) or 1.0
    levels = _distinct([h.voltage for h in found], 0.02 * span)
    by_voltage = [name for name in chosen if name != "discharge"]
    choosing = select and len(chosen) > 1
    need_levels, need_holds = (1, 2) if choosing else (len(by_voltage), len(chosen))
    if len(levels) < need_levels or len(found) < need_holds:
        where = ", ".join(f"{lv:.4g}" for lv in levels)
        seen = (
            f"{len(found)} hold(s) at {len(levels)} distinct voltage(s) ({where} {input_unit})"
            if found else "no hold (the voltage steady for seconds) in the record"
        )  # fmt: skip
        msg = (
            f"{seen}: too few to determine {len(chosen)} leakage term(s) "
            f"({', '.join(chosen)}): record holds of several seconds at more levels, up and "
            "down again (e.g. 0, 25, 50, 75, 100, 75, 50, 25, 0 % of the range), or ask for "
            "fewer terms"
        )
        raise InsufficientDataError(msg)
    if settling and holds is None:
        _both_ways(found, ranges, x, settling, input_unit)
    system = _HoldSystem(found, s)
    subsets = [chosen]
    pool = chosen
    if choosing:
        # a relaxation after each step leaves the charge higher on a hold reached from above,
        # flowing out: a discharge to the fit. While holds still settle, none is chosen, and
        # the currents (settling holds weighed by what may be left of it) are too uncertain
        # to drop a voltage term on: all of them are fitted, their uncertainty reported.
        pool = tuple(n for n in chosen if not (settling and n == "discharge")) or chosen
        subsets = [c for k in range(1, len(pool) + 1) for c in itertools.combinations(pool, k)]
        if settling and system.determines(pool, levels):
            subsets = [pool]
    if len(subsets) == 1:  # nothing to choose: fitted as asked, no hold left out
        ok = system.determines(subsets[0], levels, spare=0)
        scored = [(0.0, subsets[0])] if ok and system.physical(subsets[0]) else []
    else:
        scored = [(system.bic(c), c) for c in subsets if system.determines(c, levels)]
        scored = [(score, c) for score, c in scored if math.isfinite(score)]
        able = {n for _, c in scored for n in c}
        if scored and able != set(pool):
            _undetermined([n for n in pool if n not in able], found, input_unit)
    if not scored:
        msg = (
            f"the {len(found)} holds cannot tell the terms {', '.join(chosen)} apart"
            + (
                ": the discharge term needs holds at one voltage with different charges "
                "(hold each level once on the way up and once on the way down)"
                if "discharge" in chosen
                else ""
            )
            + "; or ask for fewer terms"
        )
        raise InsufficientDataError(msg)
    pick = min(scored, key=lambda sc: (sc[0], len(sc[1])))[1]
    coef, cov, misfit = system.fit(pick)
    values = dict.fromkeys(LEAKAGE_TERMS, 0.0)
    values.update(dict(zip(pick, coef, strict=True)))
    full = np.zeros((4, 4))
    index = [LEAKAGE_TERMS.index(name) for name in pick]
    full[np.ix_(index, index)] = cov
    drift = _choice_covariance(system, pick, coef, full, pool, levels)
    rows = [tuple(tuple(float(c) for c in row) for row in m) for m in (full, drift)]
    leak = Leakage(values["conductance"], values["quadratic"], values["bias"], s,
                   values["discharge"], input_unit, output_unit, holds=tuple(found),
                   residual=float(np.sqrt(np.mean(misfit**2))),
                   covariance=rows[0], drift_covariance=rows[1])  # fmt: skip
    _check_sure(leak, found, input_unit, settling)
    return leak


def _choice_covariance(
    system: _HoldSystem,
    pick: Sequence[str],
    coef: Sequence[float],
    cov: FloatArray,
    pool: Sequence[str],
    levels: list[float],
) -> FloatArray:
    """:attr:`Leakage.drift_covariance`: ``cov`` (4, 4), or where the choice left out terms
    of ``pool`` that the holds determine with their physics all at once, the fit of every
    term's plus the outer product of the two fits' difference."""
    if set(pick) == set(pool) or not (system.determines(pool, levels) and system.physical(pool)):
        return cov
    every, every_cov, _ = system.fit(pool)
    at = [LEAKAGE_TERMS.index(n) for n in pool]
    chosen, whole = np.zeros(4), np.zeros(4)
    chosen[[LEAKAGE_TERMS.index(n) for n in pick]] = coef
    whole[at] = every
    out = np.zeros((4, 4))
    out[np.ix_(at, at)] = every_cov
    return out + np.outer(chosen - whole, chosen - whole)


def _slope(ts: FloatArray, y: FloatArray, a: int, b: int) -> tuple[float, float]:
    """The least-squares slope of ``y`` over samples ``a:b`` and its standard error."""
    tt = ts[a:b] - ts[a:b].mean()
    qq = y[a:b] - y[a:b].mean()
    sxx = float(tt @ tt)
    slope = float(tt @ qq) / sxx
    resid = qq - slope * tt
    return slope, math.sqrt(float(resid @ resid) / max(b - a - 2, 1) / sxx)


def _steady_slope(ts: FloatArray, y: FloatArray, a: int, b: int) -> tuple[float, float]:
    """A hold's current and its standard error. A charge still relaxing (creep, dielectric
    relaxation, dipoles switching) curves: when a quadratic's curvature is significant
    (3 standard errors) the current is the slope at the hold's end, and its error grows
    by what the relaxation may still change after it (the curvature times half the hold)."""
    slope, stderr = _slope(ts, y, a, b)
    if b - a < 10:
        return slope, stderr
    tt = ts[a:b] - ts[a:b].mean()
    basis = np.column_stack([np.ones_like(tt), tt, tt**2 - float(np.mean(tt**2))])
    coef, res, *_ = np.linalg.lstsq(basis, y[a:b], rcond=None)
    dof = max(b - a - 3, 1)
    sigma2 = float(res[0]) / dof if res.size else 0.0
    cov = np.linalg.pinv(basis.T @ basis) * sigma2
    c2, e2 = float(coef[2]), math.sqrt(max(float(cov[2, 2]), 0.0))
    if not abs(c2) > 3.0 * e2:
        return slope, stderr
    half = float(tt[-1])
    g = np.array([0.0, 1.0, 2.0 * half])  # d/dt at the end
    end_slope = float(g @ coef)
    end_err = math.sqrt(max(float(g @ cov @ g), 0.0))
    return end_slope, math.hypot(end_err, abs(c2) * half)


#: A hold counts as still settling when its slope moved by more than this share of the
#: current within it (and beyond its noise): a sixth of the 3 % a calibration aims for
SETTLING_SHARE = 0.005


def _settled_start(ts: FloatArray, y: FloatArray, a: int, b: int) -> tuple[int, float]:
    """The first sample of a hold to use: the shortest trim (:data:`TRIMS`) whose slope
    agrees, within two standard errors, with the slope of the hold's last 40 %. And when
    the charge was still settling (no trim under a fifth of the hold agreed, and the slope
    moved by more than :data:`SETTLING_SHARE` of the current), how far the slope moved
    within the hold (the shortest trim's against the tail's; else 0): what is left of the
    settling after the hold may be as large."""
    n = b - a
    tail = a + math.ceil(0.6 * n)
    if b - tail < 3:
        return a + math.ceil(TRIMS[2] * n), 0.0
    s_tail, e_tail = _slope(ts, y, tail, b)
    start, moved, noise = a, 0.0, 0.0
    for i, f in enumerate(TRIMS):
        start = a + math.ceil(f * n)
        s_f, e_f = _slope(ts, y, start, b)
        if i == 0:
            moved, noise = abs(s_f - s_tail), 3.0 * math.hypot(e_f, e_tail)
        if abs(s_f - s_tail) <= 2.0 * math.hypot(e_f, e_tail):
            break
    settling = start >= a + math.ceil(0.2 * n) and moved > max(noise, SETTLING_SHARE * abs(s_tail))
    return start, moved if settling else 0.0


class _HoldSystem:
    """The hold currents as a weighted linear system in the leakage terms."""

    def __init__(self, found: list[Hold], s: float) -> None:
        volts = np.array([h.voltage for h in found])
        self.columns = {
            "conductance": volts,
            "quadratic": volts * np.abs(volts) / s,
            "bias": np.ones_like(volts),
            "discharge": -np.array([h.charge for h in found]),
        }
        self.rhs = np.array([h.current for h in found])
        err = np.array([h.stderr for h in found])
        # a hold whose charge sat on one ADC code has a slope error of 0 on paper: no hold is
        # trusted more than ten times the typical one
        typical = float(np.median(err[err > 0])) if np.any(err > 0) else 0.0
        floor = max(1e-6 * float(np.max(np.abs(self.rhs))), 0.1 * typical) or 1e-300
        self.w = 1.0 / np.maximum(err, floor)

    def determines(self, names: Sequence[str], levels: list[float], spare: int = 1) -> bool:
        """Whether the holds fix these terms (with ``spare`` holds to leave one out)."""
        by_voltage = [n for n in names if n != "discharge"]
        if len(levels) < len(by_voltage) or self.rhs.size < len(names) + spare:
            return False
        design = np.column_stack([self.columns[n] for n in names]) * self.w[:, None]
        norms = np.linalg.norm(design, axis=0)
        if norms.min() == 0:
            return False
        sv = np.linalg.svd(design / norms, compute_uv=False)
        return bool(sv[-1] >= 1e-3 * sv[0])

    def _solve(self, names: Sequence[str], rows: np.ndarray) -> FloatArray | None:
        """Bounded weighted least squares on ``rows``; None when a physical bound binds
        (that subset is then a smaller one, scored on its own)."""
        from scipy.optimize import lsq_linear

        a_mat = np.column_stack([self.columns[n] for n in names])[rows] * self.w[rows, None]
        lower = [0.0 if n in ("conductance", "discharge") else -np.inf for n in names]
        scale = np.linalg.norm(a_mat, axis=0)
        scale[scale == 0] = 1.0
        res = lsq_linear(a_mat / scale, self.rhs[rows] * self.w[rows],
                         bounds=(np.array(lower), np.full(len(names), np.inf)))  # fmt: skip
        coef = np.asarray(res.x / scale)
        values = dict(zip(names, coef, strict=True))
        at_top = values.get("conductance", 0.0) + values.get("quadratic", 0.0)
        bound = bool(np.any(res.active_mask != 0)) or any(
            values[n] <= 0.0 for n in names if n in ("conductance", "discharge")
        )
        if bound or at_top < 0.0:
            return None
        return coef

    def physical(self, names: Sequence[str]) -> bool:
        """Whether the fit on every hold keeps the physics (no negative conductance or
        discharge)."""
        return self._solve(names, np.arange(self.rhs.size)) is not None

    def bic(self, names: Sequence[str]) -> float:
        """The Bayesian information criterion of a subset on the hold currents: chi-squared
        in the holds' standard errors plus ln(holds) per term (inf: unphysical)."""
        coef = self._solve(names, np.arange(self.rhs.size))
        if coef is None:
            return math.inf
        a_mat = np.column_stack([self.columns[n] for n in names])
        chi2 = float(np.sum(((self.rhs - a_mat @ coef) * self.w) ** 2))
        return chi2 + len(names) * math.log(self.rhs.size)

    def fit(self, names: Sequence[str]) -> tuple[list[float], FloatArray, FloatArray]:
        """Coefficients, their covariance (scaled by the misfit when it exceeds the
        standard errors) and the misfit of every hold."""
        rows = np.arange(self.rhs.size)
        coef = self._solve(names, rows)
        assert coef is not None
        a_mat = np.column_stack([self.columns[n] for n in names])
        misfit = self.rhs - a_mat @ coef
        chi2 = float(np.sum((misfit * self.w) ** 2)) / max(self.rhs.size - len(names), 1)
        weighted = a_mat * self.w[:, None]
        norms = np.linalg.norm(weighted, axis=0)  # columns of volts and of coulombs: scaled
        norms[norms == 0] = 1.0
        scaled = weighted / norms
        cov = np.linalg.pinv(scaled.T @ scaled) / np.outer(norms, norms) * max(chi2, 1.0)
        return [float(c) for c in coef], cov, misfit


def _undetermined(names: list[str], found: list[Hold], unit: str) -> None:
    """Warn that terms asked for were left out because the holds cannot fix them (or fix
    them only with an unphysical sign), and say which holds would."""
    advice = {
        "discharge": "holds at one voltage reached from below and from above, with "
        "different charges",
        "quadratic": "holds at three or more voltages, the highest near the top",
        "bias": "a hold at 0 V or holds at several voltages",
        "conductance": "holds at two or more voltages",
    }
    levels = ", ".join(f"{v:.4g}" for v in _distinct([h.voltage for h in found], 1e-9))
    warn(
        f"the {len(found)} holds (at {levels} {unit}) cannot determine "
        + "; ".join(f"the {n} term (it needs {advice[n]})" for n in names)
        + ": left out",
        UserWarning,
    )


def _both_ways(
    found: list[Hold], ranges: list[tuple[int, int]], x: FloatArray, settling: int, unit: str
) -> None:
    """Refuse when holds still settling were all approached from one side: a relaxation
    after each step (creep, dielectric relaxation, switching dipoles) then flows the same
    way on every hold and cannot be told from leakage; approached from above it flows the
    other way, and the fit averages it out."""
    reach = max(abs(h.voltage) for h in found)
    sides = set()
    for h, (a, _) in zip(found, ranges, strict=True):
        # ranges start where find_holds' constant run starts: the sample before is the approach
        if abs(h.voltage) >= 0.1 * reach and a > 0:
            sides.add(bool(x[a - 1] < h.voltage))
    if len(sides) == 2:
        return
    length = float(np.mean([h.duration for h in found]))
    msg = (
        f"{settling} of {len(found)} holds were still settling when they ended (creep, "
        "relaxation), and every hold was reached from the same side, so that settling cannot "
        f"be told from leakage ({length:.3g} s used per hold): hold each level at least "
        f"{math.ceil(3 * length)} s, once on the way up and once on the way down (e.g. 0, 25, "
        f"50, 75, 100, 75, 50, 25, 0 % of the range, in {unit})"
    )
    raise InsufficientDataError(msg)


def _check_sure(leak: Leakage, found: list[Hold], unit: str, settling: int) -> None:
    """Warn (beyond 3 %) or refuse (beyond 10 %) when the current at a hold's voltage (away
    from 0 V) is uncertain, naming the hold length that would bring it under 3 %: for
    noise, the slope's error falls as duration^-3/2; for holds still settling, no rule
    holds, and several times longer is asked for."""
    reach = max(abs(h.voltage) for h in found)
    worst, rel = found[0], 0.0
    for h in found:  # where a current flows: away from 0 V
        if abs(h.voltage) < 0.1 * reach:
            continue
        current = float(leak.current(h.voltage, h.charge))
        err = float(leak.current_stderr(h.voltage, h.charge))
        if current and err / abs(current) > rel:
            worst, rel = h, err / abs(current)
    if not rel > CURRENT_RTOL:
        return
    length = float(np.mean([h.duration for h in found]))
    if settling:
        advice = (
            f"{settling} of them still settling (creep, relaxation): hold each level several "
            f"times longer, {math.ceil(3 * length)} s or more, up and down"
        )
    else:
        needed = length * (rel / CURRENT_RTOL) ** (2.0 / 3.0)
        advice = f"holds of {math.ceil(needed)} s or more would bring it under 3 %"
    msg = (
        f"the leakage current at {worst.voltage:.4g} {unit} is uncertain by {100 * rel:.2g} % "
        f"from {len(found)} holds of {length:.3g} s; {advice}"
    )
    if rel > 0.1:
        raise InsufficientDataError(msg)
    warn(msg, UserWarning)


def _distinct(values: Sequence[float], gap: float) -> list[float]:
    """Values more than ``gap`` apart (sorted; each cluster by its first member)."""
    out: list[float] = []
    for value in sorted(values):
        if not out or value - out[-1] > gap:
            out.append(value)
    return out
