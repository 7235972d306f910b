r"""Terms: the parts of a model beside its hysteresis core.

A piezohyst model is a hysteresis *core* (today the Prandtl-Ishlinskii play
operators, :mod:`piezohyst.model.cores`) plus *terms*. Each term is a small object
that supplies regressor columns, block by block with carried state; the model
is linear in every term's coefficients, so core and terms are identified
together by one bounded least-squares solve (eq. 16-17 generalised).

A term declares:

* ``kind``: its name in model files (the registry key);
* ``removed``: ``True`` for *growth* terms, which model charge that moves
  nothing (leakage, bias current, the paper's :math:`R\,y_2`) and are removed
  before compensating (eq. 19); ``False`` for terms that shape the hysteresis
  and are kept (asymmetry, creep);
* ``rate_dependent``: whether it needs the sample times;
* ``input_degree``: how its columns scale with the input (``x -> a x`` gives
  ``columns -> a**degree columns``); identification divides inputs by a power
  of two and uses this to restore exact coefficients at any scale;
* its columns (:meth:`Term.columns`), their lower bounds, named state slots,
  and the units of its coefficients.

Settings that depend on the training data (the knots of the asymmetry term,
the voltage scale of ``abs_integral``) are fixed by :meth:`Term.bind` before
fitting; the bound term is what a fitted model stores and saves.

Writing a new term needs no change to the library: subclass :class:`Term`
with a ``kind`` (registration is automatic), and pass an instance in
``terms=``::

    class TimeSquared(ph.Term):
        kind = "time_squared"
        removed = True
        rate_dependent = True
        state_names = ("elapsed",)

        def columns(self, x, t, dt, state):
            elapsed = state[0] + np.cumsum(dt)
            state[0] = elapsed[-1]
            return (elapsed**2)[:, None]

        def coefficient_units(self, input_unit, output_unit):
            return (f"{output_unit}/s^2",)

    ph.PIModel(10, terms=("integral", TimeSquared())).fit(v, q, t=t)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from .._kernels import packed as P
from .._kernels import signal as S
from .._validation import FloatArray, frozen
from ..errors import ParameterError, ShapeError

__all__ = [
    "AbsIntegral",
    "Asymmetry",
    "Creep",
    "Integral",
    "LagShape",
    "Relaxation",
    "RelaxationShape",
    "RunningIntegral",
    "StaticShape",
    "Term",
    "TimeTerm",
    "coefficient_arrays",
    "creep_time_constants",
    "growth_kinds",
    "make_term",
    "term_class",
    "term_columns",
]

_TERMS: dict[str, type[Term]] = {}


@dataclass(frozen=True)
class StaticShape:
    r"""A memoryless monotone term, as the compensator's inverse needs it.

    Output :math:`\sum_j [u_j (x - k_j)_+^2 - d_j (k_j - x)_+^2] / s`.

    Attributes
    ----------
    knots : ndarray
        :math:`k_j` (input units).
    up, down : ndarray
        :math:`u_j, d_j \ge 0` (output per input unit).
    scale : float
        :math:`s` (input units).
    """

    knots: FloatArray
    up: FloatArray
    down: FloatArray
    scale: float


@dataclass(frozen=True)
class LagShape:
    r"""First-order lags of unit DC gain, as the compensator's inverse needs them.

    Output :math:`\sum_k g_k L_{\tau_k}[x]`.

    Attributes
    ----------
    taus : ndarray
        Time constants :math:`\tau_k` (s).
    gains : ndarray
        Gains :math:`g_k \ge 0` (output per input unit).
    """

    taus: FloatArray
    gains: FloatArray


@dataclass(frozen=True)
class RelaxationShape:
    r"""A slow Preisach core behind a first-order lag, as the compensator's inverse needs it.

    Output :math:`q_s(L_\tau[x])`: a Preisach core (density :math:`\ge 0`, flat
    beyond its grid) driven by the input through a lag of unit DC gain.

    Attributes
    ----------
    tau : float
        The lag's time constant (s).
    packed : ndarray
        The slow core in ``_kernels.packed``'s Preisach layout (head, Everett nodes).
    """

    tau: float
    packed: FloatArray


class Term:
    """Base of every model term (see the module documentation).

    Subclasses set the class attributes and implement :meth:`columns`; the
    constructor arguments are the term's settings, returned by
    :meth:`get_params` (JSON-ready) and accepted back by the constructor.
    """

    kind: ClassVar[str] = ""
    removed: ClassVar[bool] = False
    rate_dependent: ClassVar[bool] = False
    input_degree: ClassVar[int] = 0
    state_names: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.kind:
            _TERMS[cls.kind] = cls

    # ----------------------------------------------------------- settings
    def get_params(self) -> dict[str, Any]:
        """The term's settings as plain JSON data (accepted by the constructor).

        Returns
        -------
        dict
            Empty for terms without settings.
        """
        return {}

    def bind(self, x_range: FloatArray) -> Term:
        """This term with its data-dependent settings fixed from the training input's range.

        Only the range is given, so a fit can stream a record it never holds
        in memory.

        Parameters
        ----------
        x_range : ndarray, shape (2,)
            The training input's minimum and maximum (input units).

        Returns
        -------
        Term
            ``self`` for terms without such settings.
        """
        return self

    @property
    def width(self) -> int:
        """Number of regressor columns (coefficients)."""
        return 1

    def labels(self) -> tuple[str, ...]:
        """One name per coefficient (``kind`` for single-column terms).

        Returns
        -------
        tuple of str
        """
        if self.width == 1:
            return (self.kind,)
        return tuple(f"{self.kind}[{j}]" for j in range(self.width))

    def lower_bounds(self) -> FloatArray:
        """Lower bound of every coefficient (``-inf`` for a free one).

        Returns
        -------
        ndarray, shape (width,)
        """
        return np.full(self.width, -np.inf)

    def coefficient_units(self, input_unit: str, output_unit: str) -> tuple[str, ...]:
        """Unit of every coefficient, given the model's input and output units.

        Parameters
        ----------
        input_unit, output_unit : str
            E.g. ``"V"`` and ``"C"``.

        Returns
        -------
        tuple of str
        """
        return (f"{output_unit}/{input_unit}",) * self.width

    # ------------------------------------------------------------ columns
    def rest_state(self, x0: float) -> FloatArray:
        """The term's state before any sample, for an actuator resting at ``x0``.

        Parameters
        ----------
        x0 : float
            The input (V) the actuator rests at.

        Returns
        -------
        ndarray, shape (len(state_names),)
            Zeros unless a term overrides it.
        """
        return np.zeros(len(self.state_names))

    def columns(
        self, x: FloatArray, t: FloatArray | None, dt: FloatArray | None, state: FloatArray
    ) -> FloatArray:
        """Regressor columns for one block of samples; ``state`` is updated in place.

        Parameters
        ----------
        x : ndarray, shape (N,)
            Input samples (input units).
        t : ndarray, shape (N,) or None
            Sample times (s); None for a rate-independent model.
        dt : ndarray, shape (N,) or None
            Interval before each sample (s); 0 for a record's first sample.
        state : ndarray, shape (len(state_names),)
            The term's state before the block, updated to the state after it.

        Returns
        -------
        ndarray, shape (N, width)
        """
        raise NotImplementedError

    # ------------------------------------------------------ compensation
    def static_shape(self, coefficients: FloatArray) -> StaticShape | None:
        """The term as a memoryless monotone shape, if it is one (kept terms).

        Parameters
        ----------
        coefficients : ndarray
            The term's fitted coefficients.

        Returns
        -------
        StaticShape or None
        """
        return None

    def lag_shape(self, coefficients: FloatArray) -> LagShape | None:
        """See :meth:`static_shape`: the term as first-order lags, if it is one."""
        return None

    def relaxation_shape(self, coefficients: FloatArray) -> RelaxationShape | None:
        """See :meth:`static_shape`: the term as a lagged Preisach core, if it is one."""
        return None

    # ------------------------------------------------------------ python
    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Term)
            and type(other) is type(self)
            and self.get_params() == other.get_params()
        )

    def __hash__(self) -> int:
        return hash((type(self), repr(self)))


def _needs_time(term: Term, dt: FloatArray | None) -> FloatArray:
    if dt is None:
        msg = f"The '{term.kind}' term is rate dependent: the model needs t= (sample times in s)."
        raise ParameterError(msg)
    return dt


class RunningIntegral(Term):
    r"""Base of the growth terms that integrate something: :math:`\int f(x)\,dt`.

    Backward rectangles, :math:`y[k] = y[k-1] + f(x[k])\,\Delta t_k`, the
    paper's discretisation (eq. 13). Subclasses give :meth:`integrand`.
    """

    removed = True
    rate_dependent = True
    state_names: ClassVar[tuple[str, ...]] = ("integral",)

    def integrand(self, x: FloatArray) -> FloatArray:
        """What is integrated over time, sample by sample.

        Parameters
        ----------
        x : ndarray
            Input samples.

        Returns
        -------
        ndarray
        """
        raise NotImplementedError

    def columns(
        self, x: FloatArray, t: FloatArray | None, dt: FloatArray | None, state: FloatArray
    ) -> FloatArray:
        """See :meth:`Term.columns`: the running integral."""
        out = np.empty((x.size, 1))
        state[0] = S.running_integral(
            frozen(self.integrand(x)), _needs_time(self, dt), state[0], out[:, 0]
        )
        return out

    def coefficient_units(self, input_unit: str, output_unit: str) -> tuple[str, ...]:
        """See :meth:`Term.coefficient_units`: output per (input x s), S for V to C."""
        return (f"{output_unit}/({input_unit}*s)",)


class Integral(RunningIntegral):
    r"""The paper's growth term :math:`\int x\,dt` (eq. 13): ohmic leakage.

    Its coefficient :math:`R` is the leakage conductance for V to C (S).
    """

    kind = "integral"
    input_degree = 1

    def integrand(self, x: FloatArray) -> FloatArray:
        """See :meth:`RunningIntegral.integrand`: the input itself."""
        return x


class TimeTerm(RunningIntegral):
    """Elapsed time :math:`t - t_0`: a constant current (op-amp bias, integrator offset)."""

    kind = "time"
    input_degree = 0
    state_names = ("elapsed",)

    def integrand(self, x: FloatArray) -> FloatArray:
        """See :meth:`RunningIntegral.integrand`: one, so the integral is the elapsed time."""
        return np.ones_like(x)

    def coefficient_units(self, input_unit: str, output_unit: str) -> tuple[str, ...]:
        """See :meth:`Term.coefficient_units`: output per s (A for C)."""
        return (f"{output_unit}/s",)


def _positive_scale(value: object, owner: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        msg = f"The 'scale' parameter of {owner} must be a positive float. Got {value!r} instead."
        raise ParameterError(msg)
    if not math.isfinite(float(value)):
        msg = f"The 'scale' parameter of {owner} must be finite. Got {value!r} instead."
        raise ParameterError(msg)
    return float(value)


def _span_scale(x: FloatArray) -> float:
    return max(float(np.ptp(x)), 1e-300)


class AbsIntegral(RunningIntegral):
    r"""Leakage rising with the voltage: :math:`\int x\,|x| / s\,dt`.

    Parameters
    ----------
    scale : float, optional
        :math:`s` (input units); default: the training input's span.
    """

    kind = "abs_integral"
    input_degree = 1
    state_names = ("abs_integral",)

    def __init__(self, scale: float | None = None) -> None:
        self.scale = _positive_scale(scale, "AbsIntegral")

    def get_params(self) -> dict[str, Any]:
        """See :meth:`Term.get_params`."""
        return {"scale": self.scale}

    def bind(self, x_range: FloatArray) -> AbsIntegral:
        """See :meth:`Term.bind`: the scale defaults to the input's span."""
        return self if self.scale is not None else AbsIntegral(_span_scale(x_range))

    def integrand(self, x: FloatArray) -> FloatArray:
        """See :meth:`RunningIntegral.integrand`: x|x|/s."""
        s = self.scale if self.scale is not None else _span_scale(x)
        return x * np.abs(x) / s


