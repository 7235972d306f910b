r"""The Duhem core: rate-independent hysteresis by its slope, :math:`dq/dv = f_\pm(v, q)`.

``f+`` while the input rises, ``f-`` while it falls, each a non-negative
bilinear surface on a grid over the (voltage, output) region the training
data covered. Linear in its coefficients, so identified by one bounded least
squares on the record's path (an integrated regression), then refined on the
output error with the exact sensitivities of the simulation. Its kernels (the
Euler step, the fit's regressors and Jacobian) are in
:mod:`piezohyst._kernels.packed`; its compensator step in C is ``c/packed.c``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..._kernels import packed as P
from ..._validation import FloatArray, frozen
from ...errors import InsufficientDataError, ParameterError, ShapeError
from ._inmemory import (
    FIT_ROWS,
    REFINE_EVALS,
    REFINE_ROWS,
    Solving,
    _growth_matrix,
    _picked_rows,
    fit_in_memory,
)
from .base import CoreFit, FitJob, PackedCore, Region, _finite, _frozen, _nodes, _slopes
from .solve import bounded_lstsq as _bounded_lstsq

#: full-range cycles (and samples per leg) over which a fitted core must settle, and the
#: step per cycle below which its loops count as closed (a fraction of the output's span)
CYCLES, CYCLE_LEG, CLOSED = 6, 500, 1e-3
#: a linear fit whose RMS misfit is within this factor of the polish's counts as nearly as good
NEARLY = 1.25

__all__ = ["DuhemHysteresis"]


@dataclass(frozen=True, eq=False)
class DuhemHysteresis(PackedCore):
    r"""Rate-independent Duhem hysteresis: :math:`dq/dv = f_\pm(v, q)` on a grid.

    ``f+`` while the input rises, ``f-`` while it falls, each bilinear between
    the nodes of a (voltage, output) grid and constant beyond its edges.
    Explicit Euler, ``q[k+1] = q[k] + f±(v[k], q[k]) (v[k+1] - v[k])``, in steps
    of at most ``dv_max`` (then the rest): a sampled trajectory's step is one
    Euler step, inverted explicitly.

    Parameters
    ----------
    v_nodes : array_like, shape (nv,)
        Equally spaced voltages (V), at least 2.
    q_nodes : array_like, shape (nq,)
        Equally spaced outputs (output units), at least 2.
    up, down : array_like, shape (nv, nq)
        Slopes (output per V) at the nodes, all > 0.
    initial_state : array_like, shape (2,)
        ``[v, q]`` before the first sample.
    region : Region, optional
        Where the training data lay.
    dv_max : float, optional
        Largest Euler step (V); default a quarter of the voltage grid's spacing.
    """

    v_nodes: FloatArray
    q_nodes: FloatArray
    up: FloatArray
    down: FloatArray
    initial_state: FloatArray
    region: Region | None = None
    dv_max: float | None = None
    packed: FloatArray = field(init=False, repr=False)
    kind: ClassVar[str] = "duhem"
    growth_from_proxy: ClassVar[bool] = True  # its loops need not close: PI settles growth
    profile_settings: ClassVar[dict[str, Any]] = {"refine": False}  # the slopes' polish
    inner: ClassVar[str] = "output"

    def __post_init__(self) -> None:
        vn = _nodes(self.v_nodes, "v_nodes")
        qn = _nodes(self.q_nodes, "q_nodes")
        shape = (vn.size, qn.size)
        up = _slopes(self.up, "up", shape)
        down = _slopes(self.down, "down", shape)
        z0 = _frozen(self.initial_state, "initial_state")
        if z0.size != 2:
            msg = f"'initial_state' must be [v, q]. Got {z0.size} values."
            raise ShapeError(msg)
        v_step = (vn[-1] - vn[0]) / (vn.size - 1)
        dv = _finite(0.25 * v_step if self.dv_max is None else self.dv_max, "dv_max")
        if not dv > 0:
            msg = f"'dv_max' must be > 0. Got {dv!r}."
            raise ParameterError(msg)
        for name, value in (("v_nodes", vn), ("q_nodes", qn), ("up", up), ("down", down),
                            ("initial_state", z0), ("dv_max", dv)):  # fmt: skip
            object.__setattr__(self, name, value)
        f_min = min(float(up.min()), float(down.min()))
        head = [P.KIND_DUHEM, vn.size, qn.size, vn[0], v_step, qn[0],
                (qn[-1] - qn[0]) / (qn.size - 1), dv, f_min]  # fmt: skip
        packed = np.concatenate([head, up.ravel(), down.ravel()])
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

    @classmethod
    def from_packed(
        cls, packed: FloatArray, initial_state: ArrayLike, region: Region | None = None
    ) -> DuhemHysteresis:
        """A core from the kernels' parameter layout (the identification's solution).

        Parameters
        ----------
        packed : ndarray
        initial_state : array_like, shape (2,)
        region : Region, optional

        Returns
        -------
        DuhemHysteresis
        """
        nv, nq = int(packed[P.DU_NV]), int(packed[P.DU_NQ])
        vn = packed[P.DU_V_LO] + packed[P.DU_V_STEP] * np.arange(nv)
        qn = packed[P.DU_Q_LO] + packed[P.DU_Q_STEP] * np.arange(nq)
        cells = nv * nq
        up = packed[P.DU_UP : P.DU_UP + cells].reshape(nv, nq)
        down = packed[P.DU_UP + cells : P.DU_UP + 2 * cells].reshape(nv, nq)
        z0 = np.asarray(initial_state, dtype=np.float64)
        return cls(vn, qn, up, down, z0, region, float(packed[P.DU_DV_MAX]))

    @property
    def summary(self) -> str:
        """See :attr:`DifferentialCore.summary`."""
        return f"Duhem, {self.v_nodes.size} × {self.q_nodes.size} grid"

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`~piezohyst.model.cores.base.Core.rest_state`."""
        q = self.region.middle(x0) if self.region is not None else float(self.initial_state[1])
        return np.array([float(x0), q])

    def slopes(self, v: ArrayLike, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``f+`` and ``f-`` at points (v, q).

        Parameters
        ----------
        v, q : array_like, shape (N,)

        Returns
        -------
        (ndarray, ndarray)
        """
        va = np.asarray(v, dtype=np.float64).reshape(-1)
        qa = np.asarray(q, dtype=np.float64).reshape(-1)
        pairs = list(zip(va, qa, strict=True))
        up = np.array([P.duhem_slope(self.packed, a, b, True)[0] for a, b in pairs])
        down = np.array([P.duhem_slope(self.packed, a, b, False)[0] for a, b in pairs])
        return up, down

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """See :meth:`DifferentialCore.describe`."""
        slope = f"{output_unit}/{input_unit}"
        return [
            ("core", "Duhem, dq/dv = f±(v, q), bilinear"),
            ("grid", f"{self.v_nodes.size} × {self.q_nodes.size} nodes over "
                     f"[{self.v_nodes[0]:.6g}, {self.v_nodes[-1]:.6g}] {input_unit} × "
                     f"[{self.q_nodes[0]:.6g}, {self.q_nodes[-1]:.6g}] {output_unit}"),
            ("rising slopes f+", f"{self.up.min():.4g} to {self.up.max():.4g} {slope}"),
            ("falling slopes f-", f"{self.down.min():.4g} to {self.down.max():.4g} {slope}"),
        ]  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """See :meth:`DifferentialCore.to_dict`."""
        return {
            "v_nodes": self.v_nodes.tolist(),
            "q_nodes": self.q_nodes.tolist(),
            "up": self.up.tolist(),
            "down": self.down.tolist(),
            "initial_state": self.initial_state.tolist(),
            "dv_max": self.dv_max,
            "region": self.region_json(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DuhemHysteresis:
        """Inverse of :meth:`to_dict` (see :meth:`~piezohyst.model.cores.base.Core.from_dict`)."""
        return cls(
            data["v_nodes"],
            data["q_nodes"],
            data["up"],
            data["down"],
            data["initial_state"],
            cls.region_from(data.get("region")),
            data.get("dv_max"),
        )

    @classmethod
    def identify(cls, job: FitJob) -> CoreFit:
        """See :meth:`~piezohyst.model.cores.base.Core.identify`."""
        return fit_in_memory(cls, job, _solve)


def _solve(job: Solving) -> tuple[DuhemHysteresis, list[FloatArray]]:
    x, y, t, terms, params, _, growth = job
    smoothing = float(params["smoothing"])
    nv, nq = params["grid"]
    if x.size < 4 * nv * nq + 2:
        msg = f"{x.size} samples cannot identify {2 * nv * nq} slopes: give a longer record"
        raise InsufficientDataError(msg)
    cells = nv * nq
    n = x.size
    g_mat = _growth_matrix(terms, x, t)
    g = np.concatenate(growth) if growth else np.zeros(0)
    qh = y - g_mat @ g if g.size else y  # the pure hysteresis the slopes describe
    mean_slope = max(float(np.ptp(qh)), 1e-300) / float(np.ptp(x))
    s_min = float(params["min_slope"]) * mean_slope
    lo, hi = float(qh.min()), float(qh.max())
    pad = 0.02 * (hi - lo)
    v_step = float(np.ptp(x)) / (nv - 1)
    head = [P.KIND_DUHEM, nv, nq, float(x.min()), v_step, lo - pad,
            (hi - lo + 2 * pad) / (nq - 1), 0.25 * v_step, s_min]  # fmt: skip
    packed = np.concatenate([head, np.zeros(2 * cells)])
    penalty = _curvature(nv, nq)
    rows = _picked_rows(n, FIT_ROWS)
    # integrated regression: the output is q0 plus the slopes summed along the measured
    # path; linear in the slopes, noise enters through the path only
    cum = np.empty((rows.size, 2 * cells))
    P.duhem_cumulative(packed, x, qh, rows, cum)
    a = np.hstack([cum, np.ones((rows.size, 1))])
    gram = a.T @ a
    weight = smoothing * max(float(np.mean(np.diag(gram)[:-1])), 1e-300)
    for half in (0, cells):
        sl = slice(half, half + cells)
        gram[sl, sl] += weight * penalty
    sol = _bounded_lstsq(gram, a.T @ qh[rows], np.append(np.full(2 * cells, s_min), -np.inf))
    packed[P.DU_UP :] = np.maximum(sol[:-1], s_min)
    q0 = float(sol[-1])
    # the state is (v, q): the record's own first output says where q starts, better
    # than any history run through a model still being fitted, so q0 is always fitted
    if params["refine"]:
        start = (packed.copy(), q0)
        packed, q0 = _refine_duhem(packed, x, qh, q0, s_min, smoothing, penalty, fit_q0=True)
        # keep the better of the two on the record, unless the polish ratchets where the linear
        # fit, nearly as good, does not: an output-error fit of half a record can fit it a
        # little better with loops that do not close, and then walks away on every cycle after
        # it (on a relaxing plant: 55 % of the span a cycle). Where the linear fit is far worse
        # (a PZT creep record: 122 % against 3.4 %), the polish stays.
        polished, linear = _sse(packed, q0, x, qh), _sse(*start, x, qh)
        ratchets = _ratchet(packed, q0, x) > max(_ratchet(*start, x), CLOSED)
        if polished > linear or (ratchets and linear <= NEARLY**2 * polished):
            packed, q0 = start
    core = DuhemHysteresis.from_packed(packed, [x[0], q0], Region.of(x, qh))
    return core, list(growth or [])


def _curvature(nv: int, nq: int) -> FloatArray:
    """DᵀD of second differences along both axes of an (nv, nq) grid (first differences
    where an axis has two nodes)."""
    rows = []
    for i in range(nv):
        for j in range(nq):
            for di, dj in ((1, 0), (0, 1)):
                a, b = i + 2 * di, j + 2 * dj
                if a < nv and b < nq:
                    r = np.zeros(nv * nq)
                    r[i * nq + j] += 1.0
                    r[(i + di) * nq + (j + dj)] -= 2.0
                    r[a * nq + b] += 1.0
                    rows.append(r)
                elif (nv if di else nq) == 2 and (i + di < nv and j + dj < nq):
                    r = np.zeros(nv * nq)
                    r[i * nq + j] += 1.0
                    r[(i + di) * nq + (j + dj)] -= 1.0
                    rows.append(r)
    d = np.array(rows) if rows else np.zeros((0, nv * nq))
    return np.asarray(d.T @ d)


def _sse(packed: FloatArray, q0: float, x: FloatArray, q: FloatArray) -> float:
    """Squared output error of a Duhem core simulated from q0 (inf if it blows up)."""
    sim = np.empty(x.size)
    P.duhem_jacobian(frozen(packed), x, q0, np.zeros(0, dtype=np.int64), sim, np.zeros((0, 1)))
    r = sim - q
    total = float(r @ r)
    return total if np.isfinite(total) else math.inf


def _ratchet(packed: FloatArray, q0: float, x: FloatArray) -> float:
    """How far a Duhem core's output moves from one full-range cycle of the record's
    voltages to the next, after six (as a fraction of the output's span; inf if it blows up).
    A core whose loops close settles to 0; one that ratchets keeps moving."""
    lo, hi = float(x.min()), float(x.max())
    leg = np.linspace(0.0, 1.0, CYCLE_LEG + 1)[1:]
    legs = [x[0] + (hi - x[0]) * leg]
    for _ in range(CYCLES):
        legs += [hi + (lo - hi) * leg, lo + (hi - lo) * leg]
    path = np.concatenate(legs)
    sim = np.empty(path.size)
    P.duhem_jacobian(frozen(packed), path, q0, np.zeros(0, dtype=np.int64), sim, np.zeros((0, 1)))
    tops = sim[CYCLE_LEG - 1 :: 2 * CYCLE_LEG]
    span = float(np.ptp(sim[-2 * CYCLE_LEG :]))
    move = abs(float(tops[-1] - tops[-2])) / max(span, 1e-300)
    return move if math.isfinite(move) else math.inf


def _refine_duhem(
    packed: FloatArray,
    x: FloatArray,
    q: FloatArray,
    q0: float,
    s_min: float,
    smoothing: float,
    penalty: FloatArray,
    *,
    fit_q0: bool,
) -> tuple[FloatArray, float]:
    """Output-error refinement of the slopes (and the start): bounded least squares on the
    simulated output, with the exact sensitivities of the simulation as its Jacobian."""
    from scipy.optimize import least_squares

    cells2 = packed.size - P.DU_UP
    cells = cells2 // 2
    rows = _picked_rows(x.size, REFINE_ROWS)
    scale = max(float(np.ptp(q)), 1e-300)
    q_rows = q[rows]
    lam, vec = np.linalg.eigh(penalty)
    root = (vec * np.sqrt(np.maximum(lam, 0.0))).T  # root.T @ root = penalty
    qsim = np.empty(x.size)
    jac_core = np.empty((rows.size, cells2 + 1))
    no_rows = np.zeros(0, dtype=np.int64)
    no_jac = np.zeros((0, cells2 + 1))
    theta0 = np.concatenate([packed[P.DU_UP :], [q0] if fit_q0 else []])

    def split(theta: FloatArray) -> tuple[FloatArray, float]:
        p = packed.copy()
        p[P.DU_UP :] = theta[:cells2]
        return p, float(theta[-1]) if fit_q0 else q0

    p0, start = split(theta0)
    P.duhem_jacobian(frozen(p0), x, start, rows, qsim, jac_core)
    # the curvature penalty has the weight it had in the linear fit, relative to the data
    col = float(np.mean(np.sum(jac_core[:, :cells2] ** 2, axis=0))) / scale**2
    w_pen = math.sqrt(smoothing * max(col, 1e-300))

    def residual(theta: FloatArray) -> FloatArray:
        p, qq = split(theta)
        P.duhem_jacobian(frozen(p), x, qq, no_rows, qsim, no_jac)
        pen = [w_pen * (root @ theta[h : h + cells]) for h in (0, cells)]
        return np.concatenate([(qsim[rows] - q_rows) / scale, *pen])

    def jacobian(theta: FloatArray) -> FloatArray:
        p, qq = split(theta)
        P.duhem_jacobian(frozen(p), x, qq, rows, qsim, jac_core)
        top = jac_core if fit_q0 else jac_core[:, :cells2]
        pen = np.zeros((2 * root.shape[0], theta.size))
        pen[: root.shape[0], :cells] = w_pen * root
        pen[root.shape[0] :, cells:cells2] = w_pen * root
        return np.vstack([top / scale, pen])

    lower = np.concatenate([np.full(cells2, s_min), [-np.inf] if fit_q0 else []])
    theta0[:cells2] = np.maximum(theta0[:cells2], s_min * (1 + 1e-9))
    res = least_squares(
        residual, theta0, jac=jacobian, bounds=(lower, np.inf), method="trf",
        x_scale="jac", max_nfev=REFINE_EVALS, tr_solver="exact",
    )  # fmt: skip
    p, qq = split(res.x)
    p[P.DU_UP :] = np.maximum(p[P.DU_UP :], s_min)
    return p, qq
