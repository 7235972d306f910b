"""What a compensator inverts: :class:`InverseSpec`, the public description of a fitted
model's hysteresis part (its core, the kept terms beside it, its training range and units,
its input and output dynamics), growth terms dropped. A model gives one
(:meth:`~piezohyst.model.model.HysteresisModel.inversion`); the compensator's engines
(:mod:`piezohyst.control.engines`) read nothing else of the model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..errors import ParameterError
from .cores.base import Core
from .dynamics import InputDynamics, OutputDynamics
from .terms import LagShape, RelaxationShape, StaticShape

__all__ = ["InverseSpec"]


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

    @classmethod
    def of(cls, model: Any) -> InverseSpec:
        """The spec of a fitted model: its core and kept terms, growth terms dropped.

        Parameters
        ----------
        model : HysteresisModel
            Fitted.

        Returns
        -------
        InverseSpec
            The operator (core) to invert and the kept terms beside it.

        Raises
        ------
        ParameterError
            If a kept term is neither a static shape nor lags (nothing can invert it).
        """
        static: StaticShape | None = None
        lags: LagShape | None = None
        relaxation: RelaxationShape | None = None
        for term, coef in zip(model.terms_, model.coefs_, strict=True):
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
        return cls(
            model.operator_,
            static,
            lags,
            model.input_range_,
            model.input_unit,
            model.output_unit,
            model.input_dynamics_,
            model.output_dynamics_,
            float(getattr(model, "region_tolerance", 0.05)),
            relaxation,
        )
