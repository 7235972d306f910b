r"""Models on a differential core: :class:`DuhemModel` and :class:`BoucWenModel`.

Both are :class:`~piezohyst.models.HysteresisModel`\ s — the same ``fit``,
``predict``/``propagate`` with a named state, ``growth``/``remove_growth``,
``inversion()`` for the :class:`~piezohyst.Compensator`, files, input and output
dynamics — whose hysteresis is a :mod:`~piezohyst.differential` core instead
of play operators, plus growth terms (leakage ``integral``, bias ``time``,
voltage-dependent leakage ``abs_integral``) identified jointly:

* :class:`DuhemModel`: one bounded least squares on the record's increments
  (slopes on a grid, the growth terms' increments beside them), repeated with
  the growth removed, then refined on the output error (Gauss-Newton with the
  exact sensitivities of the simulated output, bounds kept).
* :class:`BoucWenModel`: an outer search over the three shape parameters
  (saturation of h, :math:`\gamma/\beta`, n) around a linear bounded solve of
  :math:`c_0`, :math:`\alpha`, the offset and the growth coefficients, scored
  on the simulated output (output error).

Their fits need the record in memory (``fit_blocks`` reads it in).
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._lazy import LazyModule
from ._validation import FloatArray, as_signal, as_time, check_float
from .cores import PlayCore
from .differential import (
    BoucWenHysteresis,
    DifferentialCore,
    DuhemHysteresis,
    PreisachHysteresis,
    Region,
    everett_map,
)
from .errors import ExtrapolationWarning, InsufficientDataError, NotInvertibleError, ParameterError
from .identification import (
    BLOCK,
    Blocks,
    Summary,
    _bounded_lstsq,
    array_blocks,
    block_dt,
    default_thresholds,
    identify,
    periodic_state,
    term_columns,
)
from .models import (
    GROWTH_TERMS,
    ClassicalPI,
    History,
    HysteresisModel,
    InitialState,
    Rule,
    _bool,
    _creep,
    _dynamics_kind,
    _growth_terms,
    _output_kind,
    _unit,
)
from .terms import Relaxation, Term, make_term

if TYPE_CHECKING:
    from . import _diffkernels as D
else:  # numba loads when a model first runs (see _lazy)
    D = LazyModule("piezohyst._diffkernels", globals(), "D")

__all__ = ["BoucWenModel", "DifferentialModel", "DuhemModel", "PreisachModel"]

REFINE_ROWS = 8000  # output-error refinement: residual rows (hashed picks)
REFINE_EVALS = 25  # and evaluations
PROXY_OPERATORS = 16  # play operators of the proxy that settles the growth terms
FIT_ROWS = 40_000  # linear solves and residuals use at most this many samples (hashed picks)
SEARCH_ROWS = 5_000  # Bouc-Wen's shape search runs on a copy decimated to about this many


def _grid(value: object, name: str, owner: str) -> tuple[int, int]:
    ok = (
        isinstance(value, Sequence)
        and not isinstance(value, str)
        and len(value) == 2
        and all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in value)
        and all(2 <= int(v) <= 40 for v in value)
    )
    if not ok:
        msg = (
            f"The '{name}' parameter of {owner} must be two ints in [2, 40] (voltage nodes, "
            f"output nodes). Got {value!r} instead."
        )
        raise ParameterError(msg)
    assert isinstance(value, Sequence)
    return int(value[0]), int(value[1])


def _nodes_rule(value: object, name: str, owner: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not 3 <= value <= 60:
        msg = f"The '{name}' parameter of {owner} must be an int in [3, 60]. Got {value!r} instead."
        raise ParameterError(msg)
    return int(value)


def _rest_rule(value: object, name: str, owner: str) -> str:
    if value not in ("auto", "virgin", "branch"):
        msg = (
            f"The '{name}' parameter of {owner} must be 'auto', 'virgin' or 'branch'. "
            f"Got {value!r} instead."
        )
        raise ParameterError(msg)
    return str(value)


def _nonneg(value: object, name: str, owner: str) -> float:
    return check_float(value, name, owner, 0.0, 1e6)


def _relaxation(value: object, name: str, owner: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, int | float) and not isinstance(value, bool):
        tau = float(value)
        if math.isfinite(tau) and tau > 0:
            return tau
    msg = (
        f"The '{name}' parameter of {owner} must be None or a time constant in s > 0. "
        f"Got {value!r} instead."
    )
    raise ParameterError(msg)


def _relaxation_nodes(value: object, name: str, owner: str) -> int:
    if isinstance(value, int) and not isinstance(value, bool) and 3 <= value <= 40:
        return value
    msg = f"The '{name}' parameter of {owner} must be an int in [3, 40]. Got {value!r} instead."
    raise ParameterError(msg)


def _fraction(value: object, name: str, owner: str) -> float:
    return check_float(value, name, owner, 0.0, 1.0, low_open=True)


def _picked_rows(n: int, limit: int) -> np.ndarray:
    """All rows, or about ``limit`` of them spread by a hash of the index (no aliasing)."""
    if n <= limit:
        return np.arange(n)
    g = np.arange(n, dtype=np.uint64)
    h = (g * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    return np.flatnonzero(h < np.uint64(((1 << 24) * limit) // n))


def _term_blocks(
    terms: Sequence[Term], x: FloatArray, t: FloatArray | None
) -> Iterator[tuple[int, int, FloatArray]]:
    """Every term's columns over the record, from rest at its start, block by block:
    ``(start, stop, columns)`` (the columns array is reused from one block to the next)."""
    width = sum(term.width for term in terms)
    states = [term.rest_state(float(x[0])) for term in terms]
    block = np.empty((min(BLOCK, x.size), width))
    for start in range(0, x.size, BLOCK):
        stop = min(start + BLOCK, x.size)
        dt = block_dt(t, start, stop, None) if t is not None else None
        ts = None if t is None else t[start:stop]
        term_columns(terms, x[start:stop], ts, dt, states, block[: stop - start])
        yield start, stop, block[: stop - start]


def _growth_matrix(
    terms: Sequence[Term], x: FloatArray, t: FloatArray | None, rows: np.ndarray | None = None
) -> FloatArray:
    """Every term's columns over the record (or at ``rows``, increasing), from rest at its
    start; by blocks, so a wide term never holds a column per sample of a long record."""
    picked = np.arange(x.size) if rows is None else rows
    out = np.zeros((picked.size, sum(term.width for term in terms)))
    if out.shape[1]:
        for start, stop, cols in _term_blocks(terms, x, t):
            lo, hi = np.searchsorted(picked, [start, stop])
            out[lo:hi] = cols[picked[lo:hi] - start]
    return out


def _terms_output(
    terms: Sequence[Term], coefs: Sequence[FloatArray], x: FloatArray, t: FloatArray | None
) -> FloatArray:
    """The terms' part of the output over the record, from rest at its start."""
    out = np.zeros(x.size)
    if terms:
        coef = np.concatenate(list(coefs))
        for start, stop, cols in _term_blocks(terms, x, t):
            out[start:stop] = cols @ coef
    return out


