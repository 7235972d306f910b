"""A model's fitted state and its one writer.

:class:`Fitted` is the base of :class:`~piezohyst.model.model.HysteresisModel` that
holds what a fit found: the core and terms (:meth:`Fitted.set_fitted`), and the facts
beside them (fit quality, the training record's range, slew and window, the growth
selection's scores, the dynamics). The fit's steps (:mod:`piezohyst.model.fit_record`)
compute these and hand them to ``take_fit``; nothing else sets them.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import NotFittedError
from ..io.blocks import Summary
from .cores.base import Core, CoreFit, Propagation
from .dynamics import InputDynamics, OutputDynamics
from .state import InitialState, ModelState
from .terms import Term

__all__ = ["FIT_FACTS", "Fittable", "Fitted", "unknown_facts"]


def unknown_facts() -> dict[str, Any]:
    """What a fit learns beside the parameters, unknown (a model built by hand or just set
    fitted): fit quality, the training record's range, slew and window, the growth
    selection's scores, the input and output dynamics."""
    return {
        "rmse": math.nan,
        "nrmse": math.nan,
        "input_range": (math.nan, math.nan),
        "max_slew_rate": math.nan,
        "max_step": math.nan,
        "train_window": (math.nan, math.nan),
        "selection": {},
        "selection_folds": {},
        "selection_splits": [],
        "input_dynamics": InputDynamics(),
        "output_dynamics": OutputDynamics(),
    }


#: The facts a model takes (each stored as ``name_``; see :func:`unknown_facts`)
FIT_FACTS = frozenset(unknown_facts())


class Fittable(Protocol):
    """What the fit's steps (:mod:`~piezohyst.model.fit_record`,
    :mod:`~piezohyst.model.fit_dynamics`) read from a model and hand back to it: its
    settings, the terms it fits, an optional refinement, its one writer
    (:meth:`Fitted.take_fit`), and its run over the record for the score.
    :class:`~piezohyst.model.model.HysteresisModel` is one.

    Attributes
    ----------
    input_unit, output_unit : str
    input_dynamics, output_dynamics : str
        The dynamics settings ("none", "auto", a kind).
    core_class : type of Core
    rate_dependent_ : bool
    """

    input_unit: str
    output_unit: str
    input_dynamics: str
    output_dynamics: str

    @property
    def core_class(self) -> type[Core]: ...

    @property
    def rate_dependent_(self) -> bool: ...

    def get_params(self, deep: bool = True) -> dict[str, Any]: ...

    def check_params(self) -> dict[str, Any]: ...

    def terms_to_fit(
        self, x_range: FloatArray, params: dict[str, Any]
    ) -> tuple[list[Term], list[tuple[int, ...]] | None]: ...

    def refine_fit(
        self, x: FloatArray, y: FloatArray, t: FloatArray | None, summary: Summary,
        initial_state: InitialState,
    ) -> bool: ...  # fmt: skip

    def take_fit(self, fit: CoreFit | None = None, **facts: Any) -> None: ...

    def predict(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ModelState | InitialState = None
    ) -> FloatArray: ...

    def propagate(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ModelState | InitialState = None
    ) -> Propagation[ModelState]: ...

    def growth_coefficients(self) -> dict[str, tuple[float, str]]: ...


class Fitted:
    """The fitted attributes of a model and the methods that set them (see the module)."""

    # fitted attributes (``set_fitted`` and ``take_fit``, their one writer)
    operator_: Core
    initial_state_: FloatArray
    terms_: tuple[Term, ...]
    coefs_: tuple[FloatArray, ...]
    rmse_: float
    nrmse_: float
    input_range_: tuple[float, float]
    max_slew_rate_: float
    max_step_: float  # largest input change from one training sample to the next (V)
    #: times (s) of the first and last training samples (NaN without times)
    train_window_: tuple[float, float]
    selection_: dict[str, float]
    selection_folds_: dict[str, list[float]]
    selection_splits_: list[int]
    input_dynamics_: InputDynamics
    output_dynamics_: OutputDynamics

    def set_fitted(
        self, core: Core, terms: tuple[Term, ...], coefs: tuple[FloatArray, ...], **facts: Any
    ) -> None:
        """Make this a fitted model with the given parameters (files, known actuators).

        Fit quality and training range become unknown (NaN) unless given.

        Parameters
        ----------
        core : Core
            The fitted core (e.g. play operators, weights, offset and initial state).
        terms : tuple of Term
            Bound terms.
        coefs : tuple of ndarray
            One coefficient array per term.
        **facts
            What the fit learned beside the parameters, by name (:data:`FIT_FACTS`:
            ``rmse``, ``input_range``, ``train_window``, ...; a model file's).
        """
        self.operator_ = core
        self.initial_state_ = core.initial_state
        for name, value in core.fitted_attributes().items():
            setattr(self, name, value)
        self.terms_, self.coefs_ = terms, coefs
        self.take_fit(**{**unknown_facts(), **facts})  # unknown for a model built by hand

    def take_fit(self, fit: CoreFit | None = None, **facts: Any) -> None:
        """Apply what a fit found, the one writer of the fitted attributes: its core, terms
        and selection scores, then the facts named in :data:`FIT_FACTS` (each stored as
        ``name_``).

        Parameters
        ----------
        fit : CoreFit, optional
            The core, terms and coefficients identified (None: facts alone).
        **facts
            By name (:data:`FIT_FACTS`); another name is refused.
        """
        if fit is not None:
            self.set_fitted(fit.core, fit.terms, fit.coefs)
            if fit.selection is not None:
                sel, folds, splits = fit.selection
                facts = {"selection": sel, "selection_folds": folds,
                         "selection_splits": list(splits), **facts}  # fmt: skip
        for name, value in facts.items():
            if name not in FIT_FACTS:
                raise TypeError(f"{name!r} is not a fact a fit sets")
            setattr(self, f"{name}_", value)

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
