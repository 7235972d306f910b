"""A compensator's arguments, checked and resolved: the limits (narrowed to the voltages
the model was identified on), the slew limit (by default the training record's fastest
change), the domain and gain, and the loop's timing (an input delay split into whole
samples and a fraction; a lag's gain per sample; an output mode's sample interval).

:func:`resolve` is what every :class:`~piezohyst.Compensator` (and so the self-sensing
controller, the learning compensator and the banks built on it) checks before an engine is
built (:mod:`~piezohyst.control.engines`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Literal

from ..errors import ParameterError, warn
from ..model.dynamics import OutputDynamics
from ..model.inverse_spec import InverseSpec
from ..model.model import HysteresisModel
from .engines import EngineSettings, finite_number

__all__ = ["Domain", "Resolved", "resolve", "trained_limit"]

Domain = Literal["charge", "displacement"]


@dataclass(frozen=True)
class Resolved:
    """A compensator's arguments, checked.

    Attributes
    ----------
    spec : InverseSpec
        What the model gives its inverse.
    settings : EngineSettings
        What the engine is built with (the limits after narrowing, the slew per sample,
        the timing).
    mode : OutputDynamics
        The model's output mode, its differences at the loop's rate where given.
    requested_limits : tuple of float or None
        The limits asked for, where they were narrowed to the training range.
    slew_rate : float or None
        V/s (None: per sample, or none).
    """

    spec: InverseSpec
    settings: EngineSettings
    mode: OutputDynamics
    requested_limits: tuple[float, float] | None
    slew_rate: float | None


def resolve(
    model: HysteresisModel,
    v_min: float,
    v_max: float,
    slew_rate: float | Literal["trained"] | None,
    sample_rate: float | None,
    domain: Domain,
    gain: float | None,
    allow_extrapolation: bool,
    map_mode: OutputDynamics | None = None,
) -> Resolved:
    """The checks and settings every compensator shares.

    Parameters
    ----------
    model : HysteresisModel
    v_min, v_max, slew_rate, sample_rate, domain, gain, allow_extrapolation
        As :class:`~piezohyst.Compensator` takes them.
    map_mode : OutputDynamics, optional
        An output map's mechanical mode (between the charge and the displacement): inverted
        as a model's own mode is, after the map's inverse.

    Returns
    -------
    Resolved

    Raises
    ------
    ParameterError
        Any argument out of its range, or one the model needs missing (the loop's rate
        for a model with input dynamics, creep or relaxation).
    """
    inversion = getattr(model, "inversion", None)
    if not callable(inversion):
        msg = (
            "The 'model' parameter of Compensator must be a fitted piezohyst model (a "
            "ModelBank has ph.BankCompensator and ph.BankController). "
            f"Got {type(model).__name__} instead."
        )
        raise ParameterError(msg)
    spec: InverseSpec = inversion()
    lo = finite_number(v_min, "v_min")
    hi = finite_number(v_max, "v_max")
    if not lo < hi:
        msg = f"Compensator needs v_min < v_max. Got v_min={v_min!r}, v_max={v_max!r}."
        raise ParameterError(msg)
    if not isinstance(allow_extrapolation, bool):
        msg = f"'allow_extrapolation' must be True or False. Got {allow_extrapolation!r}."
        raise ParameterError(msg)
    requested: tuple[float, float] | None = None
    narrowed = _narrowed((lo, hi), spec.input_range, allow_extrapolation)
    if narrowed != (lo, hi):
        requested = (lo, hi)
        lo, hi = narrowed
    max_step = math.inf
    if isinstance(slew_rate, str):
        if slew_rate != "trained":
            msg = f"slew_rate must be a number in V/s, 'trained' or None. Got {slew_rate!r}."
            raise ParameterError(msg)
        slew_rate, max_step = trained_limit(model, sample_rate)
    if slew_rate is not None:
        rate = finite_number(slew_rate, "slew_rate")
        if sample_rate is None:
            msg = "A slew_rate (V/s) needs the loop's sample_rate (Hz). Got sample_rate=None."
            raise ParameterError(msg)
        fs = finite_number(sample_rate, "sample_rate")
        if rate <= 0 or fs <= 0:
            msg = f"slew_rate and sample_rate must be > 0. Got {slew_rate!r}, {sample_rate!r}."
            raise ParameterError(msg)
        max_step = rate / fs
    if domain not in ("charge", "displacement"):
        msg = (
            "The 'domain' parameter of Compensator must be 'charge' or 'displacement'. "
            f"Got {domain!r} instead."
        )
        raise ParameterError(msg)
    inv_gain = 1.0
    if domain == "displacement":
        if gain is None:
            msg = "domain='displacement' needs the gain (m per model output unit). Got None."
            raise ParameterError(msg)
        g = finite_number(gain, "gain")
        if g == 0.0:
            msg = "The 'gain' parameter of Compensator must be non-zero. Got 0."
            raise ParameterError(msg)
        inv_gain = 1.0 / g
    dyn = spec.dynamics
    timed = [(dyn.active, "input dynamics"), (spec.lags is not None, "creep"),
             (spec.relaxation is not None, "a relaxation term")]  # fmt: skip
    for needed, what in timed:
        if needed and sample_rate is None:
            msg = (f"A model with {what} needs the loop's sample_rate (Hz, --sample-rate). "
                   "Got None.")  # fmt: skip
            raise ParameterError(msg)
    delay_samples = 0
    frac = lag_gain = 0.0
    mode = spec.output_dynamics
    if map_mode is not None and map_mode.active:
        if mode.active:
            msg = (
                "the model holds a mode and so does the output map: a map's mode belongs to a "
                "model of the charge (which has none)"
            )
            raise ParameterError(msg)
        mode = map_mode
    if mode.active and sample_rate is not None:  # differences at the loop's rate
        mode = replace(mode, sample_interval=1.0 / float(sample_rate))
    if dyn.active:
        dt = 1.0 / float(sample_rate)  # type: ignore[arg-type]
        d = dyn.delay / dt
        # the whole samples go to the preview, the fraction in [-1/2, 1/2] is inverted
        # per sample (above half a sample its inverse rings: see _kernels.DYN_FRACTION)
        delay_samples = math.floor(d + 0.5)
        frac = d - delay_samples
        if abs(frac) <= 1e-9:
            frac = 0.0
        if dyn.tau > 0:
            lag_gain = 1.0 - math.exp(-dt / dyn.tau)
    settings = EngineSettings(
        lo, hi, max_step, inv_gain, sample_rate, domain, allow_extrapolation, mode.active,
        delay_samples, frac, lag_gain, dyn.active,
    )  # fmt: skip
    return Resolved(spec, settings, mode, requested, slew_rate)


def _narrowed(
    limits: tuple[float, float], trained: tuple[float, float], allow: bool
) -> tuple[float, float]:
    """The limits kept inside the voltages the model was identified on (unless ``allow``)."""
    v_min, v_max = limits
    lo, hi = trained
    if allow or math.isnan(lo) or math.isnan(hi) or (v_min >= lo and v_max <= hi):
        return limits
    new_lo, new_hi = max(v_min, lo), min(v_max, hi)
    if not new_lo < new_hi:
        msg = (
            f"The limits [{v_min:g}, {v_max:g}] V do not overlap the voltages the "
            f"model was identified on, [{lo:g}, {hi:g}] V; pass allow_extrapolation=True "
            "to use the model outside them."
        )
        raise ParameterError(msg)
    warn(
        f"Compensator limits [{v_min:g}, {v_max:g}] V narrowed to "
        f"[{new_lo:g}, {new_hi:g}] V, the voltages the model was identified on: a model "
        "is not trusted outside them (pass allow_extrapolation=True to keep the limits).",
        UserWarning,
    )
    return new_lo, new_hi


def trained_limit(model: Any, sample_rate: float | None) -> tuple[float | None, float]:
    """The default slew limit: the training record's fastest change, as (V/s, V per sample).

    Per second when the loop's rate is known; else per sample; none when the model
    does not record it (built by hand, or an older file).

    Parameters
    ----------
    model : HysteresisModel
    sample_rate : float or None
        Hz, of the loop.

    Returns
    -------
    tuple
        (V/s or None, V per sample or inf).
    """
    per_second = float(getattr(model, "max_slew_rate_", math.nan))
    per_sample = float(getattr(model, "max_step_", math.nan))
    if sample_rate is not None and math.isfinite(per_second) and per_second > 0:
        return per_second, math.inf
    if math.isfinite(per_sample) and per_sample > 0:
        return None, per_sample
    return None, math.inf
