r"""The public models: thin constructors over the one model class.

Each preset names its core, declares its own settings (with one rule each)
and the terms it fits; everything else — fit, propagate, states, growth,
inversion, files — is :class:`~piezohyst.model.HysteresisModel`'s:

======================  ======================================================
:class:`ClassicalPI`     play operators alone (eq. 11-12)
:class:`ActivePI`        play operators plus the paper's integral (eq. 13-16)
:class:`GeneralizedPI`   play operators plus asymmetry, creep and chosen growth terms
:class:`PIModel`         play operators plus any terms, custom ones included
:class:`PreisachModel`   a Preisach density plus growth (and relaxation) terms
:class:`DuhemModel`      Duhem slopes plus growth terms
:class:`BoucWenModel`    the Bouc-Wen equation plus growth terms
======================  ======================================================
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, check_float
from ..errors import ParameterError
from ..io.blocks import Summary, array_blocks
from ..metrics import rmse
from .cores.base import FitJob
from .cores.boucwen import BoucWenHysteresis
from .cores.duhem import DuhemHysteresis
from .cores.play import PIHysteresis
from .cores.preisach import PreisachHysteresis
from .estimator import (
    GROWTH_TERMS,
    Rule,
    _bool,
    _creep,
    _growth_terms,
    _int_in,
    _min_slope,
    _terms,
    _thresholds,
)
from .model import HysteresisModel, InverseSpec
from .persistence import model_class, model_names
from .state import History, InitialState, ModelState
from .terms import Asymmetry, LagShape, Relaxation, StaticShape, Term, make_term

__all__ = [
    "GROWTH_TERMS",
    "ActivePI",
    "BoucWenModel",
    "ClassicalPI",
    "DuhemModel",
    "GeneralizedPI",
    "History",
    "HysteresisModel",
    "InverseSpec",
    "ModelState",
    "PIModel",
    "PreisachModel",
    "model_class",
    "model_names",
]


def _store(model: HysteresisModel, arguments: dict[str, Any]) -> None:
    """``__init__`` stores its arguments, nothing else (the scikit-learn contract)."""
    for name, value in arguments.items():
        if name not in ("self", "__class__"):
            setattr(model, name, value)


def _growth(
    fixed: list[Term], names: tuple[str, ...] | None, x_range: FloatArray
) -> tuple[list[Term], list[tuple[int, ...]] | None]:
    """Kept terms, then growth terms by name (the term registry); ``names`` None: all of
    them, with every physical subset to choose from (the kept terms in each)."""
    auto = names is None
    chosen = GROWTH_TERMS if names is None else names
    terms = fixed + [make_term(name).bind(x_range) for name in chosen]
    if not auto:
        return terms, None
    base = tuple(range(len(fixed)))
    growth = range(len(fixed), len(terms))
    kind = {j: terms[j].kind for j in growth}

    def physical(combo: tuple[int, ...]) -> bool:
        """A conductance that rises with the voltage (``abs_integral``) presupposes the
        conductance itself (``integral``): on a record of one polarity the two columns nearly
        coincide, and the rise alone fits it as well by chance, not by physics."""
        names = {kind[j] for j in combo}
        return "abs_integral" not in names or "integral" in names or "integral" not in chosen

    subsets = [base + combo for size in range(len(chosen) + 1)
               for combo in itertools.combinations(growth, size) if physical(combo)]  # fmt: skip
    return terms, subsets


class _PlayModel(HysteresisModel):
    """The presets on play operators: their common settings."""

    core = PIHysteresis
    n_operators: int
    thresholds_: FloatArray
    weights_: FloatArray
    offset_: float
    _rules: ClassVar[dict[str, Rule]] = {
        "n_operators": _int_in(1, 1000),
        "thresholds": _thresholds,
        "min_slope": _min_slope,
    }

    def __init__(
        self,
        n_operators: int = 10,
        *,
        thresholds: ArrayLike | None = None,
        min_slope: float = 1e-3,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        _store(self, locals())


class PIModel(_PlayModel):
    """Prandtl-Ishlinskii play operators plus any terms, custom ones included.

    Parameters
    ----------
    n_operators : int, default 10
        Play operators including the linear one.
    terms : sequence of str or Term, default ()
        Term kinds (``"integral"``, ``"time"``, ``"abs_integral"``,
        ``"asymmetry"``, ``"creep"``) or :class:`~piezohyst.model.terms.Term`
        instances, custom ones included.
    thresholds, min_slope, input_unit, output_unit
        As for :class:`ClassicalPI`.

    Attributes
    ----------
    operator_ : PIHysteresis
        The identified play operators (thresholds, weights, offset, initial state).
    thresholds_, weights_, offset_, initial_state_
        Its parameters.
    terms_ : tuple of Term
        The fitted terms (data-dependent settings fixed).
    coefs_ : tuple of ndarray
        Their coefficients (see :meth:`coefficients` for labels and units).
    rmse_, nrmse_ : float
        Training fit: RMSE (output units) and RMSE / output span.
    input_range_ : tuple of float
        Smallest and largest training input (V).
    selection_ : dict
        Held-out RMSE of every term subset tried (models that select terms),
        pooled over the folds of a forward-chaining time-series
        cross-validation; ``selection_folds_`` holds each fold's.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> rec = ph.simulate(duration=4.0)
    >>> m = ph.PIModel(8, terms=("integral", "time")).fit(rec.voltage, rec.charge, t=rec.t)
    >>> sorted(m.coefficients())
    ['integral', 'time']
    """

    cli_name = ""
    _rules: ClassVar[dict[str, Rule]] = {"terms": _terms}

    def __init__(
        self,
        n_operators: int = 10,
        *,
        terms: Sequence[str | Term] = (),
        thresholds: ArrayLike | None = None,
        min_slope: float = 1e-3,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        _store(self, locals())

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`: its terms, bound
        to the input range (empty ones dropped)."""
        terms = [term.bind(x_range) for term in params["terms"]]
        return [term for term in terms if term.width > 0], None


