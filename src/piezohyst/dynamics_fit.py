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

from ._validation import FloatArray
from .cores.play import PIHysteresis, PlayCore
from .dynamics import InputDynamics, OutputDynamics
from .identification import Summary, array_blocks, block_dt, default_thresholds, identify

__all__ = ["search_dynamics"]


def _scorer(
    model: Any, x: FloatArray, y: FloatArray, t: FloatArray
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
    terms, _ = model._terms_to_fit(x_range, params)
    if model._core_class() is not PIHysteresis:  # shape terms belong to a core the proxy lacks
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
    model: Any,
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