def _split(coefficients: FloatArray, terms: Sequence[Term]) -> list[FloatArray]:
    """One coefficient array per term, from the solution's growth columns."""
    out, col = [], 0
    for term in terms:
        out.append(np.asarray(coefficients[col : col + term.width], dtype=np.float64))
        col += term.width
    return out


def _collect(blocks: Blocks) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    xs, ys, ts = [], [], []
    timed = True
    for x, y, t in blocks():
        xs.append(np.asarray(x, dtype=np.float64))
        ys.append(np.asarray(y, dtype=np.float64))
        if t is None:
            timed = False
        else:
            ts.append(np.asarray(t, dtype=np.float64))
    x_all = np.concatenate(xs) if xs else np.zeros(0)
    y_all = np.concatenate(ys) if ys else np.zeros(0)
    return x_all, y_all, (np.concatenate(ts) if timed and ts else None)


class DifferentialModel(HysteresisModel):
    """Base of the models on a differential core (see the module documentation).

    Subclasses implement :meth:`_identify`: the core and the growth
    coefficients from the record in memory.
    """

    _rules: ClassVar[dict[str, Rule]] = {
        "growth_terms": _growth_terms,
        "creep": _creep,
        "min_slope": _fraction,
        "region_tolerance": _nonneg,
        "input_unit": _unit,
        "output_unit": _unit,
        "input_dynamics": _dynamics_kind,
        "output_dynamics": _output_kind,
    }
    region_: Region | None
    region_tolerance: float

    def __init__(
        self,
        *,
        growth_terms: str | Sequence[str] = ("integral",),
        creep: Sequence[float] = (),
        min_slope: float = 0.02,
        region_tolerance: float = 0.05,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        # the settings every model on a differential core has; subclasses add theirs
        self.growth_terms = growth_terms
        self.creep = creep
        self.min_slope = min_slope
        self.region_tolerance = region_tolerance
        self.input_unit = input_unit
        self.output_unit = output_unit
        self.input_dynamics = input_dynamics
        self.output_dynamics = output_dynamics

    #: the growth terms come from the PI proxy (True) or are fitted with the core (False)
    growth_from_proxy: ClassVar[bool] = True

    # --------------------------------------------------------------- fitting
    def _terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        names = params["growth_terms"]
        if names is None:  # "auto": the input dynamics' proxy fits them all
            names = GROWTH_TERMS
        return [make_term(name).bind(x_range) for name in names], None

    def _kept_terms(self, params: dict[str, Any], x_range: FloatArray) -> list[Term]:
        """The kept terms beside the core (they shape the hysteresis): creep lags."""
        return [] if params["creep"] is None else [params["creep"]]

    def _fit(self, blocks: Blocks, initial_state: InitialState, timed: bool) -> Summary:
        params = self.check_params()
        x, y, t = _collect(blocks)
        sm = Summary.of(array_blocks(x, y, t))
        if not sm.x_max - sm.x_min > 1e-12 * max(abs(sm.x_min), abs(sm.x_max), 1e-300):
            msg = (
                f"the input never moves (constant at {sm.x_first:g} {self.input_unit}): "
                "a record without excitation holds no hysteresis to identify"
            )
            raise InsufficientDataError(msg)
        select = params["growth_terms"] is None
        names = GROWTH_TERMS if select else params["growth_terms"]
        # kept terms first (creep: they shape the hysteresis), then the growth terms
        fixed = self._kept_terms(params, sm.x_range)
        growth = [make_term(name).bind(sm.x_range) for name in names]
        if not timed or t is None:
            if any(term.rate_dependent for term in growth) and select:
                growth = []  # no times: no growth term to choose
            elif any(term.rate_dependent for term in fixed + growth):
                as_time(None, sm.n, required=True, owner=type(self).__name__)  # raises
        terms = fixed + growth
        proxy: list[FloatArray] | None = None
        if terms and (select or self.growth_from_proxy):
            terms, proxy = self._proxy(x, y, t, terms, select, initial_state, len(fixed))
        core, coefs = self._identify(
            x, y, t if terms else None, terms, params, initial_state, proxy
        )
        self.set_fitted(core, tuple(terms), tuple(coefs))
        self.input_range_ = (sm.x_min, sm.x_max)
        self.max_slew_rate_ = sm.max_slew_rate
        with warnings.catch_warnings():  # its own record: no extrapolation warning
            warnings.simplefilter("ignore", ExtrapolationWarning)
            self._score(array_blocks(x, y, t), sm)
        return sm

    def _identify(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        terms: list[Term],
        params: dict[str, Any],
        initial_state: InitialState,
        growth: list[FloatArray] | None,
    ) -> tuple[DifferentialCore, list[FloatArray]]:
        """The core and each term's coefficients (``growth``: fixed by the proxy)."""
        raise NotImplementedError

    def _proxy(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        terms: list[Term],
        select: bool,
        initial_state: InitialState,
        n_fixed: int = 0,
    ) -> tuple[list[Term], list[FloatArray]]:
        """Growth terms identified jointly with Prandtl-Ishlinskii operators (a proxy core).

        PI loops close by construction: every drift of the charge is the
        growth terms'. A Duhem core's loops need not close, so identified
        jointly with it a leak trades against the slopes; the proxy settles the
        growth (and the creep) first. With ``select`` (``growth_terms="auto"``)
        the proxy's forward-chaining cross-validation chooses the growth terms
        (``selection_``); the first ``n_fixed`` terms (creep) are in every subset.
        """
        sm = Summary.of(array_blocks(x, y, t))
        thr = default_thresholds(sm.x_range, PROXY_OPERATORS)
        z0 = np.full(thr.size, float(x[0]))
        if isinstance(initial_state, str) and initial_state == "periodic":
            z0 = periodic_state(array_blocks(x, x, None), thr, float(x[0]))
        subsets = None
        if select:
            base = tuple(range(n_fixed))
            subsets = [
                base + combo for size in range(len(terms) - n_fixed + 1)
                for combo in itertools.combinations(range(n_fixed, len(terms)), size)
            ]  # fmt: skip
        sol = identify(PlayCore(thr), terms, array_blocks(x, y, t), sm, z0, min_slope=1e-3,
                       subsets=subsets)  # fmt: skip
        if select:
            label = self._subset_label
            self._selection = (
                {label(terms, k): v for k, v in sol.scores.items()},
                {label(terms, k): v for k, v in sol.fold_scores.items()},
                sol.splits,
            )
        kept = [j for j, c in enumerate(sol.coefficients) if c is not None]
        return [terms[j] for j in kept], [np.asarray(sol.coefficients[j]) for j in kept]

    def set_fitted(self, core: Any, terms: tuple[Term, ...], coefs: tuple[FloatArray, ...]) -> None:
        """See :meth:`HysteresisModel.set_fitted`; ``core`` is a differential core.

        Parameters
        ----------
        core : DifferentialCore
        terms : tuple of Term
        coefs : tuple of ndarray
        """
        super().set_fitted(core, terms, coefs)
        chosen = self.__dict__.pop("_selection", None)
        if chosen is not None:
            self.selection_, self.selection_folds_, self.selection_splits_ = chosen

    def _set_core(self, core: Any) -> None:
        self.operator_ = core
        self.initial_state_ = core.initial_state
        self.region_ = core.region

    def _history_operators(self, history: FloatArray) -> FloatArray:
        return np.asarray(self.operator_.history_state(history), dtype=np.float64)

    def _periodic_operators(self, x: FloatArray) -> FloatArray:
        return np.asarray(self.operator_.periodic_state(x), dtype=np.float64)

    def _fast_plan(self) -> tuple[Any, ...] | None:
        self.__dict__["_fast"] = None
        return None

    def _check_region(self, x: FloatArray, core_output: FloatArray) -> None:
        region = self.operator_.region
        if region is None or x.size == 0:
            return
        d = region.distance(x, core_output)
        tol = float(self.region_tolerance) * region.span
        outside = d > tol
        if outside.any():
            k = int(np.argmax(outside))
            warnings.warn(
                f"{int(outside.sum())} of {x.size} samples (first: sample {k}, "
                f"{x[k]:.4g} {self.input_unit}) lie outside the (voltage, output) region the "
                f"{type(self).__name__} was identified on, by up to {float(d.max()):.3g} "
                f"{self.output_unit}: the model extrapolates there",
                ExtrapolationWarning,
                stacklevel=4,
            )

    # ------------------------------------------------------- pure hysteresis
    @property
    def hysteresis_(self) -> HysteresisModel:
        """The model without its growth terms (eq. 19's pure hysteresis), as a fitted model.

        Kept terms (creep) stay: they shape the hysteresis the compensator inverts.
        """
        self._check_fitted()
        model = type(self)(**{**self.get_params(), "growth_terms": ()})
        kept = [(tm, c) for tm, c in zip(self.terms_, self.coefs_, strict=True) if not tm.removed]
        model.set_fitted(self.operator_, tuple(tm for tm, _ in kept), tuple(c for _, c in kept))
        model.input_range_ = self.input_range_
        model.max_slew_rate_ = self.max_slew_rate_
        model.input_dynamics_ = self.input_dynamics_
        model.output_dynamics_ = self.output_dynamics_
        return model

    def inverse(self) -> ClassicalPI:
        """No closed-form inverse model: :class:`~piezohyst.Compensator` inverts it per sample.

        Returns
        -------
        ClassicalPI
            Never: always raises.

        Raises
        ------
        NotInvertibleError
        """
        msg = (
            f"a {type(self).__name__} has no closed-form inverse model; ph.Compensator inverts "
            "it exactly, one sample at a time"
        )
        raise NotInvertibleError(msg)

    @classmethod
    def _bare(cls, n: int, input_unit: str, output_unit: str) -> HysteresisModel:
        model = cls(input_unit=input_unit, output_unit=output_unit)
        return model


def _start_inner(core_rest: Any, x: FloatArray, initial_state: InitialState) -> FloatArray | None:
    """The core state before the record for a named initial state, or None (fit it)."""
    if isinstance(initial_state, History):
        z = core_rest.history_state(as_signal(initial_state.input, "history"))
    elif isinstance(initial_state, str) and initial_state == "periodic":
        z = core_rest.periodic_state(x)
    else:
        return None
    return np.asarray(z, dtype=np.float64)


class DuhemModel(DifferentialModel):
    r"""Rate-independent Duhem hysteresis, identified from data, plus growth terms.

    .. math::

        \frac{dq}{dv} = f_\pm(v, q), \qquad y = q + \sum_j c_j g_j(t)

    ``f+`` while the voltage rises, ``f-`` while it falls: positive bilinear
    surfaces on a ``grid`` over the (voltage, output) region the training
    record covered. The slopes see the output they produce, so the fit is an
    integrated regression on the measured path (linear in the slopes; noise
    enters through the path, not through differences of the output), refined
    on the simulated output with the exact sensitivities of the simulation
    (``refine``). A Duhem model's loops need not close by themselves, so a
    drift of the charge could trade against the slopes: the growth terms come
    from a Prandtl-Ishlinskii proxy first, whose loops close by construction.
    Minor loops are not congruent, but they converge to a steady loop over a
    few cycles rather than closing at once (no return-point memory; see
    :class:`PreisachModel` for a model that has it).

    Its state is the output itself, which the fit estimates at the record's
    first sample: ``initial_state`` (a history, or ``"periodic"``) has
    nothing to add and is ignored. Outside the region the training record
    covered the slopes are held at the grid's edge: predictions warn
    (:class:`~piezohyst.ExtrapolationWarning`) and the compensator stops at
    the region's edge unless allowed to extrapolate.

    Parameters
    ----------
    grid : (int, int), default (8, 6)
        Nodes along the voltage and the output, each in [2, 40].
    growth_terms : "auto" or sequence of {"integral", "time", "abs_integral"}, default ("integral",)
        Growth terms (removed before compensating); ``"auto"`` chooses by the
        proxy's forward-chaining cross-validation (``selection_``).
    creep : sequence of float, default ()
        Time constants (s) of kept creep lags beside the core (as
        :class:`GeneralizedPI`'s), identified with the growth terms by the
        proxy; the compensator inverts them with the core, sample by sample.
    smoothing : float, default 1e-3
        Weight of the curvature penalty on the slope surfaces, relative to the
        data's (fills cells the data barely visit).
    min_slope : float, default 0.02
        Smallest slope, as a fraction of the mean slope: strictly increasing
        branches, so an exact inverse.
    refine : bool, default True
        Refine the integrated regression on the output error.
    region_tolerance : float, default 0.05
        How far outside the recorded band (fraction of the output span)
        counts as extrapolating.
    input_unit, output_unit : str
    input_dynamics, output_dynamics : str
        As for :class:`~piezohyst.models.HysteresisModel`.

    Attributes
    ----------
    operator_ : DuhemHysteresis
        The core (slopes, grid, initial state, region).
    region_ : Region
        Where the training data lay.

    Examples
    --------
    >>> import piezohyst as ph
    >>> rec = ph.simulate(signal="decaying", duration=20.0)
    >>> model = ph.DuhemModel().fit(rec.voltage, rec.charge, t=rec.t)
    >>> bool(model.nrmse_ < 0.005)
    True
    """

    cli_name = "duhem"
    growth_from_proxy = True  # its loops need not close: the growth comes first, from PI
    _rules: ClassVar[dict[str, Rule]] = {
        "grid": _grid,
        "smoothing": _nonneg,
        "refine": _bool,
    }

    def __init__(
        self,
        grid: tuple[int, int] = (8, 6),
        *,
        growth_terms: str | Sequence[str] = ("integral",),
        creep: Sequence[float] = (),
        smoothing: float = 1e-3,
        min_slope: float = 0.02,
        refine: bool = True,
        region_tolerance: float = 0.05,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        super().__init__(
            growth_terms=growth_terms,
            creep=creep,
            min_slope=min_slope,
            region_tolerance=region_tolerance,
            input_unit=input_unit,
            output_unit=output_unit,
            input_dynamics=input_dynamics,
            output_dynamics=output_dynamics,
        )
        self.grid = grid
        self.smoothing = smoothing
        self.refine = refine

    def _identify(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        terms: list[Term],
        params: dict[str, Any],
        initial_state: InitialState,
        growth: list[FloatArray] | None,
    ) -> tuple[DifferentialCore, list[FloatArray]]:
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
        head = [D.KIND_DUHEM, nv, nq, float(x.min()), v_step, lo - pad,
                (hi - lo + 2 * pad) / (nq - 1), 0.25 * v_step, s_min]  # fmt: skip
        packed = np.concatenate([head, np.zeros(2 * cells)])
        penalty = _curvature(nv, nq)
        rows = _picked_rows(n, FIT_ROWS)
        # integrated regression: the output is q0 plus the slopes summed along the measured
        # path; linear in the slopes, noise enters through the path only
        cum = np.empty((rows.size, 2 * cells))
        D.duhem_cumulative(packed, x, qh, rows, cum)
        a = np.hstack([cum, np.ones((rows.size, 1))])
        gram = a.T @ a
        weight = smoothing * max(float(np.mean(np.diag(gram)[:-1])), 1e-300)
        for half in (0, cells):
            sl = slice(half, half + cells)
            gram[sl, sl] += weight * penalty
        sol = _bounded_lstsq(gram, a.T @ qh[rows], np.append(np.full(2 * cells, s_min), -np.inf))
        packed[D.DU_UP :] = np.maximum(sol[:-1], s_min)
        q0 = float(sol[-1])
        # the state is (v, q): the record's own first output says where q starts, better
        # than any history run through a model still being fitted, so q0 is always fitted
        if params["refine"]:
            start = (packed.copy(), q0)
            packed, q0 = _refine_duhem(packed, x, qh, q0, s_min, smoothing, penalty, fit_q0=True)
            if _sse(packed, q0, x, qh) > _sse(*start, x, qh):  # keep the better of the two
                packed, q0 = start
        core = DuhemHysteresis.from_packed(packed, [x[0], q0], Region.of(x, qh))
        return core, list(growth or [])


class PreisachModel(DifferentialModel):
    r"""The Preisach model, identified from data as an Everett function, plus growth terms.

    .. math::

        y = q + \sum_j c_j g_j(t), \qquad
        q(v) = q(a) + E(a, v) \text{ rising from a minimum } a, \qquad
        q(v) = q(b) - E(v, b) \text{ falling from a maximum } b

    with the wiping-out rule on the stack of reversal points
    (:class:`~piezohyst.differential.PreisachHysteresis`). Its minor loops are
    not congruent copies of each other (PI's limit): each has the shape its
    place in the major loop gives it; and they close (return-point memory), so
    a steady periodic drive gives a steady output. The output is linear in
    the Preisach density given the input alone, so one bounded least squares
    (density ``>= 0``, its diagonal ``>=`` the smallest slope), joint with the
    growth terms and a light curvature penalty, *is* its output-error fit.
    Learnt from loops of many sizes (the simulator's ``decaying`` signal):
    cells of the density the record never visits only get the penalty's
    interpolation.

    Parameters
    ----------
    nodes : int, default 16
        Grid nodes over the training voltage range, in [3, 60]; the density
        has ``(nodes - 1) nodes / 2`` cells.
    growth_terms : "auto" or sequence of {"integral", "time", "abs_integral"}, default ("integral",)
        Fitted jointly (its loops close: a drift can only be growth);
        ``"auto"``: the Prandtl-Ishlinskii proxy's cross-validation chooses them.
    creep : sequence of float, default ()
        Time constants (s) of kept creep lags beside the core, e.g.
        ``(0.005, 0.02, 0.05, 0.2, 0.5, 2)``: first-order lags of the voltage
        with gains ``>= 0``, fitted in the same least squares (the output stays
        linear in every coefficient) and inverted with the core by the compensator.
    relaxation : float, optional
        Time constant (s) of a relaxing part of the hysteresis
        (:class:`~piezohyst.terms.Relaxation`): a second Preisach density on
        the voltage through a first-order lag, fitted in the same least squares
        (density ``>= 0``). A real actuator's loop depends on the drive's rate
        partly because some switching follows the field late; ``0.1`` s took
        the SmartHysteresis actuator from 0.132 % to 0.128 % held out
        (``docs/validation.md``). None (default): rate-independent. Use it
        (and ``creep``) where the loop depends on the rate: on the
        rate-independent simulated bench they cost feedforward accuracy
        (decaying loops 0.56 % width, 0.66 % with relaxation), and fitted to
        charge they take up leakage the growth terms miss — give them the leak
        terms the actuator needs (the bench: ``("integral", "abs_integral")``).
    relaxation_nodes : int, default 12
        Grid nodes of the relaxing density, in [3, 40].
    rest : {"auto", "virgin", "branch"}, default "auto"
        What the first move from rest follows (a record that starts at rest,
        and later ``state="rest"`` and the compensator's start):
        ``"virgin"``, the initial loading curve of a demagnetised actuator, as
        play operators from zero state do (the grid then reaches beyond the
        range to the rest point's mirror image, where that curve's cells are
        one function of the loop width); ``"branch"``, a branch from the rest
        point, as from an extremum. ``"auto"`` fits both and takes the
        initial loading curve only where its RMSE is below 0.9 of the other's:
        the paper's experiment (the simulated bench from rest at 0 V) 0.96 % →
        0.07 %; the simulated Preisach capacitor keeps the branch (0.129 %
        either way, and the branch predicts its other records better).
    smoothing : float, default 1e-4
        Weight of the curvature penalty on the density, relative to the data's.
    min_slope : float, default 0.02
        Smallest slope, as a fraction of the mean slope.
    region_tolerance : float, default 0.05
    input_unit, output_unit : str
    input_dynamics, output_dynamics : str

    Attributes
    ----------
    operator_ : PreisachHysteresis
        The density, the grid, the initial state (reversal stack) and the region.

    Examples
    --------
    >>> import piezohyst as ph
    >>> rec = ph.simulate(signal="decaying", duration=20.0)
    >>> model = ph.PreisachModel().fit(rec.voltage, rec.charge, t=rec.t)
    >>> bool(model.nrmse_ < 0.003)
    True
    """

    cli_name = "preisach"
    growth_from_proxy = False
    _rules: ClassVar[dict[str, Rule]] = {
        "nodes": _nodes_rule,
        "relaxation": _relaxation,
        "relaxation_nodes": _relaxation_nodes,
        "rest": _rest_rule,
        "smoothing": _nonneg,
    }

    def __init__(
        self,
        nodes: int = 16,
        *,
        growth_terms: str | Sequence[str] = ("integral",),
        creep: Sequence[float] = (),
        relaxation: float | None = None,
        relaxation_nodes: int = 12,
        rest: str = "auto",
        smoothing: float = 1e-4,
        min_slope: float = 0.02,
        region_tolerance: float = 0.05,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        super().__init__(
            growth_terms=growth_terms,
            creep=creep,
            min_slope=min_slope,
            region_tolerance=region_tolerance,
            input_unit=input_unit,
            output_unit=output_unit,
            input_dynamics=input_dynamics,
            output_dynamics=output_dynamics,
        )
        self.nodes = nodes
        self.relaxation = relaxation
        self.relaxation_nodes = relaxation_nodes
        self.rest = rest
        self.smoothing = smoothing

    def _kept_terms(self, params: dict[str, Any], x_range: FloatArray) -> list[Term]:
        kept = super()._kept_terms(params, x_range)
        if params["relaxation"] is not None:
            kept.append(Relaxation(params["relaxation"], params["relaxation_nodes"]).bind(x_range))
        return kept

    def _identify(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        terms: list[Term],
        params: dict[str, Any],
        initial_state: InitialState,
        growth: list[FloatArray] | None,
    ) -> tuple[DifferentialCore, list[FloatArray]]:
        rest = _rest_point(x, initial_state)
        choice = str(params["rest"])
        kinds = ["branch"] if rest is None else (
            ["virgin", "branch"] if choice == "auto" else [choice])  # fmt: skip
        rows = _picked_rows(x.size, FIT_ROWS)
        g_mat = _growth_matrix(terms, x, t, rows)
        fits = [
            self._solve_density(x, y, t, terms, params, initial_state, rows, g_mat, k == "virgin")
            for k in kinds
        ]
        if len(fits) == 2 and not (  # the initial loading curve must earn its extra cells
            fits[0][2] < VIRGIN_GAIN * fits[1][2] and fits[1][2] > 1e-6 * float(np.ptp(y))
        ):
            fits = fits[1:]
        core, coefs, _ = fits[0]
        return core, coefs

    def _solve_density(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        terms: list[Term],
        params: dict[str, Any],
        initial_state: InitialState,
        rows: np.ndarray,
        g_mat: FloatArray,
        virgin: bool,
    ) -> tuple[PreisachHysteresis, list[FloatArray], float]:
        """One bounded least squares: (core, term coefficients, RMSE on the picked rows);
        ``virgin``: from rest the first move follows the initial loading curve."""
        n_in = int(params["nodes"])
        lo, hi = float(x.min()), float(x.max())
        span = hi - lo
        s_min = float(params["min_slope"]) * max(float(np.ptp(y)), 1e-300) / span
        grid = _preisach_grid(lo, hi, n_in, _rest_point(x, initial_state) if virgin else None)
        nodes, tie, n_par = grid.nodes, grid.tie, grid.params
        n, m, h = nodes.size, nodes.size - 1, grid.step
        upper = np.flatnonzero(np.triu(np.ones((m, m))).ravel())  # cells k <= l
        if x.size < n_par + 2:
            msg = f"{x.size} samples cannot identify {n_par} Preisach cells"
            raise InsufficientDataError(msg)
        ng = g_mat.shape[1]
        lower_g = np.concatenate([term.lower_bounds() for term in terms]) if terms else np.zeros(0)
        packed = np.concatenate([[D.KIND_PREISACH, n, n, nodes[0], h, 0.0, 0.0, 0.0, s_min],
                                 np.zeros(n * n)])  # fmt: skip
        probe = PreisachHysteresis(nodes, np.eye(m), np.zeros(D.RV_SIZE), virgin=virgin)
        start = _start_inner(probe, x, initial_state)  # the reversal stack before the record
        z0 = probe.rest_state(float(x[0])) if start is None else start
        # Everett nodes from the parameters (cells, tied where the data only see a width)
        to_nodes = np.ascontiguousarray(everett_map(n)[:, upper] @ _tie_matrix(tie, n_par))
        extra = np.hstack([g_mat, np.ones((rows.size, 1))])
        width = n_par + ng + 1
        gram = np.zeros((width, width))
        rhs = np.zeros(width)
        yy = 0.0
        st, acc, tmp = z0.copy(), np.zeros(n_par), np.zeros(n * n)
        for s0 in range(0, rows.size, DESIGN_ROWS):  # the walk in pieces: memory stays flat
            picked = rows[s0 : s0 + DESIGN_ROWS]
            stop = int(picked[-1]) + 1
            begin = 0 if s0 == 0 else int(rows[s0 - 1]) + 1
            design = np.empty((picked.size, n_par))
            D.rev_design(
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
        col = n_par
        for term in terms:  # a relaxing density is smoothed like the core's
            if isinstance(term, Relaxation):
                blk = slice(col, col + term.width)
                w = float(params["smoothing"]) * max(float(np.mean(np.diag(gram)[blk])), 1e-300)
                gram[blk, blk] += w * _curvature_upper(term.nodes - 1)
            col += term.width
        lower = np.concatenate([np.where(grid.diagonal, s_min * h, 0.0), lower_g, [-np.inf]])
        sol = _bounded_lstsq(gram, rhs, lower)
        sol[:n_par] = np.maximum(sol[:n_par], lower[:n_par])
        sse = max(yy - 2.0 * float(sol @ rhs) + float(sol @ data_gram @ sol), 0.0)
        mu = np.zeros(m * m)
        mu[upper] = sol[:n_par][tie]
        g = sol[n_par : n_par + ng]
        z0 = np.array(z0)
        z0[1] = float(sol[-1])
        coefs = _split(g, terms)
        qh = y - _terms_output(terms, coefs, x, t) if ng else y
        core = PreisachHysteresis(nodes, mu.reshape(m, m), z0, Region.of(x, qh), virgin=virgin)
        return core, coefs, math.sqrt(sse / rows.size)


def _rest_point(x: FloatArray, initial_state: InitialState) -> float | None:
    """Where a fit's record (or its history) starts from rest; None for other starts."""
    if isinstance(initial_state, History):
        return float(as_signal(initial_state.input, "history")[0])
    if initial_state is None or (isinstance(initial_state, str) and initial_state == "rest"):
        return float(x[0])
    return None


#: A Preisach fit from rest takes the initial loading curve (a demagnetised rest state) only
#: where its RMSE is below this fraction of the fit whose first move follows a branch: on one
#: record both fit the first rise, and the plainer rest state predicts other records better
#: when the curve adds little (the simulated Preisach capacitor: 0.1291 against 0.1293 %)
VIRGIN_GAIN = 0.9
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
    the range, up to the rest point's mirror image) are seen through one
    function of the loop width alone, as in a play-operator model: they share
    one parameter per width ``l - k``.
    """

    nodes: FloatArray
    step: float
    tie: np.ndarray  # parameter index of each upper cell (row-major k <= l)
    params: int
    inside: int  # parameters of the range's own cells (the first ones)
    diagonal: np.ndarray  # per parameter: a diagonal cell (bounded below by the slope)


def _preisach_grid(lo: float, hi: float, n_in: int, rest: float | None) -> _PreisachGrid:
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
    m = n - 1
    ks, ls = np.triu_indices(m)
    inside = (ks >= k_lo) & (ls < k_hi)
    tie = np.empty(ks.size, dtype=np.int64)
    n_inside = int(inside.sum())
    tie[inside] = np.arange(n_inside)
    widths = ls - ks
    tie[~inside] = n_inside + widths[~inside]
    tied = m if n_inside < ks.size else 0  # one per width, when any cell lies beyond
    diagonal = np.concatenate([(ks == ls)[inside], np.arange(tied) == 0])
    return _PreisachGrid(
        np.asarray(nodes, dtype=np.float64), h, tie, n_inside + tied, n_inside, diagonal
    )


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
    D.duhem_jacobian(packed, x, q0, np.zeros(0, dtype=np.int64), sim, np.zeros((0, 1)))
    r = sim - q
    total = float(r @ r)
    return total if np.isfinite(total) else math.inf


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

    cells2 = packed.size - D.DU_UP
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
    theta0 = np.concatenate([packed[D.DU_UP :], [q0] if fit_q0 else []])

    def split(theta: FloatArray) -> tuple[FloatArray, float]:
        p = packed.copy()
        p[D.DU_UP :] = theta[:cells2]
        return p, float(theta[-1]) if fit_q0 else q0

    p0, start = split(theta0)
    D.duhem_jacobian(p0, x, start, rows, qsim, jac_core)
    # the curvature penalty has the weight it had in the linear fit, relative to the data
    col = float(np.mean(np.sum(jac_core[:, :cells2] ** 2, axis=0))) / scale**2
    w_pen = math.sqrt(smoothing * max(col, 1e-300))

    def residual(theta: FloatArray) -> FloatArray:
        p, qq = split(theta)
        D.duhem_jacobian(p, x, qq, no_rows, qsim, no_jac)
        pen = [w_pen * (root @ theta[h : h + cells]) for h in (0, cells)]
        return np.concatenate([(qsim[rows] - q_rows) / scale, *pen])

    def jacobian(theta: FloatArray) -> FloatArray:
        p, qq = split(theta)
        D.duhem_jacobian(p, x, qq, rows, qsim, jac_core)
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
    p[D.DU_UP :] = np.maximum(p[D.DU_UP :], s_min)
    return p, qq


class BoucWenModel(DifferentialModel):
    r"""The Bouc-Wen model of hysteresis, plus growth terms.

    .. math::

        y = c_0 v + \alpha h + c + \sum_j c_j g_j(t), \qquad
        \frac{dh}{dv} = 1 - |h|^n \bigl(\beta\,\mathrm{sign}(h\,\dot v) + \gamma\bigr)

    Identified by output error: an outer search over the shape (where h
    saturates, :math:`\gamma/\beta` and n; a coarse grid, then
    ``scipy.optimize.least_squares`` within bounds) around a bounded linear
    solve of :math:`c_0 > 0`, :math:`\alpha \ge 0`, the offset and the growth
    coefficients. The bounds (:math:`\beta > 0`, :math:`|\gamma| \le \beta`,
    :math:`c_0 > 0`, :math:`\alpha \ge 0`) keep it passive with strictly
    increasing branches, so the compensator's Newton solve always has one
    root. Its minor loops are not congruent but they do not close (no
    return-point memory).

    Parameters
    ----------
    growth_terms : "auto" or sequence of {"integral", "time", "abs_integral"}, default ("integral",)
    creep : sequence of float, default ()
        Time constants (s) of kept creep lags, fitted with c0, alpha and the
        growth in the linear solve; inverted with the core by the compensator.
    min_slope : float, default 1e-3
        Smallest c0, as a fraction of the mean slope.
    region_tolerance : float, default 0.05
    input_unit, output_unit : str
    input_dynamics, output_dynamics : str

    Attributes
    ----------
    operator_ : BoucWenHysteresis
        c0, alpha, beta, gamma, n, offset and the initial state [v, h].

    Examples
    --------
    >>> import piezohyst as ph
    >>> rec = ph.simulate(signal="decaying", duration=20.0)
    >>> model = ph.BoucWenModel().fit(rec.voltage, rec.charge, t=rec.t)
    >>> bool(model.nrmse_ < 0.02), model.operator_.n >= 1.0
    (True, True)
    """

    cli_name = "bouc-wen"
    growth_from_proxy = False  # its loops close: the growth is fitted with it, jointly

    def __init__(
        self,
        growth_terms: str | Sequence[str] = ("integral",),
        *,
        creep: Sequence[float] = (),
        min_slope: float = 1e-3,
        region_tolerance: float = 0.05,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        super().__init__(
            growth_terms=growth_terms,
            creep=creep,
            min_slope=min_slope,
            region_tolerance=region_tolerance,
            input_unit=input_unit,
            output_unit=output_unit,
            input_dynamics=input_dynamics,
            output_dynamics=output_dynamics,
        )

    def _identify(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        terms: list[Term],
        params: dict[str, Any],
        initial_state: InitialState,
        growth: list[FloatArray] | None,
    ) -> tuple[DifferentialCore, list[FloatArray]]:
        from scipy.optimize import least_squares

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
            return np.array([D.KIND_BOUC_WEN, 1.0, 0.0, beta, gamma, expo, 0.0, 0.1 * h_sat,
                             g_max, 1.0])  # fmt: skip

        def solver(xv: FloatArray, yv: FloatArray, gv: FloatArray, rows: np.ndarray) -> Any:
            """The variable-projection solve on a record (all of it, or a decimated copy)."""
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
                D.bw_trace(p, xv, h0, hv)
                hr, xr = hv[rows], xv[rows]
                g_max = float(p[D.BW_G_MAX])
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
        g_max = float(p[D.BW_G_MAX])
        c0 = max(c0, s_min * (1 + 1e-12) - min(alpha, 0.0) * g_max, s_min)
        D.bw_trace(p, x, h0, h)
        offset = float(rest[0])
        pure = c0 * x + alpha * h + offset
        core = BoucWenHysteresis(c0, alpha, beta, gamma, expo, offset, np.array([x[0], h0]), p[7],
                                 Region.of(x, pure))  # fmt: skip
        return core, _split(rest[1:], terms)