class ClassicalPI(_PlayModel):
    r"""Classical (passive, rate-independent) Prandtl-Ishlinskii model, eq. 11-12.

    .. math:: y(t) = c + \sum_{i=0}^{n-1} w_i\, H_{r_i}[x](t), \qquad r_0 = 0

    Parameters
    ----------
    n_operators, thresholds, min_slope, input_unit, output_unit
        As for :class:`HysteresisModel`.

    Attributes
    ----------
    operator_ : PIHysteresis
        The immutable identified operator (thresholds, weights, offset, initial state).
    thresholds_, weights_ : ndarray
        Identified thresholds (input units) and weights (output/input units).
    offset_ : float
        Output offset (output units).
    initial_state_ : ndarray
        Operator states before the first training sample (input units).
    rmse_, nrmse_ : float
        Training fit quality: RMSE (output units) and RMSE / output span.
    input_range_ : tuple of float
        Smallest and largest training input (V): where the model was seen
        working, and the default voltage limits of the compensator commands.
    max_slew_rate_ : float
        Fastest input change in the training record (V/s; NaN without times):
        the default slew limit of a :class:`~piezohyst.Compensator` that knows
        its sample rate, and of ``piezohyst compensate``.
    max_step_ : float
        Largest input change from one training sample to the next (V): the
        default limit per sample of a compensator that does not.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> v = 70 - 70 * np.cos(np.linspace(0, 6 * np.pi, 600))
    >>> true = ph.PIHysteresis([0, 20, 40], [1.0, 0.5, -0.3])
    >>> model = ph.ClassicalPI(thresholds=[0, 20, 40]).fit(v, true.predict(v))
    >>> bool(model.nrmse_ < 1e-9)
    True
    """

    cli_name = "classical-pi"


