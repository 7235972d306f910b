"""The input- and output-dynamics searches around the linear solve.

A lag, a delay or a mechanical mode is not linear in its parameters, so
:meth:`~piezohyst.HysteresisModel.fit` searches them: each candidate filters
the command (or passes the regressor columns through the mode), one bounded
linear solve of a play-operator proxy scores it, and a grid, Brent's method
and Nelder-Mead find the best. The model then fits its own core on the
filtered command.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..io.blocks import Summary, array_blocks, block_dt
from .cores.play import PIHysteresis, PlayCore, default_thresholds
from .cores.solve import identify
from .dynamics import InputDynamics, OutputDynamics
from .fit_state import Fittable

__all__ = ["search_dynamics"]


def _scorer(
    model: Fittable, x: FloatArray, y: FloatArray, t: FloatArray
) -> Callable[[InputDynamics, OutputDynamics | None, bool], float]:
    """A cheap objective for the dynamics searches: fit RMSE (or held-out RMSE).

    Each candidate filters the command, then one bounded linear solve
    scores it, the columns through the candidate mode if any (up to 8
    operators, about 5 000 hashed rows in the sums: the search needs the
    shape of the objective, not the final model). Results are cached.
    """
    params = model.check_params()
    dt = block_dt(t, 0, t.size, None)
    assert dt is not None
    x_range = np.array([float(x.min()), float(x.max())])
    x_lo, x_hi = float(x_range[0]), float(x_range[1])
    terms, _ = model.terms_to_fit(x_range, params)
    if model.core_class is not PIHysteresis:  # shape terms belong to a core the proxy lacks
        terms = [term for term in terms if term.removed]
    rate = any(term.rate_dependent for term in terms)
    # the proxy of every model (the other cores too): up to 8 play operators
    n_proxy = min(int(params.get("n_operators", 8)), 8)
    core = PlayCore(default_thresholds(x_range, n_proxy))
    stride = max(1, x.size // 5000)
    y_stats = (float(y[0]), float(y.min()), float(y.max()))
    cache: dict[tuple[Any, ...], float] = {}

    def score(dyn: InputDynamics, mode: OutputDynamics | None, validate: bool) -> float:
        key = (dyn.delay, dyn.tau, None if mode is None else (mode.f0, mode.zeta), validate)
        if key in cache:
            return cache[key]
        u, _ = dyn.apply(x, dt)
        # a delay or a lag keeps the voltage inside the command's range: its extremes serve
        sm = Summary(u.size, float(u[0]), x_lo, x_hi, *y_stats)
        z0 = np.full(core.n_operators, float(u[0]))
        sol = identify(
            core,
            terms,
            array_blocks(u, y, t if rate else None),
            sm,
            z0,
            min_slope=float(params.get("min_slope", 1e-3)),
            validate=validate,
            stride=stride,
            block=1 << 16,
            output=mode,
        )
        cache[key] = next(iter(sol.scores.values())) if validate else sol.rmse
        return cache[key]

    return score


def search_dynamics(
    model: Fittable,
    x: FloatArray,
    y: FloatArray,
    t: FloatArray,
    kind: str,
    output: OutputDynamics | None = None,
) -> tuple[InputDynamics, OutputDynamics | None]:
    """The delay, lag (and mode, with ``output_dynamics``) that fit best.

    1-D kinds: a geometric grid, then Brent's method around its best point; the 2-D
    kind starts a short Nelder-Mead from the lag-only result. ``"auto"``
    compares on the held-out last 30 %: none, the lag alone and, when the
    2-D result holds a delay, a pure delay searched near its total lag and
    the 2-D result itself, keeping a more complex one only when it is
    better by 0.1 %. With a mode to find (``output``
    given, its resonance 0), the search is joint: a log grid of
    resonances, the lag searched at each, then Nelder-Mead over all three
    (a lag and a mode trade phase, so searching them one after the other
    lands on the wrong pair).
    """
    from scipy.optimize import minimize, minimize_scalar

    score = _scorer(model, x, y, t)
    dt0 = float(np.median(np.diff(t)))
    fs = 1.0 / dt0
    # lags of amplifiers and sensor filters: up to 50 ms (or 50 samples), never more than a
    # tenth of the record
    limit = min(max(50.0 * dt0, 0.05), 0.1 * float(t[-1] - t[0]))

    def make(name: str, delay: float, tau: float) -> InputDynamics:
        if name == "none":
            return InputDynamics()
        return InputDynamics(name, max(tau, 0.0), max(delay, 0.0), dt0)

    def search_1d(name: str, mode: OutputDynamics | None) -> tuple[InputDynamics, float]:
        def build(v: float) -> InputDynamics:
            return make(name, v, 0.0) if name == "delay" else make(name, 0.0, v)

        # lags are scale parameters: a geometric grid from a sample to the limit (and 0)
        grid = np.concatenate([[0.0], np.geomspace(min(dt0, 0.5 * limit), limit, 5)])
        values = [score(build(float(g)), mode, False) for g in grid]
        k = int(np.argmin(values))
        if 0 < k < grid.size - 1:  # a bracket with its three values known (cached)
            res = minimize_scalar(
                lambda v: score(build(max(float(v), 0.0)), mode, False),
                bracket=(grid[k - 1], grid[k], grid[k + 1]),
                method="brent",
                options={"xtol": 0.02, "maxiter": 30},  # 2 % of the lag
            )
            found = max(float(res.x), 0.0)
        else:  # at an end of the grid: a bounded search next to it
            lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
            res = minimize_scalar(
                lambda v: score(build(float(v)), mode, False),
                bounds=(lo, hi),
                method="bounded",
                options={"xatol": max(0.2 * dt0, 0.01 * float(hi - lo))},
            )
            found = float(res.x)
        if res.fun < values[k]:
            return build(found), float(res.fun)
        return build(float(grid[k])), values[k]

    def search_2d(lagged: InputDynamics, mode: OutputDynamics | None) -> InputDynamics:
        """Nelder-Mead over (delay, lag) from the lag-only result (a delay trades with it)."""
        tau1 = max(lagged.tau, dt0)
        start = np.array([0.0, lagged.tau])
        steps = np.array([[0.0, 0.0], [0.5 * tau1, -0.5 * tau1], [0.0, 0.25 * tau1]])
        simplex = start + steps
        res = minimize(
            lambda p: score(make("delay+first-order", float(p[0]), float(p[1])), mode, False),
            start,
            method="Nelder-Mead",
            bounds=[(0.0, limit), (0.0, limit)],
            options={
                "xatol": 0.1 * dt0,
                "fatol": 0.0,
                "maxfev": 14,
                "initial_simplex": np.clip(simplex, 0.0, limit),
            },
        )
        best = make("delay+first-order", float(res.x[0]), float(res.x[1]))
        as_2d = make("delay+first-order", 0.0, lagged.tau)  # the lag-only point itself
        return as_2d if score(as_2d, mode, False) < score(best, mode, False) else best

    def delay_helps(lagged: InputDynamics, mode: OutputDynamics | None) -> bool:
        """Does moving part of the lag into a delay (same total) fit better?

        A delay and a lag trade one for one, so the probes lie on the line
        of constant total lag: half of it as a delay, and all of it.
        """
        if lagged.tau < 0.5 * dt0:
            return False
        here = score(lagged, mode, False)
        half = make("delay+first-order", 0.5 * lagged.tau, 0.5 * lagged.tau)
        full = make("delay+first-order", lagged.tau, 0.0)
        return min(score(half, mode, False), score(full, mode, False)) < here

    mode = output
    if output is not None:  # joint search of the mode and a 1-D input dynamics
        simple = kind if kind in ("none", "delay", "first-order") else "first-order"
        lo_f, hi_f = fs / 200.0, fs / 3.0
        best_err, best_dyn, best_f = math.inf, InputDynamics(), lo_f
        for f0 in np.geomspace(lo_f, hi_f, 10):
            trial = OutputDynamics(float(f0), 0.05, dt0)
            if simple == "none":
                dyn, err = InputDynamics(), score(InputDynamics(), trial, False)
            else:
                dyn, err = search_1d(simple, trial)
            if err < best_err:
                best_err, best_dyn, best_f = err, dyn, float(f0)
        value = best_dyn.delay if simple == "delay" else best_dyn.tau

        def joint(p: FloatArray) -> float:
            f0 = float(np.clip(np.exp(p[0]), lo_f, hi_f))
            zeta = float(np.clip(np.exp(p[1]), 1e-3, 2.0))
            v = float(np.clip(p[2], 0.0, limit)) if simple != "none" else 0.0
            dyn = make(simple, v, 0.0) if simple == "delay" else make(simple, 0.0, v)
            return score(dyn, OutputDynamics(f0, zeta, dt0), False)

        res = minimize(
            joint,
            np.array([np.log(best_f), np.log(0.05), value]),
            method="Nelder-Mead",
            options={"xatol": 1e-4, "fatol": 0.0, "maxfev": 80},
        )
        p = res.x
        mode = OutputDynamics(
            float(np.clip(np.exp(p[0]), lo_f, hi_f)),
            float(np.clip(np.exp(p[1]), 1e-3, 2.0)),
            dt0,
        )
        v = float(np.clip(p[2], 0.0, limit))
        if kind in ("none", "delay", "first-order"):
            dyn = make(kind, v, 0.0) if kind == "delay" else make(kind, 0.0, v)
            return dyn, mode
    if kind in ("delay", "first-order"):
        return search_1d(kind, mode)[0], mode
    lagged = search_1d("first-order", mode)[0]
    if kind == "auto" and not delay_helps(lagged, mode):
        both = lagged  # the 2-D search would only confirm the lag alone
    else:
        both = search_2d(lagged, mode)
    if kind == "delay+first-order":
        return both, mode
    # auto: the kinds the 2-D result leaves plausible, on the held-out part; complexity
    # must earn its place. A 2-D result with (almost) no delay is the lag alone; one
    # with a delay earns a pure delay searched near its total lag (they trade one for one)
    ranked: list[tuple[InputDynamics, int]] = [(InputDynamics(), 0), (lagged, 1)]
    if both.delay >= 0.5 * dt0:
        lo_d, hi_d = max(both.delay - dt0, 0.0), min(both.delay + both.tau + dt0, limit)
        res_d = minimize_scalar(
            lambda d: score(make("delay", float(d), 0.0), mode, False),
            bounds=(lo_d, hi_d),
            method="bounded",
            options={"xatol": 0.1 * dt0},
        )
        ranked.append((make("delay", float(res_d.x), 0.0), 1))
        if both.tau >= 0.5 * dt0:
            ranked.append((both, 2))
    best_dyn, best_level = ranked[0][0], 0
    best_err = score(best_dyn, mode, True)
    for dyn, level in ranked[1:]:
        err = score(dyn, mode, True)
        margin = 1.0 - 1e-3 * (level - best_level) if level > best_level else 1.0
        if err < best_err * margin:
            best_dyn, best_err, best_level = dyn, err, level
    return best_dyn, mode


#: Largest 95 % half-width (samples, or the total lag when larger) that an undetermined
#: direction of the (delay, lag) profile is given: the span the profile searched
UNDETERMINED_SAMPLES = 2.0
#: Contiguous segments of the record for the jackknife of the profile's minimum
SEGMENTS = 10


def profile_dynamics(
    found: InputDynamics,
    kind: str,
    fit_sse: Callable[[InputDynamics, bool], tuple[float, FloatArray | None]],
    y: FloatArray | None = None,
    t: FloatArray | None = None,
) -> InputDynamics:
    """Refine the proxy's delay and lag with the model's own fit, and say how sure they are.

    The proxy (8 play operators) cannot tell a delay from part of a lag when
    its own misfit is larger than their difference: the objective is a valley
    along ``delay + tau = const`` (a DAC that ramps between commands is such a
    delay, half a sample). Here the model's own core is refitted at a 3x3
    design around the proxy's result — total lag ``T = delay + tau`` ± 5 %
    (at least 0.2 sample) and three delays half a sample apart, none below 0
    or beyond ``T`` — or at three points for a 1-D kind (a pure delay found by
    ``"auto"`` is one: at ``tau = 0`` the sums of squares have a kink); a
    quadratic through the sums of squares gives the minimum (kept inside the
    design, one step beyond at most) and its curvature
    ``A``. With ``sigma² = SSE_min / N_eff``, ``N_eff = N (1 - rho) / (1 + rho)``
    (``rho`` the residuals' lag-1 autocorrelation: model error is not white
    noise), the covariance is ``sigma² A⁻¹`` — the likelihood-ratio region of
    a profile, to second order. A direction without curvature (a delay and a
    lag the record cannot tell apart) gets the design's span as its
    uncertainty, not a number the data do not hold. Two terms are added for
    what the noise model misses: a delete-one-segment jackknife of the minimum
    over 10 stretches of the record (misfit that differs along it), and the
    model's resolution limit on the total lag, ``rms(residual) / rms(dy/dt)``
    (a lag error ``δT`` moves the output by about ``δT dy/dt``, so a misfit
    of that size can hide it), as a 95 % half-width of the delay and of ``tau``.

    Parameters
    ----------
    found : InputDynamics
        The proxy search's result (its ``sample_interval`` set).
    kind : str
        The model's ``input_dynamics`` setting (``"auto"`` may move between
        kinds; a fixed kind keeps its parameters).
    fit_sse : callable
        ``fit_sse(dynamics, final) -> (sum of squared residuals, residuals or
        None)``, the model's own fit on the command filtered by ``dynamics``
        (with the core's cheaper ``profile_settings`` unless ``final``).
    y, t : ndarray, optional
        The output and times, for the resolution limit (left out without them).

    Returns
    -------
    InputDynamics
        The refined values, with ``covariance``.
    """
    dt = found.sample_interval
    if not found.active or dt <= 0:
        return found
    # a pure delay found by "auto" sits on the edge tau = 0, where the sum of squares has a
    # kink: it is profiled as a delay alone
    both = kind == "delay+first-order" or (kind == "auto" and found.kind != "delay")
    one = 1 if kind == "first-order" else 0  # the 1-D kind's parameter: (delay, tau)[one]
    total0 = found.delay + found.tau

    def make(delay: float, tau: float, cov: tuple[float, ...] = ()) -> InputDynamics:
        """A fixed kind keeps its name; "auto" takes the name of the parts present."""
        delay, tau = max(delay, 0.0), max(tau, 0.0)
        name = kind
        if kind == "auto":
            name = ("delay+first-order" if delay > 0.0 and tau > 0.0
                    else "delay" if delay > 0.0 else "first-order")  # fmt: skip
        return InputDynamics(name, tau, delay, dt, cov)

    cache: dict[tuple[float, float], float] = {}
    pieces: dict[tuple[float, float], FloatArray] = {}

    def sse(delay: float, tau: float) -> float:
        key = (round(max(delay, 0.0) / dt, 9), round(max(tau, 0.0) / dt, 9))
        if key not in cache:
            total, resid = fit_sse(make(delay, tau), False)
            cache[key] = total
            if resid is not None:
                pieces[key] = np.array([float(r @ r) for r in np.array_split(resid, SEGMENTS)])
        return cache[key]

    def segment_sums(delay: float, tau: float) -> FloatArray | None:
        return pieces.get((round(max(delay, 0.0) / dt, 9), round(max(tau, 0.0) / dt, 9)))

    step = max(0.05 * total0, 0.2 * dt)
    if both:
        # coordinates (T, d): T well determined, d the split; every point keeps 0 <= d <= T
        # three delays half a sample apart around the proxy's, none below 0 or beyond T
        d0 = min(max(found.delay, 0.5 * dt), max(total0 - 0.5 * dt, 0.5 * dt))
        raw = [(total0 + i * step, d0 + j * 0.5 * dt) for i in (-1, 0, 1) for j in (-1, 0, 1)]
        pts = sorted({(tt, min(max(d, 0.0), tt)) for tt, d in raw if tt > 0.0})
        coords = np.array(pts)
        values = np.array([sse(d, tt - d) for tt, d in pts])
        center = np.array([total0, d0])
        scale = np.array([step, 0.5 * dt])
        z = (coords - center) / scale
        design = np.column_stack([np.ones(len(z)), z[:, 0], z[:, 1], z[:, 0] ** 2,
                                  z[:, 0] * z[:, 1], z[:, 1] ** 2])  # fmt: skip
        coef = np.linalg.lstsq(design, values, rcond=None)[0]
        hess = np.array([[2 * coef[3], coef[4]], [coef[4], 2 * coef[5]]])
        grad = coef[1:3]
        lo_z, hi_z = np.array([-2.0, -2.0]), np.array([2.0, 2.0])  # one step beyond at most
        try:
            zstar = np.linalg.solve(hess, -grad) if np.all(np.linalg.eigvalsh(hess) > 0) else None
        except np.linalg.LinAlgError:
            zstar = None
        best_k = int(np.argmin(values))
        candidates = [coords[best_k]]
        if zstar is not None:
            candidates.append(center + scale * np.clip(zstar, lo_z, hi_z))
        scored = [(sse(float(c[1]), float(c[0] - c[1])), float(c[0]), float(c[1]))
                  for c in candidates if 0.0 <= c[1] <= c[0]]  # fmt: skip
        best_sse, t_best, d_best = min(scored)
        # curvature in (delay, tau): T = d + tau, d = d
        m = np.array([[1.0, 1.0], [1.0, 0.0]]) / scale[:, None]
        curv = 0.5 * m.T @ hess @ m  # SSE ≈ SSE_min + δᵀ curv δ
        delay_hat, tau_hat = d_best, t_best - d_best
        sums = [segment_sums(d, tt - d) for tt, d in pts]
        spread = _jackknife_2d(design, sums, center, scale, lo_z, hi_z) if all(
            q is not None for q in sums) else np.zeros((2, 2))  # fmt: skip
    else:
        param = "tau" if kind == "first-order" else "delay"
        v0 = found.delay if param == "delay" else found.tau
        grid = np.array([max(v0 - step, 0.0), v0, v0 + step])
        grid = np.unique(grid)
        values = np.array([sse(g, 0.0) if param == "delay" else sse(0.0, g) for g in grid])
        a2, a1, _ = np.polyfit(grid, values, 2) if grid.size == 3 else (0.0, 0.0, 0.0)
        best = float(grid[int(np.argmin(values))])
        if a2 > 0:
            star = float(np.clip(-a1 / (2 * a2), max(grid[0] - step, 0.0), grid[-1] + step))
            trial = sse(star, 0.0) if param == "delay" else sse(0.0, star)
            if trial < float(values.min()):
                best = star
        best_sse = sse(best, 0.0) if param == "delay" else sse(0.0, best)
        i = 0 if param == "delay" else 1
        curv = np.zeros((2, 2))
        curv[i, i] = a2
        delay_hat, tau_hat = (best, 0.0) if param == "delay" else (0.0, best)
        sums = [segment_sums(g, 0.0) if param == "delay" else segment_sums(0.0, g) for g in grid]
        spread = np.zeros((2, 2))
        if grid.size == 3 and all(q is not None for q in sums):
            spread[i, i] = _jackknife_1d(grid, sums, step)
    chosen = make(delay_hat, tau_hat)
    final_sse, resid = fit_sse(chosen, True)  # the model's own settings, for the residuals
    n_eff = _effective_samples(resid)
    sigma2 = min(final_sse, best_sse) / n_eff
    widest = max(UNDETERMINED_SAMPLES * dt, total0)
    cov = _covariance(curv, sigma2, widest, both, one) + spread
    if resid is not None and y is not None and t is not None and y.size > 2:
        rate = np.diff(y) / np.diff(t)
        moving = float(np.sqrt(np.mean(rate * rate)))
        if moving > 0:
            from scipy.stats import chi2

            limit = float(np.sqrt(np.mean(resid * resid))) / moving  # a bound: the 95 % width
            # a delay's error and a lag's move the output alike: the bound holds for each
            free = (0, 1) if both else (one,)
            for i in free:
                cov[i, i] += limit * limit / float(chi2.ppf(0.95, 2 if both else 1))
    if kind == "auto" and both:  # a part whose 95 % interval reaches 0 must earn its place
        se_d, se_tau = math.sqrt(max(cov[0, 0], 0.0)), math.sqrt(max(cov[1, 1], 0.0))
        # the simpler kind at its own best total lag, on the fitted quadratic (then refitted)
        if tau_hat <= 1.96 * se_tau and tau_hat < delay_hat:
            total = _on_line(coef, center, scale, lambda tt: tt, delay_hat + tau_hat)
            delay_hat, tau_hat = total, 0.0
        elif delay_hat <= 1.96 * se_d:
            total = _on_line(coef, center, scale, lambda tt: 0.0 * tt, delay_hat + tau_hat)
            delay_hat, tau_hat = 0.0, total
    return make(delay_hat, tau_hat, tuple(float(c) for c in cov.ravel()))


def _on_line(
    coef: FloatArray, center: FloatArray, scale: FloatArray, delay_of: Callable[[Any], Any],
    fallback: float,
) -> float:  # fmt: skip
    """The total lag T minimising the quadratic along ``d = delay_of(T)`` (a grid search over
    the design's span, so no curvature sign is assumed)."""
    grid = center[0] + scale[0] * np.linspace(-2.0, 2.0, 401)
    grid = grid[grid > 0]
    if grid.size == 0:
        return fallback
    zt = (grid - center[0]) / scale[0]
    zd = (np.asarray(delay_of(grid), dtype=np.float64) - center[1]) / scale[1]
    q = coef[1] * zt + coef[2] * zd + coef[3] * zt**2 + coef[4] * zt * zd + coef[5] * zd**2
    return float(grid[int(np.argmin(q))])


def _jackknife_2d(
    design: FloatArray, sums: list[Any], center: FloatArray, scale: FloatArray,
    lo_z: FloatArray, hi_z: FloatArray,
) -> FloatArray:  # fmt: skip
    """Delete-one-segment jackknife covariance of the quadratic's minimum, in (delay, tau).

    Model error that differs along the record (a misfit at one drive
    frequency) moves the minimum when that part is left out; the profile's
    noise-based curvature does not see it.
    """
    table = np.array(sums)  # (points, segments)
    k = table.shape[1]
    found = []
    for j in range(k):
        values = table.sum(axis=1) - table[:, j]
        coef = np.linalg.lstsq(design, values, rcond=None)[0]
        hess = np.array([[2 * coef[3], coef[4]], [coef[4], 2 * coef[5]]])
        if not np.all(np.linalg.eigvalsh(hess) > 0):
            continue
        z = np.clip(np.linalg.solve(hess, -coef[1:3]), lo_z, hi_z)
        total, delay = center + scale * z
        found.append((delay, total - delay))
    if len(found) < 3:
        return np.zeros((2, 2))
    pts = np.array(found)
    dev = pts - pts.mean(axis=0)
    return np.asarray((len(found) - 1) / len(found) * dev.T @ dev, dtype=np.float64)


def _jackknife_1d(grid: FloatArray, sums: list[Any], step: float) -> float:
    """The 1-D kind's jackknife variance of the parabola's minimum."""
    table = np.array(sums)
    found = []
    for j in range(table.shape[1]):
        a2, a1, _ = np.polyfit(grid, table.sum(axis=1) - table[:, j], 2)
        if a2 > 0:
            found.append(float(np.clip(-a1 / (2 * a2), grid[0] - step, grid[-1] + step)))
    if len(found) < 3:
        return 0.0
    arr = np.array(found)
    return float((arr.size - 1) / arr.size * np.sum((arr - arr.mean()) ** 2))


def _effective_samples(resid: FloatArray | None) -> float:
    """``N (1 - rho) / (1 + rho)``: independent samples in autocorrelated residuals."""
    if resid is None or resid.size < 3:
        return 2.0
    r = resid - resid.mean()
    denom = float(r @ r)
    rho = float(r[:-1] @ r[1:]) / denom if denom > 0 else 0.0
    rho = min(max(rho, 0.0), 1.0 - 1e-12)
    return max(resid.size * (1.0 - rho) / (1.0 + rho), 2.0)


def _covariance(curv: FloatArray, sigma2: float, widest: float, both: bool, one: int) -> FloatArray:
    """``sigma2 curv⁻¹`` on the free parameters; a flat direction gets ``widest`` as its
    95 % half-width."""
    from scipy.stats import chi2

    k = 2 if both else 1
    floor_var = widest**2 / float(chi2.ppf(0.95, k))
    if both:
        vals, vecs = np.linalg.eigh(0.5 * (curv + curv.T))
        var = np.where(vals > 0, sigma2 / np.where(vals > 0, vals, 1.0), floor_var)
        var = np.minimum(var, floor_var)
        return np.asarray(vecs @ np.diag(var) @ vecs.T, dtype=np.float64)
    i = one
    cov = np.zeros((2, 2))
    a = float(curv[i, i])
    cov[i, i] = min(sigma2 / a, floor_var) if a > 0 else floor_var
    return cov
