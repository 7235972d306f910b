r"""Identification: one bounded least-squares solve for a core plus terms (eq. 16-17).

The output is linear in every parameter, :math:`y = W^T X` (eq. 16): the play
weights and offset of the core and the coefficients of every term. So one
linear least-squares problem identifies a model, whatever terms it holds.
Three things are added to the paper:

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

*Scale does not matter.* Input and output are divided by powers of two near
their peaks (exact), each column by the matching power of the input scale,
so volts or kilovolts, coulombs or microcoulombs give the same solve.

Term selection reuses the matrices: they are accumulated per segment of the
record (the model running through all of it), so fitting a subset of terms on
the early segments and scoring it on a later one needs no second pass.
"""

from __future__ import annotations

import functools
import itertools
import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from ..._kernels import signal as S
from ..._validation import FloatArray, frozen
from ...errors import InsufficientDataError
from ...io.blocks import BLOCK, Blocks, Summary
from ..dynamics import OutputDynamics
from ..terms import Term, term_columns


class ColumnCore(Protocol):
    """What the solve needs of a core whose output is linear in its parameters (the play
    core): its operator columns block by block, a scaled copy, and the map from slopes to
    parameters. The solve takes this protocol, not a core's class, so it imports no core."""

    @property
    def n_operators(self) -> int:
        """Operator columns (the parameters before the terms')."""
        ...

    def scaled(self, scale: float) -> ColumnCore:
        """The same core for an input divided by ``scale``."""
        ...

    def fill(self, x: FloatArray, state: FloatArray, block: FloatArray) -> None:
        """Write the operator columns for ``x`` into ``block`` (``state`` carried)."""
        ...

    def fill_rows(
        self, x: FloatArray, state: FloatArray, rows: npt.NDArray[np.intp], block: FloatArray
    ) -> None:
        """:meth:`fill` for the rows ``rows`` only (the state runs through all)."""
        ...

    def slope_map(self, p: int) -> FloatArray:
        """The matrix from (slopes, other parameters) to parameters."""
        ...


__all__ = ["Identification", "NormalEquations", "bounded_lstsq", "identify"]

# term selection by forward-chaining (blocked) time-series cross-validation: the first
# SELECT_START of the record trains, the rest is cut into SELECT_FOLDS blocks, each
# predicted by a fit on everything before it
SELECT_START = 0.4
SELECT_FOLDS = 4
#: Growth terms each larger than this many times their sum cancel: a subset not chosen
CANCEL = 3.0
SELECT_PIECES = 20  # the tested part is accumulated in pieces, grouped into folds after


