r"""Streaming feedforward compensator with safety limits.

The compensator inverts the hysteresis part of a fitted model (eq. 18) one
sample at a time. It keeps the *forward* operator states (volts: the
actuator's condition) as its state; for each desired value it derives the
inverse states from them, inverts, limits the command, then advances the
forward states with the command actually sent. Inside the limits the output
equals the analytic inverse; when a limit bites, the state still matches what
the actuator received, so the compensator recovers cleanly.

Safety, always:

* the output is finite and inside ``[v_min, v_max]``;
* a NaN or infinite desired value holds the last command and is counted;
* desired values the actuator cannot reach within the limits saturate at
  the limit instead of extrapolating the model;
* an optional slew-rate limit (V/s) bounds the change per sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from .._kernels import play as K
from .._validation import FloatArray
from ..errors import ParameterError, ShapeError, warn
from ..model.calibrations.output_map import OutputMap
from ..model.model import HysteresisModel
from .arguments import Domain, resolve
from .charges import Charges
from .engines import INVERSES, CompensatorState, Inverse
from .tally import Tallied

__all__ = ["Compensator", "CompensatorSettings", "CompensatorState"]


class Compensator(Tallied):
    r"""Feedforward hysteresis compensator for any fitted model.

    The model's growth terms are dropped (leaked charge moves nothing) and its
    hysteresis part is inverted: analytically (eq. 18) when it is play
    operators alone, otherwise exactly by a safeguarded Newton solve per
    sample. The method follows from the terms the model holds
    (:meth:`~piezohyst.model.presets.HysteresisModel.inversion`), not from its class.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model (or any object with an ``inversion()`` method returning
        an :class:`~piezohyst.model.presets.InverseSpec`).
    v_min, v_max : float
        The actuator's voltage limits (V). Every command lies inside them.
    slew_rate : float, "trained" or None, default "trained"
        Largest command change in V/s; needs ``sample_rate``. The default is
        the training record's fastest change: ``model.max_slew_rate_`` per
        second when ``sample_rate`` is given, else ``model.max_step_`` per
        sample (a model that does not record them has no limit). None: no
        limit. The same default as ``piezohyst compensate``.
    sample_rate : float, optional
        Samples per second (Hz) of the control loop, for ``slew_rate`` and for
        models with creep.
    domain : {"charge", "displacement"}
        Units of the desired values: the model's output units, or metres.
    gain : float, optional
        Displacement per model output unit (m/C), required for
        ``domain="displacement"`` (eq. 6-7: S = g·Q). Displacement 0 is the
        actuator at rest in the model's initial state.
    allow_extrapolation : bool, default False
        By default, limits wider than the voltage range the model was
        identified on (``model.input_range_``) are narrowed to it, with one
        ``UserWarning`` (the asked limits stay in :attr:`requested_limits`):
        a model is not trusted where it never saw the actuator. True keeps
        the limits as given.
    output_map : OutputMap, optional
        The map from the capacitor's charge to the displacement
        (:func:`~piezohyst.model.calibrations.from_sensor.calibrate_gain`): desired values
        are then displacements in its unit, turned into the capacitor charge
        that gives them (curvature included; on a map that turns, on the
        branch the charge is on), instead of ``gain``. Displacement 0 is the
        map's, as the sensor read it at calibration.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> h = ph.PIHysteresis([0.0, 20.0], [1e-8, 5e-9])
    >>> comp = ph.Compensator(ph.ClassicalPI.from_operator(h), v_min=0.0, v_max=140.0)
    >>> desired = h.predict([0.0, 50.0, 100.0])
    >>> np.round(comp.process(desired), 9).tolist()
    [0.0, 50.0, 100.0]
    >>> round(comp.step(float("nan")), 9), comp.nonfinite_count   # holds the last command
    (100.0, 1)
    >>> comp.step(1.0)          # far beyond what 140 V gives: saturates
    140.0

    The inverse follows the core's plan (:meth:`~piezohyst.model.cores.base.Core.inverse_plan`):
    eq. 18 for play operators, the compiled bracketed Newton step for the
    Preisach, Duhem and Bouc-Wen cores, a root search on the core for any
    other (:mod:`piezohyst.control.engines`). A :class:`~piezohyst.ModelBank` has its
    own :class:`BankCompensator`.
    """

    domain: Domain  # what the desired values are: the model's output, or metres

    #: False: the commands do not depend on readings (the controllers' one contract,
    #: :mod:`~piezohyst.control.contract`)
    reads = False

    def __init__(
        self,
        model: HysteresisModel,
        *,
        v_min: float,
        v_max: float,
        slew_rate: float | Literal["trained"] | None = "trained",
        sample_rate: float | None = None,
        domain: Domain = "charge",
        gain: float | None = None,
        allow_extrapolation: bool = False,
        output_map: OutputMap | None = None,
    ) -> None:
        #: Desired displacements as charges through the output map (None: no map); a loop
        #: built on this compensator's kernel (the self-sensing controller) uses it too
        self.charges = Charges.of(output_map, gain, model)
        self.output_map = output_map
        a = resolve(
            model, v_min, v_max, slew_rate, sample_rate,
            "charge" if output_map is not None else domain, gain, allow_extrapolation,
            None if output_map is None else output_map.mode,
        )  # fmt: skip
        spec, settings = a.spec, a.settings
        self.model, self.spec, self.gain, self.sample_rate = model, spec, gain, sample_rate
        self.v_min, self.v_max, self.slew_rate = settings.v_min, settings.v_max, a.slew_rate
        self.allow_extrapolation = allow_extrapolation
        self.domain = "displacement" if output_map is not None else domain
        #: The limits asked for, when they were narrowed to the training range (else None).
        self.requested_limits = a.requested_limits
        # input dynamics: an integer delay (handled by preview) and lags inverted per sample
        self.dynamic, self.delay_samples = settings.dynamic, settings.delay_samples
        #: A mechanical mode after the hysteresis, inverted from the desired trajectory (its
        #: differences taken at the loop's rate when given, else the training record's)
        self.mode = a.mode
        self._max_step = settings.max_step
        self._last_desired = math.nan
        self._mode_history = np.full(2, np.nan)
        #: the engine the core's inverse plan names (play, packed, python): it owns the
        #: kernel arrays (:mod:`piezohyst.control.engines`)
        self.inverse: Inverse = INVERSES[spec.operator.inverse_plan().engine](spec, settings)
        #: True when eq. 18's analytic inverse runs (no Newton solve); fixed by the model
        self.analytic = self.inverse.analytic
        self._plain = self.inverse.plain and output_map is None
        self.reset()

    @property
    def n_operators(self) -> int:
        """Values in the core's state (play operators: their number)."""
        return int(self.inverse.n_operators())

    @property
    def reference(self) -> float:
        """The model output that ``domain="displacement"`` takes as displacement 0: the
        actuator at rest in the model's initial state (0 in the charge domain)."""
        return float(self.inverse.config[self.inverse.slots()[0]])

    @property
    def state(self) -> CompensatorState:
        """The forward states and the last command (copies; see :meth:`reset`)."""
        return self.inverse.state()

    @property
    def mode_history(self) -> FloatArray:
        """The two desired values before the next one (raw; NaN: none yet), for the mode."""
        return self._mode_history.copy()

    @property
    def plain(self) -> bool:
        """True when :meth:`step` is one analytic kernel call (no input dynamics, no mode)."""
        return self._plain

    def share(self, tables: FloatArray, config: FloatArray, state: FloatArray) -> None:
        """Run on arrays owned by a multi-channel container (views of its rows; play only).

        Parameters
        ----------
        tables, config, state : ndarray
            Views of the container's rows, laid out as this compensator's own.
        """
        self.inverse.share(tables, config, state)

    @property
    def kernel_state(self) -> FloatArray:
        """The live state array the kernels update (no copy).

        For loops built on this compensator's kernel (the self-sensing
        controller); use :attr:`state` and :meth:`reset` otherwise.
        """
        return self.inverse.kernel_state

    def reset(
        self, state: CompensatorState | ArrayLike | None = None, *, voltage: float | None = None
    ) -> None:
        """Start again from a known actuator condition; counters go back to 0.

        Parameters
        ----------
        state : CompensatorState or array_like, optional
            Explicit forward states, e.g. a :attr:`state` saved earlier; or an
            array of the core's states, optionally followed by the last command.
        voltage : float, optional
            The actuator now sits at ``voltage`` (V): the model's initial
            state moved there (play operators: clamped into
            ``[v - r_i, v + r_i]``, eq. 10), lags settled there. Use this after
            an unknown history only with :meth:`precondition`, which erases it.

        Notes
        -----
        Without arguments: the model's initial state (the training record's
        start); if the limits exclude that voltage, the first command steps in.

        Raises
        ------
        ParameterError
            If the last command would lie outside the limits.
        """
        self.inverse.reset(state, voltage)
        if self.charges is not None:
            self.charges.reset()
        self._mode_history[:] = np.nan
        self._last_desired = math.nan
        self._count_reset()

    def precondition(
        self, samples: int = 1000, span: tuple[float, float] | None = None
    ) -> FloatArray:
        """The preconditioning cycle to send first: last command → high → low → back.

        A full-amplitude cycle wipes out the actuator's unknown history (the
        remanence problem: a fresh model assumes a known state). The returned
        voltages must be sent to the amplifier before the first :meth:`step`;
        the compensator's state is advanced as if they had been. With a
        slew-rate limit the cycle gets as many samples as it needs to reach
        both ends.

        Parameters
        ----------
        samples : int, default 1000
            Samples in the cycle (at least 3).
        span : (float, float), optional
            The voltages (V) the cycle reaches, inside the limits: what a
            trajectory needs (its commands, with a margin). Default: the limits.

        Returns
        -------
        ndarray
            The voltages (V) to send.
        """
        cycle = self.inverse.precondition(self._cycle(samples, span))
        self._tally[K.TALLY_PREV] = self.last_command  # a cycle at the slew limit: not counted
        self._tally[K.TALLY_ARRIVED] = 0.0  # nor the ramp from its end to the trajectory
        self._tally[K.TALLY_APPROACH] = 0.0  # (unless it does not arrive)
        self._approach_warned = False
        return cycle

    def _cycle(self, samples: int, span: tuple[float, float] | None = None) -> FloatArray:
        """last command -> v_max -> v_min -> back, each extreme reached exactly (and held
        until a lagging piezo voltage reached it)."""
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 3:
            msg = f"'samples' must be an int >= 3. Got {samples!r}."
            raise ParameterError(msg)
        start = self.last_command
        low, high = (self.v_min, self.v_max) if span is None else span
        if not self.v_min <= low < high <= self.v_max:
            msg = (
                f"'span' must lie inside the limits [{self.v_min:g}, {self.v_max:g}] V with "
                f"low < high. Got {span!r}."
            )
            raise ParameterError(msg)
        settle = 0
        if self.dynamic:  # hold each extreme until the lagging piezo voltage has reached it
            dyn = self.inverse.dyn
            gain = dyn[K.DYN_GAIN_B]  # the lag's (creep terms of other cores follow)
            settle = int(np.ceil(-np.log(1e-9) / -np.log1p(-gain))) if gain > 0 else 0
            settle += 1 if dyn[K.DYN_FRACTION] != 0 else 0  # the fraction: one sample
            settle += self.delay_samples
        return _cycle_commands([start, high, low, start], samples, self._max_step, settle)

    # -------------------------------------------------------------- commands
    def through_mode_one(self, desired: float, nxt: float) -> float:
        """:meth:`through_mode` of one desired value in floats (the next one ``nxt``, NaN:
        extrapolated), to the bit the block's arithmetic.

        Parameters
        ----------
        desired, nxt : float

        Returns
        -------
        float
        """
        e2, e1 = float(self._mode_history[0]), float(self._mode_history[1])
        target = self.mode.invert_one(desired, e1, e2, nxt)
        self._mode_history[0], self._mode_history[1] = e1, desired
        return target

    def through_mode(self, desired: FloatArray, preview: ArrayLike | None) -> FloatArray:
        """The hysteresis output that makes the model's (or the output map's) mode follow
        ``desired``; the two desired values before the next are kept (:attr:`mode_history`).

        Parameters
        ----------
        desired : ndarray
            Desired values after the output map's inverse (model output units).
        preview : array_like or None
            The next desired values (the first is used; None: extrapolated, or, for a block,
            the block's own next values).

        Returns
        -------
        ndarray
        """
        if not self.mode.active:
            return desired
        ahead = np.asarray(preview if preview is not None else [], dtype=np.float64).reshape(-1)
        target = self.mode.invert(desired, self._mode_history, ahead)
        both = np.concatenate([self._mode_history, desired])
        self._mode_history = both[-2:].copy()
        return target

    def step(
        self, desired: float, measured: float | None = None, preview: ArrayLike | None = None
    ) -> float:  # no keyword-only argument: CPython fills those from a dict, 35 ns a call
        """The command for one desired value.

        Parameters
        ----------
        desired : float
            Desired output (model output units, or m for ``domain="displacement"``).
            NaN or infinity holds the last command and is counted.
        measured : float, optional
            The reading after the command before: ignored, a feedforward compensator
            reads nothing (the controllers' one contract, :mod:`~piezohyst.control.contract`).
            Where the model takes a preview, one that is not a number is refused (a
            preview passed where it once was).
        preview : array_like, optional
            The desired values of the next samples, for a model with an input
            delay of ``delay_samples`` samples: the command sent now acts that
            many samples later, so it is computed for ``preview[delay_samples - 1]``.
            Without enough preview the target is extrapolated linearly from
            the last two desired values (the best causal guess). Lags need no
            preview: they are inverted exactly one sample at a time. A model
            with an output mode uses ``preview[0]`` for the trajectory's
            derivatives (extrapolated without it).

        Returns
        -------
        float
            The command (V), finite and inside ``[v_min, v_max]``.
        """
        try:
            d = float(desired)
        except (TypeError, ValueError):
            msg = (
                "Compensator.step takes one desired value (a number, in "
                f"{'m' if self.domain == 'displacement' else self.model.output_unit}). Got "
                f"{desired!r} instead."
            )
            raise ParameterError(msg) from None
        if self._plain:  # the common case first: one kernel call, the command counted in it
            e = self.inverse
            c = float(K.compensator_step_tallied(d, e.tables, e.config, e.kernel_state,
                                                 self._tally))  # fmt: skip
        else:  # where a preview counts, one passed where it once was (2nd) is refused
            if measured is not None and not isinstance(measured, float):
                self._check_reading(measured)
            c = float(K.tally_command(self._step_general(d, preview), self._tally))
        self._until_check -= 1
        if not self._until_check:
            self._check_limits(self.owner)
        return c

    @staticmethod
    def _check_reading(measured: object) -> None:
        """A reading that is not a number: most likely a preview passed where it once was."""
        try:
            float(measured)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            msg = (
                "Compensator.step's second argument is a reading (a number, ignored: the "
                "compensator is feedforward); give the next desired values as preview=. Got "
                f"{measured!r}."
            )
            raise ParameterError(msg) from None

    def _step_general(self, desired: float, preview: ArrayLike | None) -> float:
        """:meth:`step` for a model with input dynamics, a mode, an output map or another
        engine."""
        if self.charges is not None:
            desired, preview = self.charges.one(desired, preview)
        if self.mode.active and self.dynamic and self.delay_samples:
            return self._step_mode_delayed(float(desired), preview)
        if self.mode.active:
            desired = self.through_mode_one(float(desired), first_of(preview))
        if self.dynamic:
            return self._inner_step(self.delay_target(float(desired), preview))
        return self._inner_step(float(desired))

    def delay_target(self, desired: float, preview: ArrayLike | None) -> float:
        """The output the command sent now must bring, ``delay_samples`` samples on.

        Parameters
        ----------
        desired : float
            The output wanted at this sample (remembered for the next extrapolation).
        preview : array_like or None
            The next samples' desired values.

        Returns
        -------
        float
            ``preview[delay_samples - 1]``, or extrapolated linearly from the last two
            desired values without enough preview (see :meth:`step`); ``desired`` without
            a delay.
        """
        m = self.delay_samples
        target = desired
        if m:
            ahead = np.asarray(preview if preview is not None else [], dtype=np.float64)
            if ahead.size >= m:
                target = float(ahead[m - 1])
            elif math.isfinite(self._last_desired):
                target = desired + m * (desired - self._last_desired)
        self._last_desired = desired
        return target

    def _inner_step(self, target: float) -> float:
        """The engine's command for the hysteresis output ``target`` (after mode and delay)."""
        return float(self.inverse.inner_step(target))

    def _step_mode_delayed(self, d: float, preview: ArrayLike | None) -> float:
        """A mode and an integer delay: the command now acts ``m`` samples later, so the
        mode is inverted at the desired value ``m`` samples ahead, from the preview."""
        m = self.delay_samples
        ahead = np.asarray(preview if preview is not None else [], dtype=np.float64).reshape(-1)
        seq = [float(v) for v in self._mode_history] + [d] + [float(v) for v in ahead]
        while len(seq) < m + 5:  # up to the sample after the target, extrapolated linearly
            a, b = seq[-2], seq[-1]
            seq.append(2.0 * b - a if math.isfinite(a) else b)
        j = 2 + m  # the target's index: k + m
        e = np.array(seq)
        target = float(self.mode.invert(e[j : j + 1], e[j - 2 : j], e[j + 1 : j + 2])[0])
        self._mode_history = np.array([self._mode_history[1], d])
        self._last_desired = d
        return self._inner_step(target)

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """Commands for a block of desired values; equal to calling :meth:`step` on each.

        With an input delay, the block is its own preview: the command at
        sample k targets ``desired[k + delay_samples]``, and the last
        ``delay_samples`` targets, beyond the block, are extrapolated. Give a
        planned trajectory in one call (or blocks that overlap by the delay).

        Parameters
        ----------
        desired : array_like, shape (N,)
            Desired outputs; NaN and infinite values hold the last command.
        measured : array_like, shape (N,), optional
            Readings: ignored (feedforward), their shape checked.

        Returns
        -------
        ndarray, shape (N,)
            Commands (V).
        """
        d = np.ascontiguousarray(desired, dtype=np.float64)
        if d.ndim != 1:
            msg = f"'desired' must be a 1-D array. Got shape {d.shape}."
            raise ShapeError(msg)
        if measured is not None and np.shape(measured) != d.shape:
            msg = f"'measured' must match 'desired' (shape {d.shape}). Got {np.shape(measured)}."
            raise ShapeError(msg)
        if self.charges is not None:
            d = self.charges.block(d)
        if self.mode.active:
            d = np.ascontiguousarray(self.through_mode(d, None))
        out = np.empty_like(d)
        prev = self.last_command
        self._inner_process(d, out)
        if self.dynamic and d.size:
            self._last_desired = float(d[-1])
        self._tally[K.TALLY_PREV] = prev
        self.tally(out)
        return out

    def _inner_process(self, d: FloatArray, out: FloatArray) -> None:
        """The engine over a block of hysteresis outputs (after the mode)."""
        self.inverse.inner_process(d, out)


