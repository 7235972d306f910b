r"""The one model class: a hysteresis core plus terms and dynamics, one fit path.

A :class:`HysteresisModel` holds a core (:mod:`piezohyst.model.cores`: play
operators, Preisach, Duhem, Bouc-Wen, or one defined outside the library),
terms (:mod:`piezohyst.model.terms`) — growth terms that model charge which moves
nothing and are removed before compensating (the paper's :math:`R\int x\,dt`,
eq. 13-19), and shape terms that stay (asymmetry, creep) — and the input and
output dynamics. It knows nothing of any core's maths: it asks the core (the
:class:`~piezohyst.model.cores.base.Core` contract) to identify itself, run, give
its states, its inverse plan and its file form.

The public presets (:mod:`piezohyst.model.presets`: ``ClassicalPI``, ``ActivePI``,
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

import math
import os
from collections.abc import Sequence
from typing import Any, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, same_length
from ..errors import (
    NotInvertibleError,
)
from ..io.blocks import Blocks, Summary
from .cores.base import Core, Propagation
from .estimator import (
    GROWTH_TERMS,
    Estimator,
    Rule,
    _core_rule,
    _dynamics_kind,
    _min_slope,
    _output_kind,
    _settings_rule,
    _terms,
    _unit,
)
from .fit_record import fit_arrays, fit_stream
from .fit_state import Fitted
from .inverse_spec import InverseSpec
from .persistence import model_from_dict, model_to_dict, register, save_model
from .state import (
    History,
    InitialState,
    ModelState,
    model_table,
    range_warning,
    remove_growth,
    rest_state,
    run_model,
)
from .terms import Term, coefficient_arrays

__all__ = [
    "GROWTH_TERMS",
    "History",
    "HysteresisModel",
    "InitialState",
    "ModelState",
]


#: The settings of the one model class, one rule each (presets add theirs)
MODEL_RULES: dict[str, Rule] = {
    "core": _core_rule,
    "settings": _settings_rule,
    "terms": _terms,
    "min_slope": _min_slope,
    "input_unit": _unit,
    "output_unit": _unit,
    "input_dynamics": _dynamics_kind,
    "output_dynamics": _output_kind,
}


class HysteresisModel(Fitted, Estimator):
    """A hysteresis core plus terms and dynamics: fit, run, inverse and files (see the module).

    Parameters
    ----------
    core : Core subclass or str, default "play"
        The core to identify, by class or registry name (``"play"``,
        ``"preisach"``, ``"duhem"``, ``"bouc-wen"``, or a core registered by
        subclassing :class:`~piezohyst.model.cores.base.Core`).
    settings : dict, optional
        The core's own settings, passed to its identification step (e.g.
        ``{"n_operators": 8}`` for play operators).
    terms : sequence of str or Term, default ()
        Terms beside the core (``"integral"``, ``"time"``, a
        :class:`~piezohyst.model.terms.Term`).
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
    _rules: ClassVar[dict[str, Rule]] = MODEL_RULES

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

    @property
    def core_class(self) -> type[Core]:
        """The core class this model fits (a preset's class attribute, or the ``core`` setting)."""
        return _core_rule(self.core, "core", type(self).__name__)

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """The terms a fit identifies beside the core (a preset overrides this).

        Parameters
        ----------
        x_range : ndarray, shape (2,)
            The record's input range (the terms are bound to it).
        params : dict
            The checked settings (:meth:`check_params`), perhaps with a record's overrides.

        Returns
        -------
        tuple
            Bound terms (kept ones first), and for a selection the subsets to choose from
            (None: fit them all).
        """
        terms = [term.bind(x_range) for term in params.get("terms", ())]
        return [term for term in terms if term.width > 0], None

    def fit(
        self,
        x: ArrayLike,
        y: ArrayLike,
        t: ArrayLike | None = None,
        *,
        initial_state: InitialState = None,
        keep_outliers: bool = False,
    ) -> Self:
        """Identify the core and every term jointly from input ``x`` and output ``y``.

        Parameters
        ----------
        x, y : array_like, shape (N,)
            Input (V) and output (C, or m for displacement data).
        t : array_like, shape (N,), optional
            Sample times (s), strictly increasing, may be non-uniform. Required
            when a term is rate dependent; checked and otherwise unused.
        initial_state : {"rest", "periodic"}, History or array_like, optional
            Where the operators stand before the first sample. ``"rest"`` (default): at
            rest at ``x[0]``. ``"periodic"``: in the periodic steady state of a drive that
            had been running (a record of whole periods that starts mid-cycle). A
            :class:`History`: the input before the record. An array: the states (V).
        keep_outliers : bool, default False
            Keep the isolated outliers (an ADC glitch) the record's check names
            (:mod:`piezohyst.io.screening`); else each is its neighbours' mean.

        Returns
        -------
        HysteresisModel
            ``self``, fitted on the record in memory.

        Raises
        ------
        ParameterError
            A setting is out of its documented range.
        InsufficientDataError
            Fewer samples than parameters.
        """
        fit_arrays(self, x, y, t, initial_state=initial_state, keep_outliers=keep_outliers)
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
        fit_stream(self, blocks, timed=timed, initial_state=initial_state)
        return self

    def refine_fit(
        self, x: FloatArray, y: FloatArray, t: FloatArray | None, summary: Summary,
        initial_state: InitialState,
    ) -> bool:  # fmt: skip
        """A nonlinear refinement after the linear solve (a preset overrides this; the
        classical model's threshold search), applied through :meth:`take_fit`.

        Parameters
        ----------
        x, y, t : ndarray
            The record the model was just fitted on (input after its dynamics).
        summary : Summary
            The record's summary.
        initial_state : {"rest", "periodic"}, History, array_like or None
            As :meth:`fit` took it.

        Returns
        -------
        bool
            True if it changed the model (its score is then computed again).
        """
        return False

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
        return rest_state(self, float(x0))

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

    def propagate(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ModelState | InitialState = None
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
        return run_model(self, x, t, state, removed_only=removed_only)

    def __setattr__(self, name: str, value: Any) -> None:
        if name.endswith("_"):  # a fitted attribute changed: the fast path is rebuilt
            self.__dict__.pop("_fast", None)
        object.__setattr__(self, name, value)

    def _fast_plan(self) -> Any:
        """What :meth:`predict` runs in one kernel call, or None (the general path).

        The core decides (play operators plus at most one integral or time
        term); never with input dynamics or an output mode.
        """
        plan = None
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
        The classical and active models, from their initial state, run in one compiled
        call that also checks the input; the result is :meth:`propagate`'s to rounding
        (1e-13 of the output). An input beyond the identified range warns.
        """
        if state is None and type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 1:
            try:
                plan = self.__dict__["_fast"]
            except KeyError:
                plan = self._fast_plan() if self.is_fitted else None
            if plan is not None and x.size:
                out = plan(x, t)
                if out is not None:
                    range_warning(self, x)
                    return out  # type: ignore[no-any-return]
        return self.propagate(x, t, state).output

    def plot(self, x: ArrayLike, y: ArrayLike, t: ArrayLike | None = None) -> Any:
        """The model against a record: loop, output over time and residual.

        Parameters
        ----------
        x, y : array_like, shape (N,)
            Input (V) and measured output; ``t`` (s) for rate-dependent models.
        t : array_like, optional

        Returns
        -------
        matplotlib.figure.Figure
            A notebook shows it; ``fig.savefig("fit.png")`` writes it.
        """
        from ..plotting import model_figure  # matplotlib loads when a figure is asked for

        return model_figure(self, x, y, t)

    def _repr_html_(self) -> str:
        """A table of the model for notebooks: kind, settings, fit quality, range, terms."""
        return model_table(self)

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
        self, x: ArrayLike, y: ArrayLike, t: ArrayLike | None = None, *, leakage: Any = None
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
            :func:`~piezohyst.calibrate_leakage`) instead of the
            model's growth terms; needs ``t``.

        Returns
        -------
        ndarray, shape (N,)
        """
        return remove_growth(self, x, y, t, leakage)

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
        return InverseSpec.of(self)

    @property
    def hysteresis_(self) -> HysteresisModel:
        """The model without its growth terms (eq. 19's pure hysteresis), as a fitted model.

        Kept terms (asymmetry, creep) stay: they shape the hysteresis the
        compensator inverts. Same class and settings, growth terms dropped.
        """
        self._check_fitted()
        kept = [(tm, c) for tm, c in zip(self.terms_, self.coefs_, strict=True) if not tm.removed]
        model = type(self)(**self.get_params())
        same = (
            "input_range",
            "max_slew_rate",
            "max_step",
            "train_window",
            "input_dynamics",
            "output_dynamics",
        )  # the lag before it, the mode after it
        model.set_fitted(self.operator_, tuple(tm for tm, _ in kept), tuple(c for _, c in kept),
                         **{name: getattr(self, f"{name}_") for name in same})  # fmt: skip
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
        inv.set_fitted(core, (), (), input_range=_outputs_reached(self))  # what inputs reach
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
        coefs = coefficient_arrays(terms, coefficients)
        model = cls._bare(input_unit, output_unit, getattr(op, "n_operators", None))
        if "core" in model.get_params():
            model.core = type(op)
        model.set_fitted(op, tuple(terms), coefs)
        return model

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


def is_model(value: object) -> bool:
    """Whether ``value`` is a piezohyst model (the check at the API edge of banks and
    comparisons; behaviour never depends on which model it is).

    Parameters
    ----------
    value : object

    Returns
    -------
    bool
    """
    return isinstance(value, HysteresisModel)


def _outputs_reached(model: HysteresisModel) -> tuple[float, float]:
    """The core's outputs over the model's training input range (NaN where unknown)."""
    lo, hi = model.input_range_
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return (math.nan, math.nan)
    ends = []
    for path in ([lo, hi, lo, hi], [hi, lo, hi, lo]):  # from where the training record started
        ends.append(model.operator_.propagate(np.array(path), model.initial_state_).output)
    q = np.concatenate(ends)
    return (float(q.min()), float(q.max()))
