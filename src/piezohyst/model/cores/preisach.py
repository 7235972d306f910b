r"""The Preisach core: hysteresis by its Everett function on a grid of reversal points.

The output rising from a minimum :math:`a` is :math:`q(a) + E(a, v)`, with
wiping-out and return-point memory (a stack of reversal points). Linear in
its density, so identified by one bounded least squares (density >= 0, or a
signed PI part plus one >= 0 where the loops flatten after reversals) joint
with the growth terms and a relaxation term; inverted by the packed cores'
bracketed Newton solve. Kernels in :mod:`piezohyst._kernels.packed`
(``everett``, ``rev_move``, ``rev_design``); the compensator step in C is
``c/packed.c``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..._kernels import packed as P
from ..._kernels import signal as S
from ..._validation import FloatArray, as_signal
from ...errors import InsufficientDataError, ParameterError, ShapeError
from ..terms import Relaxation
from ._inmemory import (
    FIT_ROWS,
    Solving,
    _growth_matrix,
    _picked_rows,
    _split,
    _start_inner,
    _terms_output,
    fit_in_memory,
)
from .base import (
    CoreFit,
    FitJob,
    PackedCore,
    Region,
    _frozen,
    _nodes,
)
from .solve import bounded_lstsq as _bounded_lstsq

__all__ = ["PreisachHysteresis"]


#: Reversal points of a Preisach core's rest state (a demagnetising staircase), of
#: the stack's ``_kernels.packed.STACK``; the rest holds the reversals of the drive
DEMAG_POINTS = 20


#: Ratio of successive amplitudes of that staircase (the last is 1e-3 of the first)
DEMAG_RATIO = 0.7


def branch_sums(density: ArrayLike) -> FloatArray:
    """The density's sums from the diagonal along each column (a rising branch's slope, times
    the node spacing, after a reversal in that row) and each row (a falling branch's).

    Parameters
    ----------
    density : array_like, shape (m, m)
        Upper triangle used.

    Returns
    -------
    ndarray
        ``m (m + 1)`` sums: ``sum(mu[j:l+1, l])`` and ``sum(mu[k, k:L+1])`` for ``j <= l``,
        ``k <= L``.
    """
    mu = np.triu(np.asarray(density, dtype=np.float64))
    upper = np.triu(np.ones(mu.shape, dtype=bool))
    rising = np.cumsum(mu[::-1], axis=0)[::-1][upper]  # rows j..l of column l
    falling = np.cumsum(mu, axis=1)[upper]  # columns k..L of row k
    return np.concatenate([rising, falling])


@dataclass(frozen=True, eq=False)
class PreisachHysteresis(PackedCore):
    r"""The Preisach model, by its Everett function on a grid of reversal points.

    Rising from a minimum :math:`a`: :math:`q(v) = q(a) + E(a, v)`; falling
    from a maximum :math:`b`: :math:`q(v) = q(b) - E(v, b)`. The reversal
    points form a stack with the wiping-out rule (passing the previous
    extremum of the same direction closes the inner loop and resumes the
    outer branch), so every minor loop closes and returns to its starting
    point (return-point memory), and minor loops have the shape their place
    in the major loop gives them — not PI's congruent copies. :math:`E` is
    bilinear between the nodes, built from a Preisach density
    :math:`\mu` on the grid's cells,
    :math:`E(a_i, b_j) = \sum_{i \le k \le l < j} \mu_{kl}`. A branch's
    slope is a sum of the density from the diagonal along a row (falling) or a
    column (rising), so every branch is increasing when all those sums are
    positive (:func:`branch_sums`); the density itself may be negative off the
    diagonal, as a PI model's weights may (a loop that flattens after each
    reversal). Beyond the grid it continues with the smallest slope.

    Parameters
    ----------
    nodes : array_like, shape (n,)
        Equally spaced voltages (V), at least 2.
    density : array_like, shape (n - 1, n - 1)
        :math:`\mu_{kl}` (output units) for cells ``k <= l``, its
        :func:`branch_sums` ``> 0``; the lower half is ignored.
    initial_state : array_like
        ``[v, q, direction, k, R[0..STACK-1]]`` (see ``_kernels.packed``).
    region : Region, optional
    virgin : bool, default False
        What "at rest" means (:meth:`rest_state`): True, a demagnetised state,
        from which the first move follows the initial loading curve (as play
        operators from zero state); False, no reversal yet, the first move
        follows a branch from the rest point (as from an extremum).
    """

    nodes: FloatArray
    density: FloatArray
    initial_state: FloatArray
    region: Region | None = None
    virgin: bool = False
    packed: FloatArray = field(init=False, repr=False)
    kind: ClassVar[str] = "preisach"
    inner: ClassVar[str] = "output"

    def __post_init__(self) -> None:
        nodes = _nodes(self.nodes, "nodes")
        n = nodes.size
        mu = np.triu(np.array(self.density, dtype=np.float64))
        if mu.shape != (n - 1, n - 1):
            msg = f"'density' must have shape {(n - 1, n - 1)} (cells). Got {mu.shape}."
            raise ShapeError(msg)
        if not np.all(np.isfinite(mu)) or not branch_sums(mu).min() > 0:
            msg = (
                "the Preisach density must be finite, and its sums from the diagonal along every "
                "row and column > 0 (every branch increasing)"
            )
            raise ParameterError(msg)
        mu.flags.writeable = False
        z0 = _frozen(self.initial_state, "initial_state")
        if z0.size != P.RV_SIZE:
            msg = f"'initial_state' of a Preisach core holds {P.RV_SIZE} values. Got {z0.size}."
            raise ShapeError(msg)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "density", mu)
        object.__setattr__(self, "initial_state", z0)
        h = (nodes[-1] - nodes[0]) / (n - 1)
        s_min = float(branch_sums(mu).min()) / h  # a true lower bound: the solve's bracket
        s_out = float(np.diag(mu).min()) / h  # the smallest reversible slope (kept in the layout)
        head = [P.KIND_PREISACH, n, n, nodes[0], h, s_out, 0.0, 0.0, s_min]
        packed = np.concatenate([head, P.everett_nodes(mu).ravel()])
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

    @property
    def summary(self) -> str:
        """See :attr:`DifferentialCore.summary`."""
        n = self.nodes.size
        if self.region is None:
            return f"Preisach, {n} nodes"
        tol = 1e-9 * float(self.nodes[1] - self.nodes[0])
        lo, hi = self.region.v_lo - tol, self.region.v_hi + tol
        inside = int(np.count_nonzero((self.nodes >= lo) & (self.nodes <= hi)))
        if not self.virgin:
            return f"Preisach, {inside} nodes"
        beyond = f" (+{n - inside} nodes beyond the range)" if n > inside else ""
        return f"Preisach, {inside} nodes, initial loading curve from rest{beyond}"

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`~piezohyst.model.cores.base.Core.rest_state`."""
        q = self.region.middle(x0) if self.region is not None else float(self.initial_state[1])
        z = np.zeros(P.RV_SIZE)
        x0 = float(x0)
        z[0], z[1], z[P.RV_K], z[P.RV_R] = x0, q, 1.0, x0
        amp = min(x0 - float(self.nodes[0]), float(self.nodes[-1]) - x0)
        if self.virgin and amp > 0:
            points = x0 - amp * (-DEMAG_RATIO) ** np.arange(DEMAG_POINTS)
            z[P.RV_R : P.RV_R + DEMAG_POINTS] = points
            z[P.RV_K] = DEMAG_POINTS
            z[P.RV_DIR] = -1.0 if points[-1] > x0 else 1.0
        return z

    def everett(self, a: ArrayLike, b: ArrayLike) -> FloatArray:
        """The Everett function :math:`E(a, b)` (output units).

        Parameters
        ----------
        a, b : array_like
            Lower and upper reversal points (V).

        Returns
        -------
        ndarray
        """
        aa, bb = np.broadcast_arrays(
            np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        )
        out = np.array(
            [P.everett(self.packed, x, y)[0] for x, y in zip(aa.ravel(), bb.ravel(), strict=True)]
        )
        return out.reshape(aa.shape)

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """See :meth:`DifferentialCore.describe`."""
        mu = self.density
        return [
            ("core", "Preisach, Everett function on a grid, wiping-out memory"),
            ("grid", f"{self.nodes.size} nodes over [{self.nodes[0]:.6g}, "
                     f"{self.nodes[-1]:.6g}] {input_unit}"),
            ("density", f"{mu.sum():.4g} {output_unit} in all, "
                        f"{np.trace(mu) / mu.sum():.1%} on the diagonal (reversible)"),
            ("smallest slope", f"{self.packed[P.DU_F_MIN]:.4g} {output_unit}/{input_unit}"),
        ]  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """See :meth:`DifferentialCore.to_dict`."""
        return {
            "nodes": self.nodes.tolist(),
            "density": self.density.tolist(),
            "initial_state": self.initial_state.tolist(),
            "region": self.region_json(),
            "rest": "virgin" if self.virgin else "branch",
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PreisachHysteresis:
        """Inverse of :meth:`to_dict` (see :meth:`~piezohyst.model.cores.base.Core.from_dict`)."""
        rest = data.get("rest", "branch")  # files before the virgin rest state: a branch
        if rest not in ("virgin", "branch"):
            msg = f"the Preisach core's 'rest' must be 'virgin' or 'branch'. Got {rest!r}."
            raise ParameterError(msg)
        return cls(
            data["nodes"],
            data["density"],
            data["initial_state"],
            cls.region_from(data.get("region")),
            virgin=rest == "virgin",
        )

    @classmethod
    def identify(cls, job: FitJob) -> CoreFit:
        """See :meth:`~piezohyst.model.cores.base.Core.identify`."""
        return fit_in_memory(cls, job, _solve)


def _solve(job: Solving) -> tuple[PreisachHysteresis, list[FloatArray]]:
    x, y, t, terms, params, initial_state, _ = job
    rest = _rest_point(x, initial_state)
    choice = str(params["rest"])
    kinds = ["branch"] if rest is None else (
        ["virgin", "branch"] if choice == "auto" else [choice])  # fmt: skip
    rows = _picked_rows(x.size, FIT_ROWS)
    g_mat = _growth_matrix(terms, x, t, rows)
    fits = [_signed_or_not(job, rows, g_mat, k == "virgin") for k in kinds]
    # a branch must earn its place (the record starts at rest), unless the two fit alike at a
    # level no record's noise reaches (exact data: then rounding must not decide)
    if len(fits) == 2 and fits[1][2] < BRANCH_GAIN * max(fits[0][2], 1e-9 * float(np.ptp(y))):
        fits = fits[1:]
    core, coefs, _ = fits[0]
    return core, coefs


def _signed_or_not(
    job: Solving, rows: np.ndarray, g_mat: FloatArray, virgin: bool
) -> tuple[PreisachHysteresis, list[FloatArray], float]:
    """The density >= 0, or signed (``signed=True``); with ``"auto"`` the signed one where
    its RMSE is below :data:`SIGNED_GAIN` of the density >= 0 (it holds that one, so it fits
    at least as well: it must earn its extra freedom, as the initial loading curve must).
    The signed solve, with many cells on their bound, is the costly one: it runs only where
    the PI part alone (a small solve) already fits better than the density >= 0, the sign
    that the loops flatten after reversals."""
    choice = job.params.get("signed", "auto")
    solve = _density_solver(job, rows, g_mat, virgin, choice is not False)
    if choice != "auto":
        return solve("signed" if choice else "plain")
    plain = solve("plain")
    if solve("pi")[2] >= plain[2]:
        return plain
    signed = solve("signed")
    return signed if signed[2] < SIGNED_GAIN * plain[2] else plain


def _density_solver(
    job: Solving, rows: np.ndarray, g_mat: FloatArray, virgin: bool, with_pi: bool
) -> Callable[[str], tuple[PreisachHysteresis, list[FloatArray], float]]:
    """One pass over the record, then bounded least squares on demand: ``"plain"`` (a density
    >= 0), ``"pi"`` (the PI part alone, ``with_pi``) or ``"signed"`` (both): (core, term
    coefficients, RMSE on the picked rows); ``virgin``: from rest the first move follows
    the initial loading curve."""
    x, y, t, terms, params, initial_state, _ = job
    n_in = int(params["nodes"])
    lo, hi = float(x.min()), float(x.max())
    span = hi - lo
    s_min = float(params["min_slope"]) * max(float(np.ptp(y)), 1e-300) / span
    seen = S.unturned_bounds(x, 0.25 * span / (n_in - 1))  # a quarter cell: not a noise turn
    grid = _preisach_grid(lo, hi, n_in, _rest_point(x, initial_state) if virgin else None, seen)
    nodes, tie, n_par = grid.nodes, grid.tie, grid.params
    n, m, h = nodes.size, nodes.size - 1, grid.step
    upper = np.flatnonzero(np.triu(np.ones((m, m))).ravel())  # cells k <= l
    if x.size < n_par + 2:
        msg = f"{x.size} samples cannot identify {n_par} Preisach cells"
        raise InsufficientDataError(msg)
    ng = g_mat.shape[1]
    lower_g = np.concatenate([term.lower_bounds() for term in terms]) if terms else np.zeros(0)
    packed = np.concatenate([[P.KIND_PREISACH, n, n, nodes[0], h, 0.0, 0.0, 0.0, s_min],
                             np.zeros(n * n)])  # fmt: skip
    probe = PreisachHysteresis(nodes, np.eye(m), np.zeros(P.RV_SIZE), virgin=virgin)
    start = _start_inner(probe, x, initial_state)  # the reversal stack before the record
    z0 = probe.rest_state(float(x[0])) if start is None else start
    # Everett nodes from the parameters: a density >= 0 on the cells (tied where the data only
    # see a width), plus a PI part, one signed density per width l - k whose partial sums over
    # the widths (its own parameters) stay >= the smallest slope, so every branch increases
    cells = _tie_matrix(tie, n_par)
    m_pi = m if with_pi else 0  # the PI part's columns, when asked for
    to_cells = np.hstack([cells, (_width_matrix(m, upper) @ _from_partial_sums(m))[:, :m_pi]])
    n_all = n_par + m_pi
    to_nodes = np.ascontiguousarray(P.everett_map(n)[:, upper] @ to_cells)
    extra = np.hstack([g_mat, np.ones((rows.size, 1))])
    width = n_all + ng + 1
    gram = np.zeros((width, width))
    rhs = np.zeros(width)
    yy = 0.0
    st, acc, tmp = z0.copy(), np.zeros(n_all), np.zeros(n * n)
    for s0 in range(0, rows.size, DESIGN_ROWS):  # the walk in pieces: memory stays flat
        picked = rows[s0 : s0 + DESIGN_ROWS]
        stop = int(picked[-1]) + 1
        begin = 0 if s0 == 0 else int(rows[s0 - 1]) + 1
        design = np.empty((picked.size, n_all))
        P.rev_design(
            packed, x[begin:stop], st, picked - begin, acc, begin == 0, to_nodes, tmp, design
        )
        a = np.hstack([design, extra[s0 : s0 + picked.size]])
        gram += a.T @ a
        rhs += a.T @ y[picked]
        yy += float(y[picked] @ y[picked])
    data_gram = gram.copy()
    inside = np.diag(gram)[: grid.inside]  # the smoothing's scale: the range's own cells
    weight = float(params["smoothing"]) * max(float(np.mean(inside)), 1e-300)
    gram[:n_par, :n_par] += weight * _curvature_tied(m, upper, tie, n_par, grid.inside)
    # the PI part's density over the widths is smoothed alike (second differences)
    if m_pi:
        d2 = np.diff(np.eye(m), 2, axis=0) @ _from_partial_sums(m)
        pi = slice(n_par, n_all)
        pi_weight = float(params["smoothing"]) * max(float(np.mean(np.diag(gram)[pi])), 1e-300)
        gram[pi, pi] += pi_weight * (d2.T @ d2)
    col = n_all
    for term in terms:  # a relaxing density is smoothed like the core's
        if isinstance(term, Relaxation):
            blk = slice(col, col + term.width)
            w = float(params["smoothing"]) * max(float(np.mean(np.diag(gram)[blk])), 1e-300)
            gram[blk, blk] += w * _curvature_upper(term.nodes - 1)
        col += term.width

    def solve(variant: str) -> tuple[PreisachHysteresis, list[FloatArray], float]:
        density = np.r_[0:n_par] if variant != "pi" else np.zeros(0, dtype=np.int64)
        pi = np.r_[n_par:n_all] if variant != "plain" else np.zeros(0, dtype=np.int64)
        keep = np.concatenate([density, pi, np.r_[n_all:width]])
        floor = np.where(grid.diagonal, s_min * h, 0.0) if variant == "plain" else 0.0
        lower = np.concatenate([np.broadcast_to(floor, density.shape),
                                np.full(pi.size, s_min * h), lower_g, [-np.inf]])  # fmt: skip
        q = _bounded_lstsq(gram[np.ix_(keep, keep)], rhs[keep], lower)
        bounded = density.size + pi.size  # the density's parameters: exactly on their bounds
        q[:bounded] = np.maximum(q[:bounded], lower[:bounded])
        sol = np.zeros(width)
        sol[keep] = q
        sse = max(yy - 2.0 * float(sol @ rhs) + float(sol @ data_gram @ sol), 0.0)
        mu = np.zeros(m * m)
        mu[upper] = to_cells @ sol[:n_all]
        g = sol[n_all : n_all + ng]
        z = np.array(z0)
        z[1] = float(sol[-1])
        coefs = _split(g, terms)
        qh = y - _terms_output(terms, coefs, x, t) if ng else y
        core = PreisachHysteresis(nodes, mu.reshape(m, m), z, Region.of(x, qh), virgin=virgin)
        return core, coefs, math.sqrt(sse / rows.size)

    return solve


def _rest_point(x: FloatArray, initial_state: Any) -> float | None:
    """Where a fit's record (or its history) starts from rest; None for other starts."""
    history = getattr(initial_state, "input", None)
    if history is not None:  # a History
        return float(as_signal(history, "history")[0])
    if initial_state is None or (isinstance(initial_state, str) and initial_state == "rest"):
        return float(x[0])
    return None


#: A Preisach fit from rest keeps the initial loading curve (a demagnetised rest state) unless
#: the fit whose first move follows a branch has an RMSE below this fraction of its own. On a
#: record that never falls back to its rest voltage the two fit alike (the first rise is the
#: only rise from there), and they predict full-range cycles very differently: fitted on 40 s
#: of decaying loops and tested on full cycles from rest, units 4-6 of the simulated plants'
#: batches, the initial loading curve left 1.0-2.1 % (Preisach capacitor), 1.5 % (Duhem),
#: 1.6-2.5 % (two-state), 5.9-6.5 % (Bouc-Wen), a branch 6.1-6.9, 3.3, 4.7-5.9 and 11.2-11.6 %.
#: Chosen there (the branch had been the default on a tie), checked on units 1-3
#: (``docs/validation.md``)
BRANCH_GAIN = 0.9

#: A Preisach fit keeps a signed density (``signed="auto"``) only where its RMSE is below this
#: fraction of the non-negative one's: where a density >= 0 cannot draw the loops (a branch
#: that flattens after each reversal: the non-negative fit's RMSE 3-5x the signed one's on
#: Bouc-Wen capacitors), not where it fits a little worse (0.86-0.98 on Preisach, Duhem and
#: two-state capacitors, where the extra freedom compensated the bench's own loops worse:
#: 0.96 % width against 0.68 %). Set after seeing those ratios.
SIGNED_GAIN = 0.5


#: Rows of the Preisach design formed at a time (memory: this many x its parameters)
DESIGN_ROWS = 8192


#: Nodes of a Preisach grid at most, with the reach a fit from rest adds (its spacing grows
#: beyond it)
MAX_GRID = 47


@dataclass(frozen=True)
class _PreisachGrid:
    """A Preisach fit's grid: nodes, and which parameter each upper cell takes.

    Cells inside the training range each have their own density. Cells the
    record reaches only through the initial loading curve from rest (beyond
    the range, up to the rest point's mirror image), and cells wholly below
    the lowest voltage the record fell to after its first fall (above the
    highest it rose to after its first rise), which it switched only on its
    way to a new extreme, a column of them at once, are seen through one
    function of the loop width alone, as in a play-operator model: they share
    one parameter per width ``l - k``. Without the second rule the curvature
    penalty continued the density there from the cells above, and a fit on
    decaying loops that never fell below 14 V predicted full-range cycles on
    plants of other physics to 3.3-7.0 % (1.5-2.5 % with it).
    """

    nodes: FloatArray
    step: float
    tie: np.ndarray  # parameter index of each upper cell (row-major k <= l)
    params: int
    inside: int  # parameters of the range's own cells (the first ones)
    diagonal: np.ndarray  # per parameter: a diagonal cell (bounded below by the slope)


def _preisach_grid(
    lo: float,
    hi: float,
    n_in: int,
    rest: float | None,
    seen: tuple[float, float] = (math.nan, math.nan),
) -> _PreisachGrid:
    h = (hi - lo) / (n_in - 1)
    first, last = lo, hi
    if rest is not None:  # the first rise and fall from rest reach the rest point's mirror
        first, last = min(lo, 2 * rest - hi), max(hi, 2 * rest - lo)
    below = math.ceil((lo - first) / h - 1e-9)
    above = math.ceil((last - hi) / h - 1e-9)
    n = n_in + below + above
    if n > max(MAX_GRID, n_in):  # coarser, to keep the solve small
        n = max(MAX_GRID, n_in)
        h = (last - first) / (n - 1)
        below = round((lo - first) / h)
    nodes = (lo - below * h) + h * np.arange(n)
    k_lo, k_hi = below, round((hi - nodes[0]) / h)  # the training range's first and last node
    # cells wholly below the lowest turn (above the highest) the record switched only on its
    # way to a new extreme, a column (row) of them at once: seen through their widths alone
    if math.isfinite(seen[0]):
        k_lo = max(k_lo, math.floor((seen[0] - nodes[0]) / h + 1e-9))
    if math.isfinite(seen[1]):
        k_hi = min(k_hi, math.ceil((seen[1] - nodes[0]) / h - 1e-9))
    m = n - 1
    ks, ls = np.triu_indices(m)
    inside = (ks >= k_lo) & (ls < k_hi)
    tie = np.empty(ks.size, dtype=np.int64)
    n_inside = int(inside.sum())
    tie[inside] = np.arange(n_inside)
    widths = ls - ks
    tie[~inside] = n_inside + widths[~inside]  # with the cells beyond: one rule for both
    tied = m if n_inside < ks.size else 0
    diagonal = np.concatenate([(ks == ls)[inside], np.arange(tied) == 0])
    return _PreisachGrid(
        np.asarray(nodes, dtype=np.float64), h, tie, n_inside + tied, n_inside, diagonal
    )


def _width_matrix(m: int, upper: np.ndarray) -> FloatArray:
    """(upper cells, m): 1 where a cell's width ``l - k`` is the column's."""
    ks, ls = np.divmod(upper, m)
    out = np.zeros((upper.size, m))
    out[np.arange(upper.size), ls - ks] = 1.0
    return out


def _from_partial_sums(m: int) -> FloatArray:
    """(m, m): the densities per width from their partial sums (first differences)."""
    return np.eye(m) - np.eye(m, k=-1)


def _tie_matrix(tie: np.ndarray, n_par: int) -> FloatArray:
    out = np.zeros((tie.size, n_par))
    out[np.arange(tie.size), tie] = 1.0
    return out


def _curvature_tied(
    m: int, upper: np.ndarray, tie: np.ndarray, n_par: int, split: int | None = None
) -> FloatArray:
    """The curvature penalty of an (m, m) grid's upper triangle (k <= l): second
    differences whose three cells all lie there, on the parameters ``tie`` maps the
    cells (row-major ``upper``) to; with ``split``, only those whose three parameters lie
    on one side of it (the range's own cells, or the tied ones beyond it: the initial
    loading curve need not continue the loops' density)."""
    index = np.full(m * m, -1)
    index[upper] = tie
    grid = index.reshape(m, m)
    out = np.zeros((n_par, n_par))
    coef = np.array([1.0, -2.0, 1.0])
    for first, second, third in (
        (grid[:-2, :], grid[1:-1, :], grid[2:, :]),
        (grid[:, :-2], grid[:, 1:-1], grid[:, 2:]),
    ):
        ok = (first >= 0) & (second >= 0) & (third >= 0)
        if split is not None:
            side = first < split
            ok &= (side == (second < split)) & (side == (third < split))
        trip = np.stack([first[ok], second[ok], third[ok]], axis=1)
        for a in range(3):
            for b in range(3):
                np.add.at(out, (trip[:, a], trip[:, b]), coef[a] * coef[b])
    return out


def _curvature_upper(m: int) -> FloatArray:
    """The curvature penalty of an (m, m) grid restricted to its upper triangle (k <= l)."""
    cells = m * (m + 1) // 2
    return _curvature_tied(m, np.flatnonzero(np.triu(np.ones((m, m))).ravel()),
                           np.arange(cells), cells)  # fmt: skip
