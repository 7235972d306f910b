r"""Self-sensing closed loop: feedforward inverse plus feedback on the measured charge.

Feedforward through an inverse model is as good as the model class: PI minor
loops are congruent, real ones are not. The charge is measured anyway (the
Sawyer-Tower circuit the model was identified with), and displacement follows
the capacitor charge (eq. 6-7), so a loop closed on the measured charge,
minus the charge that leaked, corrects the model-class error without a
position sensor::

    desired d ──►(+)──► inverse model (eq. 18) ──► v ──► amplifier, piezo ──► charge amp
                 ▲  u = d + kp·e + I                │ model state follows v        │
                 │                                  ▼                              ▼
                 └── e = d[k-1] − (q_meas[k] − L[k] + frame) ◄── L += i(v)·dt ◄── q_meas

The error compares the charge read at a sample with what the previous
sample asked for (the reading is the response to the commands before it).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from .._kernels import play as K
from .._validation import FloatArray
from ..errors import ParameterError, ShapeError
from ..model.calibrations.leakage import Leakage
from ..model.calibrations.output_map import OutputMap
from ..model.model import HysteresisModel
from .compensator import (
    Compensator,
    CompensatorSettings,
    CompensatorState,
    first_of,
)
from .contract import reading

__all__ = [
    "ControllerState",
    "LoopSettings",
    "SelfSensingController",
    "build_controller",
]

Domain = Literal["charge", "displacement"]


@dataclass(frozen=True)
class ControllerState:
    """Everything a :class:`SelfSensingController` carries from sample to sample.

    Attributes
    ----------
    compensator : CompensatorState
        Forward operator states (V) and the last command.
    feedback : ndarray
        The feedback state (integral, leaked charge, frame, previous desired,
        counters, leakage refresh; layout ``CS_*`` in ``_kernels``).
    """

    compensator: CompensatorState
    feedback: FloatArray


def _gain(value: object, name: str, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
        msg = (
            f"The {name!r} parameter of SelfSensingController must be a number in "
            f"[{low:g}, {high:g}]. Got {value!r} instead."
        )
        raise ParameterError(msg)
    return float(value)


#: Voltages where :func:`_first_slope` reverses, and its reversal's depth (of the range)
FIRST_SLOPE_LEVELS = 24
FIRST_SLOPE_STEP = 1e-3


def _first_slope(comp: Compensator, span: float) -> float:
    """The model's smallest slope just after a reversal over its mean slope (``span`` over
    the limits): from rest, up to each of :data:`FIRST_SLOPE_LEVELS` voltages and back a
    little, and down from the top limit to each and up a little."""
    lo, hi = comp.v_min, comp.v_max
    delta = FIRST_SLOPE_STEP * (hi - lo)
    op = comp.spec.operator
    slopes = []
    for level in np.linspace(lo + 2 * delta, hi - 2 * delta, FIRST_SLOPE_LEVELS):
        for start, turn in ((lo, -delta), (hi, delta)):
            path = np.concatenate([[lo], np.linspace(start, level, 50), [level + turn]])
            y = op.predict(path)
            slopes.append((y[-2] - y[-1]) / -turn)
    return max(float(min(slopes)), 0.0) / (span / (hi - lo))


class SelfSensingController:
    r"""Hysteresis feedforward plus charge feedback, without a position sensor.

    Each sample: the leakage estimate :math:`L` advances by
    :math:`i(v, q)\,\Delta t` for the command held over the last sample; the
    error is :math:`e = d_{k-1} - (q_k - L_k + \text{frame})`; the command is
    the model's inverse of :math:`d_k + k_p e + I_k` with
    :math:`I_k = I_{k-1} + k_i e` (kept only when the command delivered it:
    anti-windup at the limits and the slew limit). The model's state follows
    the voltage actually sent. The first finite measurement after a reset
    sets the frame, so the actuator should rest (or have been preconditioned)
    when the loop starts.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model whose hysteresis part is play operators alone
        (``ClassicalPI``, ``ActivePI``, or presets with growth terms only):
        the loop uses the analytic inverse (eq. 18); or a Preisach, Duhem or
        Bouc-Wen core (its compiled inverse). Its input dynamics (an
        amplifier's lag and delay, ``input_dynamics=``) are inverted as the
        :class:`~piezohyst.Compensator` inverts them, and the leakage flows at
        the piezo's voltage (the lag's output).
    v_min, v_max : float
        Voltage limits (V); narrowed to the model's training range unless
        ``allow_extrapolation`` (as for :class:`~piezohyst.control.compensator.Compensator`).
    sample_rate : float
        Loop rate (Hz).
    leakage : Leakage, optional
        The leakage to subtract from the measured charge; default the model's
        growth terms (:meth:`Leakage.from_model`). Calibrate it from holds
        (:func:`~piezohyst.calibrate_leakage`) for the best result.
    ki : float, default 0.5
        Integral gain per sample, in [0, 1.9]: 1 removes a constant error in
        one sample but passes the measurement noise; the loop's bandwidth is
        about ``ki * sample_rate / (2 pi)`` (see ``docs/realtime.md``). The
        correction passes through the model's inverse, so the gain the actuator
        sees is ``ki`` times its slope over the model's: where a model's branches
        start far flatter than the actuator's (a Preisach density at its floor
        just after a reversal), that gain passes 2 and the loop chatters near
        the Nyquist rate: lower ``ki``, set ``flat_guard`` or choose a core
        whose branches start steep.
    flat_guard : bool, default False
        Lower the integral gain in use (:attr:`ki_used`) to twice the model's
        smallest slope just after a reversal over its mean slope
        (:attr:`first_slope`, probed at 24 voltages from both sides) where
        that is below ``ki``: just after a reversal the loop's gain is then at
        most twice the actuator's slope over the model's mean, below 2
        wherever the actuator's slope is below its mean. On the simulated
        plants it ends a Preisach model's chatter (Duhem plant: width
        0.64-1.5 % -> 0.26-0.28 %, 0.49 % of the span above 100 Hz -> 0.01 %)
        but slows the loop of models that are right to start flat (Bouc-Wen
        on the Duhem plant: 0.09-0.19 % -> 0.46 %), so it is not the default:
        set it when :attr:`first_slope` is far below the actuator's
        (``docs/realtime.md``).
    kp : float, default 0.0
        Proportional gain, in [0, 1].
    slew_rate : float, "trained" or None, default "trained"
        Largest command change (V/s); the default is the training record's
        fastest change, as for :class:`~piezohyst.Compensator`.
    domain : {"charge", "displacement"}
        Units of the desired values (the measured values are always charge,
        in the model's output units).
    gain : float, optional
        m per model output unit, for ``domain="displacement"``.
    allow_extrapolation : bool, default False
        Keep limits wider than the training range.
    refresh_leakage : bool, default False
        Refine the bias current online from holds of the desired value:
        during a hold the hysteresis is still, so the integral's drift is the
        leakage error. Attributes the whole error to the bias current.
    hold_time : float, default 2.0
        Seconds per refresh window (a quarter of it settles first).
    hold_tolerance : float, optional
        How far the desired value may move and still be a hold (desired
        units); default 1e-4 of the model's output span.
    refresh_gain : float, default 0.5
        Fraction of the estimated bias error corrected per window, in (0, 1].
    output_map : OutputMap, optional
        Desired values are displacements, turned into the capacitor charge through
        this map (:func:`~piezohyst.model.calibrations.from_sensor.calibrate_gain`); the loop
        still closes on the measured charge: the sensor is not needed.

    Examples
    --------
    >>> import piezohyst as ph
    >>> rec = ph.simulate(duration=6.0)
    >>> model = ph.ActivePI(10).fit(rec.voltage, rec.charge, rec.t)
    >>> ctl = ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=1000.0)
    >>> bench = ph.simulation.Bench(voltage=ctl.last_command)
    >>> target = model.hysteresis_.predict([10.0, 20.0, 30.0])
    >>> commands = []
    >>> for d in target:
    ...     commands.append(ctl.step(d, bench.reading.charge))
    ...     _ = bench.apply(commands[-1])
    >>> all(0.0 <= v <= 140.0 for v in commands)
    True

    A :class:`~piezohyst.ModelBank` has its own :class:`BankController`.
    """

    #: True: each command depends on the reading before it (the controllers' one contract,
    #: :mod:`~piezohyst.control.contract`)
    reads = True
    #: Who its warnings name (a stage's loop names its actuator)
    owner = "SelfSensingController"

    def __init__(
        self,
        model: HysteresisModel,
        *,
        v_min: float,
        v_max: float,
        sample_rate: float,
        leakage: Leakage | None = None,
        ki: float = 0.5,
        kp: float = 0.0,
        slew_rate: float | Literal["trained"] | None = "trained",
        domain: Domain = "charge",
        gain: float | None = None,
        allow_extrapolation: bool = False,
        refresh_leakage: bool = False,
        hold_time: float = 2.0,
        hold_tolerance: float | None = None,
        refresh_gain: float = 0.5,
        flat_guard: bool = False,
        output_map: OutputMap | None = None,
    ) -> None:
        fs = _gain(sample_rate, "sample_rate", 1e-300, math.inf)
        comp = Compensator(
            model,
            v_min=v_min,
            v_max=v_max,
            slew_rate=slew_rate,
            sample_rate=fs,
            domain=domain,
            gain=gain,
            allow_extrapolation=allow_extrapolation,
            output_map=output_map,
        )
        if not comp.inverse.closed_loop():
            msg = (
                "SelfSensingController runs a compiled inverse: play operators alone (eq. 18) "
                f"or a Preisach, Duhem or Bouc-Wen core; this {type(model).__name__} keeps "
                "asymmetry or creep beside play operators, or its core has no compiled step"
            )
            raise ParameterError(msg)
        if comp.spec.output_dynamics.active:  # the model's own: a map's mode is the map's
            msg = (
                f"SelfSensingController closes its loop on the charge, which has no mode; this "
                f"{type(model).__name__} holds one (fitted on a displacement): fit the model on "
                "the charge, and the mode into the output map (calibrate_gain finds it)"
            )
            raise ParameterError(msg)
        if comp.mode.active and comp.delay_samples:
            msg = (
                "SelfSensingController inverts the output map's mode or a delay of whole "
                f"samples ({comp.delay_samples}), not both: fit the model without the delay"
            )
            raise ParameterError(msg)
        if leakage is None:
            leakage = Leakage.from_model(model)
        if not isinstance(leakage, Leakage):
            msg = f"'leakage' must be a Leakage (see calibrate_leakage). Got {leakage!r}."
            raise ParameterError(msg)
        if not isinstance(flat_guard, bool):
            msg = f"'flat_guard' must be True or False. Got {flat_guard!r}."
            raise ParameterError(msg)
        if not isinstance(refresh_leakage, bool):
            msg = f"'refresh_leakage' must be True or False. Got {refresh_leakage!r}."
            raise ParameterError(msg)
        self.compensator = comp
        self.model = model
        self.leakage = leakage
        self.sample_rate = fs
        self.ki = _gain(ki, "ki", 0.0, 1.9)
        self.kp = _gain(kp, "kp", 0.0, 1.0)
        self.refresh_leakage = refresh_leakage
        sweep = np.concatenate([np.linspace(comp.v_min, comp.v_max, 200), [comp.v_min]])
        h = comp.spec.operator.predict(sweep)
        span = float(np.ptp(h)) or 1.0  # model output over the limits
        ref_slot, gain_slot = comp.inverse.slots()
        self.ctl = np.zeros(K.CTL_SIZE)
        self.ctl[K.CTL_KP] = self.kp
        self.ctl[K.CTL_G0] = leakage.conductance
        self.ctl[K.CTL_G1] = leakage.quadratic
        self.ctl[K.CTL_INV_SCALE] = 1.0 / leakage.scale
        self.ctl[K.CTL_DISCHARGE] = leakage.discharge
        self.ctl[K.CTL_DT] = 1.0 / fs
        self.ctl[K.CTL_REF] = comp.inverse.config[ref_slot]
        self.ctl[K.CTL_INV_GAIN] = comp.inverse.config[gain_slot]
        self.ctl[K.CTL_TOL] = 1e-9 * span
        inv_gain = float(comp.inverse.config[gain_slot])
        tol = 1e-4 * span if hold_tolerance is None else abs(float(hold_tolerance)) * abs(inv_gain)
        self.ctl[K.CTL_HOLD_TOL] = tol
        self.ctl[K.CTL_HOLD_SAMPLES] = max(8.0, round(_gain(hold_time, "hold_time", 0, 1e6) * fs))
        # the guard: just after a reversal the loop's gain is ki times the actuator's slope over
        # the model's; at most 2 first_slope for ki, it is at most twice the actuator's slope
        # over the model's mean
        self.flat_guard = flat_guard
        self._span = span
        self._first: float | None = None
        #: The integral gain the loop runs with: ``ki``, or lower (``flat_guard``)
        self.ki_used = min(self.ki, 2.0 * self.first_slope) if flat_guard else self.ki
        self.ctl[K.CTL_KI] = self.ki_used
        self.ctl[K.CTL_REFRESH] = (
            _gain(refresh_gain, "refresh_gain", 1e-6, 1.0) if refresh_leakage else 0.0
        )
        # the compensator's kernel sees model units: the controller converts desired values
        self.config = comp.inverse.config.copy()
        self.config[ref_slot] = 0.0
        self.config[gain_slot] = 1.0
        self.feedback = np.zeros(K.CS_SIZE)
        self.reset()

    # ----------------------------------------------------------------- state
    @property
    def first_slope(self) -> float:
        """The model's smallest slope just after a reversal, over its mean slope between
        the limits (probed once, on first use; see ``flat_guard``)."""
        if self._first is None:
            self._first = _first_slope(self.compensator, self._span)
        return self._first

    @property
    def previews(self) -> int:
        """The next desired values :meth:`step` uses where a planned trajectory gives them
        (``preview``): a delay's whole samples, or one for an output map's mode; 0: none."""
        comp = self.compensator
        return max(comp.delay_samples, 1 if comp.mode.active else 0)

    @property
    def v_min(self) -> float:
        """Lower command limit (V), after narrowing."""
        return self.compensator.v_min

    @property
    def v_max(self) -> float:
        """Upper command limit (V), after narrowing."""
        return self.compensator.v_max

    @property
    def last_command(self) -> float:
        """The command sent last (V): where the actuator sits now."""
        return self.compensator.last_command

    def _fresh_feedback(self) -> None:
        fb = self.feedback
        fb[:] = 0.0
        fb[K.CS_D_PREV] = math.nan
        fb[K.CS_HOLD_REF] = math.nan
        fb[K.CS_BIAS] = self.leakage.bias

    def reset(self, state: ControllerState | None = None, *, voltage: float | None = None) -> None:
        """Start again: the feedforward state as :meth:`Compensator.reset`, feedback cleared.

        The next finite measurement sets the frame again.

        Parameters
        ----------
        state : ControllerState, optional
            A :attr:`state` saved earlier (restores the feedback too).
        voltage : float, optional
            The actuator rests at this voltage (V).
        """
        if state is not None:
            fb = np.asarray(state.feedback, dtype=np.float64)
            if fb.shape != (K.CS_SIZE,):
                msg = f"'state.feedback' must hold {K.CS_SIZE} values. Got shape {fb.shape}."
                raise ShapeError(msg)
            self.compensator.reset(state.compensator)
            self.feedback[:] = fb
            return
        self.compensator.reset(voltage=voltage)
        self._fresh_feedback()

    @property
    def state(self) -> ControllerState:
        """A copy of the whole state (see :meth:`reset`)."""
        return ControllerState(self.compensator.state, self.feedback.copy())

    def precondition(self, samples: int = 1000) -> FloatArray:
        """The full-range cycle to send first (:meth:`Compensator.precondition`).

        The feedback restarts after it: the next measurement sets the frame.

        Parameters
        ----------
        samples : int, default 1000

        Returns
        -------
        ndarray
            Voltages (V) to send before the first :meth:`step`.
        """
        out = self.compensator.precondition(samples)
        self._fresh_feedback()
        return out

    @property
    def saturated_count(self) -> int:
        """Commands sent at a voltage limit because the loop asked beyond it (see
        :attr:`Compensator.saturated_count`)."""
        return self.compensator.saturated_count

    @property
    def nonfinite_count(self) -> int:
        """Non-finite desired values (the last command was held)."""
        return self.compensator.nonfinite_count

    @property
    def extrapolated_count(self) -> int:
        """Desired displacements beyond the output map's calibrated range (see
        :attr:`Compensator.extrapolated_count`)."""
        return self.compensator.extrapolated_count

    @property
    def measurement_faults(self) -> int:
        """Non-finite measurements (that sample ran on feedforward alone)."""
        return int(self.feedback[K.CS_FAULTS])

    @property
    def leakage_refreshes(self) -> int:
        """Bias-current refreshes made from holds (``refresh_leakage``)."""
        return int(self.feedback[K.CS_REFRESHES])

    @property
    def leakage_estimate(self) -> Leakage:
        """The leakage in use now (the bias current refreshed online, if enabled)."""
        from dataclasses import replace

        return replace(self.leakage, bias=float(self.feedback[K.CS_BIAS]))

    @property
    def integral(self) -> float:
        """The integral action (model output units): the model error being corrected."""
        return float(self.feedback[K.CS_INTEGRAL])

    # -------------------------------------------------------------- commands
    def step(
        self, desired: float, measured: float | None = None, preview: ArrayLike | None = None
    ) -> float:
        """The command for one sample.

        Parameters
        ----------
        desired : float
            Output wanted at this sample (model output units, or m). NaN or
            infinity holds the last command.
        measured : float, optional
            Charge read at this sample, before this command acts (model output
            units). None, NaN or infinity: feedforward alone for this sample, counted
            in :attr:`measurement_faults`.
        preview : array_like, optional
            The desired values of the next samples, for a model with an input delay
            (as :meth:`Compensator.step <piezohyst.Compensator.step>`): the command is
            computed for ``preview[delay_samples - 1]``, the reading still compared with
            ``desired``. Lags need none. With an output map that holds a mode, ``preview[0]``
            gives the trajectory's derivatives (extrapolated from the last two without it;
            with it, ``step`` equals ``process`` to the bit).

        Returns
        -------
        float
            The command (V): finite, inside ``[v_min, v_max]``.
        """
        comp = self.compensator
        d = float(desired)
        if comp.charges is not None:  # metres through the output map, to the model's charge
            d, preview = comp.charges.one(d, preview)
            if comp.mode.active:  # and the map's mode inverted: the charge that rings there
                d = comp.through_mode_one(d, first_of(preview))
        try:  # the common case inline (a step runs per sample); reading() names the rest
            m = math.nan if measured is None else float(measured)
        except (TypeError, ValueError):
            m = reading(measured, "SelfSensingController")
        loop = (self.config, self.ctl, self.feedback)
        if comp.delay_samples:
            c = comp.inverse.controller_step(d, m, loop, comp.delay_target(d, preview))
        else:
            c = comp.inverse.controller_step(d, m, loop)
        comp.tally_one(c, self.owner)
        return c

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """Commands for recorded blocks; equal to :meth:`step` on each sample.

        Parameters
        ----------
        desired, measured : array_like, shape (N,)
            ``measured`` None: no readings (feedforward alone, every sample counted).
            With an input delay the block is its own preview (as
            :meth:`Compensator.process <piezohyst.Compensator.process>`).

        Returns
        -------
        ndarray, shape (N,)
            Commands (V).
        """
        d = np.ascontiguousarray(desired, dtype=np.float64)
        m = np.full(d.shape, np.nan) if measured is None else measured
        m = np.ascontiguousarray(m, dtype=np.float64)
        if d.ndim != 1 or d.shape != m.shape:
            msg = (
                "'desired' and 'measured' must be 1-D arrays of one length. "
                f"Got shapes {d.shape} and {m.shape}."
            )
            raise ShapeError(msg)
        out = np.empty_like(d)
        comp = self.compensator
        if comp.charges is not None:
            d = comp.charges.block(d)
            if comp.mode.active:
                d = np.ascontiguousarray(comp.through_mode(d, None))
        comp.inverse.controller_process(d, m, (self.config, self.ctl, self.feedback), out)
        comp.tally(out, self.owner)
        return out

    @property
    def slew_limited_count(self) -> int:
        """Commands held back by the slew limit (see :meth:`Compensator.tally`)."""
        return self.compensator.slew_limited_count

    @property
    def command_count(self) -> int:
        """Commands sent from the first that reached the trajectory on (see
        :attr:`Compensator.command_count`)."""
        return self.compensator.command_count

    @property
    def sent_count(self) -> int:
        """Every command sent since the last reset, the approach included."""
        return self.compensator.sent_count


def build_controller(
    settings: CompensatorSettings,
    model: HysteresisModel,
    *,
    leakage: Leakage | None = None,
    ki: float = 0.5,
    kp: float = 0.0,
    refresh_leakage: bool = False,
) -> SelfSensingController:
    """A controller with the limits, domain and slew of ``settings``, checked as files are.

    Limits default to the model's training range; wider ones are refused
    unless ``settings.allow_extrapolation`` (see :class:`CompensatorSettings`).

    Parameters
    ----------
    settings : CompensatorSettings
        ``sample_rate`` is required.
    model : HysteresisModel
    leakage : Leakage, optional
    ki, kp : float
    refresh_leakage : bool

    Returns
    -------
    SelfSensingController

    Raises
    ------
    ParameterError
    """
    if settings.sample_rate is None:
        msg = "the self-sensing controller needs the loop's sample rate (Hz)"
        raise ParameterError(msg)
    comp = settings.build(model)
    return SelfSensingController(
        model,
        v_min=comp.v_min,
        v_max=comp.v_max,
        sample_rate=settings.sample_rate,
        leakage=leakage,
        ki=ki,
        kp=kp,
        slew_rate=settings.slew_rate,
        domain=settings.domain,
        gain=settings.gain,
        allow_extrapolation=settings.allow_extrapolation,
        refresh_leakage=refresh_leakage,
        output_map=settings.output_map,
    )


@dataclass(frozen=True)
class LoopSettings:
    """The self-sensing controller's own settings (see :class:`~piezohyst.SelfSensingController`).

    Attributes
    ----------
    leakage : path or None
        A leakage file (:func:`~piezohyst.workflows.calibrate_leakage_file`); None: the
        model's growth terms.
    ki, kp : float
        Integral and proportional gains.
    refresh_leakage : bool
        Refine the bias current online from holds of the desired value.
    """

    leakage: str | os.PathLike[str] | None = None
    ki: float = 0.5
    kp: float = 0.0
    refresh_leakage: bool = False

    def build(self, settings: CompensatorSettings, model: HysteresisModel) -> SelfSensingController:
        """The controller for ``model`` with ``settings`` (limits, slew, sample rate).

        Parameters
        ----------
        settings : CompensatorSettings
        model : HysteresisModel

        Returns
        -------
        SelfSensingController
        """
        leakage = None if self.leakage is None else Leakage.load(self.leakage)
        if leakage is not None and (leakage.input_unit, leakage.output_unit) != (
            model.input_unit,
            model.output_unit,
        ):
            msg = (
                f"{self.leakage}: the leakage is in {leakage.output_unit}/{leakage.input_unit}, "
                f"the model in {model.output_unit}/{model.input_unit}"
            )
            raise ParameterError(msg)
        return build_controller(
            settings,
            model,
            leakage=leakage,
            ki=self.ki,
            kp=self.kp,
            refresh_leakage=self.refresh_leakage,
        )
