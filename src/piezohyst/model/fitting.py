"""How a model is fitted: the record in, the dynamics searched, the core identified, scored.

:func:`fit_arrays` (``HysteresisModel.fit``) searches the input and output
dynamics when asked (:mod:`piezohyst.model.dynamics_fit`), then
:func:`identify_model` hands the record and the terms to the core's
identification step (:meth:`~piezohyst.model.cores.base.Core.identify`), and
:func:`score_model` runs the fitted model over the record for its error.
:func:`fit_stream` is the same from blocks read one at a time.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, as_time, same_length
from ..errors import (
    ExtrapolationWarning,
    IdentifiabilityWarning,
    InsufficientDataError,
    ParameterError,
    RecordWarning,
    TimeAxisError,
)
from ..io.blocks import Blocks, Summary, array_blocks, block_dt
from ..io.screening import screen
from .cores.base import Core, CoreFit, FitJob
from .dynamics import InputDynamics, OutputDynamics
from .dynamics_fit import profile_dynamics, search_dynamics
from .estimator import _dynamics_kind, _output_kind
from .state import InitialState, ModelState
from .terms import Term

__all__ = [
    "apply_fit",
    "fit_arrays",
    "fit_stream",
    "identify_model",
    "score_model",
    "screened",
    "set_fitted",
]

SCORE_PIECE = 1 << 16  # samples per piece when scoring a fit (2 MB of temporaries)


def fit_arrays(
    model: Any,
    x: ArrayLike,
    y: ArrayLike,
    t: ArrayLike | None = None,
    *,
    initial_state: InitialState = None,
    keep_outliers: bool = False,
) -> Any:
    xs = as_signal(x, "x")
    ys = as_signal(y, "y")
    same_length(xs, ys, "x", "y")
    ts = as_time(t, xs.size, required=False, owner=type(model).__name__)
    xs, ys = screened(xs, ys, ts, keep_outliers, model.input_unit, model.output_unit)
    dyn = InputDynamics()
    us = xs
    owner = type(model).__name__
    kind = _dynamics_kind(model.input_dynamics, "input_dynamics", owner)
    out_kind = _output_kind(model.output_dynamics, "output_dynamics", owner)
    if kind != "none" or out_kind != "none":
        if ts is None:
            msg = (
                f"{owner}(input_dynamics={kind!r}, output_dynamics={out_kind!r}) needs the "
                "sample times: pass t= (s)"
            )
            raise TimeAxisError(msg)
        seed_mode = OutputDynamics() if out_kind != "none" else None
        dyn, mode = search_dynamics(model, xs, ys, ts, kind, seed_mode)
        dt = block_dt(ts, 0, ts.size, None)
        if mode is not None:  # the solve filters its columns through it; set_fitted keeps it
            model._fitting_output = mode
        dyn = profile_dynamics(dyn, kind, _own_fit(model, xs, ys, ts, dt, initial_state), ys, ts)
        _check_identifiable(dyn)
        us, _ = dyn.apply(xs, dt)
    blocks = array_blocks(us, ys, ts)
    try:
        summary = identify_model(model, blocks, initial_state, ts is not None)
        if model._refine(us, ys, ts, summary, initial_state):
            _training_facts(model, summary)  # each refit reset them
            score_model(model, blocks, summary)  # the refinement changed the model
    finally:
        model.__dict__.pop("_fitting_output", None)
    if dyn.active:  # commands, their range and slew are the logged input's
        model.input_range_ = (float(xs.min()), float(xs.max()))
        assert ts is not None
        logged = Summary.of(array_blocks(xs, ys, ts))
        model.max_slew_rate_, model.max_step_ = logged.max_slew_rate, logged.max_step
    model.input_dynamics_ = dyn
    return model


def screened(
    x: FloatArray,
    y: FloatArray,
    t: FloatArray | None,
    keep_outliers: bool,
    x_unit: str | None = None,
    y_unit: str | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``x`` and ``y`` with their isolated outliers replaced (unless kept), each finding
    named in a :class:`~piezohyst.errors.RecordWarning` (see :mod:`piezohyst.io.screening`).

    Parameters
    ----------
    x, y : ndarray
    t : ndarray or None
    keep_outliers : bool
    x_unit, y_unit : str, optional
        For the message.

    Returns
    -------
    tuple of ndarray
    """
    found = screen({"x": x, "y": y}, t)
    if found.outliers:
        message = found.outlier_message("the record", {"x": x_unit, "y": y_unit}, arrays=True)
        if keep_outliers:
            message = message.split("; kept out of")[0] + "; kept, as asked (keep_outliers)"
        warnings.warn(message, RecordWarning, stacklevel=4)
    if found.holes:
        warnings.warn(found.hole_message("the record", arrays=True), RecordWarning, stacklevel=4)
    if keep_outliers:
        return x, y
    return found.cleaned("x", x), found.cleaned("y", y)


