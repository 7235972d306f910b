"""The learning laws behind one small interface.

A law answers three questions for :class:`~.compensator.LearningCompensator`, which
otherwise does not know which law it runs:

* :meth:`Law.reference`: what the next trial's compensator inverts, given the correction
  learned so far, the reference the trial before ran, and the lead-in's probe;
* :meth:`Law.update`: the correction after a trial, from what it measured (:class:`Evidence`);
* :meth:`Law.said`: one sentence for :meth:`~.compensator.LearningCompensator.describe`,

and checks what it cannot learn (:meth:`Law.check_lag`, :meth:`Law.check_samples`).
:data:`LAWS` maps each law's name to it. A new law is a class here and a name in
:data:`LAWS`; ``law="auto"`` chooses among them in
:func:`~.compensator.resolved_law`.

* ``"harmonic"`` (:class:`HarmonicLaw`) corrects the *reference*: each harmonic of the
  error through the model's inverse and the design's learning filter
  (:mod:`~piezohyst.control.learning.design`).
* ``"jacobian"`` (:class:`JacobianLaw`) corrects the *commands*, through the model's
  Jacobian along them (:mod:`~piezohyst.control.learning.jacobian`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from ...errors import ParameterError
from .design import LearningDesign
from .jacobian import MAX_SAMPLES, damped_step, trial_jacobian, uniform_shift

FloatArray = np.ndarray

__all__ = ["LAWS", "Evidence", "HarmonicLaw", "JacobianLaw", "Law", "gated"]


@dataclass(frozen=True)
class Evidence:
    """What one trial gives a law to learn from.

    Attributes
    ----------
    design : LearningDesign
        The learning filter and gain's design.
    gain : float
        The learning gain now (halved after a rollback).
    correction : ndarray
        The correction the trial ran with (desired units, or V for the Jacobian law).
    error : ndarray
        Desired minus measured over the trial, gaps filled and wound down where a command
        sat at a limit.
    sensor : bool
        A sensor's displacement (its offset is learned) rather than the charge (not).
    gate : float
        The noise gate (``noise_gate``; 0: none).
    commands : ndarray
        The trial's voltages.
    respond : callable
        Commands -> the model's output in the desired's units, the trial run after itself.
    volt_span : float
        ``v_max - v_min`` (V).
    steer : complex or ndarray of complex
        The factor each harmonic of the error is learned through (1; the measured
        response's inverse where the model's would grow the error: :mod:`.harmonics`).
    """

    design: LearningDesign
    gain: float
    correction: FloatArray
    error: FloatArray
    sensor: bool
    gate: float
    commands: FloatArray
    respond: Callable[[FloatArray], FloatArray]
    volt_span: float
    steer: Any = 1.0


class Law(Protocol):
    """What a learning law answers (see the module's docstring)."""

    name: ClassVar[str]

    def reference(
        self, correction: FloatArray, previous: FloatArray, probe: FloatArray | float
    ) -> tuple[FloatArray, Any, FloatArray | None]:
        """The trial's compensator input: the history it ran after (a correction of the
        desired), the correction it inverts now, and volts added to its commands (or None)."""
        ...

    def update(self, ev: Evidence) -> FloatArray:
        """The correction for the next trial."""
        ...

    def said(self, design: LearningDesign) -> str:
        """One sentence on the law and its setting."""
        ...

    def own(self, design: LearningDesign) -> Any:
        """The law's own factor at each harmonic, beside the model's (:mod:`.harmonics`)."""
        ...

    def check_lag(self, lag: float) -> None:
        """Raise ParameterError where the law cannot learn through a stated lag."""
        ...

    def check_samples(self, samples: int) -> None:
        """Raise ParameterError where the law cannot learn a trial this long."""
        ...


def gated(design: LearningDesign, e: FloatArray, gate: float) -> Any:
    """The spectrum of ``e`` without the bins whose power is below ``gate`` times the
    measurement noise's per bin (``design.noise``; see ``noise_gate``).

    Parameters
    ----------
    design : LearningDesign
    e : ndarray
        One trial's error.
    gate : float
        0: every bin kept.

    Returns
    -------
    ndarray of complex
        ``rfft(e)`` with the quiet bins zeroed (never the mean's).
    """
    err = np.fft.rfft(e)
    if gate > 0 and math.isfinite(design.noise) and design.noise > 0:
        quiet = np.abs(err) ** 2 < gate * design.noise**2 * e.size
        quiet[0] = False  # a sensor's offset is learned whole
        err[quiet] = 0.0
    return err


class HarmonicLaw:
    """Corrects the reference: ``Q (c + gain L e)`` over the periodic trial; the mean is kept
    for a charge (its zero is unknown). Any trial length, any stated lag."""

    name: ClassVar[str] = "harmonic"

    def reference(
        self, correction: FloatArray, previous: FloatArray, probe: FloatArray | float
    ) -> tuple[FloatArray, Any, FloatArray | None]:
        return previous, correction + probe, None

    def update(self, ev: Evidence) -> FloatArray:
        old, err = np.fft.rfft(ev.correction), gated(ev.design, ev.error, ev.gate) * ev.steer
        spectrum = old + ev.gain * ev.design.l() * err
        spectrum[0] = old[0] + (ev.gain * err[0] if ev.sensor else 0.0)
        return np.fft.irfft(ev.design.q() * spectrum, n=ev.correction.size)

    def said(self, design: LearningDesign) -> str:
        return design.describe()

    def own(self, design: LearningDesign) -> Any:
        return design.l()

    def check_lag(self, lag: float) -> None:
        return None

    def check_samples(self, samples: int) -> None:
        return None


class JacobianLaw:
    """Corrects the commands, in volts, by the damped least-squares step through the model's
    Jacobian along them (:mod:`.jacobian`); the reference stays the periodic desired."""

    name: ClassVar[str] = "jacobian"

    def reference(
        self, correction: FloatArray, previous: FloatArray, probe: FloatArray | float
    ) -> tuple[FloatArray, Any, FloatArray | None]:
        return np.zeros(correction.size), probe, correction

    def update(self, ev: Evidence) -> FloatArray:
        e = ev.error
        err = gated(ev.design, e, ev.gate) * ev.steer
        offset = float(err[0].real) / e.size if ev.sensor else 0.0  # a sensor's: as a shift
        err[0] = 0.0
        ef = np.fft.irfft(ev.design.q() * err, n=e.size)
        jac = trial_jacobian(ev.respond, ev.commands, ev.volt_span)
        jac -= jac.mean(axis=0)  # the rest, offset-free
        shift = uniform_shift(ev.respond, ev.commands, offset) if offset else 0.0
        # a new array: the learner's record of the trial before keeps its own
        return ev.correction + ev.gain * (np.asarray(damped_step(jac, ef)) + shift)

    def said(self, design: LearningDesign) -> str:
        return (
            f"the Jacobian law, learning gain {design.gain:.3g}, cutoff {design.cutoff:.4g} Hz "
            "(the harmonic law's design; its condition does not bound this law: a trial whose "
            "error grows is undone and the gain halved)"
        )

    def own(self, design: LearningDesign) -> Any:
        return 1.0

    def check_lag(self, lag: float) -> None:
        if lag > 0:
            msg = ("law='jacobian' learns through the model's own lag: a stated one learned 10 or "
                   "40 Hz scans worse than the harmonic law (docs/benchmarks.md); identify it "
                   "with the model (input_dynamics='auto') or use law='harmonic'")  # fmt: skip
            raise ParameterError(msg)

    def check_samples(self, samples: int) -> None:
        if samples > MAX_SAMPLES:
            msg = (
                f"law='jacobian' learns trials of up to {MAX_SAMPLES} samples (its Jacobian "
                f"is n x n): this one has {samples}; 'harmonic' or 'auto' learns any"
            )
            raise ParameterError(msg)


#: Every law by its name (``LearningCompensator(law=...)``)
LAWS: dict[str, Law] = {law.name: law for law in (HarmonicLaw(), JacobianLaw())}
