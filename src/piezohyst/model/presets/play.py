"""The play-operator presets: :class:`ClassicalPI` (eq. 11-12), :class:`ActivePI` (the
paper's integral, eq. 13-16), :class:`GeneralizedPI` (asymmetry, creep, chosen growth terms)
and :class:`PIModel` (any terms)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import FloatArray
from ...io.blocks import Summary, array_blocks
from ...metrics import rmse
from ..cores.base import FitJob
from ..cores.play import PIHysteresis
from ..estimator import (
    Rule,
    _bool,
    _creep,
    _growth_terms,
    _int_in,
    _min_slope,
    _terms,
    _thresholds,
)
from ..model import HysteresisModel
from ..state import InitialState
from ..terms import Asymmetry, LagShape, StaticShape, Term, make_term
from ._shared import Common, growth_terms_to_fit

__all__ = ["ActivePI", "ClassicalPI", "GeneralizedPI", "PIModel"]


class _PlayFitted:
    """What ``fit`` sets on a play-operator model (attributes, not arguments: declared outside
    the dataclass so they are not its fields)."""

    thresholds_: FloatArray
    weights_: FloatArray
    offset_: float


@dataclass(eq=False, repr=False)
class _PlayModel(HysteresisModel, Common, _PlayFitted):
    """The presets on play operators: their common settings."""

    core = PIHysteresis
    _rules: ClassVar[dict[str, Rule]] = {
        "n_operators": _int_in(1, 1000),
        "thresholds": _thresholds,
        "min_slope": _min_slope,
    }
    n_operators: int = 10
    _: KW_ONLY
    thresholds: ArrayLike | None = None
    min_slope: float = 1e-3


@dataclass(eq=False, repr=False)
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
    _: KW_ONLY
    terms: Sequence[str | Term] = ()

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


@dataclass(eq=False, repr=False)
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
    _rules: ClassVar[dict[str, Rule]] = {
        "growth_terms": _growth_terms,
        "asymmetry": _int_in(0, 50),
        "creep": _creep,
        "optimize_thresholds": _bool,
    }
    _: KW_ONLY
    growth_terms: str | Sequence[str] = "auto"
    asymmetry: int = 3
    creep: Sequence[float] = ()
    optimize_thresholds: bool = False

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        fixed: list[Term] = []
        if params["asymmetry"]:
            fixed.append(Asymmetry(params["asymmetry"]).bind(x_range))
        if params["creep"] is not None:
            fixed.append(params["creep"])
        return growth_terms_to_fit(fixed, params["growth_terms"], x_range)

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