def _check_identifiable(dyn: InputDynamics) -> None:
    """Warn when the record leaves the delay and lag undetermined: the 95 % region reaches
    half the total lag, and a sample, in some direction (at one drive frequency a lag, a
    delay and hysteresis look alike)."""
    if not dyn.active or not dyn.covariance:
        return
    total = dyn.delay + dyn.tau
    from scipy.stats import chi2

    widest = float(np.linalg.eigvalsh(np.array(dyn.covariance).reshape(2, 2)).max())
    half = math.sqrt(max(widest, 0.0) * float(chi2.ppf(0.95, 2)))
    if half >= max(0.5 * total, dyn.sample_interval):  # a sample: no lag found is no warning
        warnings.warn(
            f"the record (or the model's misfit) cannot separate a lag from hysteresis (delay "
            f"+ lag {1e3 * total:.3g} ± {1e3 * half:.2g} ms, 95 %): record loops at two "
            "frequencies or more, the fastest near the scan rate (piezohyst excite --kind "
            "multifreq)",
            IdentifiabilityWarning,
            stacklevel=4,
        )


def _own_fit(
    model: Any, xs: FloatArray, ys: FloatArray, ts: FloatArray, dt: Any, initial_state: InitialState
) -> Any:
    """``fit_sse(dynamics)`` for :func:`profile_dynamics`: the model's own fit on the
    command filtered by ``dynamics`` (warnings kept for the final fit)."""
    cheap = model.core_class.profile_settings

    def fit_sse(dyn: InputDynamics, final: bool) -> tuple[float, FloatArray | None]:
        us, _ = dyn.apply(xs, dt)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                blocks = array_blocks(us, ys, ts)
                identify_model(model, blocks, initial_state, True, None if final else cheap)
            except (InsufficientDataError, ParameterError):
                return math.inf, None
            resid = model.predict(us, t=ts) - ys
        return float(resid @ resid), resid

    return fit_sse


def fit_stream(
    model: Any, blocks: Blocks, *, timed: bool = True, initial_state: InitialState = None
) -> Any:
    if model.get_params().get("optimize_thresholds"):
        msg = (
            f"{type(model).__name__}(optimize_thresholds=True) searches the thresholds over "
            "the record in memory: use fit"
        )
        raise ParameterError(msg)
    if (
        model.get_params().get("input_dynamics", "none") != "none"
        or model.get_params().get("output_dynamics", "none") != "none"
    ):
        msg = (
            f"{type(model).__name__} with input or output dynamics searches them over the "
            "record in memory: use fit"
        )
        raise ParameterError(msg)
    identify_model(model, blocks, initial_state, timed)
    model.input_dynamics_ = InputDynamics()
    return model


def identify_model(
    model: Any,
    blocks: Blocks,
    initial_state: InitialState,
    timed: bool,
    overrides: dict[str, Any] | None = None,
) -> Summary:
    params = {**model.check_params(), **(overrides or {})}
    sm = Summary.of(blocks)
    if not sm.x_max - sm.x_min > 1e-12 * max(abs(sm.x_min), abs(sm.x_max), 1e-300):
        msg = (
            f"the input never moves (constant at {sm.x_first:g} {model.input_unit}): "
            "a record without excitation holds no hysteresis to identify"
        )
        raise InsufficientDataError(msg)
    if not sm.y_max - sm.y_min > 1e-12 * max(abs(sm.y_min), abs(sm.y_max), 1e-300):
        msg = (
            f"the output never moves (constant at {sm.y_min:g} {model.output_unit}): "
            "nothing to identify; is it the right column?"
        )
        raise InsufficientDataError(msg)
    terms, subsets = model._terms_to_fit(sm.x_range, params)
    if not timed and any(term.rate_dependent for term in terms):
        as_time(None, sm.n, required=True, owner=type(model).__name__)  # raises
    job = FitJob(blocks, sm, terms, subsets, initial_state,
                 {**params, **(params.get("settings") or {})}, type(model).__name__,
                 model.input_unit, model.output_unit,
                 model.__dict__.get("_fitting_output"))  # fmt: skip
    apply_fit(model, model.core_class.identify(job))
    _training_facts(model, sm)
    score_model(model, blocks, sm)
    return sm


