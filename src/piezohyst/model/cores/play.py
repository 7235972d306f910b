r"""The play-operator core: Prandtl-Ishlinskii hysteresis (paper eq. 9-12, 18).

Everything about it in one place: :class:`PIHysteresis`, the immutable fitted
core (propagation, the eq. 18 inverse, its states, its file form);
:class:`PlayCore`, the regressor columns it contributes to the one linear
solve (:mod:`piezohyst.model.cores.solve`); its identification step
(:meth:`PIHysteresis.identify`), and :func:`growth_proxy`, the PI fit other
cores use to settle their growth terms. The per-sample loops are the play
kernels in :mod:`piezohyst._kernels`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from numpy.typing import ArrayLike

from ..._kernels import play as K
from ..._validation import FloatArray, as_signal, check_int, frozen
from ...errors import NotInvertibleError, NumericRangeError, ParameterError, ShapeError
from ...io.blocks import Blocks, Summary, array_blocks, without_time
from ..terms import Integral, Term, TimeTerm
from .base import PERIODIC_PASSES, Core, CoreFit, FitJob, InversePlan, Propagation, _frozen
from .solve import Identification, identify

__all__ = [
    "PIHysteresis",
    "PlayCore",
    "default_thresholds",
    "growth_proxy",
    "history_state",
    "initial_operators",
    "periodic_state",
]


@dataclass(frozen=True, eq=False)
class PIHysteresis(Core):
    r"""Classical Prandtl-Ishlinskii operator (paper eq. 9-12) with an output offset.

    .. math::

        y(t) = c + \sum_{i=0}^{n-1} w_i\, z_i(t), \qquad
        z_i(t) = \max\bigl(x(t) - r_i,\ \min\{x(t) + r_i,\ z_i(t - T)\}\bigr)

    The recursion runs on the unweighted operator state :math:`z_i` (the paper's
    eq. 13-14 write it on :math:`w_i z_i`, a slip).

    Parameters
    ----------
    thresholds : array_like, shape (n,)
        Play thresholds :math:`r_i` in input units (V), strictly increasing and
        starting at 0 (the linear part).
    weights : array_like, shape (n,)
        Weights :math:`w_i` in output units per input unit (e.g. C/V).
    offset : float
        Output offset :math:`c` in output units.
    initial_state : array_like, shape (n,), optional
        Operator states *before* the first sample, in input units. The first
        sample is clamped into ``[x0 - r_i, x0 + r_i]`` (eq. 10). Default: all 0,
        the paper's :math:`y_0 = 0`.

    Examples
    --------
    >>> import numpy as np
    >>> h = PIHysteresis([0.0, 1.0], [1.0, 0.5])
    >>> h.predict([0.0, 2.0, 0.0]).tolist()
    [0.0, 2.5, 0.5]
    >>> bool(np.allclose(h.inverse().predict(h.predict([0.0, 2.0, 0.0])), [0.0, 2.0, 0.0]))
    True
    """

    thresholds: FloatArray
    weights: FloatArray
    offset: float = 0.0
    initial_state: FloatArray = field(default=None)  # type: ignore[arg-type]
    kind: ClassVar[str] = "play"  # the core's name in model files
    c_source: ClassVar[str | None] = "play.c"
    takes_mode: ClassVar[bool] = True  # its columns pass through the mode (solve.identify)
    file_fields: ClassVar[dict[str, str]] = {
        "thresholds": "numbers", "weights": "numbers", "offset": "number",
        "initial_state": "numbers",
    }  # fmt: skip

    def __post_init__(self) -> None:
        r = _frozen(self.thresholds, "thresholds")
        w = _frozen(self.weights, "weights")
        if r.size != w.size:
            msg = (
                f"'thresholds' and 'weights' must have the same length. Got {r.size} and {w.size}."
            )
            raise ShapeError(msg)
        if r[0] != 0.0:
            msg = f"'thresholds' must start at 0 (the linear operator). Got {r[0]!r}."
            raise ParameterError(msg)
        if r.size > 1 and np.any(np.diff(r) <= 0):
            msg = f"'thresholds' must be strictly increasing. Got {r.tolist()}."
            raise ParameterError(msg)
        if not np.isfinite(self.offset):
            msg = f"'offset' must be finite. Got {self.offset!r}."
            raise ParameterError(msg)
        if self.initial_state is None:
            z0 = np.zeros_like(r)
            z0.flags.writeable = False
        else:
            z0 = _frozen(self.initial_state, "initial_state")
            if z0.size != r.size:
                msg = f"'initial_state' must hold one state per operator ({r.size}). Got {z0.size}."
                raise ShapeError(msg)
        object.__setattr__(self, "thresholds", r)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "offset", float(self.offset))
        object.__setattr__(self, "initial_state", z0)

    # ------------------------------------------------------------------ basics
    @property
    def n_operators(self) -> int:
        """Number of play operators, the linear one included."""
        return int(self.thresholds.size)

    @property
    def loading_slopes(self) -> FloatArray:
        r"""Slopes of the initial loading curve, :math:`\sum_{j \le i} w_j` (output/input)."""
        return np.cumsum(self.weights)

    @property
    def is_invertible(self) -> bool:
        """True when the first weight and every partial sum of weights are positive."""
        return bool(np.all(self.loading_slopes > 0.0))

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`~piezohyst.model.cores.base.Core.rest_state`."""
        return np.full(self.n_operators, float(x0))

    def loading_curve(self, s: ArrayLike) -> FloatArray:
        r"""Initial loading curve :math:`\varphi(s) = \sum_i w_i \max(s - r_i, 0)`, s >= 0.

        Parameters
        ----------
        s : array_like
            Input excursions from rest (input units), >= 0.

        Returns
        -------
        ndarray
            Output change along the first loading (output units).
        """
        s_arr = np.asarray(s, dtype=np.float64)
        return np.asarray(np.maximum(s_arr[..., None] - self.thresholds, 0.0) @ self.weights)

    # ------------------------------------------------------------- evaluation
    def propagate(self, x: ArrayLike, state: ArrayLike | None = None) -> Propagation[FloatArray]:
        """See :meth:`~piezohyst.model.cores.base.Core.propagate`."""
        xs = as_signal(x, "x", allow_empty=True)
        z = self._state(state)
        y = np.empty_like(xs)
        K.pi_forward(frozen(xs), frozen(self.thresholds), frozen(self.weights), z, y)
        if self.offset != 0.0:
            y += self.offset
        return Propagation(y, z)

    def predict(self, x: ArrayLike, state: ArrayLike | None = None) -> FloatArray:
        """See :meth:`propagate`, which this calls: the output alone."""
        return self.propagate(x, state).output

    def _state(self, state: ArrayLike | None) -> FloatArray:
        if state is None:
            return np.array(self.initial_state, dtype=np.float64)
        z = as_signal(state, "state").copy()
        if z.size != self.n_operators:
            msg = f"'state' must hold {self.n_operators} operator states. Got {z.size}."
            raise ShapeError(msg)
        return z

    # ---------------------------------------------------------------- inverse
    def inverse(self) -> PIHysteresis:
        r"""Analytic inverse (paper eq. 18, with the inverse weights :math:`w'`).

        With loading slopes :math:`S_i = \sum_{j \le i} w_j` (all > 0):

        .. math::

            r'_i = \sum_{j \le i} w_j (r_i - r_j), \quad
            w'_0 = 1/w_0, \quad w'_i = \frac{-w_i}{S_i S_{i-1}}, \quad
            c' = -c / S_{n-1}

        and the inverse operators start from
        :math:`z'_i = c + \sum_{j \le i} w_j z_i + \sum_{j > i} w_j z_j`
        (:meth:`inverse_state`). The inverse of the inverse is the original.

        Returns
        -------
        PIHysteresis
            Output units in, input units out.

        Raises
        ------
        NotInvertibleError
            If the first weight or any partial sum of weights is not positive.
        """
        slopes = self.loading_slopes
        if not np.all(slopes > 0.0):
            bad = int(np.argmax(slopes <= 0.0))
            msg = (
                "The hysteresis model has no analytic inverse: every partial sum of weights "
                f"must be > 0, but the sum up to operator {bad} is {slopes[bad]:.6g}."
            )
            raise NotInvertibleError(msg)
        r, w = self.thresholds, self.weights
        r_inv = np.array([np.dot(w[: i + 1], r[i] - r[: i + 1]) for i in range(r.size)])
        w_inv = np.empty_like(w)
        w_inv[0] = 1.0 / w[0]
        w_inv[1:] = -w[1:] / (slopes[1:] * slopes[:-1])
        return PIHysteresis(
            thresholds=r_inv,
            weights=w_inv,
            offset=-self.offset / slopes[-1],
            initial_state=self.inverse_state(self.initial_state),
        )

    def inverse_state(self, state: ArrayLike) -> FloatArray:
        r"""States of the inverse operators matching forward states ``state`` (eq. 18).

        :math:`z'_i = c + z_i \sum_{j \le i} w_j + \sum_{j > i} w_j z_j`.

        Parameters
        ----------
        state : array_like, shape (n,)
            Forward operator states (input units).

        Returns
        -------
        ndarray, shape (n,)
            Inverse operator states (output units).
        """
        z = self._state(state)
        w = self.weights
        tail = np.concatenate([np.cumsum((w * z)[::-1])[::-1][1:], [0.0]])
        return np.asarray(self.offset + np.cumsum(w) * z + tail, dtype=np.float64)

    @property
    def summary(self) -> str:
        """A few words on the core, for one-line descriptions."""
        return f"{self.n_operators} operators"

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """See :meth:`~piezohyst.model.cores.base.Core.describe`."""
        fmt = ", ".join
        return [
            ("core", f"Prandtl-Ishlinskii, {self.n_operators} play operators"),
            ("thresholds", f"{fmt(f'{r:.4g}' for r in self.thresholds)} {input_unit}"),
            ("weights", f"{fmt(f'{w:.4g}' for w in self.weights)} {output_unit}/{input_unit}"),
        ]

    # ------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """See :meth:`~piezohyst.model.cores.base.Core.to_dict`."""
        return {
            "thresholds": self.thresholds.tolist(),
            "weights": self.weights.tolist(),
            "offset": self.offset,
            "initial_state": self.initial_state.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PIHysteresis:
        """See :meth:`~piezohyst.model.cores.base.Core.from_dict`."""
        return cls(
            thresholds=data["thresholds"],
            weights=data["weights"],
            offset=data["offset"],
            initial_state=data["initial_state"],
        )

    # ------------------------------------------------------ the core contract
    def history_state(self, history: ArrayLike) -> FloatArray:
        """See :meth:`~piezohyst.model.cores.base.Core.history_state`."""
        return history_state(history, self.thresholds)

    @classmethod
    def states_before_fit(
        cls, settings: dict[str, Any], window: Summary
    ) -> tuple[dict[str, Any], Core] | None:
        """See :meth:`~piezohyst.model.cores.base.Core.states_before_fit`: the thresholds
        from the window's range (unless set), and play operators of those thresholds (their
        states do not depend on the weights the fit identifies)."""
        thr = settings.get("thresholds")
        if thr is None:
            thr = default_thresholds(window.x_range, int(settings["n_operators"]))
        thr = np.asarray(thr, dtype=np.float64)
        return {**settings, "thresholds": thr}, cls(thr, np.ones(thr.size))

    def periodic_state(self, x: ArrayLike) -> FloatArray:
        """See :meth:`~piezohyst.model.cores.base.Core.periodic_state`."""
        xs = as_signal(x, "x")
        return periodic_state(_array_blocks(xs), self.thresholds, float(xs[0]))

    def output(self, state: ArrayLike) -> float:
        """See :meth:`~piezohyst.model.cores.base.Core.output`."""
        return float(self.offset + self.weights @ self._state(state))

    @property
    def min_slope(self) -> float:
        """The smallest loading-curve slope (output per V)."""
        return float(self.loading_slopes.min())

    def fitted_attributes(self) -> dict[str, Any]:
        """See :meth:`~piezohyst.model.cores.base.Core.fitted_attributes`."""
        return {"thresholds_": self.thresholds, "weights_": self.weights, "offset_": self.offset}

    def fast_plan(
        self, terms: tuple[Any, ...], coefs: tuple[FloatArray, ...]
    ) -> Callable[[FloatArray, Any], FloatArray | None] | None:
        """See :meth:`~piezohyst.model.cores.base.Core.fast_plan`."""
        if not terms:
            kind, coef = K.FAST_NONE, 0.0
        elif len(terms) == 1 and type(terms[0]) in (Integral, TimeTerm):
            kind = K.FAST_INTEGRAL if terms[0].kind == "integral" else K.FAST_TIME
            coef = float(coefs[0][0])
        else:
            return None
        r, w, z0, offset = self.thresholds, self.weights, self.initial_state, float(self.offset)

        def plan(x: FloatArray, t: Any) -> FloatArray | None:
            timed = t is not None
            if (not timed and kind == K.FAST_NONE) or (
                type(t) is np.ndarray and t.dtype == np.float64 and t.shape == x.shape
            ):
                out = np.empty(x.size)
                xc = frozen(x)  # one type of input: one compiled specialization
                tc = frozen(t) if timed else xc
                if K.fast_predict(xc, tc, timed, r, w, z0, offset, kind, coef, out) < 0:
                    return out
            return None

        return plan

    def inverse_plan(self) -> InversePlan:
        """See :meth:`~piezohyst.model.cores.base.Core.inverse_plan`."""
        if not self.is_invertible:
            self.inverse()  # raises NotInvertibleError with the reason
        return InversePlan("play", self.min_slope)

    @classmethod
    def identify(cls, job: FitJob) -> CoreFit:
        """See :meth:`~piezohyst.model.cores.base.Core.identify`."""
        params, sm = job.params, job.summary
        thr = params.get("thresholds")
        if thr is None:
            thr = default_thresholds(sm.x_range, params["n_operators"])
        rate = any(term.rate_dependent for term in job.terms)
        blocks = job.blocks if rate else without_time(job.blocks)
        z0 = initial_operators(thr, sm.x_first, job.initial_state, job.blocks)
        sol = identify(PlayCore(thr), job.terms, blocks, sm, z0,
                       min_slope=float(params["min_slope"]), subsets=job.subsets,
                       output=job.output)  # fmt: skip
        values = np.concatenate([sol.core, *[c for c in sol.coefficients if c is not None]])
        tiny = np.finfo(np.float64).tiny * 2**20  # below this, parameters lose digits
        lost = (values != 0) & (np.abs(values) < tiny)
        if lost.any() or not np.all(np.isfinite(values)):
            msg = (
                f"the model's parameters (e.g. {values[lost][0] if lost.any() else values[0]:.3g}"
                f" {job.output_unit}/{job.input_unit}) leave the range of double precision: "
                "express the data in other units (e.g. uC instead of C, or kV instead of V)"
            )
            raise NumericRangeError(msg)
        return solution_fit(PlayCore(thr).build(sol.core, z0), job.terms, sol)


class PlayCore:
    r"""Play operators with thresholds :math:`r_i` (:math:`r_0 = 0`) and an offset.

    Columns: the operator states :math:`z_i` (input units), then a constant 1
    (the offset). The weights are solved in loading-curve slopes
    :math:`S_i = \sum_{j \le i} w_j \ge \epsilon`, which guarantees the
    analytic inverse (eq. 18) while allowing the negative weights of a
    saturating curve.

    Parameters
    ----------
    thresholds : ndarray, shape (n,)
        Strictly increasing from 0 (input units).
    """

    input_degree = 1

    def __init__(self, thresholds: FloatArray) -> None:
        self.thresholds = np.asarray(thresholds, dtype=np.float64)

    @property
    def n_operators(self) -> int:
        """Number of play operators (the linear one included)."""
        return int(self.thresholds.size)

    @property
    def width(self) -> int:
        """Operator columns plus the offset column."""
        return self.n_operators + 1

    def rest_state(self, x0: float) -> FloatArray:
        """Every operator at rest at input ``x0`` (memory wiped).

        Parameters
        ----------
        x0 : float
            The input the actuator rests at.

        Returns
        -------
        ndarray, shape (n,)
        """
        return np.full(self.n_operators, float(x0))

    def scaled(self, scale: float) -> PlayCore:
        """The same core for an input divided by ``scale`` (a power of two: exact).

        Parameters
        ----------
        scale : float

        Returns
        -------
        PlayCore
        """
        return PlayCore(self.thresholds / scale)

    def fill(self, x: FloatArray, state: FloatArray, block: FloatArray) -> None:
        """Write the core's operator columns for ``x`` into ``block[:len(x), :n]``.

        Parameters
        ----------
        x : ndarray, shape (N,)
            Input samples (input units).
        state : ndarray, shape (n,)
            Operator states, updated in place.
        block : ndarray, shape (M, p), M >= N
            Destination; its offset column (``n``) must already hold 1.
        """
        K.play_states(x, self.thresholds, state, block)

    def fill_rows(
        self, x: FloatArray, state: FloatArray, rows: npt.NDArray[np.intp], block: FloatArray
    ) -> None:
        """:meth:`fill` for the rows ``rows`` of ``x`` only (the states run through all).

        Parameters
        ----------
        x : ndarray, shape (N,)
        state : ndarray, shape (n,)
            Updated in place.
        rows : ndarray of int, sorted
        block : ndarray, shape (len(rows), p)
        """
        K.play_states_rows(x, self.thresholds, state, rows, block)

    def slope_map(self, p: int) -> FloatArray:
        """Matrix M with ``parameters = M @ (slopes, other parameters)``.

        Parameters
        ----------
        p : int
            Total parameter count (core and terms).

        Returns
        -------
        ndarray, shape (p, p)
        """
        n = self.n_operators
        m = np.eye(p)
        m[np.arange(1, n), np.arange(0, n - 1)] = -1.0
        return m

    def build(self, params: FloatArray, initial_state: FloatArray) -> PIHysteresis:
        """The fitted operator from solved weights and offset.

        Parameters
        ----------
        params : ndarray, shape (n + 1,)
            Weights (output per input unit) then the offset (output units).
        initial_state : ndarray, shape (n,)
            Operator states before the first training sample (input units).

        Returns
        -------
        PIHysteresis
        """
        n = self.n_operators
        return PIHysteresis(self.thresholds, params[:n], float(params[n]), initial_state)


def history_state(
    history: ArrayLike, thresholds: ArrayLike, state: ArrayLike | None = None
) -> FloatArray:
    """Play-operator states (input units) after ``history``, starting at rest at its first sample.

    To fit or predict a later part of a record, the operators must start where
    the earlier input left them, not at rest.

    Parameters
    ----------
    history : array_like
        The earlier input (V).
    thresholds : array_like
        The play thresholds (V).
    state : array_like, optional
        The states before ``history`` when it continues earlier blocks.

    Returns
    -------
    ndarray
        One state per threshold (V).

    Examples
    --------
    >>> history_state([0.0, 10.0, 4.0], [0.0, 2.0, 5.0]).tolist()
    [4.0, 6.0, 5.0]
    """
    h = as_signal(history, "history")
    thr = as_signal(thresholds, "thresholds")
    z = np.full(thr.size, h[0]) if state is None else np.array(state, dtype=np.float64)
    K.pi_forward(frozen(h), frozen(thr), frozen(np.zeros(thr.size)), z, np.empty(h.size))
    return z


def periodic_state(blocks: Blocks, thresholds: ArrayLike, x_first: float) -> FloatArray:
    """Play-operator states at the start of a record that is one period of a periodic drive.

    The record is run again and again from rest at ``x_first`` until the
    states at its end repeat (a play operator forgets its start once the
    input has passed both its extremes): the periodic steady state, where an
    actuator driven by this signal for a while sits when the record starts.

    Parameters
    ----------
    blocks : Blocks
        The record (only the input is read).
    thresholds : array_like
        The play thresholds (V).
    x_first : float
        The record's first input.

    Returns
    -------
    ndarray
        One state per threshold (V): where the periodic drive leaves each operator at the
        record's start.

    Examples
    --------
    >>> import numpy as np
    >>> x = 5.0 + 5.0 * np.sin(np.linspace(0.0, 2 * np.pi, 101))  # starts mid-cycle, rising
    >>> periodic_state(array_blocks(x, x, None), [0.0, 2.0], float(x[0])).round(3).tolist()
    [5.0, 3.0]
    """
    thr = as_signal(thresholds, "thresholds")
    z = np.full(thr.size, float(x_first))
    for _ in range(PERIODIC_PASSES):
        before = z.copy()
        for xb, _, _ in blocks():
            if xb.size:
                z = history_state(xb, thr, z)
        if np.array_equal(z, before):
            break
    return z


def _array_blocks(x: FloatArray) -> Blocks:
    return lambda: iter([(x, x, None)])


def initial_operators(
    thr: FloatArray, x_first: float, initial_state: Any, blocks: Blocks | None = None
) -> FloatArray:
    """Play-operator states before a record for a named start (or given states).

    Parameters
    ----------
    thr : ndarray
        The thresholds (V).
    x_first : float
        The record's first input.
    initial_state : {"rest", "periodic"}, History, array_like or None
    blocks : callable, optional
        The record (for ``"periodic"``).

    Returns
    -------
    ndarray
    """
    if initial_state is None or (isinstance(initial_state, str) and initial_state == "rest"):
        return np.full(thr.size, x_first)
    if isinstance(initial_state, str):
        if initial_state != "periodic" or blocks is None:
            msg = (
                "'initial_state' must be 'rest', 'periodic', a History, or operator "
                f"states. Got {initial_state!r}."
            )
            raise ParameterError(msg)
        return periodic_state(blocks, thr, x_first)
    history = getattr(initial_state, "input", None)
    if history is not None:  # a History
        return history_state(history, thr)
    z0 = as_signal(initial_state, "initial_state")
    if z0.size != thr.size:
        msg = f"'initial_state' must hold one state per operator ({thr.size}). Got {z0.size}."
        raise ShapeError(msg)
    return z0


def subset_label(terms: Sequence[Term], subset: tuple[int, ...]) -> str:
    """A growth subset's label: its removed terms' kinds joined by '+', or 'none'.

    Parameters
    ----------
    terms : sequence of Term
    subset : tuple of int

    Returns
    -------
    str
    """
    removed = [terms[j].kind for j in subset if terms[j].removed]
    return "+".join(removed) or "none"


def solution_fit(core: Core, terms: Sequence[Term], sol: Identification) -> CoreFit:
    """A :class:`CoreFit` from the linear solve's result (its kept terms and scores).

    Parameters
    ----------
    core : Core
    terms : sequence of Term
    sol : Identification

    Returns
    -------
    CoreFit
    """
    kept = [j for j, c in enumerate(sol.coefficients) if c is not None]
    selection = (
        {subset_label(terms, s): e for s, e in sol.scores.items()},
        {subset_label(terms, s): f for s, f in sol.fold_scores.items()},
        list(sol.splits),
    )
    return CoreFit(core, tuple(terms[j] for j in kept),
                   tuple(np.asarray(sol.coefficients[j]) for j in kept), selection)  # fmt: skip


#: Play operators of the proxy that settles other cores' growth terms
PROXY_OPERATORS = 16


def growth_proxy(
    x: FloatArray,
    y: FloatArray,
    t: FloatArray | None,
    terms: list[Term],
    subsets: list[tuple[int, ...]] | None,
    initial_state: Any,
) -> tuple[list[Term], list[FloatArray], Any]:
    """Growth terms identified jointly with play operators (a proxy for another core).

    PI loops close by construction: every drift of the charge is the growth
    terms'. A Duhem core's loops need not close, so identified jointly with
    it a leak trades against the slopes; the proxy settles the growth (and
    the creep) first. With ``select`` the proxy's forward-chaining
    cross-validation chooses the growth terms; the first ``n_fixed`` terms
    (creep) are in every subset.

    Parameters
    ----------
    x, y : ndarray
        The record.
    t : ndarray or None
        Its times.
    terms : list of Term
    subsets : list of tuple of int, or None
        The term combinations to choose among (indices into ``terms``); None: all kept.
    initial_state : any

    Returns
    -------
    (list of Term, list of ndarray, selection or None)
        The kept terms, their coefficients, and the selection's scores.
    """
    blocks = array_blocks(x, y, t)
    sm = Summary.of(blocks)
    thr = default_thresholds(sm.x_range, PROXY_OPERATORS)
    z0 = np.full(thr.size, float(x[0]))
    if isinstance(initial_state, str) and initial_state == "periodic":
        z0 = periodic_state(array_blocks(x, x, None), thr, float(x[0]))
    sol = identify(PlayCore(thr), terms, blocks, sm, z0, min_slope=1e-3, subsets=subsets)
    fit = solution_fit(PlayCore(thr).build(sol.core, z0), terms, sol)
    return list(fit.terms), list(fit.coefs), None if subsets is None else fit.selection


def default_thresholds(x: ArrayLike, n_operators: int) -> FloatArray:
    r"""Evenly spaced thresholds over half of the input's range.

    :math:`r_i = i \cdot \Delta x / (2n)`, :math:`i = 0 \dots n-1`, where
    :math:`\Delta x` is the input's span. The largest threshold stays below
    :math:`\Delta x / 2`: a wider play never reverses inside the range and only
    adds a column collinear with the input and the offset. The rule depends on
    the span only, so it suits unipolar (0..Vmax) and bipolar drive alike.

    Parameters
    ----------
    x : array_like
        The training input (V).
    n_operators : int
        Number of thresholds, 0 included, in [1, 1000].

    Returns
    -------
    ndarray, shape (n_operators,)

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