#: A file workflow's limit this far beyond the training voltages (a fraction of their span)
#: is narrowed to them, with a warning, rather than refused: the record's peak measured a
#: little under the amplifier's setting (139.65 V of 140 V)
LIMIT_SLACK = 0.01


def _cycle_commands(knots: list[float], samples: int, step: float, settle: int) -> FloatArray:
    """Straight legs through ``knots`` sharing ``samples``, none faster than ``step`` per
    sample, each ending exactly on its knot (reaching v_max and v_min is what wipes history)
    and the first two extremes held ``settle`` samples more."""
    legs = np.abs(np.diff(knots))
    share = legs / max(float(legs.sum()), 1e-300)
    counts = np.maximum(np.round(share * (samples - 1)).astype(int), 1)
    if math.isfinite(step):
        counts = np.maximum(counts, np.ceil(legs / step * (1 + 1e-12)).astype(int))
    pieces = [
        np.linspace(a, b, int(m) + 1)[1:]
        for a, b, m in zip(knots[:-1], knots[1:], counts, strict=True)
    ]
    for j in (0, 1):
        pieces[j] = np.concatenate([pieces[j], np.full(settle, knots[j + 1])])
    return np.concatenate(pieces)


@dataclass(frozen=True)
class CompensatorSettings:
    """How to build a :class:`~piezohyst.Compensator` from a model file.

    Attributes
    ----------
    v_min, v_max : float or None
        Voltage limits (V); None: the model's training range.
    domain : {"charge", "displacement"}
        Units of the desired values.
    gain : float or None
        m per model output unit, for ``domain="displacement"``.
    slew_rate : float, "trained" or None
        Largest change in V/s (needs ``sample_rate``); "trained": the training
        record's fastest (see :class:`Compensator`); None: no limit.
    sample_rate : float or None
        Loop rate (Hz).
    allow_extrapolation : bool
        Allow limits beyond the voltages the model was identified on (refused
        otherwise, not narrowed: a file workflow states what it will do).
    output_map : OutputMap or None
        The charge -> displacement map (``calibrate-gain``'s file) instead of a gain.
    """

    v_min: float | None = None
    v_max: float | None = None
    domain: Domain = "charge"
    gain: float | None = None
    slew_rate: float | Literal["trained"] | None = "trained"
    sample_rate: float | None = None
    allow_extrapolation: bool = False
    output_map: OutputMap | None = None

    def build(self, model: HysteresisModel) -> Compensator:
        """A compensator for ``model`` whose limits default to its training voltage range.

        Parameters
        ----------
        model : HysteresisModel
            The fitted model to invert.

        Returns
        -------
        Compensator
            With these settings' limits, domain, gain, slew and sample rate.

        Raises
        ------
        ParameterError
            A limit is missing and the model does not record its training range.
        """
        lo, hi = model.input_range_
        known = not (math.isnan(lo) or math.isnan(hi))
        if (self.v_min is None or self.v_max is None) and not known:
            msg = "the model does not record its training voltage range: give v_min and v_max"
            raise ParameterError(msg)
        v_min, v_max = self.v_min, self.v_max
        if known and not self.allow_extrapolation:
            # a limit a hair beyond the record (commanded 140 V, measured 139.65 V) is the
            # record's limit: narrowed to it, and said; further beyond is refused
            slack = LIMIT_SLACK * (hi - lo)
            narrowed = (v_min is not None and lo - slack <= v_min < lo,
                        v_max is not None and hi < v_max <= hi + slack)  # fmt: skip
            if any(narrowed):
                v_min = lo if narrowed[0] else v_min
                v_max = hi if narrowed[1] else v_max
                warn(
                    f"the limits [{self.v_min if self.v_min is not None else lo:g}, "
                    f"{self.v_max if self.v_max is not None else hi:g}] V were narrowed to "
                    f"[{v_min if v_min is not None else lo:.6g}, "
                    f"{v_max if v_max is not None else hi:.6g}] V, the voltages the model was "
                    "identified on (--allow-extrapolation keeps them)",
                    UserWarning,
                )
        wide = (v_min is not None and v_min < lo) or (v_max is not None and v_max > hi)
        if known and wide and not self.allow_extrapolation:
            msg = (
                f"the limits [{self.v_min if self.v_min is not None else lo:g}, "
                f"{self.v_max if self.v_max is not None else hi:g}] V go beyond the voltages "
                f"the model was identified on, [{lo:.6g}, {hi:.6g}] V: give limits inside "
                "them (or leave --v-min/--v-max out: they default to them), or allow "
                "extrapolation explicitly (--allow-extrapolation, allow_extrapolation=True)"
            )
            raise ParameterError(msg)
        return Compensator(
            model,
            v_min=lo if v_min is None else float(v_min),
            v_max=hi if v_max is None else float(v_max),
            domain=self.domain,
            gain=self.gain,
            slew_rate=self.slew_rate,
            sample_rate=self.sample_rate,
            allow_extrapolation=self.allow_extrapolation,
            output_map=self.output_map,
        )


def first_of(preview: ArrayLike | None) -> float:
    """The first of a preview's values (NaN without one): the next desired value a mode's
    inverse takes.

    Parameters
    ----------
    preview : array_like or None

    Returns
    -------
    float
    """
    if preview is None:
        return math.nan
    ahead = np.ravel(np.asarray(preview, dtype=np.float64))
    return float(ahead[0]) if ahead.size else math.nan