class Asymmetry(Term):
    r"""Static monotone term that bends the loop's centre line (asymmetric loops).

    .. math::

        \sum_j \bigl[u_j (x - k_j)_+^2 - d_j (k_j - x)_+^2\bigr] / s,
        \qquad u_j, d_j \ge 0

    a one-sided quadratic spline that never decreases, so the hysteresis part
    stays strictly increasing in the current input (invertible).

    Parameters
    ----------
    n_knots : int, default 3
        Knots evenly inside the training range.
    knots : sequence of float, optional
        Explicit knots (input units); fixed by :meth:`bind` if not given.
    scale : float, optional
        :math:`s` (input units); default: the training input's span.
    """

    kind = "asymmetry"
    input_degree = 1

    def __init__(
        self, n_knots: int = 3, knots: Sequence[float] | None = None, scale: float | None = None
    ) -> None:
        if isinstance(n_knots, bool) or not isinstance(n_knots, int) or not 0 <= n_knots <= 50:
            msg = (
                f"The 'n_knots' parameter of Asymmetry must be an int in [0, 50]. Got {n_knots!r}."
            )
            raise ParameterError(msg)
        self.n_knots = n_knots
        self.knots = None if knots is None else tuple(float(k) for k in knots)
        if self.knots is not None:
            if len(self.knots) != n_knots or not all(math.isfinite(k) for k in self.knots):
                msg = f"Asymmetry needs {n_knots} finite knots. Got {list(self.knots)!r}."
                raise ParameterError(msg)
        self.scale = _positive_scale(scale, "Asymmetry")

    def get_params(self) -> dict[str, Any]:
        """See :meth:`Term.get_params`."""
        return {
            "n_knots": self.n_knots,
            "knots": None if self.knots is None else list(self.knots),
            "scale": self.scale,
        }

    def bind(self, x_range: FloatArray) -> Asymmetry:
        """See :meth:`Term.bind`: knots evenly inside the input's range, scale its span."""
        if self.knots is not None and self.scale is not None:
            return self
        lo, hi = float(x_range.min()), float(x_range.max())
        knots = lo + (hi - lo) * np.arange(1, self.n_knots + 1) / (self.n_knots + 1)
        return Asymmetry(self.n_knots, knots.tolist(), max(hi - lo, 1e-300))

    def _knots(self) -> tuple[FloatArray, float]:
        if self.knots is None or self.scale is None:
            msg = "Asymmetry must be bound to the training data (Term.bind) before use."
            raise ParameterError(msg)
        return np.asarray(self.knots, dtype=np.float64), self.scale

    @property
    def width(self) -> int:
        """Two coefficients per knot (rising and falling side)."""
        return 2 * self.n_knots

    def labels(self) -> tuple[str, ...]:
        """See :meth:`Term.labels`."""
        return tuple(f"up[{j}]" for j in range(self.n_knots)) + tuple(
            f"down[{j}]" for j in range(self.n_knots)
        )

    def lower_bounds(self) -> FloatArray:
        """See :meth:`Term.lower_bounds`: every coefficient >= 0 (monotone)."""
        return np.zeros(self.width)

    def columns(
        self, x: FloatArray, t: FloatArray | None, dt: FloatArray | None, state: FloatArray
    ) -> FloatArray:
        """See :meth:`Term.columns`."""
        knots, s = self._knots()
        d = x[:, None] - knots[None, :]
        return np.concatenate(
            [np.maximum(d, 0.0) ** 2 / s, -(np.maximum(-d, 0.0) ** 2) / s], axis=1
        )

    def static_shape(self, coefficients: FloatArray) -> StaticShape:
        """See :meth:`Term.static_shape`."""
        knots, s = self._knots()
        k = self.n_knots
        return StaticShape(knots, coefficients[:k].copy(), coefficients[k:].copy(), s)


