r"""The one model class: a hysteresis core plus terms and dynamics, one fit path.

A :class:`HysteresisModel` holds a core (:mod:`piezohyst.cores`: play
operators, Preisach, Duhem, Bouc-Wen, or one defined outside the library),
terms (:mod:`piezohyst.terms`) — growth terms that model charge which moves
nothing and are removed before compensating (the paper's :math:`R\int x\,dt`,
eq. 13-19), and shape terms that stay (asymmetry, creep) — and the input and
output dynamics. It knows nothing of any core's maths: it asks the core (the
:class:`~piezohyst.cores.base.Core` contract) to identify itself, run, give
its states, its inverse plan and its file form.

The public presets (:mod:`piezohyst.models`: ``ClassicalPI``, ``ActivePI``,
``GeneralizedPI``, ``PIModel``, ``PreisachModel``, ``DuhemModel``,
``BoucWenModel``) are thin constructors: their own settings, their core and
the terms they fit.

They follow the scikit-learn estimator contract without inheriting from it:
``__init__`` only stores its arguments; ``get_params(deep=True)``/
``set_params`` are read from ``__init__``, so ``sklearn.base.clone`` works;
:meth:`~HysteresisModel.fit` checks the parameters, identifies and returns
``self``; learned values end in ``_``; using a model before ``fit`` raises
:class:`~piezohyst.errors.NotFittedError`; :meth:`~HysteresisModel.score` is
scikit-learn's R².

Initial state
-------------
A fitted model starts its core *at rest at the training record's first
input* unless told otherwise; growth integrals start at 0 and creep lags
settled at the first input. :class:`ModelState` is the named state between
blocks; :meth:`~HysteresisModel.rest_state` and
:meth:`~HysteresisModel.state_after` build one.
"""

from __future__ import annotations

import inspect
import math
import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike

from ._lazy import LazyModule
from ._validation import FloatArray, as_signal, as_time, check_float, check_int, same_length
from .cores.base import Core, CoreFit, FitJob, Propagation, core_class
from .dynamics import KINDS as DYNAMICS_KINDS
from .dynamics import InputDynamics, OutputDynamics
from .dynamics_fit import search_dynamics
from .errors import (
    ExtrapolationWarning,
    InsufficientDataError,
    NotFittedError,
    NotInvertibleError,
    ParameterError,
    ShapeError,
    TimeAxisError,
)
from .identification import BLOCK, Blocks, Summary, array_blocks, block_dt, term_columns
from .leakage import Leakage
from .persistence import model_from_dict, model_to_dict, register, save_model
from .terms import Creep, LagShape, RelaxationShape, StaticShape, Term, make_term

if TYPE_CHECKING:
    from . import _kernels as K
else:  # numba loads when a model first runs (see _lazy)
    K = LazyModule("piezohyst._kernels", globals(), "K")

__all__ = [
    "GROWTH_TERMS",
    "History",
    "HysteresisModel",
    "InitialState",
    "InverseSpec",
    "ModelState",
]

GROWTH_TERMS = ("integral", "time", "abs_integral")


@dataclass(frozen=True)
class History:
    """The input an actuator saw before a record: its operators start where it left them.

    Attributes
    ----------
    input : ndarray
        The earlier input (V), from rest at its first sample.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> before = np.array([0.0, 100.0, 40.0])
    >>> h = ph.PIHysteresis([0.0, 20.0], [1e-8, 5e-9])
    >>> model = ph.ClassicalPI.from_operator(h)
    >>> x = np.array([40.0, 60.0])
    >>> model.predict(x, state=ph.History(before)).tolist() == h.predict(
    ...     np.concatenate([before, x]))[3:].tolist()
    True
    """

    input: FloatArray

    def __post_init__(self) -> None:
        object.__setattr__(self, "input", as_signal(self.input, "History.input"))


#: What a fit or a prediction may start from: "rest" (None), "periodic", a History, or states
InitialState = str | History | ArrayLike | None