def score_model(model: Any, blocks: Blocks, sm: Summary) -> None:
    """Fit quality over the record (one pass, state carried) and the leakage check."""
    sse = 0.0
    state: ModelState | None = None
    rate = model.rate_dependent_
    with warnings.catch_warnings():  # its own record: no extrapolation warning
        warnings.simplefilter("ignore", ExtrapolationWarning)
        for x_blk, y_blk, t_blk in blocks():
            for a in range(0, x_blk.size, SCORE_PIECE):  # memory O(piece), not O(record)
                x, y = x_blk[a : a + SCORE_PIECE], y_blk[a : a + SCORE_PIECE]
                t = t_blk[a : a + SCORE_PIECE] if rate and t_blk is not None else None
                run = model.propagate(x, t, state)
                state = run.state
                r = run.output - y
                sse += float(np.sum(r * r))  # not BLAS: no thread pool woken for a sum
    model.rmse_ = math.sqrt(sse / sm.n)
    model.nrmse_ = model.rmse_ / max(sm.y_max - sm.y_min, 1e-300)
    _check_leakage(model, sm)


def _check_leakage(model: Any, sm: Summary) -> None:
    """Warn when the identified leakage drains the capacitance faster than one sample."""
    growth = model.growth_coefficients()
    if math.isnan(sm.t_first) or sm.n < 2 or "integral" not in growth:
        return
    conductance = growth["integral"][0]
    capacitance = (sm.y_max - sm.y_min) / (sm.x_max - sm.x_min)  # mean slope, output per input
    dt = (sm.t_last - sm.t_first) / (sm.n - 1)  # mean interval
    if conductance > 0 and capacitance / conductance < dt:
        warnings.warn(
            f"the identified leakage {conductance:.3g} {model.output_unit}/"
            f"({model.input_unit}*s) would discharge the actuator in "
            f"{capacitance / conductance:.3g} s, less than one sample ({dt:.3g} s): check "
            "the time unit",
            UserWarning,
            stacklevel=4,
        )


def set_fitted(
    model: Any, core: Core, terms: tuple[Term, ...], coefs: tuple[FloatArray, ...]
) -> None:
    """Make ``model`` fitted with these parameters; fit quality and training range unknown."""
    model.operator_ = core
    model.initial_state_ = core.initial_state
    for name, value in core.fitted_attributes().items():
        setattr(model, name, value)
    model.terms_ = terms
    model.coefs_ = coefs
    model.selection_ = {}
    model.selection_folds_ = {}
    model.selection_splits_ = []
    model.rmse_ = model.nrmse_ = math.nan  # set by fit; unknown for a model built by hand
    model.input_range_ = (math.nan, math.nan)
    model.max_slew_rate_ = model.max_step_ = math.nan
    model.train_window_ = (math.nan, math.nan)
    model.input_dynamics_ = InputDynamics()
    model.output_dynamics_ = getattr(model, "_fitting_output", OutputDynamics())


def apply_fit(model: Any, fit: CoreFit) -> None:
    """Make ``model`` the identification's result (core, terms, selection scores)."""
    model.set_fitted(fit.core, fit.terms, fit.coefs)
    if fit.selection is not None:
        model.selection_, model.selection_folds_, splits = fit.selection
        model.selection_splits_ = list(splits)


def _training_facts(model: Any, sm: Summary) -> None:
    """What the fit learns of its record beside the parameters: its voltages, fastest slew
    and the times of its first and last samples."""
    model.input_range_ = (sm.x_min, sm.x_max)
    model.max_slew_rate_ = sm.max_slew_rate
    model.max_step_ = sm.max_step
    model.train_window_ = (sm.t_first, sm.t_last)
