"""How a model is fitted: the record in, the dynamics searched, the core identified, scored.

:func:`fit_arrays` (``HysteresisModel.fit``) searches the input and output
dynamics when asked (:mod:`piezohyst.model.fit_dynamics`), then
:func:`identify_model` hands the record and the terms to the core's
identification step (:meth:`~piezohyst.model.cores.base.Core.identify`), and
:func:`score_model` runs the fitted model over the record for its error.
:func:`fit_stream` is the same from blocks read one at a time.

These functions compute; they set nothing on a model. What a step finds (a
:class:`~piezohyst.model.cores.base.CoreFit`, the record's facts, the score)
is handed to the model's ``take_fit``, the one writer of its fitted attributes.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import Any, TypedDict

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, as_time, same_length
from ..errors import (
    ExtrapolationWarning,
    IdentifiabilityWarning,
    InsufficientDataError,
    ParameterError,
    PiezohystError,
    RecordWarning,
    TimeAxisError,
    warn,
)
from ..io.blocks import Blocks, Summary, array_blocks, block_dt
from ..io.screening import screen
from ..units import is_length
from .calibrations.from_holds import calibrate_leakage
from .cores.base import FitJob
from .dynamics import InputDynamics, OutputDynamics
from .estimator import _dynamics_kind, _output_kind
from .fit_dynamics import profile_dynamics, search_dynamics
from .fit_state import Fittable
from .state import InitialState, ModelState
from .terms import Creep, Term, creep_time_constants

__all__ = [
    "RecordFacts",
    "Score",
    "fit_arrays",
    "fit_stream",
    "identify_model",
    "record_facts",
    "score_model",
    "screened",
    "undetermined",
]

SCORE_PIECE = 1 << 16  # samples per piece when scoring a fit (2 MB of temporaries)
#: A record whose input and output changes correlate below minus this falls as its input
#: rises (``Summary.co_move``, the largest over changes across 1, 8 and 64 samples): no
#: model here can follow it. Measured on the PZT periods: displacement falling (800-1200 V)
#: -0.74..-0.86; its butterflies (1400 V, rising and falling) +0.35..+0.45; the
#: polarisation's rising loops +0.50..+0.84. Independent
#: noise pulls the correlation towards 0; noise shared by both channels with opposite signs
#: (one reference in both) can pull it below at one sample, not over 64 where the drive shows.
FALLING = 0.5


def fit_arrays(
    model: Fittable,
    x: ArrayLike,
    y: ArrayLike,
    t: ArrayLike | None = None,
    *,
    initial_state: InitialState = None,
    keep_outliers: bool = False,
) -> None:
    """Fit ``model`` on a record in memory: screened, its dynamics searched when the model
    asks, its core and terms identified and scored (:meth:`HysteresisModel.fit
    <piezohyst.model.model.HysteresisModel.fit>`).

    Parameters
    ----------
    model : Fittable
        Takes what the fit finds through its one writer (``take_fit``).
    x, y : array_like, shape (N,)
        Input and output.
    t : array_like, shape (N,), optional
        Sample times (s).
    initial_state : {"rest", "periodic"}, History, array_like or None
        Where the operators stand before the first sample.
    keep_outliers : bool
        Fit single-sample glitches too (they are named and dropped by default).
    """
    xs = as_signal(x, "x")
    ys = as_signal(y, "y")
    same_length(xs, ys, "x", "y")
    ts = as_time(t, xs.size, required=False, owner=type(model).__name__)
    xs, ys = screened(xs, ys, ts, keep_outliers, model.input_unit, model.output_unit)
    dyn = InputDynamics()
    mode: OutputDynamics | None = None
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
        own = _own_fit(model, xs, ys, ts, dt, initial_state, mode)
        dyn = profile_dynamics(dyn, kind, own, ys, ts)
        _check_identifiable(dyn)
        us, _ = dyn.apply(xs, dt)
    blocks = array_blocks(us, ys, ts)
    summary = identify_model(model, blocks, initial_state, ts is not None, output_mode=mode)
    if model.refine_fit(us, ys, ts, summary, initial_state):
        # each refit reset the record's facts; the refinement changed the model's score
        model.take_fit(**record_facts(summary), **score_model(model, blocks, summary))
    facts: dict[str, Any] = {"input_dynamics": dyn}
    if dyn.active:  # commands, their range and slew are the logged input's
        assert ts is not None
        logged = Summary.of(array_blocks(xs, ys, ts))
        facts["input_range"] = (float(xs.min()), float(xs.max()))
        facts["max_slew_rate"], facts["max_step"] = logged.max_slew_rate, logged.max_step
    model.take_fit(**facts)


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
        warn(message, RecordWarning)
    if found.holes:
        warn(found.hole_message("the record", arrays=True), RecordWarning)
    if keep_outliers:
        return x, y
    return found.cleaned("x", x), found.cleaned("y", y)


def undetermined(dyn: InputDynamics) -> float:
    """The 95 % half-width (s) of identified input dynamics where the record leaves them
    undetermined (the region reaches half the total lag, and a sample, in some direction: at
    one drive frequency a lag, a delay and hysteresis look alike); 0 where it determines them.

    Parameters
    ----------
    dyn : InputDynamics

    Returns
    -------
    float
    """
    if not dyn.active or not dyn.covariance:
        return 0.0
    total = dyn.delay + dyn.tau
    from scipy.stats import chi2

    widest = float(np.linalg.eigvalsh(np.array(dyn.covariance).reshape(2, 2)).max())
    half = math.sqrt(max(widest, 0.0) * float(chi2.ppf(0.95, 2)))
    return half if half >= max(0.5 * total, dyn.sample_interval) else 0.0


def _check_identifiable(dyn: InputDynamics) -> None:
    """Warn when the record leaves the delay and lag undetermined (:func:`undetermined`)."""
    half = undetermined(dyn)
    total = dyn.delay + dyn.tau
    if half:  # a sample: no lag found is no warning
        warn(
            f"the record (or the model's misfit) cannot separate a lag from hysteresis (delay "
            f"+ lag {1e3 * total:.3g} ± {1e3 * half:.2g} ms, 95 %): record loops at two "
            "frequencies or more, the fastest near the scan rate (piezohyst excite --kind "
            "multifreq)",
            IdentifiabilityWarning,
        )


def _own_fit(
    model: Fittable,
    xs: FloatArray,
    ys: FloatArray,
    ts: FloatArray,
    dt: FloatArray | None,
    initial_state: InitialState,
    mode: OutputDynamics | None,
) -> Callable[[InputDynamics, bool], tuple[float, FloatArray | None]]:
    """``fit_sse(dynamics)`` for :func:`profile_dynamics`: the model's own fit on the
    command filtered by ``dynamics`` (warnings kept for the final fit)."""
    cheap = model.core_class.profile_settings

    def fit_sse(dyn: InputDynamics, final: bool) -> tuple[float, FloatArray | None]:
        us, _ = dyn.apply(xs, dt)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                blocks = array_blocks(us, ys, ts)
                identify_model(model, blocks, initial_state, True, None if final else cheap, mode)
            except (InsufficientDataError, ParameterError):
                return math.inf, None
            resid = model.predict(us, t=ts) - ys
        return float(resid @ resid), resid

    return fit_sse


def fit_stream(
    model: Fittable,
    blocks: Blocks,
    *,
    timed: bool = True,
    initial_state: InitialState = None,
) -> None:
    """Fit ``model`` from blocks read one at a time (a record larger than memory):
    identified and scored in passes over the blocks (:meth:`HysteresisModel.fit_blocks
    <piezohyst.model.model.HysteresisModel.fit_blocks>`).

    Parameters
    ----------
    model : Fittable
        Without input or output dynamics and threshold search (they need the record in
        memory: refused by name).
    blocks : Blocks
        The record's block source (:mod:`piezohyst.io.blocks`).
    timed : bool
        The blocks carry sample times.
    initial_state : {"rest", "periodic"}, History, array_like or None
    """
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
    model.take_fit(input_dynamics=InputDynamics())


def identify_model(
    model: Fittable,
    blocks: Blocks,
    initial_state: InitialState,
    timed: bool,
    overrides: dict[str, Any] | None = None,
    output_mode: OutputDynamics | None = None,
) -> Summary:
    """Identify ``model``'s core and terms from ``blocks`` and hand the result to the model
    (its parameters, the record's facts, its score); returns the record's summary.

    ``overrides`` replace settings (a cheap profile); ``output_mode``: a mechanical mode the
    solve filters its columns through (a search's candidate), kept on the model."""
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
    if sm.co_move < -FALLING:
        msg = (
            f"the output falls as the input rises (their changes correlate at "
            f"{sm.co_move:.2f}): every model here rises with its input; negate the output "
            "(a sensor that counts the other way, or an actuator poled against the field: "
            "--output-scale -1 or -10 um/V, output_scale= where the record is read) and the "
            "model's predictions with it"
        )
        raise InsufficientDataError(msg)
    displacement = is_length(model.output_unit) and _default_growth(model)
    if displacement:  # a displacement sees no leaked charge: what drifts in it is creep
        params = {**params, **displacement_terms(params, sm, timed)}
    elif (
        model.get_params().get("growth_terms") == "domain"
        and "growth_terms" not in (overrides or {})
        and timed
        and holds_show_rise(blocks, sm)
    ):  # the charge's leak, and its rise with the voltage where the holds show one
        params = {**params, "growth_terms": ("integral", "abs_integral")}
    terms, subsets = model.terms_to_fit(sm.x_range, params)
    if displacement:  # a growth term fixed by the model (ActivePI's integrator) goes too
        fixed_growth = any(term.removed for term in terms) and "growth_terms" not in params
        terms, subsets = [term for term in terms if not term.removed], None
        if fixed_growth and "creep" not in params and timed and sm.n > 1:
            # ... and what it stood for, a drift of the output, is held by creep operators
            # timed by the record, as the models with a creep setting get here (ActivePI on
            # a displacement became ClassicalPI: 0.36 % held out where creep gives 0.15 %)
            terms.append(Creep(creep_time_constants(sm.t_last - sm.t_first, sm.n)))
    selection = None
    if _by_evidence(model, overrides, displacement, timed) and subsets is None:
        terms, selection = growth_by_evidence(blocks, terms, initial_state)
    if not timed and any(term.rate_dependent for term in terms):
        as_time(None, sm.n, required=True, owner=type(model).__name__)  # raises
    fitted = blocks
    if output_mode is not None and output_mode.active and not model.core_class.takes_mode:
        fitted = _mode_taken_out(blocks, output_mode)  # scored on the record as measured
    job = FitJob(fitted, sm, terms, subsets, initial_state,
                 {**params, **(params.get("settings") or {})}, type(model).__name__,
                 model.input_unit, model.output_unit, output_mode)  # fmt: skip
    fit = model.core_class.identify(job)
    mode = {} if output_mode is None else {"output_dynamics": output_mode}
    model.take_fit(fit, **record_facts(sm), **mode)
    if selection is not None:  # how the record's own later part chose the growth terms
        sel, folds, splits = selection
        model.take_fit(selection=sel, selection_folds=folds, selection_splits=list(splits))
    model.take_fit(**score_model(model, blocks, sm))
    return sm


#: The output is low-passed above this many times the mode's frequency before the mode's
#: inverse: the inverse's gain grows as the frequency squared above the mode, so a sensor's
#: noise there would be amplified by more than this squared (100)
MODE_BAND = 10.0


def _mode_taken_out(blocks: Blocks, mode: OutputDynamics) -> Blocks:
    """The record with its output through the mode's exact inverse: what a core that does
    not pass its regressors through the mode is fitted to (a Preisach, Duhem or Bouc-Wen
    core; the play operators' solve filters its columns instead). Until this, those cores
    were fitted to the output as if it held no mode: on the bench with a 150 Hz mode and a
    4 ms lag the Preisach model fitted 1.6 % (PI 0.23 %) and its lag came out 4.4 ms.

    Above :data:`MODE_BAND` times the mode's frequency (where that is below 0.45 of the
    sample rate) the output is first low-passed without phase (a second-order Butterworth,
    forward and back): sampled at 10 kHz, the bench's 150 Hz mode's exact inverse amplified
    the laser's noise and the Preisach fit left 0.54 % (0.09 % low-passed)."""
    parts = list(blocks())
    x = np.concatenate([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    nyquist = 0.5 / mode.sample_interval
    cut = MODE_BAND * mode.f0
    if cut < 0.9 * nyquist and y.size > 12:
        from scipy.signal import butter, filtfilt

        b, a = butter(2, cut / nyquist)
        y = np.asarray(filtfilt(b, a, y), dtype=np.float64)
    y = mode.unapply(y)
    t = None if parts[0][2] is None else np.concatenate([p[2] for p in parts])
    return array_blocks(x, y, t)


#: The domain's growth terms are dropped where the proxy's forward chaining forecasts the
#: record's later part this many times worse with them than without. Not the proxy's plain
#: choice: on charge records its scores disagreed with the models' own by up to 1.47x
#: (``docs/benchmarks.md``, "Growth terms on charge records": it preferred no growth where
#: the Bouc-Wen fit needed the leak, 9.5 % against 3.4 %); a ramp that the record cannot
#: support forecasts many times worse (178 % against 1 % on the other lab's record)
RAMP_MARGIN = 2.0


def _by_evidence(
    model: Fittable, overrides: dict[str, Any] | None, displacement: bool, timed: bool
) -> bool:
    """Whether the record's default growth terms must earn their place by forecasting its
    later part: ``growth_terms="domain"`` left as it is, on a timed record not known to be a
    displacement (one without units included)."""
    return (
        not displacement
        and timed
        and model.get_params().get("growth_terms") == "domain"
        and "growth_terms" not in (overrides or {})
    )


def growth_by_evidence(
    blocks: Blocks, terms: list[Term], initial_state: InitialState
) -> tuple[list[Term], Selection | None]:
    """The domain's growth terms (a charge's leak) dropped where the record's own later part
    says they forecast far worse (:data:`RAMP_MARGIN`): the Prandtl-Ishlinskii proxy's
    forward-chaining time-series cross-validation
    (:func:`~piezohyst.model.cores.play.growth_proxy`) between none and all of them, the
    kept terms in both. A leak's integral fitted to a record whose drift is creep, or that
    has none (a displacement logged without units), ramps on beyond it: measured on a 10 Hz
    displacement record of another lab, 178 % error on its last 40 %.

    Parameters
    ----------
    blocks : Blocks
    terms : list of Term
        The bound terms (kept ones and growth ones).
    initial_state : InitialState

    Returns
    -------
    (list of Term, selection or None)
        The terms to fit jointly with the core (the growth ones dropped if they did not
        earn their place), and the selection's scores for the model's ``selection_``.
    """
    from .cores.play import growth_proxy, subset_label

    growth = [j for j, term in enumerate(terms) if term.removed]
    if not growth:
        return terms, None
    base = tuple(j for j in range(len(terms)) if j not in growth)
    full = tuple(range(len(terms)))
    x, y, t = _collected(blocks)
    _, _, selection = growth_proxy(x, y, t, terms, [base, full], initial_state)
    assert selection is not None
    scores = selection[0]
    without, with_growth = (
        scores.get(subset_label(terms, base)),
        scores.get(subset_label(terms, full)),
    )
    if without is None or with_growth is None or with_growth <= RAMP_MARGIN * without:
        return terms, selection  # kept: they do not forecast worse by the margin
    return [terms[j] for j in base], selection


def _collected(blocks: Blocks) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """The whole record in memory (the cores that choose by evidence hold it anyway)."""
    parts = list(blocks())
    x = np.concatenate([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    timed = all(p[2] is not None for p in parts)
    t = np.concatenate([p[2] for p in parts]) if timed else None
    return x, y, t


def displacement_terms(params: dict[str, Any], sm: Summary, timed: bool) -> dict[str, Any]:
    """The default terms of a displacement record: no growth terms (the displacement does not
    see leaked charge), and creep operators timed by the record
    (:func:`~piezohyst.model.terms.creep_time_constants`) where the model takes them, the
    record has times and the user set none: the field's standard for a piezo's displacement
    (Kuhnen's modified PI model), a drift that settles instead of a ramp the record cannot
    support."""
    out: dict[str, Any] = {}
    if "growth_terms" in params:
        out["growth_terms"] = ()
    if "creep" in params and params["creep"] is None and timed and sm.n > 1:
        out["creep"] = Creep(creep_time_constants(sm.t_last - sm.t_first, sm.n))
    return out


#: The rise of the leak's conductance with the voltage (``abs_integral``) joins a charge
#: record's default growth (``growth_terms="domain"``) where the record's holds determine it
#: beyond this many standard errors (:func:`holds_show_rise`)
HOLDS_RISE_SIGMAS = 3.0
#: Samples the holds are read from at most: a longer record is averaged in groups
HOLDS_SAMPLES = 1 << 20


def holds_show_rise(blocks: Blocks, sm: Summary) -> bool:
    """Whether the record's constant-voltage holds show the leak's conductance rising with the
    voltage: :func:`~piezohyst.calibrate_leakage` on the record chooses its
    ``quadratic`` term, beyond :data:`HOLDS_RISE_SIGMAS` of its standard errors.

    On a hold the hysteresis is still, so the charge's slope is the leak alone; a fit over
    the whole record cannot tell the rise from a model's misfit (a model of another class
    takes it to draw what it lacks), and a record without holds (one frequency at decaying
    amplitude) leaves it undetermined. Holds still settling (relaxation, creep) are refused
    by the calibration: no rise then. Measured on units 4-6 of the plants' batches
    (``docs/benchmarks.md``, "The rise where the holds show it")."""
    if sm.n < 3 or not math.isfinite(sm.t_first):
        return False
    group = -(-sm.n // HOLDS_SAMPLES)
    t, x, y = _averaged(blocks, group)
    with warnings.catch_warnings():  # the calibration's notes on its holds are not the fit's
        warnings.simplefilter("ignore")
        try:
            leak = calibrate_leakage(t, x, y)
        except PiezohystError:  # no holds, too few, or still settling
            return False
    stderr = leak.stderr().get("quadratic", 0.0)
    return bool(leak.quadratic > HOLDS_RISE_SIGMAS * stderr)


def _averaged(blocks: Blocks, group: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The record's times, inputs and outputs, averaged in consecutive groups of ``group``
    samples (1: as they are); a last partial group is dropped."""
    parts: list[FloatArray] = []
    carry = np.zeros((3, 0))
    for x, y, t in blocks():
        if t is None:  # an untimed record has no holds to read
            return np.zeros(0), np.zeros(0), np.zeros(0)
        rows = np.concatenate([carry, np.vstack([t, x, y])], axis=1)
        whole = rows.shape[1] // group * group
        if whole:
            parts.append(rows[:, :whole].reshape(3, -1, group).mean(axis=2))
        carry = rows[:, whole:]
    t, x, y = np.concatenate(parts, axis=1) if parts else np.zeros((3, 0))
    return t, x, y


def _default_growth(model: Fittable) -> bool:
    """Whether the model's growth terms follow the record's domain: ``growth_terms`` left to
    "domain" (the packed presets' default) or "auto", or fixed by the model (ActivePI's
    integrator), not named by the user."""
    params = model.get_params()
    if "growth_terms" in params:
        return params["growth_terms"] in ("domain", "auto")
    return "terms" not in params or not params["terms"]  # PIModel's terms are named


#: A growth selection's scores: by subset label, per fold, and the folds' split points
Selection = tuple[dict[str, float], dict[str, list[float]], list[int]]


class Score(TypedDict):
    """A fit's quality over its record (output units, and over the output's span)."""

    rmse: float
    nrmse: float


class RecordFacts(TypedDict):
    """What a fit learns of its record beside the parameters."""

    input_range: tuple[float, float]
    max_slew_rate: float
    max_step: float
    train_window: tuple[float, float]


def score_model(model: Fittable, blocks: Blocks, sm: Summary) -> Score:
    """Fit quality over the record (one pass, state carried) and the leakage check:
    ``{"rmse": ..., "nrmse": ...}`` for the model to take."""
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
    _check_leakage(model, sm)
    err = math.sqrt(sse / sm.n)
    return {"rmse": err, "nrmse": err / max(sm.y_max - sm.y_min, 1e-300)}


def _check_leakage(model: Fittable, sm: Summary) -> None:
    """Warn when the identified leakage drains the capacitance faster than one sample."""
    growth = model.growth_coefficients()
    if math.isnan(sm.t_first) or sm.n < 2 or "integral" not in growth:
        return
    conductance = growth["integral"][0]
    capacitance = (sm.y_max - sm.y_min) / (sm.x_max - sm.x_min)  # mean slope, output per input
    dt = (sm.t_last - sm.t_first) / (sm.n - 1)  # mean interval
    if conductance > 0 and capacitance / conductance < dt:
        warn(
            f"the identified leakage {conductance:.3g} {model.output_unit}/"
            f"({model.input_unit}*s) would discharge the actuator in "
            f"{capacitance / conductance:.3g} s, less than one sample ({dt:.3g} s): check "
            "the time unit",
            UserWarning,
        )


def record_facts(sm: Summary) -> RecordFacts:
    """What the fit learns of its record beside the parameters: its voltages, fastest slew
    and the times of its first and last samples."""
    return {
        "input_range": (sm.x_min, sm.x_max),
        "max_slew_rate": sm.max_slew_rate,
        "max_step": sm.max_step,
        "train_window": (sm.t_first, sm.t_last),
    }
