"""The packed-core presets: :class:`PreisachModel` (a Preisach density, with relaxation),
:class:`DuhemModel` (Duhem slopes) and :class:`BoucWenModel` (the Bouc-Wen equation), each
with growth (and creep) terms."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass
from typing import Any, ClassVar

import numpy as np

from ..._validation import FloatArray, check_float
from ...errors import ParameterError
from ..cores.boucwen import BoucWenHysteresis
from ..cores.duhem import DuhemHysteresis
from ..cores.preisach import PreisachHysteresis
from ..estimator import (
    Rule,
    _bool,
    _creep,
    _growth_terms,
)
from ..model import HysteresisModel
from ..terms import Relaxation, Term
from ._shared import Common, growth_terms_to_fit

__all__ = ["BoucWenModel", "DuhemModel", "PreisachModel"]


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
    return growth_terms_to_fit(fixed, params["growth_terms"], x_range)


@dataclass(eq=False, repr=False)
class PreisachModel(HysteresisModel, Common):
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

    nodes: int = 16
    _: KW_ONLY
    growth_terms: str | Sequence[str] = "domain"
    creep: Sequence[float] = ()
    relaxation: float | None = None
    relaxation_nodes: int = 12
    rest: str = "auto"
    smoothing: float = 1e-4
    signed: bool | str = "auto"
    min_slope: float = 0.02
    region_tolerance: float = 0.05

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        tau = params["relaxation"]
        if tau is None:
            return _packed_terms(params, x_range)
        slow = Relaxation(tau, params["relaxation_nodes"]).bind(x_range)
        return _packed_terms(params, x_range, slow)


@dataclass(eq=False, repr=False)
class DuhemModel(HysteresisModel, Common):
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
    >>> model.operator_.up.shape, model.operator_.is_invertible   # the rising slopes' grid
    ((8, 6), True)
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

    grid: tuple[int, int] = (8, 6)
    _: KW_ONLY
    growth_terms: str | Sequence[str] = "domain"
    creep: Sequence[float] = ()
    smoothing: float = 1e-3
    min_slope: float = 0.02
    refine: bool = True
    region_tolerance: float = 0.05

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        return _packed_terms(params, x_range)


@dataclass(eq=False, repr=False)
class BoucWenModel(HysteresisModel, Common):
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

    growth_terms: str | Sequence[str] = "domain"
    _: KW_ONLY
    creep: Sequence[float] = ()
    min_slope: float = 1e-3
    region_tolerance: float = 0.05

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]:
        """See :meth:`~piezohyst.model.model.HysteresisModel.terms_to_fit`."""
        return _packed_terms(params, x_range)