class ActivePI(_PlayModel):
    r"""Active (time-dependent) Prandtl-Ishlinskii model, eq. 13-16.

    A classical PI model plus one integrator with growth rate :math:`R`:

    .. math::

        y(t) = c + \sum_i w_i\, H_{r_i}[x](t) + R\, y_2(t), \qquad
        y_2(t_k) = y_2(t_{k-1}) + x(t_k)\,(t_k - t_{k-1}), \quad y_2(t_0) = 0

    For a charge output, :math:`R` is the leakage conductance (C/(V s) = S) of
    the resistor in parallel with the piezo (Fig. 3). All parameters are
    identified jointly (eq. 16-17) with the slope constraints that guarantee
    the inverse of the hysteresis part. The time stamps may be non-uniform.

    Parameters are those of :class:`ClassicalPI`; ``fit`` needs ``t``.

    Attributes
    ----------
    growth_rate_ : float
        :math:`R` in output units per (input unit x s); S for V to C.
    hysteresis_ : ClassicalPI
        The pure hysteresis part :math:`y_1` (eq. 19), leakage removed; its
        ``inverse()`` is the feedforward compensator of eq. 18.

    Notes
    -----
    The state (:class:`ModelState`) holds the operator states, the integral
    :math:`y_2` (V s) and the last time stamp. ``inverse()`` inverts the
    hysteresis part only: leaked charge moves nothing.
    """

    cli_name = "active-pi"

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        return [make_term("integral")], None

    @property
    def growth_rate_(self) -> float:
        """:math:`R` (output per input unit and s; S for V to C)."""
        self._check_fitted()
        growth = self.growth_coefficients()  # built without the integral: no leakage
        return float(growth["integral"][0]) if "integral" in growth else 0.0