def _folds(parts: list[NormalEquations]) -> list[NormalEquations]:
    """[training start, fold 1, ...]: up to SELECT_FOLDS folds of 2 or more input reversals.

    A fold shorter than a cycle of the drive tests half a loop; when the
    tested part holds fewer than two folds' worth of reversals, the record's
    last 30 % is the one test block (the first 70 % trains).
    """
    start, pieces = parts[0], parts[1:]
    total = sum(p.reversals for p in pieces)
    target = max(2, -(-total // SELECT_FOLDS))
    folds: list[NormalEquations] = []
    acc: NormalEquations | None = None
    for piece in pieces:
        acc = piece if acc is None else acc + piece
        if acc.reversals >= target and len(folds) < SELECT_FOLDS - 1:
            folds.append(acc)
            acc = None
    if acc is not None:
        if acc.reversals >= 2 or not folds:
            folds.append(acc)
        else:  # a last piece with less than a cycle joins the fold before it
            folds[-1] = folds[-1] + acc
    if len(folds) < 2:
        half = len(pieces) // 2
        return [functools.reduce(operator.add, [start, *pieces[:half]]),
                functools.reduce(operator.add, pieces[half:])]  # fmt: skip
    return [start, *folds]


@dataclass(frozen=True)
class NormalEquations:
    """Accumulated :math:`X^T X`, :math:`X^T y`, :math:`y^T y` over some samples.

    Attributes
    ----------
    gram : ndarray, shape (p, p)
    rhs : ndarray, shape (p,)
    yy : float
    n_samples : int
    reversals : int
        Reversals of the input counted in these samples (when asked for).
    """

    gram: FloatArray
    rhs: FloatArray
    yy: float
    n_samples: int
    reversals: int = 0

    def __add__(self, other: NormalEquations) -> NormalEquations:
        return NormalEquations(
            self.gram + other.gram,
            self.rhs + other.rhs,
            self.yy + other.yy,
            self.n_samples + other.n_samples,
            self.reversals + other.reversals,
        )

    def sse(self, beta: FloatArray, columns: FloatArray) -> float:
        """Sum of squared residuals of parameters ``beta`` on ``columns``, from the matrices.

        Parameters
        ----------
        beta : ndarray
            Parameters of the chosen columns.
        columns : ndarray of int
            Indices of the columns ``beta`` belongs to.

        Returns
        -------
        float
            :math:`y^T y - 2 \\beta^T b + \\beta^T G \\beta`, never below 0.
        """
        g = self.gram[np.ix_(columns, columns)]
        b = self.rhs[columns]
        return max(self.yy - 2.0 * float(beta @ b) + float(beta @ g @ beta), 0.0)


def _power_of_two(values: FloatArray) -> float:
    """A power of two near max|values| (exact to divide by), 1 for all zeros."""
    peak = float(np.max(np.abs(values)))
    if peak == 0.0:
        return 1.0
    return float(2.0 ** np.round(np.log2(peak)))


def _accumulate(
    core: ColumnCore,
    terms: Sequence[Term],
    blocks: Blocks,
    x_first: float,
    y_ref: float,
    scales: tuple[float, float],
    z0: FloatArray,
    col_scale: FloatArray,
    edges: Sequence[int],
    stride: int = 1,
    block: int = BLOCK,
    output: OutputDynamics | None = None,
    reversal_band: float | None = None,
) -> list[NormalEquations]:
    """Normal equations of every segment ``edges[k]:edges[k+1]`` (model run through all).

    One pass over the record; with ``stride`` > 1 the model still runs through
    every sample but only about one row in ``stride`` enters the sums, picked
    by a hash of its index (no aliasing with a periodic drive): a cheap
    objective for an outer search. With ``output`` (a mechanical mode) every
    column goes through it before entering the sums: the output is linear in
    the parameters, so filtering the columns filters the model. The core runs
    on the scaled input ``x / sx``
    (a power of two: exact), the terms on ``x`` with their columns divided by
    their scale; the output is taken as ``y / sy - y_ref``.
    """
    n = core.n_operators
    p = col_scale.size
    sx, sy = scales
    work = np.empty((0, p))  # made at the first block that needs it, no larger than it
    scaled_core = core.scaled(sx)
    z = z0 / sx
    states = [term.rest_state(x_first) for term in terms]
    parts = [(np.zeros((p, p)), np.zeros(p), [0.0]) for _ in edges[1:]]
    counts = [0 for _ in edges[1:]]
    turns = [0 for _ in edges[1:]]
    turn_state = np.zeros(3)
    pos = 0  # index of the next sample in the record
    seg = 0
    mode_state: FloatArray | None = None
    t_prev: float | None = None
    for x_blk, y_blk, t_blk in blocks():
        size = x_blk.size
        k = 0
        while k < size and seg < len(parts):
            while seg < len(parts) and pos + k >= edges[seg + 1]:
                seg += 1
            if seg == len(parts):
                break
            stop = min(size, k + block, edges[seg + 1] - pos)
            m = stop - k
            xs = x_blk[k:stop]
            if reversal_band is not None:
                turns[seg] += int(S.reversals(frozen(xs), reversal_band, turn_state))
            ts = None if t_blk is None else t_blk[k:stop]
            dt = None
            if terms and ts is not None:
                dt = np.empty(m)
                dt[0] = 0.0 if t_prev is None else ts[0] - t_prev
                dt[1:] = np.diff(ts)
                t_prev = float(ts[-1])
            filtered = output is not None and output.active
            if stride > 1 and not filtered:
                # a cheap objective: the model runs through every sample, a few rows are summed
                keep = _picked(pos + k, m, stride)
                b = np.empty((keep.size, p))
                b[:, n] = 1.0
                scaled_core.fill_rows(xs / sx, z, keep, b)
                if terms:
                    cols = np.empty((m, p - n - 1))
                    term_columns(terms, xs, ts, dt, states, cols)
                    b[:, n + 1 :] = cols[keep]
                ys = y_blk[k:stop][keep] / sy - y_ref
            else:
                if work.shape[0] < m:
                    work = np.empty((max(m, min(block, x_blk.size)), p))
                    work[:, n] = 1.0
                scaled_core.fill(xs / sx, z, work)
                if terms:
                    term_columns(terms, xs, ts, dt, states, work[:m, n + 1 :])
                if filtered:
                    assert output is not None
                    work[:m, n] = 1.0  # the offset column, filtered in place before
                    if mode_state is None:
                        mode_state = output.rest_state(work[0])
                    work[:m] = output.apply_columns(work[:m], mode_state)
                b, ys = work[:m], y_blk[k:stop] / sy - y_ref
                if stride > 1:  # the rows kept: the rest is never touched again
                    keep = _picked(pos + k, m, stride)
                    b, ys = b[keep], ys[keep]
            b[:, n + 1 :] /= col_scale[n + 1 :]
            gram, rhs, yy = parts[seg]
            gram += b.T @ b
            rhs += b.T @ ys
            yy[0] += float(ys @ ys)
            counts[seg] += ys.size
            k = stop
        pos += size
    return [
        NormalEquations(gram, rhs, yy[0], count, turn)
        for (gram, rhs, yy), count, turn in zip(parts, counts, turns, strict=True)
    ]


@functools.lru_cache(maxsize=256)
def _picked(first: int, m: int, stride: int) -> npt.NDArray[np.intp]:
    """About one in ``stride`` of the rows ``first .. first + m - 1``, by a hash of the index.

    Cached: an outer search asks for the same rows at every evaluation.
    """
    g = np.arange(first, first + m, dtype=np.uint64)
    h = (g * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)  # Fibonacci hashing, 24 bits
    return np.flatnonzero(h < np.uint64((1 << 24) // stride)).astype(np.intp)


#: Eigenvalues of a column-scaled Gram matrix below this fraction of the largest mark
#: directions the data do not determine. Along one, the fitted output moves by less than
#: ``sqrt(RANK_RTOL) = 1e-6`` of its response along the best-determined direction: below the
#: resolution of a 16-bit converter (1.5e-5 of its span) by a factor of 15, and far above the
#: rounding of an accumulated Gram matrix (about ``sqrt(rows) * eps``, 2e-13 for 10**6 rows),
#: so the split between identified and unidentified directions does not move with the last bit
#: (over the test suite's 880 solves the scaled eigenvalues lay at or below 1.2e-16 of the
#: largest, or at or above 1.7e-11, but one at 4.4e-13, which this cuts).
RANK_RTOL = 1e-12
#: Weight of the minimum-norm tie-break in a bounded solve, relative to the largest
#: eigenvalue. It must outweigh the rounding of the data term's gradient, which an active
#: bound's multiplier carries into the unidentified directions at up to about 1e-12 of the
#: largest eigenvalue: measured on a fold solve of a relaxing proxy (85 parameters, 57 at
#: their bounds), a one-ulp change of the Gram matrix moved the solution by 1-3 % with
#: weights of 2e-16 or 1e-14, 0.03-0.5 % with 1e-12, and 2e-6 to 5e-5 with 1e-10; the data
#: term's value moved in its thirteenth digit at most.
TIE_BREAK = 1e-10


def bounded_lstsq(gram: FloatArray, rhs: FloatArray, lower: FloatArray) -> FloatArray:
    """Minimise ``q'Gq - 2b'q`` subject to ``q >= lower`` (``-inf`` = free).

    Columns are scaled to unit norm and the scaled Gram matrix is split by its
    eigenvalues: the directions above :data:`RANK_RTOL` of the largest are
    identified by the data and solved for; the others are not (constant or
    collinear columns, cells a record never separates) and take the
    minimum-norm rule: the solution has no component along them, as
    :func:`numpy.linalg.lstsq` gives. Where that solution breaks a bound, the
    bounded problem is solved on the identified directions alone, with the same
    rule as its tie-break: a weight ``mu = TIE_BREAK * lambda_max`` on ``|q|^2``
    picks, among the solutions that fit the identified directions (nearly)
    equally, the one nearest zero. It shrinks an identified direction by
    ``lambda / (lambda + mu)``: by 1e-8 or less for the directions that carry a
    fit (``lambda >= 1e-2 lambda_max``), and it pulls the weakest ones
    (``lambda < mu``) to zero like the unidentified ones.
    Nothing is regularised toward the rounding noise that an unidentified
    direction's right-hand side holds, so a one-ulp change of the Gram matrix
    moves the solution by rounding amplified by the problem's conditioning
    (``1e-12`` relative where no bound is active, up to ``5e-5`` with many active
    bounds and a near-null free face), and the fitted output less.

    Parameters
    ----------
    gram : ndarray, shape (p, p)
        :math:`X^T X`.
    rhs : ndarray, shape (p,)
        :math:`X^T y`.
    lower : ndarray, shape (p,)
        The lower bounds (``-inf``: free).

    Returns
    -------
    ndarray, shape (p,)
        The solution ``q``.
    """
    p = rhs.size
    d = np.sqrt(np.abs(np.diag(gram)))
    d = np.where(d > 1e-300, d, 1.0)
    g = gram / np.outer(d, d)
    b = rhs / d
    lo = lower * d
    lam, vec = np.linalg.eigh(0.5 * (g + g.T))
    top = max(float(lam[-1]), 1e-300)
    keep = lam > RANK_RTOL * top
    basis, lam = vec[:, keep], lam[keep]
    proj = basis.T @ b
    q = basis @ (proj / lam)  # the minimum-norm least-squares solution
    if np.any(q < lo):
        from scipy.optimize import lsq_linear  # only here: keeps the command line's start fast

        # ||diag(sqrt lam) V'q - proj / sqrt lam||^2 = q'Gq - 2b'q + const on the kept V
        root = np.sqrt(lam)
        mu = TIE_BREAK * top
        res = lsq_linear(
            np.vstack([root[:, None] * basis.T, math.sqrt(mu) * np.eye(p)]),
            np.concatenate([proj / root, np.zeros(p)]),
            bounds=(lo, np.full(p, np.inf)),
            method="bvls",
            tol=1e-15,
            max_iter=20 * p,
        )
        q = np.maximum(res.x, lo)
    return np.asarray(q / d, dtype=np.float64)


@dataclass(frozen=True)
class Identification:
    """What :func:`identify` found, in the data's own units.

    Attributes
    ----------
    core : ndarray, shape (n + 1,)
        Play weights (output per input unit), then the offset (output units).
    coefficients : tuple of (ndarray or None)
        Each term's coefficients; None for a term the selection left out.
    scores : dict
        Held-out RMSE (output units) of every subset tried, keyed by the tuple
        of term indices (empty without selection or validation); with
        selection, pooled over the folds.
    rmse : float
        RMSE of the final solve over the rows it used (output units).
    fold_scores : dict
        With selection: each subset's held-out RMSE per fold, in time order.
    splits : list of int
        With selection: the first sample of each fold, then the record's length.
    """

    core: FloatArray
    coefficients: tuple[FloatArray | None, ...]
    scores: dict[tuple[int, ...], float]
    rmse: float = float("nan")
    fold_scores: dict[tuple[int, ...], list[float]] = field(default_factory=dict)
    splits: list[int] = field(default_factory=list)


def identify(
    core: ColumnCore,
    terms: Sequence[Term],
    blocks: Blocks,
    summary: Summary,
    initial_state: FloatArray,
    *,
    min_slope: float,
    subsets: Sequence[tuple[int, ...]] | None = None,
    holdout: float = 0.3,
    validate: bool = False,
    stride: int = 1,
    block: int = BLOCK,
    output: OutputDynamics | None = None,
) -> Identification:
    """Identify a core and terms jointly from checked inputs (the one fit path).

    Parameters
    ----------
    core : ColumnCore
        The hysteresis core.
    terms : sequence of Term
        Bound terms (see :meth:`Term.bind`); with ``subsets``, every candidate.
    blocks : Blocks
        The record: input (V), output, and times (s) where a term is rate
        dependent. Read once (see :func:`array_blocks` for arrays).
    summary : Summary
        The record's extremes and length (:meth:`Summary.of`).
    initial_state : ndarray, shape (n,)
        Operator states before the first sample (input units).
    min_slope : float
        Lower bound of every loading-curve slope, relative to the mean slope
        ``span(y) / span(x)``.
    subsets : sequence of tuple of int, optional
        Term subsets (indices into ``terms``) to choose from, by forward-chaining
        time-series cross-validation: the record after its first 40 % is cut
        into 4 blocks, and each block is predicted by the subset fitted on
        everything before it (the model running through the whole record).
        The best pooled held-out RMSE wins, where a larger subset must beat a
        smaller one by 0.1 %; it is refitted on everything. Default: all
        terms, no selection.
    holdout : float, default 0.3
        Fraction of the record held out for ``validate``.
    validate : bool, default False
        Score the (single) subset on the held-out part too (``scores``).
    stride : int, default 1
        Use about one row in ``stride`` in the sums (the model runs through
        all): a cheaper, noisier fit for outer searches.
    block : int
        Samples per block (larger: less overhead, more memory).
    output : OutputDynamics, optional
        A mode between the model's output and the measured one.

    Returns
    -------
    Identification

    Raises
    ------
    InsufficientDataError
        If the record has no more samples than parameters.
    """
    n = core.n_operators
    sm = summary
    sx = _power_of_two(np.array([sm.x_min, sm.x_max]))
    sy = _power_of_two(np.array([sm.y_min, sm.y_max]))
    y_ref = sm.y_first / sy  # centred: keeps y'y, and the selection's residuals, well conditioned
    col_scale = np.concatenate(
        [np.full(n, sx), [1.0], *[np.full(term.width, sx**term.input_degree) for term in terms]]
    )
    span_x, span_y = (sm.x_max - sm.x_min) / sx, (sm.y_max - sm.y_min) / sy
    mean_slope = span_y / span_x if span_x > 1e-12 and span_y > 1e-12 else 1.0
    offsets = np.cumsum([n + 1, *[term.width for term in terms]])
    term_cols = [
        np.arange(a - w, a) for a, w in zip(offsets[1:], [t.width for t in terms], strict=True)
    ]
    lowers = [
        term.lower_bounds() * col_scale[c] / sy for term, c in zip(terms, term_cols, strict=True)
    ]
    candidates = [tuple(range(len(terms)))] if subsets is None else list(subsets)
    selecting = len(candidates) > 1
    if selecting:  # forward chaining over pieces, grouped into folds after the pass
        first = int(SELECT_START * sm.n)
        edges = sorted({0, *(first + (sm.n - first) * j // SELECT_PIECES
                             for j in range(SELECT_PIECES)), sm.n})  # fmt: skip
    else:
        split = int((1.0 - holdout) * sm.n) if validate else sm.n
        edges = [0, split, sm.n] if 0 < split < sm.n else [0, sm.n]
    parts = _accumulate(
        core,
        terms,
        blocks,
        sm.x_first,
        y_ref,
        (sx, sy),
        initial_state,
        col_scale,
        edges,
        stride,
        block,
        output,
        0.05 * (sm.x_max - sm.x_min) if selecting else None,
    )
    whole = functools.reduce(operator.add, parts)
    splits: list[int] = []
    if selecting:
        parts = _folds(parts)
        splits = list(itertools.accumulate(p.n_samples for p in parts))

    def columns_of(subset: tuple[int, ...]) -> FloatArray:
        return np.concatenate([np.arange(n + 1), *[term_cols[j] for j in subset]]).astype(int)

    def solve(eqs: NormalEquations, subset: tuple[int, ...]) -> FloatArray:
        cols = columns_of(subset)
        p = cols.size
        if eqs.n_samples <= p:
            msg = (
                f"Identifying {p} parameters ({n} operator weights, the offset"
                f"{', ' + ', '.join(terms[j].kind for j in subset) if subset else ''}) needs "
                f"more than {p} samples. Got {eqs.n_samples}."
            )
            raise InsufficientDataError(msg)
        lower = np.concatenate(
            [np.full(n, min_slope * mean_slope), [-np.inf], *[lowers[j] for j in subset]]
        )
        m = core.slope_map(p)
        g = eqs.gram[np.ix_(cols, cols)]
        return np.asarray(m @ bounded_lstsq(m.T @ g @ m, m.T @ eqs.rhs[cols], lower))

    def cancelling(subset: tuple[int, ...]) -> bool:
        """Growth terms that mostly cancel each other on the record (each larger than
        :data:`CANCEL` times their sum) fit its drift by a difference of large terms, which
        a record with another voltage history does not repeat: not a choice to make."""
        growth = [j for j in subset if terms[j].removed]
        if len(growth) < 2:
            return False
        try:
            beta = solve(whole, subset)
        except InsufficientDataError:
            return False
        cols = list(columns_of(subset))
        own = [np.array([cols.index(c) for c in term_cols[j]]) for j in growth]
        every = np.concatenate([term_cols[j] for j in growth])
        b = np.concatenate([beta[i] for i in own])
        total = float(b @ whole.gram[np.ix_(every, every)] @ b)
        sizes = [
            float(beta[i] @ whole.gram[np.ix_(term_cols[j], term_cols[j])] @ beta[i])
            for j, i in zip(growth, own, strict=True)
        ]
        return max(sizes) > CANCEL**2 * max(total, 1e-300)

    scores: dict[tuple[int, ...], float] = {}
    fold_scores: dict[tuple[int, ...], list[float]] = {}
    best = candidates[0]
    if (selecting or validate) and len(parts) >= 2:
        best_err = np.inf
        for subset in candidates:
            if selecting and cancelling(subset):
                continue
            sse = 0.0
            count = 0
            folds: list[float] = []
            train = parts[0]
            for test in parts[1:]:  # train on everything before the test block
                try:
                    beta = solve(train, subset)
                except InsufficientDataError:
                    train = train + test
                    continue
                fold_sse = test.sse(beta, columns_of(subset))
                folds.append(float(np.sqrt(fold_sse / test.n_samples)) * sy)
                sse += fold_sse
                count += test.n_samples
                train = train + test
            if not count:
                continue
            err = float(np.sqrt(sse / count)) * sy
            scores[subset] = err
            fold_scores[subset] = folds
            if err < best_err * (1 - 1e-3):  # a term must earn its place
                best, best_err = subset, err
    scaled = solve(whole, best)
    fit_rmse = float(np.sqrt(whole.sse(scaled, columns_of(best)) / whole.n_samples)) * sy
    beta = scaled / col_scale[columns_of(best)] * sy
    beta[n] += y_ref * sy
    coefficients: list[FloatArray | None] = [None] * len(terms)
    pos = n + 1
    for j in best:
        coefficients[j] = beta[pos : pos + terms[j].width].copy()
        pos += terms[j].width
    return Identification(
        beta[: n + 1].copy(), tuple(coefficients), scores, fit_rmse, fold_scores, splits
    )
