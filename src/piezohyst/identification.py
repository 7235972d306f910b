r"""Identification of Prandtl-Ishlinskii weights (paper eq. 16-17).

The output is linear in the parameters, :math:`y = W^T X` (eq. 16), so the
weights, the offset and (for the active model) the growth rate follow from one
linear least-squares problem. Two things are added to the paper:

*Invertibility is guaranteed, not hoped for.* The analytic inverse (eq. 18)
needs the first weight and every partial sum of weights positive. We solve in
the loading-curve slopes :math:`S_i = \sum_{j \le i} w_j` instead of the
weights, with lower bounds :math:`S_i \ge \epsilon`: a box-constrained least
squares (:func:`scipy.optimize.lsq_linear`). Forcing every :math:`w_i \ge 0`
would also guarantee it, but cannot fit a saturating voltage-charge curve,
whose later weights are negative.

*Memory does not grow with the operator count times the samples.* The Gram
matrix :math:`X^T X` and :math:`X^T y` are accumulated block by block (play
states from the numba kernel, products by BLAS), so a fit on :math:`10^6`
samples keeps one block of a few thousand rows plus :math:`O(p^2)`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import lsq_linear

from . import _kernels
from ._validation import FloatArray, as_signal, check_int
from .errors import InsufficientDataError, ParameterError

__all__ = [
    "LinearSolution",
    "NormalEquations",
    "default_thresholds",
    "history_state",
    "identify",
    "solve_pi",
    "solve_slopes",
    "time_steps",
]

BLOCK = 4096  # samples per block when accumulating or streaming


def default_thresholds(x: ArrayLike, n_operators: int) -> FloatArray:
    r"""Evenly spaced thresholds over half of the input's range.

    :math:`r_i = i \cdot \Delta x / (2n)`, :math:`i = 0 \dots n-1`, where
    :math:`\Delta x` is the input's span. The largest threshold stays below
    :math:`\Delta x / 2`: a wider play never reverses inside the range and only
    adds a column collinear with the input and the offset. The rule depends on
    the span only, so it suits unipolar (0..Vmax) and bipolar drive alike.

    Examples
    --------
    >>> default_thresholds([0.0, 140.0], 4).tolist()
    [0.0, 17.5, 35.0, 52.5]
    """
    xs = as_signal(x, "x")
    n = check_int(n_operators, "n_operators", "default_thresholds", 1, 1000)
    span = float(xs.max() - xs.min())
    if span <= 0.0:
        return np.arange(n, dtype=np.float64)  # any increasing set: the input never moves
    return np.arange(n, dtype=np.float64) * (span / (2.0 * n))


def history_state(history: ArrayLike, thresholds: ArrayLike) -> FloatArray:
    """Play-operator states (input units) after ``history``, starting at rest at its first sample.

    To fit or predict a later part of a record, the operators must start where
    the earlier input left them, not at rest.

    Examples
    --------
    >>> history_state([0.0, 10.0, 4.0], [0.0, 2.0, 5.0]).tolist()
    [4.0, 6.0, 5.0]
    """
    h = as_signal(history, "history")
    thr = as_signal(thresholds, "thresholds")
    z = np.full(thr.size, h[0])
    _kernels.pi_forward(h, thr, np.zeros(thr.size), z, np.empty_like(h))
    return z


def time_steps(t: FloatArray, t_previous: float | None = None) -> FloatArray:
    """Sample intervals (s) for the backward-rectangle integral; first is 0 unless continuing."""
    dt = np.empty_like(t)
    dt[0] = 0.0 if t_previous is None else t[0] - t_previous
    dt[1:] = np.diff(t)
    return dt


@dataclass(frozen=True)
class NormalEquations:
    """Accumulated :math:`X^T X`, :math:`X^T y`, :math:`y^T y` of eq. 16.

    Columns: the n play operators, the constant (offset), then the integral
    :math:`\\int x\\,dt` when ``dt`` is given (active model).
    """

    gram: FloatArray
    rhs: FloatArray
    yy: float
    n_samples: int

    @classmethod
    def accumulate(
        cls,
        x: FloatArray,
        y: FloatArray,
        thresholds: FloatArray,
        initial_state: FloatArray,
        dt: FloatArray | None = None,
        *,
        extra: Callable[[int, int], FloatArray] | None = None,
        extra_width: int = 0,
    ) -> NormalEquations:
        """Accumulate over blocks of samples; memory O(block x p + p^2).

        ``dt`` adds the active model's integral column. ``extra(start, stop)``
        returns ``extra_width`` further columns for samples ``start:stop``; it is
        called once per block, in order, so it may carry state.
        """
        if dt is not None:
            acc = [0.0]

            def integral(start: int, stop: int) -> FloatArray:
                out = np.empty(stop - start)
                acc[0] = _kernels.running_integral(x[start:stop], dt[start:stop], acc[0], out)
                return out[:, None]

            extra, extra_width = integral, 1
        n = thresholds.size
        p = n + 1 + (extra_width if extra is not None else 0)
        gram = np.zeros((p, p))
        rhs = np.zeros(p)
        yy = 0.0
        block = np.empty((min(BLOCK, x.size), p))
        block[:, n] = 1.0
        z = initial_state.copy()
        for start in range(0, x.size, block.shape[0]):
            xs = x[start : start + block.shape[0]]
            ys = y[start : start + block.shape[0]]
            m = xs.size
            _kernels.play_states(xs, thresholds, z, block)
            if extra is not None:
                block[:m, n + 1 :] = extra(start, start + m)
            b = block[:m]
            gram += b.T @ b
            rhs += b.T @ ys
            yy += float(ys @ ys)
        return cls(gram, rhs, yy, x.size)


def _bounded_lstsq(gram: FloatArray, rhs: FloatArray, lower: FloatArray) -> FloatArray:
    """Minimise ``q'Gq - 2b'q`` subject to ``q >= lower`` (``-inf`` = free).

    Columns are scaled to unit norm; eigenvalues of the scaled Gram matrix are
    floored at 1e-12 of the largest (a ridge in the directions the data do not
    determine), so constant or collinear columns, and rounding that makes a
    singular Gram matrix slightly indefinite, cannot break the solve.
    """
    p = rhs.size
    d = np.sqrt(np.abs(np.diag(gram)))
    d = np.where(d > 1e-300, d, 1.0)
    g = gram / np.outer(d, d)
    b = rhs / d
    lo = lower * d
    lam, vec = np.linalg.eigh(0.5 * (g + g.T))
    lam = np.maximum(lam, 1e-12 * max(float(lam[-1]), 1e-300))
    proj = vec.T @ b
    q = vec @ (proj / lam)
    if np.any(q < lo):
        # ||diag(sqrt(lam)) V' q - proj / sqrt(lam)||^2 = q'Gq - 2b'q + const
        root = np.sqrt(lam)
        res = lsq_linear(
            root[:, None] * vec.T,
            proj / root,
            bounds=(lo, np.full(p, np.inf)),
            method="bvls",
            tol=1e-13,
        )
        q = np.maximum(res.x, lo)
    return np.asarray(q / d, dtype=np.float64)


@dataclass(frozen=True)
class LinearSolution:
    """Weights, offset and growth rate from :func:`solve_pi`."""

    weights: FloatArray
    offset: float
    growth_rate: float


def solve_slopes(
    gram: FloatArray,
    rhs: FloatArray,
    n_operators: int,
    *,
    min_slope: float,
    lower: FloatArray,
) -> FloatArray:
    r"""Bounded least squares with the first ``n_operators`` columns solved in slopes.

    The first ``n_operators`` parameters are play weights, found through the
    loading slopes :math:`S_i \ge` ``min_slope``; ``lower`` bounds the other
    parameters (``-inf`` for free ones). With :math:`w = M S` (:math:`M` the
    first-difference matrix), the Gram matrix in slope coordinates is
    :math:`M^T X^T X M`. Returns the parameters with weights (not slopes) first.
    """
    p = rhs.size
    n = n_operators
    if not np.isfinite(min_slope) or min_slope <= 0:
        msg = f"'min_slope' must be a positive float. Got {min_slope!r}."
        raise ParameterError(msg)
    m = np.eye(p)
    m[np.arange(1, n), np.arange(0, n - 1)] = -1.0
    bounds = np.concatenate([np.full(n, min_slope), lower])
    return np.asarray(m @ _bounded_lstsq(m.T @ gram @ m, m.T @ rhs, bounds))


def solve_pi(equations: NormalEquations, *, min_slope: float, growth: bool) -> LinearSolution:
    """The classical/active model's solve: weights, then offset, then growth rate."""
    p = equations.rhs.size
    n = p - 1 - int(growth)
    if equations.n_samples <= p:
        msg = (
            f"Identifying {p} parameters ({n} operator weights, the offset"
            f"{', the growth rate' if growth else ''}) needs more than {p} samples. "
            f"Got {equations.n_samples}."
        )
        raise InsufficientDataError(msg)
    sol = solve_slopes(
        equations.gram, equations.rhs, n, min_slope=min_slope, lower=np.full(p - n, -np.inf)
    )
    return LinearSolution(
        weights=sol[:n].copy(),
        offset=float(sol[n]),
        growth_rate=float(sol[n + 1]) if growth else 0.0,
    )


