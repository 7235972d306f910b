"""A model's fitted state and its one writer.

:class:`Fitted` is the base of :class:`~piezohyst.model.model.HysteresisModel` that
holds what a fit found: the core and terms (:meth:`Fitted.set_fitted`), and the facts
beside them (fit quality, the training record's range, slew and window, the growth
selection's scores, the dynamics). The fit's steps (:mod:`piezohyst.model.fit_record`)
compute these and hand them to ``_take``; nothing else sets them.
"""

from __future__ import annotations

import math
from typing import Any

from .._validation import FloatArray
from ..errors import NotFittedError
from .cores.base import Core, CoreFit
from .dynamics import InputDynamics, OutputDynamics
from .terms import Term

__all__ = ["FIT_FACTS", "Fitted", "unknown_facts"]


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


class Fitted:
    """The fitted attributes of a model and the methods that set them (see the module)."""

    # fitted attributes (``set_fitted`` and ``_take``, their one writer)
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
        self._take(**{**unknown_facts(), **facts})  # unknown for a model built by hand

    def _take(self, fit: CoreFit | None = None, **facts: Any) -> None:
        """Apply what a fit found: its core, terms and selection scores, then the facts
        named in :data:`~piezohyst.model.fit_record.FIT_FACTS` (each stored as ``name_``)."""
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
