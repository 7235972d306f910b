r"""The Bouc-Wen core: :math:`y = c_0 v + \alpha h + c`,
:math:`dh/dv = 1 - |h|^n (\beta\,\mathrm{sign}(h\,dv) + \gamma)`.

Five physical parameters, the model most papers on piezo stacks fit;
identified by a search over its shape around a bounded linear solve, run by
RK4 in small voltage steps, inverted by a safeguarded Newton solve per
sample. Kernels in :mod:`piezohyst._kernels.packed`; the compensator step in C
is ``c/packed.c``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..._kernels import packed as P
from ..._validation import FloatArray
from ...errors import InsufficientDataError, ParameterError, ShapeError
from ._inmemory import (
    FIT_ROWS,
    SEARCH_ROWS,
    Solving,
    _growth_matrix,
    _picked_rows,
    _split,
    _start_inner,
    fit_in_memory,
)
from .base import CoreFit, FitJob, PackedCore, Region, _finite, _frozen
from .solve import bounded_lstsq as _bounded_lstsq

__all__ = ["BoucWenHysteresis"]


@dataclass(frozen=True, eq=False)
class BoucWenHysteresis(PackedCore):
    r"""The Bouc-Wen model: :math:`y = c_0 v + \alpha h + c`.

    .. math::

        \frac{dh}{dv} = 1 - |h|^n \bigl(\beta\,\mathrm{sign}(h\,\dot v) + \gamma\bigr)

    (the usual form with :math:`A = 1`, so :math:`h` is in volts), integrated
    in the voltage by classical Runge-Kutta with sub-steps of at most
    ``dv_max`` V: rate independent. :math:`h` saturates at
    :math:`(\beta + \gamma)^{-1/n}` on a long rise.

    Parameters
    ----------
    c0 : float
        Linear slope (output per V), > 0.
    alpha : float
        Weight of the hysteretic variable (output per V), of either sign (the
        sign sets the loop's orientation) with ``c0 + alpha g_max > 0``,
        :math:`g_{max} = 2\beta / (\beta + \gamma)` the largest ``dh/dv``.
    beta, gamma : float
        Shape: ``beta > 0``, ``|gamma| <= beta`` (stable loops, increasing branches).
    n : float
        Smoothness of the transition, in [1, 6].
    offset : float
        Output at v = 0, h = 0.
    initial_state : array_like, shape (2,)
        ``[v, h]`` before the first sample.
    dv_max : float, optional
        Largest integration sub-step (V); default a tenth of the saturation value of h.
    region : Region, optional
    """

    c0: float
    alpha: float
    beta: float
    gamma: float
    n: float
    offset: float
    initial_state: FloatArray
    dv_max: float | None = None
    region: Region | None = None
    packed: FloatArray = field(init=False, repr=False)
    kind: ClassVar[str] = "bouc_wen"
    inner: ClassVar[str] = "h"

    def __post_init__(self) -> None:
        names = ("c0", "alpha", "beta", "gamma", "n", "offset")
        vals = {k: _finite(getattr(self, k), k) for k in names}
        if not vals["beta"] > 0 or abs(vals["gamma"]) > vals["beta"] * (1 + 1e-12):
            msg = "Bouc-Wen needs beta > 0 and |gamma| <= beta (bounded, stable loops)."
            raise ParameterError(msg)
        g_max = (
            2.0 * vals["beta"] / (vals["beta"] + vals["gamma"])
            if vals["beta"] + vals["gamma"] > 0
            else 2.0
        )
        s_min = vals["c0"] + min(vals["alpha"], 0.0) * g_max
        if not vals["c0"] > 0 or not s_min > 0:
            msg = (
                "Bouc-Wen needs c0 > 0 and c0 + alpha * g_max > 0 (strictly increasing "
                f"branches; g_max = {g_max:.6g})."
            )
            raise ParameterError(msg)
        if not 1.0 <= vals["n"] <= 6.0:
            msg = f"Bouc-Wen's exponent n must lie in [1, 6]. Got {vals['n']!r}."
            raise ParameterError(msg)
        for k, v in vals.items():
            object.__setattr__(self, k, v)
        z0 = _frozen(self.initial_state, "initial_state")
        if z0.size != 2:
            msg = f"'initial_state' must be [v, h]. Got {z0.size} values."
            raise ShapeError(msg)
        object.__setattr__(self, "initial_state", z0)
        dv = self.dv_max
        if dv is None:
            dv = 0.1 * self.h_max if math.isfinite(self.h_max) else 1.0
        dv = _finite(dv, "dv_max")
        if not dv > 0:
            msg = f"'dv_max' must be > 0. Got {dv!r}."
            raise ParameterError(msg)
        object.__setattr__(self, "dv_max", dv)
        packed = np.array([P.KIND_BOUC_WEN, vals["c0"], vals["alpha"], vals["beta"],
                           vals["gamma"], vals["n"], vals["offset"], dv, g_max, s_min])  # fmt: skip
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

    @property
    def h_max(self) -> float:
        """The value h saturates at on a long rise, :math:`(\\beta + \\gamma)^{-1/n}` (V)."""
        s = self.beta + self.gamma
        return float(s ** (-1.0 / self.n)) if s > 0 else math.inf

    @property
    def min_slope(self) -> float:
        r"""The smallest slope dy/dv, :math:`c_0 + \min(\alpha, 0)\, g_{max}` (output per V).

        Its own slot of the packed layout (``BW_S_MIN``): the slot the Duhem and Preisach
        cores keep it in holds Bouc-Wen's ``g_max``, which this property returned before
        (a dimensionless 2.06 for a slope of 6e-9 C/V; the kernels read the right slot).
        """
        return float(self.packed[P.BW_S_MIN])

    @property
    def summary(self) -> str:
        """See :attr:`DifferentialCore.summary`."""
        return f"Bouc-Wen, n = {self.n:.3g}"

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`DifferentialCore.rest_state`: h = 0 at ``x0``."""
        return np.array([float(x0), 0.0])

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """See :meth:`DifferentialCore.describe`."""
        slope = f"{output_unit}/{input_unit}"
        return [
            ("core", "Bouc-Wen, y = c0 v + alpha h + offset"),
            ("c0", f"{self.c0:.6g} {slope}"),
            ("alpha", f"{self.alpha:.6g} {slope}"),
            ("beta, gamma", f"{self.beta:.6g}, {self.gamma:.6g} {input_unit}^-{self.n:.4g}"),
            ("n", f"{self.n:.4g}"),
            ("h saturates at", f"{self.h_max:.6g} {input_unit}"),
            ("offset", f"{self.offset:.6g} {output_unit}"),
        ]

    def to_dict(self) -> dict[str, Any]:
        """See :meth:`DifferentialCore.to_dict`."""
        return {
            "c0": self.c0,
            "alpha": self.alpha,
            "beta": self.beta,
            "gamma": self.gamma,
            "n": self.n,
            "offset": self.offset,
            "dv_max": self.dv_max,
            "initial_state": self.initial_state.tolist(),
            "region": self.region_json(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BoucWenHysteresis:
        """Inverse of :meth:`to_dict` (see :meth:`~piezohyst.model.cores.base.Core.from_dict`)."""
        return cls(
            data["c0"],
            data["alpha"],
            data["beta"],
            data["gamma"],
            data["n"],
            data["offset"],
            data["initial_state"],
            data.get("dv_max"),
            cls.region_from(data.get("region")),
        )

    @classmethod
    def identify(cls, job: FitJob) -> CoreFit:
        """See :meth:`~piezohyst.model.cores.base.Core.identify`."""
        return fit_in_memory(cls, job, _solve)


def _solve(job: Solving) -> tuple[BoucWenHysteresis, list[FloatArray]]:
    from scipy.optimize import least_squares

    x, y, t, terms, params, initial_state, _ = job

    n = x.size
    g_mat = _growth_matrix(terms, x, t)
    m = g_mat.shape[1]
    if n < 8 + m:
        msg = f"{n} samples cannot identify a Bouc-Wen model with {m} growth terms"
        raise InsufficientDataError(msg)
    lower_g = np.concatenate([term.lower_bounds() for term in terms]) if terms else np.zeros(0)
    span = float(np.ptp(x))
    mean_slope = max(float(np.ptp(y)), 1e-300) / span
    s_min = float(params["min_slope"]) * mean_slope
    lower = np.concatenate([[s_min, 0.0, -np.inf], lower_g])
    scale = max(float(np.ptp(y)), 1e-300)

    def shape(theta: FloatArray) -> tuple[float, float, float]:
        h_sat = span * math.exp(float(theta[0]))
        rho, expo = float(theta[1]), float(theta[2])
        total = h_sat ** (-expo)  # beta + gamma
        beta = total / (1.0 + rho)
        return beta, rho * beta, expo

    def packed(theta: FloatArray) -> FloatArray:
        beta, gamma, expo = shape(theta)
        h_sat = span * math.exp(float(theta[0]))
        g_max = 2.0 * beta / (beta + gamma)
        return np.array([P.KIND_BOUC_WEN, 1.0, 0.0, beta, gamma, expo, 0.0, 0.1 * h_sat,
                         g_max, 1.0])  # fmt: skip

    def solver(xv: FloatArray, yv: FloatArray, gv: FloatArray, rows: np.ndarray) -> Any:
        """The variable-projection solve on a record (all of it, or a decimated copy)."""
        xv = np.ascontiguousarray(xv)  # a decimated copy is strided: one kernel type, once
        hv = np.empty(xv.size)
        g_rows = gv[rows].T if m else np.zeros((0, rows.size))

        def solve(theta: FloatArray) -> tuple[float, float, FloatArray, FloatArray, float]:
            """(c0, alpha, offset and growth, residual rows, h0): the better orientation.

            alpha >= 0: c0 >= s_min. alpha = -a <= 0: with u = c0 - a g_max >= s_min,
            y = u v + a (g_max v - h), so both are bounds on the columns' coefficients.
            """
            p = packed(theta)
            probe = BoucWenHysteresis(1.0, 0.0, p[3], p[4], p[5], 0.0,
                                      np.array([xv[0], 0.0]), p[7])  # fmt: skip
            start = _start_inner(probe, xv, initial_state)
            h0 = 0.0 if start is None else float(start[1])
            P.bw_trace(p, xv, h0, hv)
            hr, xr = hv[rows], xv[rows]
            g_max = float(p[P.BW_G_MAX])
            best_fit: tuple[float, float, FloatArray, FloatArray, float] | None = None
            for second in (hr, g_max * xr - hr):
                a = np.vstack([xr, second, np.ones(rows.size), g_rows]).T
                coef = _bounded_lstsq(a.T @ a, a.T @ yv[rows], lower)
                r = a @ coef - yv[rows]
                if second is hr:
                    c0, alpha = float(coef[0]), float(coef[1])
                else:
                    c0, alpha = float(coef[0]) + float(coef[1]) * g_max, -float(coef[1])
                if best_fit is None or float(r @ r) < float(best_fit[3] @ best_fit[3]):
                    best_fit = (c0, alpha, coef[2:], r, h0)
            assert best_fit is not None
            return best_fit

        return solve

    # the shape is searched on a decimated copy (the model is rate independent: fewer,
    # longer steps integrate the same loops), then polished on the whole record
    stride = max(1, n // SEARCH_ROWS)
    xc = x[::stride]
    coarse = solver(xc, y[::stride], g_mat[::stride], np.arange(xc.size))
    solve = solver(x, y, g_mat, _picked_rows(n, FIT_ROWS))
    bounds = ([math.log(1e-3), -0.95, 1.0], [math.log(10.0), 1.0, 6.0])

    def coarse_residual(theta: FloatArray) -> FloatArray:
        return np.asarray(coarse(theta)[3] / scale, dtype=np.float64)

    def residual(theta: FloatArray) -> FloatArray:
        return np.asarray(solve(theta)[3] / scale, dtype=np.float64)

    best, best_cost = None, math.inf
    for hs, rho, expo in itertools.product((0.03, 0.1, 0.3, 1.0), (-0.6, 0.3, 1.0), (1.0, 2.5)):
        theta = np.array([math.log(hs), rho, expo])
        cost = float(np.sum(coarse_residual(theta) ** 2))
        if cost < best_cost:
            best, best_cost = theta, cost
    assert best is not None
    res = least_squares(coarse_residual, best, bounds=bounds, method="trf",
                        x_scale=[1.0, 0.5, 1.0], diff_step=1e-4, max_nfev=40)  # fmt: skip
    if stride > 1:  # polish on the whole record
        start_cost = float(np.sum(residual(res.x) ** 2))
        res = least_squares(residual, res.x, bounds=bounds, method="trf",
                            x_scale=[1.0, 0.5, 1.0], diff_step=1e-4, max_nfev=6)  # fmt: skip
        best_cost = start_cost
        best = res.x if float(np.sum(res.fun**2)) <= start_cost else best
    theta = res.x if float(np.sum(res.fun**2)) <= best_cost else best
    c0, alpha, rest, _, h0 = solve(theta)
    h = np.empty(n)
    beta, gamma, expo = shape(theta)
    p = packed(theta)
    g_max = float(p[P.BW_G_MAX])
    c0 = max(c0, s_min * (1 + 1e-12) - min(alpha, 0.0) * g_max, s_min)
    P.bw_trace(p, x, h0, h)
    offset = float(rest[0])
    pure = c0 * x + alpha * h + offset
    core = BoucWenHysteresis(c0, alpha, beta, gamma, expo, offset, np.array([x[0], h0]), p[7],
                             Region.of(x, pure))  # fmt: skip
    return core, _split(rest[1:], terms)