def _power_of_two_scale(values: FloatArray) -> float:
    """A power of two near max|values| (exact to divide by), 1 for all zeros."""
    peak = float(np.max(np.abs(values)))
    if peak == 0.0:
        return 1.0
    return float(2.0 ** np.round(np.log2(peak)))


def identify(
    x: FloatArray,
    y: FloatArray,
    thresholds: FloatArray,
    *,
    dt: FloatArray | None = None,
    min_slope: float = 1e-3,
    initial_state: FloatArray | None = None,
) -> LinearSolution:
    """Weights, offset (and growth rate if ``dt`` is given) for checked inputs.

    The operators start from ``initial_state`` (input units), by default at
    rest at ``x[0]``. ``min_slope`` is relative to the
    mean slope ``span(y) / span(x)``. Input and output are first divided by
    powers of two near their peaks, so the solve is the same at any scale
    (volts or kilovolts, coulombs or microcoulombs).
    """
    sx = _power_of_two_scale(x)
    sy = _power_of_two_scale(y)
    xs, ys, thr = x / sx, y / sy, thresholds / sx
    span_x, span_y = float(np.ptp(xs)), float(np.ptp(ys))
    mean_slope = span_y / span_x if span_x > 1e-12 and span_y > 1e-12 else 1.0
    z0 = np.full(thr.size, xs[0]) if initial_state is None else initial_state / sx
    eqs = NormalEquations.accumulate(xs, ys, thr, z0, dt=dt)
    sol = solve_pi(eqs, min_slope=min_slope * mean_slope, growth=dt is not None)
    return LinearSolution(
        weights=sol.weights * (sy / sx),
        offset=sol.offset * sy,
        growth_rate=sol.growth_rate * (sy / sx),
    )