def creep_time_constants(duration: float, samples: int) -> tuple[float, float, float]:
    """Three creep time constants inside a record: a decade apart, the slowest a fifth of
    its duration, none below ten samples (each is seen to act, none outlives the record).
    Chosen from the time axis alone, never from scores.

    Parameters
    ----------
    duration : float
        The record's length (s).
    samples : int

    Returns
    -------
    tuple of float

    Examples
    --------
    >>> creep_time_constants(10.0, 10_001)
    (0.02, 0.2, 2.0)
    """
    dt = duration / max(samples - 1, 1)
    slow = duration / 5.0
    return tuple(max(slow / 10.0**k, 10.0 * dt) for k in (2, 1, 0))  # type: ignore[return-value]


class Creep(Term):
    r"""Creep operators: first-order lags of unit DC gain, gains :math:`g_k \ge 0`.

    After a step the output keeps moving, roughly logarithmically in time
    with log-spaced time constants. Exact for piecewise-constant input.

    Parameters
    ----------
    taus : sequence of float
        Time constants (s), 1 to 20 of them.
    """

    kind = "creep"
    rate_dependent = True
    input_degree = 1

    def __init__(self, taus: Sequence[float] = (0.1, 1.0, 10.0)) -> None:
        try:
            arr = np.asarray(list(taus), dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            arr = np.array([np.nan])
        if not 1 <= arr.size <= 20 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            msg = (
                "The 'creep' time constants must be 1 to 20 positive values in s. "
                f"Got {taus!r} instead."
            )
            raise ParameterError(msg)
        self.taus = tuple(float(v) for v in arr)

    def get_params(self) -> dict[str, Any]:
        """See :meth:`Term.get_params`."""
        return {"taus": list(self.taus)}

    @property
    def width(self) -> int:
        """One gain per time constant."""
        return len(self.taus)

    @property
    def state_names(self) -> tuple[str, ...]:  # type: ignore[override]
        """One lag state (input units) per time constant."""
        return tuple(f"lag[{tau:g} s]" for tau in self.taus)

    def labels(self) -> tuple[str, ...]:
        """See :meth:`Term.labels`."""
        return tuple(f"creep[{tau:g} s]" for tau in self.taus)

    def lower_bounds(self) -> FloatArray:
        """See :meth:`Term.lower_bounds`: every gain >= 0."""
        return np.zeros(self.width)

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`Term.rest_state`: every lag settled at ``x0``."""
        return np.full(self.width, float(x0))

    def columns(
        self, x: FloatArray, t: FloatArray | None, dt: FloatArray | None, state: FloatArray
    ) -> FloatArray:
        """See :meth:`Term.columns`: the lag outputs (input units)."""
        out = np.empty((x.size, self.width))
        S.lag_filter(frozen(x), _needs_time(self, dt), np.asarray(self.taus), state, out)
        return out

    def lag_shape(self, coefficients: FloatArray) -> LagShape:
        """See :meth:`Term.lag_shape`."""
        return LagShape(np.asarray(self.taus), coefficients.copy())


class Relaxation(Term):
    r"""Relaxing hysteresis: a second Preisach density acting on the voltage through a lag.

    .. math::

        q_s(t) = \mathcal{P}_\mu\bigl[L_\tau[x]\bigr](t), \qquad \mu \ge 0

    The part of the switching that follows the field with a delay: a Preisach
    core (:class:`~piezohyst.model.cores.preisach.PreisachHysteresis`, density on
    ``nodes`` reversal points over the training range) whose input is the
    voltage through a first-order lag of time constant ``tau``. The loop then
    depends on the drive's rate: faster drives leave the slow part behind.
    Linear in the density, so it is fitted in the same least squares as the
    core beside it; the density is ``>= 0`` and the lag passes a rising voltage
    on as a rising one, so the output stays strictly increasing in each
    sample's voltage: the compensator inverts it with the core.

    Parameters
    ----------
    tau : float
        The lag's time constant (s), > 0.
    nodes : int, default 12
        Reversal-point grid nodes, in [3, 40]; ``nodes (nodes - 1) / 2`` cells.
    v_range : sequence of 2 float, optional
        The grid's voltage range; fixed by :meth:`bind` from the training input.
    """

    kind = "relaxation"
    rate_dependent = True
    input_degree = 0

    def __init__(
        self, tau: float = 0.1, nodes: int = 12, v_range: Sequence[float] | None = None
    ) -> None:
        ok = isinstance(tau, int | float) and not isinstance(tau, bool)
        if not ok or not math.isfinite(float(tau)) or float(tau) <= 0:
            msg = f"The 'tau' of a relaxation term must be a positive time in s. Got {tau!r}."
            raise ParameterError(msg)
        if isinstance(nodes, bool) or not isinstance(nodes, int) or not 3 <= nodes <= 40:
            msg = f"The 'nodes' of a relaxation term must be an int in [3, 40]. Got {nodes!r}."
            raise ParameterError(msg)
        self.tau = float(tau)
        self.nodes = nodes
        self.v_range: tuple[float, float] | None = None
        if v_range is not None:
            lo, hi = (float(v) for v in v_range)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                msg = f"A relaxation term's 'v_range' must be [lo, hi], lo < hi. Got {v_range}."
                raise ParameterError(msg)
            self.v_range = (lo, hi)
        m = nodes - 1
        self._upper = np.flatnonzero(np.triu(np.ones((m, m))).ravel())  # cells k <= l
        self._map = P.everett_map(nodes)[:, self._upper]  # Everett nodes from the cells

    def get_params(self) -> dict[str, Any]:
        """See :meth:`Term.get_params`."""
        return {
            "tau": self.tau,
            "nodes": self.nodes,
            "v_range": None if self.v_range is None else list(self.v_range),
        }

    def bind(self, x_range: FloatArray) -> Relaxation:
        """See :meth:`Term.bind`: the grid spans the training input's range."""
        if self.v_range is not None:
            return self
        lo, hi = float(x_range.min()), float(x_range.max())
        return Relaxation(self.tau, self.nodes, (lo, max(hi, lo + 1e-300)))

    def _head(self) -> FloatArray:
        if self.v_range is None:
            msg = "Relaxation must be bound to the training data (Term.bind) before use."
            raise ParameterError(msg)
        lo, hi = self.v_range
        n = self.nodes
        # a Preisach core's packed head (beyond the grid each branch keeps its edge slope)
        return np.array([P.KIND_PREISACH, n, n, lo, (hi - lo) / (n - 1), 0.0, 0.0, 0.0, 0.0])

    @property
    def width(self) -> int:
        """One coefficient per cell of the density."""
        return int(self._upper.size)

    @property
    def state_names(self) -> tuple[str, ...]:  # type: ignore[override]
        """The slow core's state (its first value is the lagged voltage), then the output's
        derivatives by the Everett values at the nodes since the rest state."""
        core = ("lagged voltage", "output", "direction", "reversals")
        stack = tuple(f"reversal[{j}]" for j in range(P.STACK))
        acc = tuple(f"d output/d E[{j}]" for j in range(self.nodes * self.nodes))
        return core + stack + acc

    def labels(self) -> tuple[str, ...]:
        """See :meth:`Term.labels`: ``relaxation[k,l]`` per cell."""
        m = self.nodes - 1
        return tuple(f"relaxation[{c // m},{c % m}]" for c in self._upper)

    def lower_bounds(self) -> FloatArray:
        """See :meth:`Term.lower_bounds`: a density is >= 0."""
        return np.zeros(self.width)

    def coefficient_units(self, input_unit: str, output_unit: str) -> tuple[str, ...]:
        """See :meth:`Term.coefficient_units`: output units per cell."""
        return (output_unit,) * self.width

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`Term.rest_state`: the lag settled at ``x0``, no reversal yet."""
        z = np.zeros(len(self.state_names))
        z[0], z[P.RV_K], z[P.RV_R] = float(x0), 1.0, float(x0)
        return z

    def columns(
        self, x: FloatArray, t: FloatArray | None, dt: FloatArray | None, state: FloatArray
    ) -> FloatArray:
        """See :meth:`Term.columns`: the Preisach regressors of the lagged voltage."""
        head = self._head()
        n = self.nodes
        lagged = np.empty((x.size, 1))
        lag = state[0:1].copy()  # the slow core's voltage is the lag's state
        S.lag_filter(frozen(x), _needs_time(self, dt), np.array([self.tau]), lag, lagged)
        packed = np.concatenate([head, np.zeros(n * n)])
        core = state[: P.RV_SIZE]  # views: updated in place
        acc = state[P.RV_SIZE :]
        nodes_cols = np.empty((x.size, n * n))
        P.rev_columns(packed, np.ascontiguousarray(lagged[:, 0]), core, acc, nodes_cols)
        return np.asarray(nodes_cols @ self._map, dtype=np.float64)

    def relaxation_shape(self, coefficients: FloatArray) -> RelaxationShape:
        """See :meth:`Term.relaxation_shape`."""
        m = self.nodes - 1
        mu = np.zeros(m * m)
        mu[self._upper] = np.maximum(coefficients, 0.0)
        packed = np.concatenate([self._head(), P.everett_nodes(mu.reshape(m, m)).ravel()])
        return RelaxationShape(self.tau, packed)


def term_class(kind: str) -> type[Term]:
    """The term class registered under ``kind``.

    Parameters
    ----------
    kind : str
        A term's ``kind`` (e.g. ``"integral"``), as stored in model files.

    Returns
    -------
    type
        A :class:`Term` subclass.

    Raises
    ------
    ParameterError
        If no term of that kind is known (a custom term's module must be imported).
    """
    if kind not in _TERMS:
        msg = (
            f"unknown term {kind!r}; known: {sorted(_TERMS)} (a custom term must be "
            "defined, i.e. its module imported, before a model using it is loaded)"
        )
        raise ParameterError(msg)
    return _TERMS[kind]


def growth_kinds() -> tuple[str, ...]:
    """Every registered growth term (removed before compensating) a model can name.

    The built-in ``integral``, ``time`` and ``abs_integral`` first, then any
    term registered since (a :class:`Term` subclass with ``removed = True``).

    Returns
    -------
    tuple of str
    """
    builtin = ("integral", "time", "abs_integral")
    return builtin + tuple(k for k, cls in _TERMS.items() if cls.removed and k not in builtin)


def make_term(spec: str | Term, params: Mapping[str, Any] | None = None) -> Term:
    """A term from its ``kind`` name (with settings) or a term instance as it is.

    Parameters
    ----------
    spec : str or Term
        ``"integral"``, ``"time"``, ``"abs_integral"``, ``"asymmetry"``,
        ``"creep"``, a custom term's ``kind``, or an instance.
    params : mapping, optional
        Settings for the named kind (ignored for an instance).

    Returns
    -------
    Term

    Examples
    --------
    >>> make_term("creep", {"taus": [0.5, 5.0]})
    Creep(taus=[0.5, 5.0])
    """
    if isinstance(spec, Term):
        return spec
    if not isinstance(spec, str):
        msg = f"A term must be a kind name or a Term instance. Got {spec!r} instead."
        raise ParameterError(msg)
    settings = dict(params or {})
    try:
        return term_class(spec)(**settings)
    except TypeError as exc:
        msg = f"bad settings {settings!r} for the {spec!r} term: {exc}"
        raise ParameterError(msg) from None


def coefficient_arrays(
    terms: Sequence[Term], coefficients: Sequence[ArrayLike]
) -> tuple[FloatArray, ...]:
    """One float array per term, each of the term's width (checked).

    Parameters
    ----------
    terms : sequence of Term
    coefficients : sequence of array_like

    Returns
    -------
    tuple of ndarray

    Raises
    ------
    ShapeError
        A count or a width does not match.
    """
    if len(terms) != len(coefficients):
        msg = f"one coefficient array per term: got {len(terms)} terms, {len(coefficients)}."
        raise ShapeError(msg)
    coefs = tuple(np.array(c, dtype=np.float64).reshape(-1) for c in coefficients)
    for term, c in zip(terms, coefs, strict=True):
        if c.size != term.width:
            msg = f"the {term.kind!r} term takes {term.width} coefficients. Got {c.size}."
            raise ShapeError(msg)
    return coefs


def term_columns(
    terms: Sequence[Term],
    x: FloatArray,
    t: FloatArray | None,
    dt: FloatArray | None,
    states: Sequence[FloatArray],
    out: FloatArray,
) -> None:
    """Every term's columns for one block, side by side in ``out`` (states updated).

    Parameters
    ----------
    terms : sequence of Term
    x, t, dt : ndarray
        The block's input, times and intervals (see :meth:`Term.columns`).
    states : sequence of ndarray
        One state per term, updated in place.
    out : ndarray, shape (len(x), total width)
    """
    col = 0
    for term, state in zip(terms, states, strict=True):
        out[:, col : col + term.width] = term.columns(x, t, dt, state)
        col += term.width