class GeneralizedPI(_PlayModel):
    r"""Generalized PI model: PI + asymmetry + creep + selectable growth terms.

    .. math::

        y = c + \sum_i w_i H_{r_i}[x]
            + \underbrace{\sum_j \frac{u_j (x - k_j)_+^2 - d_j (k_j - x)_+^2}{s}}_{\text{asymmetry}}
            + \underbrace{\sum_k g_k L_{\tau_k}[x]}_{\text{creep}}
            + \underbrace{\sum_m R_m G_m[x]}_{\text{growth}}

    Every term is linear in its coefficient, so all are identified jointly by
    the one bounded least-squares solve; the hysteresis part stays strictly
    increasing in the current input and is inverted exactly, sample by
    sample, by :class:`~piezohyst.Compensator`.

    Parameters
    ----------
    n_operators, thresholds, min_slope, input_unit, output_unit
        As for :class:`ClassicalPI`.
    growth_terms : "auto" or sequence of str, default "auto"
        Growth terms among ``"integral"`` (ohmic leakage), ``"time"`` (a
        constant bias current), ``"abs_integral"`` (leakage rising with the
        voltage); ``()`` for none. On a displacement record (``output_unit`` a
        length) ``"auto"`` means none, with creep operators timed by the record
        when ``creep`` is left empty. ``"auto"`` fits every subset on the first
        70 % of the record, scores it on the last 30 % (the model running
        through the whole record; one accumulation, subsets solved on
        sub-matrices) and keeps the best; ``"abs_integral"`` only beside
        ``"integral"`` (a rising conductance presupposes the conductance: on a
        record of one polarity the rise alone fits as well by chance, and on
        a two-state capacitor it left 7.7 % held out where both left 3.6 %).
    asymmetry : int, default 3
        Knots of the static monotone term (0 turns it off).
    creep : sequence of float, default ()
        Time constants (s) of the creep operators, e.g. ``(0.1, 1, 10)``.
    optimize_thresholds : bool, default False
        Refine the thresholds by bounded nonlinear least squares around the
        linear solve (L-BFGS-B over threshold increments; slower).

    Attributes
    ----------
    growth_terms_ : tuple of str
        Growth terms used; ``growth_coefs_`` their coefficients.
    knots_, static_up_, static_down_, static_scale_
        Asymmetry term (V, output/V, output/V, V); empty when off.
    creep_taus_, creep_gains_ : ndarray
        Creep time constants (s) and gains (output/V).
    selection_ : dict
        Held-out RMSE of every growth subset tried (``growth_terms="auto"``),
        pooled over 4 forward-chaining folds (the first 40 % trains, each later
        block is predicted from everything before it).
    selection_folds_ : dict
        The same per fold, in time order. Each fold holds two or more
        reversals of the input (at most 4 folds); a record with fewer has one
        test block, its last 30 %.
    selection_splits_ : list of int
        The first sample of each fold, then the record's length.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> rec = ph.simulate(duration=10.0)
    >>> model = ph.GeneralizedPI(10).fit(rec.voltage, rec.charge, t=rec.t)
    >>> bool(model.nrmse_ < 0.005), len(model.growth_terms_) > 0
    (True, True)
    >>> len(model.selection_folds_["none"])      # forward-chaining folds, each a few cycles
    3
    """

    cli_name = "generalized-pi"
    optimize_thresholds: bool
    _rules: ClassVar[dict[str, Rule]] = {
        "growth_terms": _growth_terms,
        "asymmetry": _int_in(0, 50),
        "creep": _creep,
        "optimize_thresholds": _bool,
    }

    def __init__(
        self,
        n_operators: int = 10,
        *,
        growth_terms: str | Sequence[str] = "auto",
        asymmetry: int = 3,
        creep: Sequence[float] = (),
        optimize_thresholds: bool = False,
        thresholds: ArrayLike | None = None,
        min_slope: float = 1e-3,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        _store(self, locals())

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        fixed: list[Term] = []
        if params["asymmetry"]:
            fixed.append(Asymmetry(params["asymmetry"]).bind(x_range))
        if params["creep"] is not None:
            fixed.append(params["creep"])
        return _growth(fixed, params["growth_terms"], x_range)

    def refine_fit(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray | None,
        summary: Summary,
        initial_state: InitialState,
    ) -> bool:
        """See :meth:`~piezohyst.model.model.HysteresisModel.refine_fit`: nonlinear least
        squares over the thresholds, the linear solve inside."""
        if not self.optimize_thresholds or self.thresholds_.size < 2:
            return False
        from scipy.optimize import minimize

        terms = list(self.terms_)
        kept = self.output_dynamics_  # the mode the fit found, if any: the solve filters through it
        mode = kept if kept.active else None
        selection, folds, splits = self.selection_, self.selection_folds_, self.selection_splits_
        span = max(float(np.ptp(x)), 1e-300)
        start = np.log(np.diff(self.thresholds_) / span)
        t_fit = t if self.rate_dependent_ else None
        blocks = array_blocks(x, y, t_fit)
        params = self.check_params()

        def objective(logs: FloatArray) -> float:
            thr = np.concatenate([[0.0], np.cumsum(np.exp(logs) * span)])
            if thr[-1] >= span:  # a play wider than the range never reverses
                return 1e300
            job = FitJob(blocks, summary, terms, None, initial_state, {**params, "thresholds": thr},
                         type(self).__name__, self.input_unit, self.output_unit, mode)  # fmt: skip
            self.take_fit(PIHysteresis.identify(job), output_dynamics=kept)
            return rmse(self.predict(x, t=t_fit), y) / span

        before = objective(start)
        res = minimize(objective, start, method="L-BFGS-B", options={"maxiter": 30})
        objective(res.x if res.fun < before else start)
        self.take_fit(selection=selection, selection_folds=folds, selection_splits=splits)
        return True

    def set_fitted(
        self, core: Any, terms: tuple[Term, ...], coefs: tuple[FloatArray, ...], **facts: Any
    ) -> None:
        """See :meth:`HysteresisModel.set_fitted`; also sets the 0.1 names of the terms."""
        super().set_fitted(core, terms, coefs, **facts)
        static = StaticShape(np.zeros(0), np.zeros(0), np.zeros(0), 1.0)
        lags = LagShape(np.zeros(0), np.zeros(0))
        growth: list[tuple[str, FloatArray]] = []
        for term, coef in zip(terms, coefs, strict=True):
            static = term.static_shape(coef) or static
            lags = term.lag_shape(coef) or lags
            if term.removed:
                growth.append((term.kind, coef))
        self.knots_, self.static_scale_ = static.knots, static.scale
        self.static_up_, self.static_down_ = static.up, static.down
        self.creep_taus_, self.creep_gains_ = lags.taus, lags.gains
        self.growth_terms_ = tuple(kind for kind, _ in growth)
        self.growth_coefs_ = np.concatenate([c for _, c in growth]) if growth else np.zeros(0)


# ---------------------------------------------------- cores beyond play operators
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


def _signed_rule(value: object, name: str, owner: str) -> bool | str:
    if value == "auto" or isinstance(value, bool):
        return value
    msg = f"The {name!r} parameter of {owner} must be True, False or 'auto'. Got {value!r} instead."
    raise ParameterError(msg)


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


#: The settings every preset on a packed core shares (beside the base class's)
PACKED_RULES: dict[str, Rule] = {
    "growth_terms": _growth_terms,
    "creep": _creep,
    "region_tolerance": _nonneg,
}


def _packed_terms(
    params: dict[str, Any], x_range: FloatArray, *kept: Term
) -> tuple[list[Term], list[tuple[int, ...]] | None]:
    """Creep lags and ``kept`` terms (they shape the hysteresis), then the growth terms."""
    fixed = ([] if params["creep"] is None else [params["creep"]]) + list(kept)
    return _growth(fixed, params["growth_terms"], x_range)


class PreisachModel(HysteresisModel):
    r"""The Preisach model, identified from data as an Everett function, plus growth terms.

    .. math::

        y = q + \sum_j c_j g_j(t), \qquad
        q(v) = q(a) + E(a, v) \text{ rising from a minimum } a, \qquad
        q(v) = q(b) - E(v, b) \text{ falling from a maximum } b

    with the wiping-out rule on the stack of reversal points
    (:class:`~piezohyst.model.cores.preisach.PreisachHysteresis`). Its minor loops are
    not congruent copies of each other (PI's limit): each has the shape its
    place in the major loop gives it; and they close (return-point memory), so
    a steady periodic drive gives a steady output. The output is linear in
    the Preisach density given the input alone, so one bounded least squares
    (density ``>= 0``, its diagonal ``>=`` the smallest slope; or signed, see
    ``signed``), joint with the growth terms and a light curvature penalty,
    *is* its output-error fit.
    Learnt from loops of many sizes (the simulator's ``decaying`` signal):
    cells of the density the record never visits only get the penalty's
    interpolation.

    Parameters
    ----------
    nodes : int, default 16
        Grid nodes over the training voltage range, in [3, 60]; the density
        has ``(nodes - 1) nodes / 2`` cells.
    growth_terms : "domain", "auto" or sequence of str, default "domain"
        Among ``"integral"``, ``"time"``, ``"abs_integral"``. ``"domain"``: the
        record's: ``("integral",)`` (the charge's leakage) on a charge record, with
        ``"abs_integral"`` (its conductance rising with the voltage) where the record's
        holds show that rise (:func:`~piezohyst.model.fit_record.holds_show_rise`), and
        none on a displacement record (``output_unit`` a length: the displacement
        does not see leaked charge; ``"auto"`` chooses none there either), where
        creep operators timed by the record take the drift instead when ``creep``
        is left empty (:func:`~piezohyst.model.fit_record.displacement_terms`).
        Fitted jointly (its loops close: a drift can only be growth);
        ``"auto"``: the Prandtl-Ishlinskii proxy's cross-validation chooses them.
    creep : sequence of float, default ()
        Time constants (s) of kept creep lags beside the core, e.g.
        ``(0.005, 0.02, 0.05, 0.2, 0.5, 2)``: first-order lags of the voltage
        with gains ``>= 0``, fitted in the same least squares (the output stays
        linear in every coefficient) and inverted with the core by the compensator.
    relaxation : float, optional
        Time constant (s) of a relaxing part of the hysteresis
        (:class:`~piezohyst.model.terms.Relaxation`): a second Preisach density on
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
        point, as from an extremum. ``"auto"`` fits both and keeps the
        initial loading curve unless the branch's RMSE is below 0.9 of its
        own (the paper's experiment, the simulated bench from rest at 0 V:
        the curve 0.07 %, a branch 0.96 %). Where the record never falls back
        to its rest voltage the two fit alike and the curve predicts other
        records better: on decaying loops of plants of other physics, full
        cycles to 1.0-2.5 % where a branch left 3.3-7.0 %
        (``cores.preisach.BRANCH_GAIN``).
    smoothing : float, default 1e-4
        Weight of the curvature penalty on the density, relative to the data's.
    signed : bool or "auto", default "auto"
        A density ``>= 0`` makes every branch steepen after a reversal; a
        branch that flattens instead (a PI model's negative weights, a
        Bouc-Wen capacitor) needs negative density off the diagonal. True
        fits the density as a PI part (one signed value per loop width, its
        partial sums ``>=`` the smallest slope) plus a part ``>= 0``, so
        every branch still increases (the core checks its sums from the
        diagonal). ``"auto"`` keeps the signed one only where its RMSE is
        below half that of the density ``>= 0`` (tried only where the PI part
        alone already fits better, the sign that the loops flatten): on a
        Bouc-Wen capacitor 0.70 % against 3.80 % (held out 2.9 % against
        10.4 %); the simulated Preisach capacitor keeps its density ``>= 0``
        (0.17 % either way).
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
    core = PreisachHysteresis
    _rules: ClassVar[dict[str, Rule]] = {
        **PACKED_RULES,
        "nodes": _nodes_rule,
        "relaxation": _relaxation,
        "relaxation_nodes": _relaxation_nodes,
        "rest": _rest_rule,
        "smoothing": _nonneg,
        "signed": _signed_rule,
    }

    def __init__(
        self,
        nodes: int = 16,
        *,
        growth_terms: str | Sequence[str] = "domain",
        creep: Sequence[float] = (),
        relaxation: float | None = None,
        relaxation_nodes: int = 12,
        rest: str = "auto",
        smoothing: float = 1e-4,
        signed: bool | str = "auto",
        min_slope: float = 0.02,
        region_tolerance: float = 0.05,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        _store(self, locals())

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        tau = params["relaxation"]
        if tau is None:
            return _packed_terms(params, x_range)
        slow = Relaxation(tau, params["relaxation_nodes"]).bind(x_range)
        return _packed_terms(params, x_range, slow)


class DuhemModel(HysteresisModel):
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
    growth_terms : "domain", "auto" or sequence of str, default "domain"
        Among ``"integral"``, ``"time"``, ``"abs_integral"``. ``"domain"``: the
        record's: ``("integral",)`` (the charge's leakage) on a charge record, with
        ``"abs_integral"`` (its conductance rising with the voltage) where the record's
        holds show that rise (:func:`~piezohyst.model.fit_record.holds_show_rise`), and
        none on a displacement record (``output_unit`` a length: the displacement
        does not see leaked charge; ``"auto"`` chooses none there either), where
        creep operators timed by the record take the drift instead when ``creep``
        is left empty (:func:`~piezohyst.model.fit_record.displacement_terms`).
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
        As for :class:`~piezohyst.model.presets.HysteresisModel`.

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
    core = DuhemHysteresis
    _rules: ClassVar[dict[str, Rule]] = {
        **PACKED_RULES,
        "grid": _grid,
        "smoothing": _nonneg,
        "refine": _bool,
    }

    def __init__(
        self,
        grid: tuple[int, int] = (8, 6),
        *,
        growth_terms: str | Sequence[str] = "domain",
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
        _store(self, locals())

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        return _packed_terms(params, x_range)


class BoucWenModel(HysteresisModel):
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
    growth_terms : "domain", "auto" or sequence of str, default "domain"
        Among ``"integral"``, ``"time"``, ``"abs_integral"``. ``"domain"``: the
        record's: ``("integral",)`` (the charge's leakage) on a charge record, with
        ``"abs_integral"`` (its conductance rising with the voltage) where the record's
        holds show that rise (:func:`~piezohyst.model.fit_record.holds_show_rise`), and
        none on a displacement record (``output_unit`` a length: the displacement
        does not see leaked charge; ``"auto"`` chooses none there either), where
        creep operators timed by the record take the drift instead when ``creep``
        is left empty (:func:`~piezohyst.model.fit_record.displacement_terms`).
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
    core = BoucWenHysteresis
    _rules: ClassVar[dict[str, Rule]] = PACKED_RULES

    def __init__(
        self,
        growth_terms: str | Sequence[str] = "domain",
        *,
        creep: Sequence[float] = (),
        min_slope: float = 1e-3,
        region_tolerance: float = 0.05,
        input_unit: str = "V",
        output_unit: str = "C",
        input_dynamics: str = "none",
        output_dynamics: str = "none",
    ) -> None:
        _store(self, locals())

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        return _packed_terms(params, x_range)