@dataclass(frozen=True)
class ModelState:
    """The state of a model between two blocks of samples.

    Attributes
    ----------
    operators : ndarray, shape (n,)
        Play-operator states (input units, e.g. V).
    terms : tuple of ndarray
        One state per term of the fitted model (see the model's
        :meth:`~HysteresisModel.state_names`): integrals in input unit x s,
        elapsed time in s, creep lags in input units.
    t_last : float or None
        Time (s) of the last sample run, None before any (or for a
        rate-independent model run without times).
    input : ndarray
        The input dynamics' state (delay buffer and lag; empty without them).
    output : ndarray
        The output mode's state (position, velocity; empty without it).
    """

    operators: FloatArray
    terms: tuple[FloatArray, ...] = ()
    t_last: float | None = None
    input: FloatArray = field(default_factory=lambda: np.zeros(0))
    output: FloatArray = field(default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data.

        Returns
        -------
        dict
        """
        return {
            "operators": self.operators.tolist(),
            "terms": [s.tolist() for s in self.terms],
            "t_last": self.t_last,
            "input": self.input.tolist(),
            "output": self.output.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelState:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict

        Returns
        -------
        ModelState
        """
        t_last = data.get("t_last")
        return cls(
            as_signal(data["operators"], "operators").copy(),
            tuple(as_signal(s, "terms", allow_empty=True).copy() for s in data.get("terms", [])),
            None if t_last is None else float(t_last),
            as_signal(data.get("input", []), "input", allow_empty=True).copy(),
            as_signal(data.get("output", []), "output", allow_empty=True).copy(),
        )


@dataclass(frozen=True)
class InverseSpec:
    """What a compensator must invert: the public description of a model's hysteresis part.

    Attributes
    ----------
    operator : Core
        The fitted core (play operators, a Preisach density, ...).
    static : StaticShape or None
        A kept memoryless monotone term (asymmetry).
    lags : LagShape or None
        Kept first-order lags (creep).
    input_range : tuple of float
        The training input range (V); NaN when unknown.
    input_unit, output_unit : str
        The model's units.
    dynamics : InputDynamics
        Delay and lag between the command and the hysteresis (none by default).
    output_dynamics : OutputDynamics
        A mode between the hysteresis and the output (none by default).
    region_tolerance : float
        For a core that records its region (Duhem, Bouc-Wen): how far outside
        it, as a fraction of its output span, counts as extrapolating.
    relaxation : RelaxationShape or None
        A kept slow Preisach core behind a lag (relaxing hysteresis).
    """

    operator: Core
    static: StaticShape | None
    lags: LagShape | None
    input_range: tuple[float, float]
    input_unit: str
    output_unit: str
    dynamics: InputDynamics = field(default_factory=InputDynamics)
    output_dynamics: OutputDynamics = field(default_factory=OutputDynamics)
    region_tolerance: float = 0.05
    relaxation: RelaxationShape | None = None

    @property
    def analytic(self) -> bool:
        """True when eq. 18 inverts it exactly (no kept term beside the play operators)."""
        return self.static is None and self.lags is None and self.relaxation is None


# ------------------------------------------------------------ parameter rules
# A rule checks one constructor argument and returns the value to use; every
# model declares its rules once (``_rules``), merged along the class hierarchy,
# and ``fit`` applies all of them before any work. A test requires a rule for
# every constructor argument.
Rule = Callable[[Any, str, str], Any]


def _unit(value: object, name: str, owner: str) -> str:
    if not isinstance(value, str) or not value:
        msg = f"The '{name}' parameter of {owner} must be a non-empty str. Got {value!r} instead."
        raise ParameterError(msg)
    return value


def _int_in(low: int, high: int) -> Rule:
    def rule(value: object, name: str, owner: str) -> int:
        return check_int(value, name, owner, low, high)

    return rule


def _min_slope(value: object, name: str, owner: str) -> float:
    return check_float(value, name, owner, 0.0, 1.0, low_open=True)


def _bool(value: object, name: str, owner: str) -> bool:
    if not isinstance(value, bool):
        msg = f"The '{name}' parameter of {owner} must be True or False. Got {value!r} instead."
        raise ParameterError(msg)
    return value


def _thresholds(value: object, name: str, owner: str) -> FloatArray | None:
    if value is None:
        return None
    try:
        thr = as_signal(value, name)  # type: ignore[arg-type]
    except ValueError:
        thr = np.array([np.nan])
    if (
        thr.size > 1000
        or not np.all(np.isfinite(thr))
        or thr[0] != 0.0
        or (thr.size > 1 and np.any(np.diff(thr) <= 0))
    ):
        msg = (
            f"The '{name}' parameter of {owner} must be 1 to 1000 strictly increasing "
            f"values starting at 0. Got {thr.tolist()[:8]}{'...' if thr.size > 8 else ''}."
        )
        raise ParameterError(msg)
    return thr


def _growth_terms(value: object, name: str, owner: str) -> tuple[str, ...] | None:
    """None for 'auto' (choose), else the distinct terms in GROWTH_TERMS order."""
    if isinstance(value, str):
        if value != "auto":
            msg = (
                f"The '{name}' parameter of {owner} must be 'auto' or a sequence "
                f"of {list(GROWTH_TERMS)}. Got {value!r} instead."
            )
            raise ParameterError(msg)
        return None
    terms = tuple(value) if isinstance(value, Sequence) else (value,)
    if any(term not in GROWTH_TERMS for term in terms) or len(set(terms)) != len(terms):
        msg = (
            f"The '{name}' parameter of {owner} must hold distinct terms from "
            f"{list(GROWTH_TERMS)}. Got {list(terms)!r} instead."
        )
        raise ParameterError(msg)
    return tuple(t for t in GROWTH_TERMS if t in terms)


def _creep(value: object, name: str, owner: str) -> Creep | None:
    if isinstance(value, Sequence) and not isinstance(value, str):
        if len(value) == 0:
            return None
        try:
            return Creep(value)
        except ParameterError:
            pass
    msg = (
        f"The '{name}' parameter of {owner} must be up to 20 positive time "
        f"constants in s. Got {value!r} instead."
    )
    raise ParameterError(msg)


def _dynamics_kind(value: object, name: str, owner: str) -> str:
    choices = (*DYNAMICS_KINDS, "auto")
    if value not in choices:
        msg = f"The '{name}' parameter of {owner} must be one of {choices}. Got {value!r} instead."
        raise ParameterError(msg)
    return str(value)


def _output_kind(value: object, name: str, owner: str) -> str:
    if value not in ("none", "second-order"):
        msg = (
            f"The '{name}' parameter of {owner} must be 'none' or 'second-order'. "
            f"Got {value!r} instead."
        )
        raise ParameterError(msg)
    return str(value)


def _terms(value: object, name: str, owner: str) -> tuple[Term, ...]:
    if isinstance(value, str | Term) or not isinstance(value, Sequence):
        msg = (
            f"The '{name}' parameter of {owner} must be a sequence of term kinds or Term "
            f"instances. Got {value!r} instead."
        )
        raise ParameterError(msg)
    terms = tuple(make_term(spec) for spec in value)
    kinds = [term.kind for term in terms]
    if len(set(kinds)) != len(kinds):
        msg = f"The '{name}' parameter of {owner} must not repeat a kind. Got {kinds!r}."
        raise ParameterError(msg)
    return terms


def _core_rule(value: object, name: str, owner: str) -> type[Core]:
    if isinstance(value, str):
        found = core_class(value)
        if found is not None:
            return found
    elif isinstance(value, type) and issubclass(value, Core) and value.kind:
        return value
    msg = (
        f"The '{name}' parameter of {owner} must be a registered core (a Core subclass with a "
        f"kind, or one of its names). Got {value!r} instead."
    )
    raise ParameterError(msg)


def _settings_rule(value: object, name: str, owner: str) -> dict[str, Any]:
    if value is None:
        return {}
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return dict(value)
    msg = f"The '{name}' parameter of {owner} must be None or a dict of settings. Got {value!r}."
    raise ParameterError(msg)


SCORE_PIECE = 1 << 16  # samples per piece when scoring a fit (2 MB of temporaries)


class HysteresisModel:
    """A hysteresis core plus terms and dynamics: fit, run, inverse and files (see the module).

    Parameters
    ----------
    core : Core subclass or str, default "play"
        The core to identify, by class or registry name (``"play"``,
        ``"preisach"``, ``"duhem"``, ``"bouc-wen"``, or a core registered by
        subclassing :class:`~piezohyst.cores.base.Core`).
    settings : dict, optional
        The core's own settings, passed to its identification step (e.g.
        ``{"n_operators": 8}`` for play operators).
    terms : sequence of str or Term, default ()
        Terms beside the core (``"integral"``, ``"time"``, a
        :class:`~piezohyst.terms.Term`).
    min_slope : float, default 1e-3
        Lower bound of the core's slope, as a fraction of the mean slope
        ``span(y) / span(x)``: it guarantees the inverse.
    input_unit, output_unit : str, default "V", "C"
        Units recorded with the model.
    input_dynamics : {"none", "delay", "first-order", "delay+first-order", "auto"}
        Dynamics between the logged command and the hysteresis (an amplifier's
        lag, a logging delay), identified jointly by a search around the
        linear solve; ``"auto"`` chooses the kind on a held-out last 30 %.
        Needs the sample times. The result is ``input_dynamics_``.
    output_dynamics : {"none", "second-order"}
        A mechanical mode between the hysteresis and the measured output (for
        displacement records near resonance). The result is ``output_dynamics_``.
    """

    cli_name: ClassVar[str] = ""
    _rules: ClassVar[dict[str, Rule]] = {
        "core": _core_rule,
        "settings": _settings_rule,
        "terms": _terms,
        "min_slope": _min_slope,
        "input_unit": _unit,
        "output_unit": _unit,
        "input_dynamics": _dynamics_kind,
        "output_dynamics": _output_kind,
    }
    selection_: dict[str, float]
    selection_folds_: dict[str, list[float]]
    selection_splits_: list[int]
    input_dynamics_: InputDynamics
    output_dynamics_: OutputDynamics

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        register(cls)

    def __init__(
        self,
        core: type[Core] | str = "play",
        *,
        settings: dict[str, Any] | None = None,
        terms: Sequence[str | Term] = (),
        min_slope: float = 1e-3,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        # the one model class: a core (class or registry name), its settings, terms, dynamics
        self.core = core
        self.settings = settings
        self.terms = terms
        self.min_slope = min_slope
        self.input_unit = input_unit
        self.output_unit = output_unit
        self.input_dynamics = input_dynamics
        self.output_dynamics = output_dynamics

    def _core_class(self) -> type[Core]:
        """The core class this model fits (a preset's class attribute, or the ``core`` setting)."""
        return _core_rule(self.core, "core", type(self).__name__)

    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values() if p.name != "self"]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor arguments, as given (scikit-learn's contract).

        Parameters
        ----------
        deep : bool, default True
            Accepted for scikit-learn; a model holds no sub-estimators.

        Returns
        -------
        dict
            Name to value, read from ``__init__``'s signature.
        """
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params: Any) -> Self:
        """Set constructor arguments (scikit-learn's contract); checked at the next ``fit``.

        Parameters
        ----------
        **params
            Names from :meth:`get_params`; any other name raises.

        Returns
        -------
        HysteresisModel
            ``self``.
        """
        valid = self._param_names()
        for name, value in params.items():
            if name not in valid:
                msg = (
                    f"Invalid parameter {name!r} for {type(self).__name__}. "
                    f"Valid parameters are: {valid}."
                )
                raise ParameterError(msg)
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        sig = inspect.signature(type(self).__init__)
        shown = [
            f"{k}={v!r}"
            for k, v in self.get_params().items()
            if not _same(v, sig.parameters[k].default)
        ]
        return f"{type(self).__name__}({', '.join(shown)})"

    @classmethod
    def parameter_rules(cls) -> dict[str, Rule]:
        """Every constructor argument's rule, declared once per class along its hierarchy.

        Returns
        -------
        dict
            Argument name to a function ``rule(value, name, owner)`` that
            returns the checked value or raises :class:`ParameterError`.
        """
        rules: dict[str, Rule] = {}
        for klass in reversed(cls.__mro__):
            rules.update(vars(klass).get("_rules", {}))
        names = set(cls._param_names())
        return {name: rule for name, rule in rules.items() if name in names}

    def check_params(self) -> dict[str, Any]:
        """Apply every parameter rule (in ``__init__`` order), as ``fit`` does first.

        Returns
        -------
        dict
            The checked values by name.

        Raises
        ------
        ParameterError
            Naming the first argument that breaks its rule.
        """
        rules = self.parameter_rules()
        owner = type(self).__name__
        return {name: rules[name](value, name, owner) for name, value in self.get_params().items()}

    def _terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """Bound terms to fit (kept ones first) and, for a selection, the subsets to choose from."""
        terms = [term.bind(x_range) for term in params.get("terms", ())]
        return [term for term in terms if term.width > 0], None

    def fit(
        self,
        x: ArrayLike,
        y: ArrayLike,
        t: ArrayLike | None = None,
        *,
        initial_state: InitialState = None,
    ) -> Self:
        """Identify the core and every term jointly from input ``x`` and output ``y``.

        Parameters
        ----------
        x : array_like, shape (N,)
            Input (V).
        y : array_like, shape (N,)
            Output (C, or m for displacement data).
        t : array_like, shape (N,), optional
            Sample times (s), strictly increasing, may be non-uniform. Required
            when a term is rate dependent; checked and otherwise unused.
        initial_state : {"rest", "periodic"}, History or array_like, optional
            Where the operators stand before the first sample. ``"rest"``
            (default): at rest at ``x[0]``. ``"periodic"``: the record is one
            period (or whole periods) of a periodic drive that had been
            running, so they start in the periodic steady state (the record
            run again and again until its states repeat) — for a record that
            starts mid-cycle. A :class:`History`: the input before the
            record. An array: the operator states (V) themselves.

        Returns
        -------
        HysteresisModel
            ``self``, fitted.

        Raises
        ------
        ParameterError
            A setting is out of its documented range.
        InsufficientDataError
            Fewer samples than parameters.
        """
        xs = as_signal(x, "x")
        ys = as_signal(y, "y")
        same_length(xs, ys, "x", "y")
        ts = as_time(t, xs.size, required=False, owner=type(self).__name__)
        dyn = InputDynamics()
        us = xs
        owner = type(self).__name__
        kind = _dynamics_kind(self.input_dynamics, "input_dynamics", owner)
        out_kind = _output_kind(self.output_dynamics, "output_dynamics", owner)
        if kind != "none" or out_kind != "none":
            if ts is None:
                msg = (
                    f"{owner}(input_dynamics={kind!r}, output_dynamics={out_kind!r}) needs the "
                    "sample times: pass t= (s)"
                )
                raise TimeAxisError(msg)
            seed_mode = OutputDynamics() if out_kind != "none" else None
            dyn, mode = search_dynamics(self, xs, ys, ts, kind, seed_mode)
            us, _ = dyn.apply(xs, block_dt(ts, 0, ts.size, None))
            if mode is not None:  # the solve filters its columns through it; set_fitted keeps it
                self._fitting_output = mode
        blocks = array_blocks(us, ys, ts)
        try:
            summary = self._fit(blocks, initial_state, ts is not None)
            if self._refine(us, ys, ts, summary, initial_state):
                self._score(blocks, summary)  # the refinement changed the model
        finally:
            self.__dict__.pop("_fitting_output", None)
        if dyn.active:  # commands, their range and slew are the logged input's
            self.input_range_ = (float(xs.min()), float(xs.max()))
            assert ts is not None
            self.max_slew_rate_ = Summary.of(array_blocks(xs, ys, ts)).max_slew_rate
        self.input_dynamics_ = dyn
        return self

    def fit_blocks(
        self, blocks: Blocks, *, timed: bool = True, initial_state: InitialState = None
    ) -> Self:
        """Identify from a record read block by block: memory does not grow with its length.

        The same identification as :meth:`fit` (to rounding): one pass for the
        record's extremes, one accumulating the normal equations, one for the
        fit quality. A file streams in through
        :meth:`piezohyst.io.RecordingStream.blocks`.

        Parameters
        ----------
        blocks : callable
            Called once per pass, returns an iterable of ``(x, y, t)`` blocks
            from the record's start (``t`` in s, or None; strictly increasing
            across blocks, as the caller checks).
        timed : bool, default True
            Whether the blocks carry times.
        initial_state : {"rest", "periodic"}, History or array_like, optional
            As for :meth:`fit` (``"periodic"`` reads the blocks until the
            operator states repeat).

        Returns
        -------
        HysteresisModel
            ``self``, fitted.

        Raises
        ------
        ParameterError
            A setting out of range, or one that needs the record in memory
            (``optimize_thresholds``).
        InsufficientDataError
            A record without excitation, or with fewer samples than parameters.
        """
        if self.get_params().get("optimize_thresholds"):
            msg = (
                f"{type(self).__name__}(optimize_thresholds=True) searches the thresholds over "
                "the record in memory: use fit"
            )
            raise ParameterError(msg)
        if (
            self.get_params().get("input_dynamics", "none") != "none"
            or self.get_params().get("output_dynamics", "none") != "none"
        ):
            msg = (
                f"{type(self).__name__} with input or output dynamics searches them over the "
                "record in memory: use fit"
            )
            raise ParameterError(msg)
        self._fit(blocks, initial_state, timed)
        self.input_dynamics_ = InputDynamics()
        return self

    def _fit(self, blocks: Blocks, initial_state: InitialState, timed: bool) -> Summary:
        params = self.check_params()
        sm = Summary.of(blocks)
        if not sm.x_max - sm.x_min > 1e-12 * max(abs(sm.x_min), abs(sm.x_max), 1e-300):
            msg = (
                f"the input never moves (constant at {sm.x_first:g} {self.input_unit}): "
                "a record without excitation holds no hysteresis to identify"
            )
            raise InsufficientDataError(msg)
        terms, subsets = self._terms_to_fit(sm.x_range, params)
        if not timed and any(term.rate_dependent for term in terms):
            as_time(None, sm.n, required=True, owner=type(self).__name__)  # raises
        job = FitJob(blocks, sm, terms, subsets, initial_state,
                     {**params, **(params.get("settings") or {})}, type(self).__name__,
                     self.input_unit, self.output_unit,
                     self.__dict__.get("_fitting_output"))  # fmt: skip
        self._set_fit(self._core_class().identify(job))
        self.input_range_ = (sm.x_min, sm.x_max)
        self.max_slew_rate_ = sm.max_slew_rate
        self._score(blocks, sm)
        return sm

    def _set_fit(self, fit: CoreFit) -> None:
        """Make this model the identification's result (core, terms, selection scores)."""
        self.set_fitted(fit.core, fit.terms, fit.coefs)
        if fit.selection is not None:
            self.selection_, self.selection_folds_, splits = fit.selection
            self.selection_splits_ = list(splits)

    def _score(self, blocks: Blocks, sm: Summary) -> None:
        """Fit quality over the record (one pass, state carried) and the leakage check."""
        sse = 0.0
        state: ModelState | None = None
        rate = self.rate_dependent_
        with warnings.catch_warnings():  # its own record: no extrapolation warning
            warnings.simplefilter("ignore", ExtrapolationWarning)
            for x_blk, y_blk, t_blk in blocks():
                for a in range(0, x_blk.size, SCORE_PIECE):  # memory O(piece), not O(record)
                    x, y = x_blk[a : a + SCORE_PIECE], y_blk[a : a + SCORE_PIECE]
                    t = t_blk[a : a + SCORE_PIECE] if rate and t_blk is not None else None
                    run = self.propagate(x, t, state)
                    state = run.state
                    r = run.output - y
                    sse += float(np.sum(r * r))  # not BLAS: no thread pool woken for a sum
        self.rmse_ = math.sqrt(sse / sm.n)
        self.nrmse_ = self.rmse_ / max(sm.y_max - sm.y_min, 1e-300)
        self._check_leakage(sm)

    def _check_leakage(self, sm: Summary) -> None:
        """Warn when the identified leakage drains the capacitance faster than one sample."""
        growth = self.growth_coefficients()
        if math.isnan(sm.t_first) or sm.n < 2 or "integral" not in growth:
            return
        conductance = growth["integral"][0]
        capacitance = (sm.y_max - sm.y_min) / (sm.x_max - sm.x_min)  # mean slope, output per input
        dt = (sm.t_last - sm.t_first) / (sm.n - 1)  # mean interval
        if conductance > 0 and capacitance / conductance < dt:
            warnings.warn(
                f"the identified leakage {conductance:.3g} {self.output_unit}/"
                f"({self.input_unit}*s) would discharge the actuator in "
                f"{capacitance / conductance:.3g} s, less than one sample ({dt:.3g} s): check "
                "the time unit",
                UserWarning,
                stacklevel=4,
            )

    def _refine(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        summary: Summary,
        initial_state: InitialState,
    ) -> bool:
        """Optional nonlinear refinement after the linear solve; True if it changed the model."""
        return False

    def set_fitted(
        self, core: Core, terms: tuple[Term, ...], coefs: tuple[FloatArray, ...]
    ) -> None:
        """Make this a fitted model with the given parameters (files, known actuators).

        Fit quality and training range become unknown (NaN) until set.

        Parameters
        ----------
        core : Core
            The fitted core (e.g. play operators, weights, offset and initial state).
        terms : tuple of Term
            Bound terms.
        coefs : tuple of ndarray
            One coefficient array per term.
        """
        self._set_core(core)
        self.terms_ = terms
        self.coefs_ = coefs
        self.selection_ = {}
        self.selection_folds_ = {}
        self.selection_splits_ = []
        self.rmse_ = self.nrmse_ = math.nan  # set by fit; unknown for a model built by hand
        self.input_range_ = (math.nan, math.nan)
        self.max_slew_rate_ = math.nan
        self.input_dynamics_ = InputDynamics()
        self.output_dynamics_ = getattr(self, "_fitting_output", OutputDynamics())

    def _set_core(self, core: Core) -> None:
        """The core and the fitted attributes that describe it."""
        self.operator_ = core
        self.initial_state_ = core.initial_state
        for name, value in core.fitted_attributes().items():
            setattr(self, name, value)

    def _check_fitted(self) -> None:
        if not hasattr(self, "operator_"):
            msg = (
                f"This {type(self).__name__} instance is not fitted yet. Call 'fit' with "
                "input and output data first, or load a saved model with ph.load_model."
            )
            raise NotFittedError(msg)

    @property
    def is_fitted(self) -> bool:
        """True once :meth:`fit` ran (or the model was loaded)."""
        return hasattr(self, "operator_")

    @property
    def rate_dependent_(self) -> bool:
        """True when a fitted term needs the sample times."""
        self._check_fitted()
        return self.input_dynamics_.active or any(term.rate_dependent for term in self.terms_)

    def coefficients(self) -> dict[str, tuple[float, str]]:
        """Every term coefficient with its unit, by label (``"integral"``, ``"creep[1 s]"``).

        Returns
        -------
        dict
            Label to (value, unit).
        """
        self._check_fitted()
        out: dict[str, tuple[float, str]] = {}
        for term, coef in zip(self.terms_, self.coefs_, strict=True):
            units = term.coefficient_units(self.input_unit, self.output_unit)
            for label, c, u in zip(term.labels(), coef, units, strict=True):
                out[label] = (float(c), u)
        return out

    def growth_coefficients(self) -> dict[str, tuple[float, str]]:
        """Coefficients of the growth terms only (what compensation removes).

        Returns
        -------
        dict
            Label to (value, unit).
        """
        self._check_fitted()
        labels = {lab for term in self.terms_ if term.removed for lab in term.labels()}
        return {k: v for k, v in self.coefficients().items() if k in labels}

    def state_names(self) -> tuple[tuple[str, ...], ...]:
        """Names of each fitted term's state slots, in :attr:`ModelState.terms` order.

        Returns
        -------
        tuple of tuple of str
        """
        self._check_fitted()
        return tuple(term.state_names for term in self.terms_)

    def rest_state(self, x0: float) -> ModelState:
        """An actuator resting at input ``x0`` with its memory wiped, no time run yet.

        Parameters
        ----------
        x0 : float
            The voltage it rests at (V): every operator, and every creep lag, sits there.

        Returns
        -------
        ModelState
            Growth integrals at 0, ``t_last`` None.
        """
        self._check_fitted()
        dyn = self.input_dynamics_
        return ModelState(
            self.operator_.rest_state(float(x0)),
            tuple(term.rest_state(float(x0)) for term in self.terms_),
            None,
            dyn.rest_state(float(x0)) if dyn.active else np.zeros(0),
            np.full(2, np.nan) if self.output_dynamics_.active else np.zeros(0),
        )

    def state_after(self, history: ArrayLike, t: ArrayLike | None = None) -> ModelState:
        """The state after running ``history`` from the model's initial state.

        Parameters
        ----------
        history : array_like
            Earlier input samples (V).
        t : array_like, optional
            Their times (s), for rate-dependent models.

        Returns
        -------
        ModelState
        """
        return self.propagate(history, t).state

    def _named_start(
        self, state: str | History, xs: FloatArray, ts: FloatArray | None
    ) -> ModelState | None:
        """ "rest", "periodic" or a History as a start state for the input ``xs``.

        Growth terms start at rest (their integrals count from the record's
        start); input dynamics, when the model has them, settle over the same
        passes as the operators.
        """
        x0 = float(xs[0])
        dyn = self.input_dynamics_
        if isinstance(state, History):
            z = self.operator_.history_state(as_signal(state.input, "history"))
        elif state == "rest":
            return None
        elif state == "periodic":
            if dyn.active:
                assert ts is not None
                dt = block_dt(ts, 0, ts.size, None)
                assert dt is not None
                dt[0] = float(np.median(np.diff(ts))) if ts.size > 1 else 0.0  # the wrap
                inner = dyn.rest_state(x0)
                u = xs
                for _ in range(2):  # the lag settles into the period, then the operators
                    u, inner = dyn.apply(xs, dt, inner)
                z = self.operator_.periodic_state(u)
                terms = tuple(term.rest_state(x0) for term in self.terms_)
                out = np.full(2, np.nan) if self.output_dynamics_.active else np.zeros(0)
                return ModelState(z, terms, None, inner, out)
            z = self.operator_.periodic_state(xs)
        else:
            msg = (
                "'state' must be a ModelState, operator states, 'rest', 'periodic' or a "
                f"History. Got {state!r}."
            )
            raise ParameterError(msg)
        return self._start(z, x0)

    def _start(self, state: ModelState | ArrayLike | None, x0: float) -> ModelState:
        n = self.operator_.initial_state.size
        dyn = self.input_dynamics_
        if state is None:
            return ModelState(
                self.operator_.initial_state.copy(),
                tuple(term.rest_state(x0) for term in self.terms_),
                None,
                dyn.rest_state(x0) if dyn.active else np.zeros(0),
                np.full(2, np.nan) if self.output_dynamics_.active else np.zeros(0),
            )
        if not isinstance(state, ModelState):  # operator states only
            z = as_signal(state, "state").copy()
            if z.size != n:
                msg = (
                    f"'state' must be a ModelState or {n} operator states (V). Got {z.size} values."
                )
                raise ShapeError(msg)
            rest = dyn.rest_state(x0) if dyn.active else np.zeros(0)
            out = np.full(2, np.nan) if self.output_dynamics_.active else np.zeros(0)
            return ModelState(
                z, tuple(term.rest_state(x0) for term in self.terms_), None, rest, out
            )
        z = as_signal(state.operators, "state.operators").copy()
        if z.size != n or len(state.terms) != len(self.terms_):
            msg = (
                f"'state' does not match this model: {n} operators and {len(self.terms_)} "
                f"term states expected, got {z.size} and {len(state.terms)}."
            )
            raise ShapeError(msg)
        terms = []
        for term, s in zip(self.terms_, state.terms, strict=True):
            arr = as_signal(s, "state.terms", allow_empty=True).copy()
            if arr.size != len(term.state_names):
                msg = f"the state of term {term.kind!r} needs {len(term.state_names)} values."
                raise ShapeError(msg)
            terms.append(arr)
        inp = np.array(state.input, dtype=np.float64)
        expected = dyn.rest_state(x0).size if dyn.active else 0
        if inp.size != expected:
            msg = f"the input dynamics state needs {expected} values. Got {inp.size}."
            raise ShapeError(msg)
        outp = np.array(state.output, dtype=np.float64)
        if outp.size != (2 if self.output_dynamics_.active else 0):
            msg = f"the output mode's state needs 2 values. Got {outp.size}."
            raise ShapeError(msg)
        return ModelState(z, tuple(terms), state.t_last, inp, outp)

    def propagate(
        self,
        x: ArrayLike,
        t: ArrayLike | None = None,
        state: ModelState | InitialState = None,
    ) -> Propagation[ModelState]:
        """Output and final state; chunks, each passed the last state, equal one call.

        Parameters
        ----------
        x : array_like, shape (N,)
            Input (V).
        t : array_like, shape (N,), optional
            Times (s); required by rate-dependent models, continuing after
            ``state.t_last``.
        state : ModelState, {"rest", "periodic"}, History or array_like, optional
            Where to start: a :class:`ModelState`; the operator states alone
            (V; terms at rest); ``"periodic"``, the periodic steady state of
            ``x`` run as one period of a periodic drive (for a record that
            starts mid-cycle); a :class:`History` of earlier input; or
            ``"rest"``, at rest at ``x[0]``. Default: the model's initial
            state (where its training record started).

        Returns
        -------
        Propagation
            ``output`` (N,) in output units and the final :class:`ModelState`.
        """
        return self._run(x, t, state, removed_only=False)

    def _run(
        self,
        x: ArrayLike,
        t: ArrayLike | None,
        state: ModelState | InitialState,
        *,
        removed_only: bool,
    ) -> Propagation[ModelState]:
        self._check_fitted()
        xs = as_signal(x, "x", allow_empty=True)
        rate = self.rate_dependent_
        ts = as_time(t, xs.size, required=rate and xs.size > 0, owner=type(self).__name__)
        start: ModelState | ArrayLike | None
        if isinstance(state, History | str):
            start = self._named_start(state, xs, ts) if xs.size else None
        else:
            start = state
        st = self._start(start, float(xs[0]) if xs.size else 0.0)
        if xs.size == 0:
            return Propagation(xs.copy(), st)
        if rate and ts is not None and st.t_last is not None and ts[0] <= st.t_last:
            msg = (
                f"'t' must continue after the state's last time {st.t_last!r}. "
                f"Got t[0]={float(ts[0])!r}."
            )
            raise TimeAxisError(msg)
        if self.input_dynamics_.active:  # the command becomes the voltage on the piezo
            assert ts is not None
            xs, _ = self.input_dynamics_.apply(xs, block_dt(ts, 0, ts.size, st.t_last), st.input)
        if removed_only:
            out = np.zeros_like(xs)
            z = st.operators
        else:
            out, z = self.operator_.propagate(xs, st.operators)
            self._check_region(xs, out)
        use = [j for j, term in enumerate(self.terms_) if term.removed or not removed_only]
        terms = [self.terms_[j] for j in use]
        states = [st.terms[j] for j in use]
        if terms:
            coef = np.concatenate([self.coefs_[j] for j in use])
            t_run = ts if rate else None
            cols = np.empty((min(BLOCK, xs.size), coef.size))
            for start in range(0, xs.size, BLOCK):
                stop = min(start + BLOCK, xs.size)
                block = cols[: stop - start]
                dt = block_dt(t_run, start, stop, st.t_last)
                ts_b = None if t_run is None else t_run[start:stop]
                term_columns(terms, xs[start:stop], ts_b, dt, states, block)
                out[start:stop] += block @ coef
        t_last = float(ts[-1]) if (rate and ts is not None) else st.t_last
        mode = self.output_dynamics_
        if mode.active:  # the mechanical mode between the hysteresis and the displacement
            if removed_only:  # the growth alone, through the mode from rest at its start
                out = mode.apply(out)[0]
            else:
                ms = st.output.reshape(2, 1)
                if np.isnan(ms).any():  # not started yet: at rest at the first output
                    ms[:] = mode.rest_state([out[0]])
                out = mode.apply(out, ms)[0]
        return Propagation(out, ModelState(z, st.terms, t_last, st.input, st.output))

    def _check_region(self, x: FloatArray, core_output: FloatArray) -> None:
        """Warn when a run leaves the (voltage, output) region the core was identified on."""
        region = self.operator_.region
        if region is None or x.size == 0:
            return
        d = region.distance(x, core_output)
        tol = float(getattr(self, "region_tolerance", 0.05)) * region.span
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

    def __setattr__(self, name: str, value: Any) -> None:
        if name.endswith("_"):  # a fitted attribute changed: the fast path is rebuilt
            self.__dict__.pop("_fast", None)
        object.__setattr__(self, name, value)

    def _fast_plan(self) -> tuple[Any, ...] | None:
        """What :meth:`predict` runs in one kernel call, or None (the general path).

        The core decides (play operators plus at most one integral or time
        term); never with input dynamics or an output mode.
        """
        plan: tuple[Any, ...] | None = None
        if not (self.input_dynamics_.active or self.output_dynamics_.active):
            plan = self.operator_.fast_plan(self.terms_, self.coefs_)
        self.__dict__["_fast"] = plan
        return plan

    def predict(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ModelState | InitialState = None
    ) -> FloatArray:
        """Modelled output for input ``x`` (see :meth:`propagate`).

        Parameters
        ----------
        x : array_like, shape (N,)
            Input (V).
        t : array_like, shape (N,), optional
            Times (s), required by rate-dependent models.
        state : ModelState, {"rest", "periodic"}, History or array_like, optional
            Start state; default the model's initial state.

        Returns
        -------
        ndarray, shape (N,)
            Output (output units).

        Notes
        -----
        The classical and active models, from their initial state, run in one
        compiled call that also checks the input (a few microseconds for
        short blocks); the result is :meth:`propagate`'s to rounding (the sums
        are formed in another order, 1e-13 of the output or better).
        """
        if state is None and type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 1:
            try:
                plan = self.__dict__["_fast"]
            except KeyError:
                plan = self._fast_plan() if self.is_fitted else None
            if plan is not None and x.size:
                r, w, z0, offset, kind, coef = plan
                timed = t is not None
                if (not timed and kind == K.FAST_NONE) or (
                    type(t) is np.ndarray and t.dtype == np.float64 and t.shape == x.shape
                ):
                    out = np.empty(x.size)
                    tt = t if timed else x
                    if K.fast_predict(x, tt, timed, r, w, z0, offset, kind, coef, out) < 0:
                        return out
        return self.propagate(x, t, state).output

    def growth(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ModelState | ArrayLike | None = None
    ) -> FloatArray:
        r"""The growth terms alone (output units): what :meth:`remove_growth` subtracts.

        For :class:`ActivePI` this is :math:`R\,y_2` (eq. 19).

        Parameters
        ----------
        x : array_like, shape (N,)
            Input (V).
        t : array_like, shape (N,), optional
            Times (s).
        state : ModelState or array_like, optional
            Start state.

        Returns
        -------
        ndarray, shape (N,)
            Zeros for a model without growth terms.
        """
        return self._run(x, t, state, removed_only=True).output

    def remove_growth(
        self,
        x: ArrayLike,
        y: ArrayLike,
        t: ArrayLike | None = None,
        *,
        leakage: Leakage | None = None,
    ) -> FloatArray:
        r"""Eq. 19: the measured output minus the identified growth, :math:`y - R y_2`.

        For a charge record this is the pure capacitor charge (Fig. 8).

        Parameters
        ----------
        x : array_like, shape (N,)
            Input (V).
        y : array_like, shape (N,)
            Measured output.
        t : array_like, shape (N,), optional
            Times (s).
        leakage : Leakage, optional
            Remove this leakage (e.g. calibrated from holds,
            :func:`~piezohyst.leakage.calibrate_leakage`) instead of the
            model's growth terms; needs ``t``.

        Returns
        -------
        ndarray, shape (N,)
        """
        ys = as_signal(y, "y")
        if leakage is not None:
            if t is None:
                msg = "remove_growth with a leakage needs the sample times t (s). Got t=None."
                raise TimeAxisError(msg)
            g = leakage.charge(x, t, ys if leakage.discharge else None)
        else:
            g = self.growth(x, t)
        same_length(g, ys, "x", "y")
        return np.asarray(ys - g)

    def score(self, x: ArrayLike, y: ArrayLike, t: ArrayLike | None = None) -> float:
        """Coefficient of determination R² of the prediction (scikit-learn's ``score``).

        Parameters
        ----------
        x, y : array_like, shape (N,)
            Input (V) and measured output.
        t : array_like, shape (N,), optional
            Times (s).

        Returns
        -------
        float
            ``1 - SS_res / SS_tot``: 1 is perfect, 0 is predicting the mean.
        """
        ys = as_signal(y, "y")
        pred = self.predict(x, t)
        same_length(pred, ys, "x", "y")
        ss_tot = float(np.sum((ys - ys.mean()) ** 2))
        ss_res = float(np.sum((ys - pred) ** 2))
        return 1.0 - ss_res / ss_tot if ss_tot > 0 else (1.0 if ss_res == 0 else -math.inf)

    def inversion(self) -> InverseSpec:
        """What a compensator must invert: the hysteresis part, growth terms dropped.

        Returns
        -------
        InverseSpec

        Raises
        ------
        ParameterError
            If a kept term is neither a static shape nor lags (nothing can invert it).
        """
        self._check_fitted()
        static: StaticShape | None = None
        lags: LagShape | None = None
        relaxation: RelaxationShape | None = None
        for term, coef in zip(self.terms_, self.coefs_, strict=True):
            if term.removed:
                continue
            s, lag = term.static_shape(coef), term.lag_shape(coef)
            slow = term.relaxation_shape(coef)
            if s is not None and static is None:
                static = s
            elif lag is not None and lags is None:
                lags = lag
            elif slow is not None and relaxation is None:
                relaxation = slow
            else:
                msg = (
                    f"the {term.kind!r} term shapes the hysteresis but cannot be inverted: the "
                    "compensator inverts play operators plus at most one static shape and one "
                    "set of lags"
                )
                raise ParameterError(msg)
        return InverseSpec(
            self.operator_,
            static,
            lags,
            self.input_range_,
            self.input_unit,
            self.output_unit,
            self.input_dynamics_,
            self.output_dynamics_,
            float(getattr(self, "region_tolerance", 0.05)),
            relaxation,
        )

    @property
    def hysteresis_(self) -> HysteresisModel:
        """The model without its growth terms (eq. 19's pure hysteresis), as a fitted model.

        Kept terms (asymmetry, creep) stay: they shape the hysteresis the
        compensator inverts. Same class and settings, growth terms dropped.
        """
        self._check_fitted()
        kept = [(tm, c) for tm, c in zip(self.terms_, self.coefs_, strict=True) if not tm.removed]
        model = type(self)(**self.get_params())
        model.set_fitted(self.operator_, tuple(tm for tm, _ in kept), tuple(c for _, c in kept))
        model.input_range_ = self.input_range_
        model.max_slew_rate_ = self.max_slew_rate_
        model.input_dynamics_ = self.input_dynamics_  # the lag sits before the hysteresis
        model.output_dynamics_ = self.output_dynamics_  # and the mode after it
        return model

    def inverse(self) -> HysteresisModel:
        """The analytic inverse (eq. 18) of the hysteresis part, as a fitted model.

        Its ``predict(desired_output)`` returns the input (V) that produces it
        (growth terms dropped: leaked charge moves nothing).

        Returns
        -------
        HysteresisModel
            Of the same class, units swapped, no terms.

        Raises
        ------
        NotInvertibleError
            If the model keeps a term beside the core (asymmetry, creep): use
            :class:`~piezohyst.Compensator`, which inverts it exactly sample by
            sample; if its core has no closed-form inverse; or if the weights
            violate eq. 18's conditions.
        """
        spec = self.inversion()
        if not spec.analytic:
            msg = (
                f"this {type(self).__name__} keeps asymmetry or creep terms, which have no "
                "closed-form inverse; use ph.Compensator, which inverts them exactly sample by "
                "sample"
            )
            raise NotInvertibleError(msg)
        core = self.operator_.inverse()
        inv = self._bare(self.output_unit, self.input_unit, getattr(core, "n_operators", None))
        inv.set_fitted(core, (), ())
        return inv

    @classmethod
    def from_operator(
        cls,
        op: Core,
        *,
        terms: Sequence[Term] = (),
        coefficients: Sequence[ArrayLike] = (),
        input_unit: str = "V",
        output_unit: str = "C",
    ) -> HysteresisModel:
        """A fitted model around given parameters (a known actuator, a test).

        Parameters
        ----------
        op : Core
            The core (e.g. a :class:`~piezohyst.PIHysteresis`: play operators,
            weights, offset and initial state).
        terms : sequence of Term
            Bound terms (settings fixed), e.g. ``(ph.terms.Integral(),)``.
        coefficients : sequence of array_like
            One array of coefficients per term.
        input_unit, output_unit : str
            Units recorded with the model.

        Returns
        -------
        HysteresisModel
            An instance of ``cls``.
        """
        if len(terms) != len(coefficients):
            msg = f"one coefficient array per term: got {len(terms)} terms, {len(coefficients)}."
            raise ShapeError(msg)
        coefs = tuple(np.array(c, dtype=np.float64).reshape(-1) for c in coefficients)
        for term, c in zip(terms, coefs, strict=True):
            if c.size != term.width:
                msg = f"the {term.kind!r} term takes {term.width} coefficients. Got {c.size}."
                raise ShapeError(msg)
        model = cls._bare(input_unit, output_unit, getattr(op, "n_operators", None))
        if "core" in model.get_params():
            model.core = type(op)
        model.set_fitted(op, tuple(terms), coefs)
        return model

    @classmethod
    def _bare(
        cls, input_unit: str, output_unit: str, n_operators: int | None = None
    ) -> HysteresisModel:
        """An unfitted instance with default settings and these units (and operator count)."""
        model = cls.__new__(cls)
        for p in inspect.signature(cls.__init__).parameters.values():
            if p.name != "self":
                setattr(model, p.name, p.default)
        model.input_unit = input_unit
        model.output_unit = output_unit
        if n_operators is not None and "n_operators" in model.get_params():
            model.n_operators = n_operators
        return model

    def params_to_json(self) -> dict[str, Any]:
        """The constructor arguments as plain JSON data (separate from :meth:`get_params`).

        Returns
        -------
        dict
        """
        return {name: _to_json(value) for name, value in self.get_params().items()}

    @classmethod
    def params_from_json(cls, data: dict[str, Any]) -> dict[str, Any]:
        """Constructor arguments from :meth:`params_to_json` data.

        Parameters
        ----------
        data : dict

        Returns
        -------
        dict
        """
        out = dict(data)
        if "terms" in out:
            out["terms"] = tuple(_term_from_json(v) for v in out["terms"])
        return out

    def to_dict(self) -> dict[str, Any]:
        """The fitted model as plain JSON data, with schema version and checksum.

        Returns
        -------
        dict
        """
        return model_to_dict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> HysteresisModel:
        """Rebuild a fitted model from :meth:`to_dict` data (checked).

        Parameters
        ----------
        data : dict

        Returns
        -------
        HysteresisModel
        """
        model: HysteresisModel = model_from_dict(data, expected=cls)
        return model

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model as JSON (never pickle), atomically, with the umask's permissions.

        Parameters
        ----------
        path : str or os.PathLike
        """
        save_model(self, path)


register(HysteresisModel)  # files of a model built on any core name this class


def _same(a: object, b: object) -> bool:
    try:
        return bool(a == b) if not isinstance(a, np.ndarray) else False
    except (ValueError, TypeError):
        return False


def _to_json(value: object) -> Any:
    if isinstance(value, type) and issubclass(value, Core):
        return value.kind
    if isinstance(value, Term):
        return {"kind": value.kind, "params": value.get_params()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple | list):
        return [_to_json(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _term_from_json(value: object) -> str | Term:
    if isinstance(value, dict):
        return make_term(str(value.get("kind")), value.get("params") or {})
    if isinstance(value, str):
        return value
    msg = f"a term must be a kind name or {{'kind', 'params'}}, got {value!r}"
    raise ParameterError(msg)
