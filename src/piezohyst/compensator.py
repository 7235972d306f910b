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
import warnings
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._lazy import LazyModule
from ._validation import FloatArray, as_signal
from .bank import ModelBank
from .cores.base import PackedCore
from .cores.play import PIHysteresis
from .errors import NotInvertibleError, ParameterError, ShapeError
from .model import HysteresisModel, InverseSpec

if TYPE_CHECKING:
    from . import _diffkernels as D
    from . import _kernels as K
else:  # numba loads when a model first runs (see _lazy)
    D = LazyModule("piezohyst._diffkernels", globals(), "D")
    K = LazyModule("piezohyst._kernels", globals(), "K")

__all__ = ["BankCompensator", "Compensator", "CompensatorState", "CoreCompensator"]

Domain = Literal["charge", "displacement"]


def _finite_number(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        msg = f"The '{name}' parameter of Compensator must be a number. Got {value!r} instead."
        raise ParameterError(msg)
    v = float(value)
    if not math.isfinite(v):
        msg = f"The '{name}' parameter of Compensator must be finite. Got {value!r} instead."
        raise ParameterError(msg)
    return v


@dataclass(frozen=True)
class CompensatorState:
    """The actuator's condition as a compensator sees it (forward states only).

    Attributes
    ----------
    operators : ndarray, shape (n,)
        Play-operator states (V) after the commands sent so far.
    lags : ndarray, shape (m,)
        Creep lag states (V); empty without creep.
    command : float
        The last command sent (V).
    dynamics : ndarray
        The input dynamics' state (V; empty without input dynamics).
    """

    operators: FloatArray
    lags: FloatArray
    command: float
    dynamics: FloatArray = field(default_factory=lambda: np.zeros(0))


class Compensator:
    r"""Feedforward hysteresis compensator for any fitted model.

    The model's growth terms are dropped (leaked charge moves nothing) and its
    hysteresis part is inverted: analytically (eq. 18) when it is play
    operators alone, otherwise exactly by a safeguarded Newton solve per
    sample. The method follows from the terms the model holds
    (:meth:`~piezohyst.models.HysteresisModel.inversion`), not from its class.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model (or any object with an ``inversion()`` method returning
        an :class:`~piezohyst.models.InverseSpec`).
    v_min, v_max : float
        The actuator's voltage limits (V). Every command lies inside them.
    slew_rate : float, optional
        Largest command change in V/s; needs ``sample_rate``.
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

    Given a :class:`~piezohyst.ModelBank`, it builds a
    :class:`BankCompensator` (one command per channel per step).
    """

    def __new__(cls, model: HysteresisModel | ModelBank, **kwargs: Any) -> Compensator:
        if isinstance(model, ModelBank):  # many channels: the bank's compensator
            return BankCompensator(model, **kwargs)  # type: ignore[return-value]
        if cls is Compensator and _differential(model):  # a Duhem or Bouc-Wen core
            return super().__new__(CoreCompensator)
        return super().__new__(cls)

    def __init__(
        self,
        model: HysteresisModel,
        *,
        v_min: float,
        v_max: float,
        slew_rate: float | None = None,
        sample_rate: float | None = None,
        domain: Domain = "charge",
        gain: float | None = None,
        allow_extrapolation: bool = False,
    ) -> None:
        spec, max_step, inv_gain = self._settings(
            model, v_min, v_max, slew_rate, sample_rate, domain, gain, allow_extrapolation
        )
        plan = spec.operator.inverse_plan()
        if plan.engine != "play":  # a core with no compiled inverse step (defined elsewhere)
            msg = (
                f"a {type(spec.operator).__name__} core has no compiled inverse step: the "
                "compensator inverts play operators and the Preisach, Duhem and Bouc-Wen cores"
            )
            raise NotInvertibleError(msg)
        op = _play(spec)
        if not op.is_invertible:
            op.inverse()  # raises NotInvertibleError with the reason
        dyn = spec.dynamics
        if spec.relaxation is not None:
            msg = (
                "a relaxation term is inverted beside a Preisach, Duhem or Bouc-Wen core only: "
                "fit a PreisachModel(relaxation=...) instead"
            )
            raise ParameterError(msg)
        if dyn.active and not spec.analytic:
            msg = (
                "A model with input dynamics is compensated with the analytic inverse only: fit "
                "it without asymmetry or creep terms."
            )
            raise ParameterError(msg)
        #: True when eq. 18's analytic inverse runs (no Newton solve); fixed by the model
        self.analytic = spec.analytic
        self._plain = spec.analytic and not dyn.active and not self.mode.active
        n = op.n_operators
        self.tables = np.zeros((5, n))
        self.tables[K.TAB_R] = op.thresholds
        self.tables[K.TAB_W] = op.weights
        self.config = np.zeros(K.CONFIG_SIZE)
        self.config[K.CFG_OFFSET] = op.offset
        self.config[K.CFG_V_MIN] = self.v_min
        self.config[K.CFG_V_MAX] = self.v_max
        self.config[K.CFG_MAX_STEP] = max_step
        self.config[K.CFG_INV_GAIN] = inv_gain
        self.config[K.CFG_STATIC_SCALE] = 1.0
        if spec.analytic:
            inv = op.inverse()
            self.tables[K.TAB_S] = op.loading_slopes
            self.tables[K.TAB_RI] = inv.thresholds
            self.tables[K.TAB_WI] = inv.weights
            self.config[K.CFG_INV_OFFSET] = inv.offset
            reach = max(abs(self.v_min), abs(self.v_max)) + float(op.thresholds[-1])
            self.config[K.CFG_BOUND] = 2.0 * float(np.abs(op.weights).sum()) * reach + 1.0
            self.static = np.zeros((3, 0))
            self.lags = np.zeros((3, 0))
            n_aux = n
        else:
            st = spec.static
            self.static = np.zeros((3, 0)) if st is None else np.vstack([st.knots, st.up, st.down])
            if st is not None:
                self.config[K.CFG_STATIC_SCALE] = st.scale
            lg = spec.lags
            if lg is None:
                self.lags = np.zeros((3, 0))
            else:
                dt = 1.0 / float(sample_rate)  # type: ignore[arg-type]
                self.lags = np.vstack([lg.taus, lg.gains, 1.0 - np.exp(-dt / lg.taus)])
            n_aux = self.lags.shape[1]
        self._state = np.zeros(n + n_aux + 3)
        self._n_aux = n_aux
        if domain == "displacement":  # displacement 0 = output at rest in the initial state
            if spec.analytic:
                self.config[K.CFG_REFERENCE] = op.offset + float(op.weights @ op.initial_state)
            else:
                self._set_forward(self._initial_forward())
                self.config[K.CFG_REFERENCE] = self._output_now(float(op.initial_state[0]))
        self.reset()

    def _settings(
        self,
        model: HysteresisModel,
        v_min: float,
        v_max: float,
        slew_rate: float | None,
        sample_rate: float | None,
        domain: Domain,
        gain: float | None,
        allow_extrapolation: bool,
    ) -> tuple[InverseSpec, float, float]:
        """The checks and settings every compensator shares; (spec, max step, inverse gain)."""
        inversion = getattr(model, "inversion", None)
        if not callable(inversion):
            msg = (
                "The 'model' parameter of Compensator must be a fitted piezohyst model. "
                f"Got {type(model).__name__} instead."
            )
            raise ParameterError(msg)
        spec: InverseSpec = inversion()
        self.v_min = _finite_number(v_min, "v_min")
        self.v_max = _finite_number(v_max, "v_max")
        if not self.v_min < self.v_max:
            msg = f"Compensator needs v_min < v_max. Got v_min={v_min!r}, v_max={v_max!r}."
            raise ParameterError(msg)
        if not isinstance(allow_extrapolation, bool):
            msg = f"'allow_extrapolation' must be True or False. Got {allow_extrapolation!r}."
            raise ParameterError(msg)
        self.allow_extrapolation = allow_extrapolation
        #: The limits asked for, when they were narrowed to the training range (else None).
        self.requested_limits: tuple[float, float] | None = None
        self._narrow_to(spec.input_range)
        max_step = math.inf
        if slew_rate is not None:
            rate = _finite_number(slew_rate, "slew_rate")
            if sample_rate is None:
                msg = "A slew_rate (V/s) needs the loop's sample_rate (Hz). Got sample_rate=None."
                raise ParameterError(msg)
            fs = _finite_number(sample_rate, "sample_rate")
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
            g = _finite_number(gain, "gain")
            if g == 0.0:
                msg = "The 'gain' parameter of Compensator must be non-zero. Got 0."
                raise ParameterError(msg)
            inv_gain = 1.0 / g
        dyn = spec.dynamics
        timed = [(dyn.active, "input dynamics"), (spec.lags is not None, "creep"),
                 (spec.relaxation is not None, "a relaxation term")]  # fmt: skip
        for needed, what in timed:
            if needed and sample_rate is None:
                msg = f"A model with {what} needs the loop's sample_rate (Hz). Got None."
                raise ParameterError(msg)
        self.model = model
        self.spec = spec
        self.domain: Domain = domain
        self.gain = gain
        self.slew_rate = slew_rate
        self.sample_rate = sample_rate
        # input dynamics: an integer delay (handled by preview) and lags inverted per sample
        self.dynamic = dyn.active
        self.delay_samples = 0
        self.dyn = np.zeros(2)
        self.dstate = np.zeros(2)
        self._last_desired = math.nan
        #: A mechanical mode after the hysteresis, inverted from the desired trajectory (its
        #: differences taken at the loop's rate when given, else the training record's)
        self.mode = spec.output_dynamics
        if self.mode.active and sample_rate is not None:
            self.mode = replace(self.mode, sample_interval=1.0 / float(sample_rate))
        self._mode_history = np.full(2, np.nan)
        if dyn.active:
            dt = 1.0 / float(sample_rate)  # type: ignore[arg-type]
            d = dyn.delay / dt
            self.delay_samples = math.floor(d + 1e-9)
            frac = d - self.delay_samples
            if frac > 1e-9:  # the fraction of a sample inverted as a lag of that length
                self.dyn[K.DYN_GAIN_A] = 1.0 - math.exp(-1.0 / frac)
            if dyn.tau > 0:
                self.dyn[K.DYN_GAIN_B] = 1.0 - math.exp(-dt / dyn.tau)
        self._max_step = max_step
        return spec, max_step, inv_gain

    def _narrow_to(self, trained: tuple[float, float]) -> None:
        """Keep every command inside the voltages the model was identified on."""
        lo, hi = trained
        if self.allow_extrapolation or math.isnan(lo) or math.isnan(hi):
            return
        if self.v_min >= lo and self.v_max <= hi:
            return
        new_lo, new_hi = max(self.v_min, lo), min(self.v_max, hi)
        if not new_lo < new_hi:
            msg = (
                f"The limits [{self.v_min:g}, {self.v_max:g}] V do not overlap the voltages the "
                f"model was identified on, [{lo:g}, {hi:g}] V; pass allow_extrapolation=True "
                "to use the model outside them."
            )
            raise ParameterError(msg)
        self.requested_limits = (self.v_min, self.v_max)
        warnings.warn(
            f"Compensator limits [{self.v_min:g}, {self.v_max:g}] V narrowed to "
            f"[{new_lo:g}, {new_hi:g}] V, the voltages the model was identified on: a model "
            "is not trusted outside them (pass allow_extrapolation=True to keep the limits).",
            UserWarning,
            stacklevel=3,
        )
        self.v_min, self.v_max = new_lo, new_hi

    # ----------------------------------------------------------------- state
    @property
    def n_operators(self) -> int:
        """Number of play operators of the inverted model."""
        return int(self.tables.shape[1])

    def _initial_forward(self) -> tuple[FloatArray, FloatArray]:
        op = _play(self.spec)
        x0 = float(op.initial_state[0])
        return op.initial_state.copy(), np.full(self.lags.shape[1], x0)

    def _set_forward(self, forward: tuple[FloatArray, FloatArray]) -> None:
        n = self.n_operators
        self._state[:n] = forward[0]
        if not self.analytic:
            self._state[n : n + self._n_aux] = forward[1]
        else:
            K.inverse_states(self.tables, self.config, self._state)

    def _output_now(self, v: float) -> float:
        """The hysteresis part's output (model units) if ``v`` were sent from the current state."""
        y, _ = K.hysteresis_output(v, self.tables, self.static, self.lags, self.config, self._state)
        return float(y)

    @property
    def state(self) -> CompensatorState:
        """The forward states and the last command (copies; see :meth:`reset`)."""
        n = self.n_operators
        lags = self._state[n : n + self._n_aux] if not self.analytic else np.zeros(0)
        return CompensatorState(
            self._state[:n].copy(),
            lags.copy(),
            float(self._state[K.ST_LAST]),
            self.dstate.copy() if self.dynamic else np.zeros(0),
        )

    @property
    def mode_history(self) -> FloatArray:
        """The two desired values before the next one (raw; NaN: none yet), for the mode."""
        return self._mode_history.copy()

    @property
    def plain(self) -> bool:
        """True when :meth:`step` is one analytic kernel call (no input dynamics, no mode)."""
        return self._plain

    def share(self, tables: FloatArray, config: FloatArray, state: FloatArray) -> None:
        """Run on arrays owned by a multi-channel container (views of its rows).

        The arrays must hold this compensator's current values (the bank
        stacks them first); from then on both see every update.

        Parameters
        ----------
        tables, config, state : ndarray
            Views of the container's rows, laid out as this compensator's own.
        """
        if not (
            np.array_equal(tables, self.tables)
            and np.array_equal(config, self.config)
            and np.array_equal(state, self._state)
        ):
            msg = "shared arrays must hold the compensator's current tables, config and state"
            raise ParameterError(msg)
        self.tables, self.config, self._state = tables, config, state

    @property
    def last_command(self) -> float:
        """The command sent last (V): where the actuator sits now."""
        return float(self._state[K.ST_LAST])

    @property
    def kernel_state(self) -> FloatArray:
        """The live state array the kernels update (layout ``ST_*`` in ``_kernels``; no copy).

        For loops built on this compensator's kernel (the self-sensing
        controller); use :attr:`state` and :meth:`reset` otherwise.
        """
        return self._state

    @property
    def nonfinite_count(self) -> int:
        """Desired values that were NaN or infinite (the last command was held)."""
        return int(self._state[K.ST_NONFINITE])

    @property
    def saturated_count(self) -> int:
        """Samples whose command was clipped to ``[v_min, v_max]``."""
        return int(self._state[K.ST_SATURATED])

    def reset(
        self, state: CompensatorState | ArrayLike | None = None, *, voltage: float | None = None
    ) -> None:
        """Start again from a known actuator condition; counters go back to 0.

        Parameters
        ----------
        state : CompensatorState or array_like, optional
            Explicit forward states, e.g. a :attr:`state` saved earlier; or an
            array of the operator states (V), optionally followed by the last
            command.
        voltage : float, optional
            The actuator now sits at ``voltage`` (V): the model's initial state
            is projected onto it (eq. 10: each operator clamped into
            ``[v - r_i, v + r_i]``), lags settled there. Use this after an
            unknown history only with :meth:`precondition`, which erases it.

        Notes
        -----
        Without arguments: the model's initial state (the training record's
        start); if the limits exclude that voltage, the first command steps in.

        Raises
        ------
        ParameterError
            If the last command would lie outside the limits.
        """
        n = self.n_operators
        m = self.lags.shape[1]
        op = _play(self.spec)
        if isinstance(state, CompensatorState):
            ops = as_signal(state.operators, "state.operators")
            lags = as_signal(state.lags, "state.lags", allow_empty=True)
            if ops.size != n or lags.size != m:
                msg = (
                    f"'state' must hold {n} operator and {m} lag states. "
                    f"Got {ops.size}, {lags.size}."
                )
                raise ShapeError(msg)
            last = float(state.command)
        elif state is not None:
            z = as_signal(state, "state")
            if z.size not in (n, n + 1):
                msg = f"'state' must hold {n} operator states (and the last command). Got {z.size}."
                raise ShapeError(msg)
            ops = z[:n]
            lags = np.full(m, float(ops[0]))
            last = (
                float(z[-1]) if z.size == n + 1 else float(np.clip(ops[0], self.v_min, self.v_max))
            )
        elif voltage is None:
            ops, lags = self._initial_forward()
            last = float(np.clip(ops[0], self.v_min, self.v_max))
        else:
            v = _finite_number(voltage, "voltage")
            ops = np.clip(op.initial_state, v - op.thresholds, v + op.thresholds)
            lags = np.full(m, v)
            last = v
        if not self.v_min <= last <= self.v_max:
            msg = (
                f"The actuator's voltage {last!r} V is outside the limits "
                f"[{self.v_min}, {self.v_max}] V."
            )
            raise ParameterError(msg)
        self._set_forward((np.array(ops, dtype=np.float64), np.array(lags, dtype=np.float64)))
        self.dstate[:] = last  # the piezo settled at the last command
        self._mode_history[:] = np.nan
        if isinstance(state, CompensatorState) and state.dynamics.size == 2 and self.dynamic:
            self.dstate[:] = state.dynamics
        self._last_desired = math.nan
        self._state[K.ST_LAST] = last
        self._state[K.ST_NONFINITE] = 0.0
        self._state[K.ST_SATURATED] = 0.0

    def precondition(self, samples: int = 1000) -> FloatArray:
        """The preconditioning cycle to send first: last command → v_max → v_min → back.

        A full-amplitude cycle wipes out the actuator's unknown history (the
        remanence problem: a fresh model assumes a known state). The returned
        voltages must be sent to the amplifier before the first :meth:`step`;
        the compensator's state is advanced as if they had been. With a
        slew-rate limit the cycle gets as many samples as it needs to reach
        both limits.

        Parameters
        ----------
        samples : int, default 1000
            Samples in the cycle (at least 3).

        Returns
        -------
        ndarray
            The voltages (V) to send.
        """
        cycle = self._cycle(samples)
        n = self.n_operators
        r = self.tables[K.TAB_R]
        z = self._state[:n]
        lag = self._state[n : n + self._n_aux] if not self.analytic else np.empty(0)
        alpha = self.lags[2]
        out = np.empty_like(cycle)
        last = self.last_command
        step = self._max_step
        for k, v_target in enumerate(cycle):
            v = min(max(v_target, last - step), last + step)
            u = K._advance_dynamics(v, self.dyn, self.dstate) if self.dynamic else v
            z[:] = np.clip(z, u - r, u + r)
            lag += alpha * (u - lag)
            out[k] = last = v
        self._state[K.ST_LAST] = last
        if self.analytic:
            K.inverse_states(self.tables, self.config, self._state)
        return out

    def _cycle(self, samples: int) -> FloatArray:
        """last command -> v_max -> v_min -> back, each extreme reached exactly (and held
        until a lagging piezo voltage reached it)."""
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 3:
            msg = f"'samples' must be an int >= 3. Got {samples!r}."
            raise ParameterError(msg)
        start = self.last_command
        knots = [start, self.v_max, self.v_min, start]
        legs = np.abs(np.diff(knots))
        step = self._max_step
        # every leg ends exactly on its knot: reaching v_max and v_min is what wipes history
        share = legs / max(float(legs.sum()), 1e-300)
        counts = np.maximum(np.round(share * (samples - 1)).astype(int), 1)
        if math.isfinite(step):
            counts = np.maximum(counts, np.ceil(legs / step * (1 + 1e-12)).astype(int))
        pieces = [
            np.linspace(a, b, int(m) + 1)[1:]
            for a, b, m in zip(knots[:-1], knots[1:], counts, strict=True)
        ]
        if self.dynamic:  # hold each extreme until the lagging piezo voltage has reached it
            gains = self.dyn[self.dyn > 0]
            settle = int(np.ceil(np.sum(-np.log(1e-9) / -np.log1p(-gains)))) if gains.size else 0
            settle += self.delay_samples
            for j in (0, 1):
                pieces[j] = np.concatenate([pieces[j], np.full(settle, knots[j + 1])])
        cycle = np.concatenate(pieces)
        return cycle

    # -------------------------------------------------------------- commands
    def _through_mode(self, desired: FloatArray, preview: ArrayLike | None) -> FloatArray:
        """The hysteresis output that makes the model's mode follow ``desired``."""
        if not self.mode.active:
            return desired
        ahead = np.asarray(preview if preview is not None else [], dtype=np.float64).reshape(-1)
        target = self.mode.invert(desired, self._mode_history, ahead)
        both = np.concatenate([self._mode_history, desired])
        self._mode_history = both[-2:].copy()
        return target

    def step(self, desired: float, preview: ArrayLike | None = None) -> float:
        """The command for one desired value.

        Parameters
        ----------
        desired : float
            Desired output (model output units, or m for ``domain="displacement"``).
            NaN or infinity holds the last command and is counted.
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
        if self._plain:  # the common case first: one kernel call
            return float(K.compensator_step(float(desired), self.tables, self.config, self._state))
        if self.mode.active and self.dynamic and self.delay_samples:
            return self._step_mode_delayed(float(desired), preview)
        if self.mode.active:
            desired = float(self._through_mode(np.array([float(desired)]), preview)[0])
        if self.dynamic:
            d = float(desired)
            m = self.delay_samples
            target = d
            if m:
                ahead = np.asarray(preview if preview is not None else [], dtype=np.float64)
                if ahead.size >= m:
                    target = float(ahead[m - 1])
                elif math.isfinite(self._last_desired):
                    target = d + m * (d - self._last_desired)
            self._last_desired = d
            return self._inner_step(target)
        return self._inner_step(float(desired))

    def _inner_step(self, target: float) -> float:
        """The kernel's command for the hysteresis output ``target`` (after mode and delay)."""
        if self.dynamic:
            return float(
                K.dynamic_step(target, self.tables, self.config, self._state, self.dyn, self.dstate)
            )
        if self.analytic:
            return float(K.compensator_step(target, self.tables, self.config, self._state))
        return float(
            K.numeric_step(target, self.tables, self.static, self.lags, self.config, self._state)
        )

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

    def process(self, desired: ArrayLike) -> FloatArray:
        """Commands for a block of desired values; equal to calling :meth:`step` on each.

        With an input delay, the block is its own preview: the command at
        sample k targets ``desired[k + delay_samples]``, and the last
        ``delay_samples`` targets, beyond the block, are extrapolated. Give a
        planned trajectory in one call (or blocks that overlap by the delay).

        Parameters
        ----------
        desired : array_like, shape (N,)
            Desired outputs; NaN and infinite values hold the last command.

        Returns
        -------
        ndarray, shape (N,)
            Commands (V).
        """
        d = np.ascontiguousarray(desired, dtype=np.float64)
        if d.ndim != 1:
            msg = f"'desired' must be a 1-D array. Got shape {d.shape}."
            raise ShapeError(msg)
        if self.mode.active:
            d = np.ascontiguousarray(self._through_mode(d, None))
        out = np.empty_like(d)
        self._inner_process(d, out)
        if self.dynamic and d.size:
            self._last_desired = float(d[-1])
        return out

    def _inner_process(self, d: FloatArray, out: FloatArray) -> None:
        """The kernel over a block of hysteresis outputs (after the mode)."""
        if self.dynamic:
            K.dynamic_process(
                d,
                self.delay_samples,
                self.tables,
                self.config,
                self._state,
                self.dyn,
                self.dstate,
                out,
            )
        elif self.analytic:
            K.compensator_process(d, self.tables, self.config, self._state, out)
        else:
            K.numeric_process(d, self.tables, self.static, self.lags, self.config, self._state, out)


def _play(spec: InverseSpec) -> PIHysteresis:
    """The play operators of a spec (every model the base class compensates has them)."""
    assert isinstance(spec.operator, PIHysteresis)
    return spec.operator


def _differential(model: object) -> bool:
    inversion = getattr(model, "inversion", None)
    return callable(inversion) and inversion().operator.inverse_plan().engine == "packed"


class CoreCompensator(Compensator):
    r"""The :class:`Compensator` of a model on a differential core (Duhem, Bouc-Wen).

    Built by ``ph.Compensator(model, ...)`` for such a model: the same
    parameters, limits, slew limit, NaN handling, counters, input dynamics
    (lags inverted per sample, an integer delay by preview) and output mode.
    Each sample inverts the core's step from the actuator's state: explicitly
    for Duhem, by a safeguarded Newton solve (at most
    ``_diffkernels.NEWTON_MAX`` iterations) for Bouc-Wen; the state then
    advances with the command actually sent.

    Beyond the (voltage, output) region the model was identified on (its
    ``region_tolerance``), a command that would move the actuator further
    out is not sent: the command stops at the region's edge (with input
    dynamics: the last command is held) and is counted in
    :attr:`outside_count`, unless ``allow_extrapolation=True`` (then it is
    sent and counted). Moves back towards the region always pass.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model on a differential core.
    v_min, v_max, slew_rate, sample_rate, domain, gain, allow_extrapolation
        As for :class:`Compensator`; ``allow_extrapolation`` also lets
        commands leave the identified region.
    """

    def __init__(
        self,
        model: HysteresisModel,
        *,
        v_min: float,
        v_max: float,
        slew_rate: float | None = None,
        sample_rate: float | None = None,
        domain: Domain = "charge",
        gain: float | None = None,
        allow_extrapolation: bool = False,
    ) -> None:
        spec, max_step, inv_gain = self._settings(
            model, v_min, v_max, slew_rate, sample_rate, domain, gain, allow_extrapolation
        )
        core = spec.operator
        assert isinstance(core, PackedCore)
        self.core = core
        self.analytic = False
        self._plain = False
        self.params = np.array(core.packed)
        self.config = np.zeros(D.CC_SIZE)
        self.config[D.CC_V_MIN] = self.v_min
        self.config[D.CC_V_MAX] = self.v_max
        self.config[D.CC_MAX_STEP] = max_step
        self.config[D.CC_INV_GAIN] = inv_gain
        self.config[D.CC_REFUSE] = 0.0 if allow_extrapolation else 1.0
        region = core.region
        if region is None:
            self.config[D.CC_TOL] = math.inf
            self.region = np.zeros((2, 0))
        else:
            self.config[D.CC_TOL] = spec.region_tolerance * region.span
            self.config[D.CC_RV_LO] = region.v_lo
            self.config[D.CC_RV_HI] = region.v_hi
            self.region = region.array
        if domain == "displacement":  # displacement 0 = the output in the initial state
            self.config[D.CC_REF] = core.output(core.initial_state)
        fs = float(sample_rate or 0.0)  # given whenever lags or a slow core need it (_settings)
        lg = spec.lags
        if lg is not None:  # kept creep lags: affine in each sample's voltage, solved with it
            alphas = 1.0 - np.exp(-1.0 / (fs * np.asarray(lg.taus)))
            self.lags = np.vstack([lg.taus, lg.gains, alphas])
            pairs = np.column_stack([lg.gains, alphas]).ravel()
            self.dyn = np.concatenate([self.dyn[: D.DYN_LAGS], pairs])
            self.dstate = np.zeros(D.DYN_LAGS + alphas.size)
        else:
            self.lags = np.zeros((3, 0))
        ns = core.n_states
        self.config[D.CC_NS] = ns
        slow = spec.relaxation
        if slow is not None:  # a slow Preisach core after the main one: params and state
            self.config[D.CC_SLOW_AT] = self.params.size
            self.config[D.CC_SLOW_A] = 1.0 - math.exp(-1.0 / (fs * slow.tau))
            self.params = np.concatenate([self.params, slow.packed])
            ns += D.RV_SIZE
        #: the slow core's packed parameters (empty without a relaxation term)
        self.slow = np.zeros(0) if slow is None else np.array(slow.packed)
        self._ns = ns
        self._state = np.zeros(self._ns + D.DS_STATUS)
        #: scratch for the kernel's trial steps (the core's state after a candidate command)
        self.trial = np.zeros(self._ns)
        self.reset()

    @property
    def n_operators(self) -> int:
        """Values in the core's state (the last voltage, the internal variable, ...)."""
        return self._ns

    @property
    def state(self) -> CompensatorState:
        """The core's state ``[v, x, ...]`` as ``operators``, and the last command (copies)."""
        return CompensatorState(
            self._state[: self._ns].copy(),
            self.dstate[D.DYN_LAGS :].copy(),
            float(self._state[self._ns + D.DS_STATUS + D.DS_LAST]),
            self.dstate[: D.DYN_LAGS].copy() if self.dynamic else np.zeros(0),
        )

    @property
    def last_command(self) -> float:
        """The command sent last (V)."""
        return float(self._state[self._ns + D.DS_STATUS + D.DS_LAST])

    @property
    def nonfinite_count(self) -> int:
        """Desired values that were NaN or infinite (the last command was held)."""
        return int(self._state[self._ns + D.DS_STATUS + D.DS_NONFINITE])

    @property
    def saturated_count(self) -> int:
        """Desired values out of reach within ``[v_min, v_max]`` (the nearer limit was sent)."""
        return int(self._state[self._ns + D.DS_STATUS + D.DS_SATURATED])

    @property
    def outside_count(self) -> int:
        """Commands that would have left the identified region (held unless extrapolating)."""
        return int(self._state[self._ns + D.DS_STATUS + D.DS_OUTSIDE])

    def share(self, tables: FloatArray, config: FloatArray, state: FloatArray) -> None:
        """Not available: a bank runs these channels one by one.

        Parameters
        ----------
        tables, config, state : ndarray
        """
        msg = "a compensator on a differential core runs on its own arrays"
        raise ParameterError(msg)

    def _with_slow(self, z: FloatArray) -> FloatArray:
        """The core's state, then the slow core's at rest at the same voltage (if any)."""
        if not self.slow.size:
            return z
        rest = np.zeros(D.RV_SIZE)
        rest[0] = rest[D.RV_R] = float(z[0])
        rest[D.RV_K] = 1.0
        return np.concatenate([z, rest])

    def _moved(self, start: FloatArray, v: float) -> FloatArray:
        """The core's state after the voltage moves from ``start`` to ``v`` in small steps."""
        v0 = float(start[0])
        span = max(self.v_max - self.v_min, 1e-300)
        steps = max(2, math.ceil(abs(v - v0) / (span / 400.0)) + 1)
        return self.core.propagate(np.linspace(v0, v, steps), start).state

    def reset(
        self, state: CompensatorState | ArrayLike | None = None, *, voltage: float | None = None
    ) -> None:
        """Start again from a known condition; counters back to 0.

        Parameters
        ----------
        state : CompensatorState or array_like, optional
            ``[v, x]`` (the core's state), optionally followed by the last command.
        voltage : float, optional
            The actuator now sits at ``voltage``: the model's initial state moved
            there along a ramp.

        Raises
        ------
        ParameterError
            If the last command would lie outside the limits.
        """
        core = self.core
        if isinstance(state, CompensatorState):
            z = as_signal(state.operators, "state.operators")
            if z.size != self._ns:
                msg = f"'state' must hold the core's {self._ns} values [v, x, ...]. Got {z.size}."
                raise ShapeError(msg)
            last = float(state.command)
        elif state is not None:
            z = as_signal(state, "state")
            ns = self._ns
            if z.size not in (ns, ns + 1):
                msg = (
                    f"'state' must hold the core's {ns} values and optionally the last "
                    f"command. Got {z.size}."
                )
                raise ShapeError(msg)
            last = (
                float(z[ns]) if z.size == ns + 1 else float(np.clip(z[0], self.v_min, self.v_max))
            )
            z = z[:ns]
        elif voltage is None:
            z = self._with_slow(np.array(core.initial_state))
            last = float(np.clip(z[0], self.v_min, self.v_max))
        else:
            last = _finite_number(voltage, "voltage")
            z = self._with_slow(self._moved(np.array(core.initial_state), last))
        if not self.v_min <= last <= self.v_max:
            msg = (
                f"The actuator's voltage {last!r} V is outside the limits "
                f"[{self.v_min}, {self.v_max}] V."
            )
            raise ParameterError(msg)
        self._state[:] = 0.0
        self._state[: self._ns] = z
        self._state[self._ns + D.DS_STATUS + D.DS_LAST] = last
        self.dstate[:] = last  # the piezo and every creep lag settled at the last command
        if isinstance(state, CompensatorState):
            if state.dynamics.size == D.DYN_LAGS and self.dynamic:
                self.dstate[: D.DYN_LAGS] = state.dynamics
            lags = as_signal(state.lags, "state.lags", allow_empty=True)
            if lags.size == self.lags.shape[1]:
                self.dstate[D.DYN_LAGS :] = lags
            elif lags.size:
                msg = (
                    f"'state.lags' must hold the model's {self.lags.shape[1]} creep lag "
                    f"states. Got {lags.size}."
                )
                raise ShapeError(msg)
        self._mode_history[:] = np.nan
        self._last_desired = math.nan

    def precondition(self, samples: int = 1000) -> FloatArray:
        """The preconditioning cycle to send first (see :meth:`Compensator.precondition`).

        Parameters
        ----------
        samples : int, default 1000

        Returns
        -------
        ndarray
            The voltages (V) to send; the state advanced as if they had been.
        """
        cycle = self._cycle(samples)
        u = np.empty_like(cycle)
        alphas = self.lags[2]
        ns = int(self.config[D.CC_NS])
        slow = self._state[ns : self._ns]  # a view: the slow core moves in place
        a = float(self.config[D.CC_SLOW_A])
        for k, v in enumerate(cycle):
            u[k] = K._advance_dynamics(v, self.dyn, self.dstate) if self.dynamic else v
            self.dstate[D.DYN_LAGS :] += alphas * (u[k] - self.dstate[D.DYN_LAGS :])
            if slow.size:
                c = float(slow[0])
                D.rev_move(self.slow, slow, c + a * (u[k] - c), True, np.zeros(0), False)
        self._state[:ns] = self.core.propagate(u, self._state[:ns]).state
        self._state[self._ns + D.DS_STATUS + D.DS_LAST] = cycle[-1]
        return cycle

    def _inner_step(self, target: float) -> float:
        return float(
            D.core_step(
                target,
                self.params,
                self.config,
                self._state,
                self.region,
                self.dyn,
                self.dstate,
                self.trial,
            )
        )

    def _inner_process(self, d: FloatArray, out: FloatArray) -> None:
        D.core_process(d, self.delay_samples, self.params, self.config, self._state, self.region,
                       self.dyn, self.dstate, self.trial, out)  # fmt: skip


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
    slew_rate : float or None
        Largest change in V/s (needs ``sample_rate``).
    sample_rate : float or None
        Loop rate (Hz).
    allow_extrapolation : bool
        Allow limits beyond the voltages the model was identified on (refused
        otherwise, not narrowed: a file workflow states what it will do).
    """

    v_min: float | None = None
    v_max: float | None = None
    domain: Domain = "charge"
    gain: float | None = None
    slew_rate: float | None = None
    sample_rate: float | None = None
    allow_extrapolation: bool = False

    def build(self, model: HysteresisModel) -> Compensator:
        """A compensator for ``model`` whose limits default to its training voltage range.

        Parameters
        ----------
        model : HysteresisModel
            A fitted model.

        Returns
        -------
        Compensator

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
        wide = (self.v_min is not None and self.v_min < lo) or (
            self.v_max is not None and self.v_max > hi
        )
        if known and wide and not self.allow_extrapolation:
            msg = (
                f"the limits [{self.v_min if self.v_min is not None else lo:g}, "
                f"{self.v_max if self.v_max is not None else hi:g}] V go beyond the voltages "
                f"the model was identified on, [{lo:g}, {hi:g}] V; allow extrapolation "
                "explicitly to command them"
            )
            raise ParameterError(msg)
        return Compensator(
            model,
            v_min=lo if self.v_min is None else float(self.v_min),
            v_max=hi if self.v_max is None else float(self.v_max),
            domain=self.domain,
            gain=self.gain,
            slew_rate=self.slew_rate,
            sample_rate=self.sample_rate,
            allow_extrapolation=self.allow_extrapolation,
        )


def per_channel(value: object, c: int, name: str) -> list[Any]:
    """A setting for each of ``c`` channels: a scalar (or None) repeated, or ``c`` values.

    Parameters
    ----------
    value : float, None or array_like
    c : int
        Channels.
    name : str
        The setting, named in the error.

    Returns
    -------
    list
        ``c`` values.
    """
    if value is None or isinstance(value, int | float | np.integer | np.floating):
        return [value] * c
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size != c:
        msg = f"'{name}' must be a number or one value per channel ({c}). Got {arr.size} values."
        raise ShapeError(msg)
    return [float(a) for a in arr]


class BankCompensator:
    r"""Feedforward compensation of every channel of a :class:`~piezohyst.ModelBank`.

    Channel ``c`` is exactly the :class:`Compensator` of ``bank[c]`` (same
    inverse, limits, slew limit, NaN handling and counters; :meth:`channel`
    returns it, live): :meth:`step` takes one desired value per channel and
    returns one command per channel. When every channel inverts analytically
    without input dynamics (play operators and removed growth terms), all
    channels run in one numba kernel, in parallel across cores, allocating
    nothing; otherwise the channels' own compensators run one after another.

    Usually built as ``ph.Compensator(bank, v_min=..., v_max=...)``.

    Parameters
    ----------
    bank : ModelBank
        A fitted bank (every channel fitted).
    v_min, v_max : float or array_like of C
        Voltage limits (V), shared or one per channel.
    slew_rate, gain : float or array_like of C, optional
        As for :class:`Compensator`, shared or per channel.
    sample_rate : float, optional
        The loop rate (Hz), shared.
    domain : {"charge", "displacement"}
    allow_extrapolation : bool, default False
        Limits beyond a channel's identified range are narrowed to it, with
        one warning naming how many channels were narrowed.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> units = [ph.PIHysteresis([0.0, 20.0], [g * 1e-8, 5e-9]) for g in (1.0, 2.0)]
    >>> bank = ph.ModelBank.from_models([ph.ClassicalPI.from_operator(u) for u in units])
    >>> comp = ph.Compensator(bank, v_min=0.0, v_max=140.0)
    >>> desired = np.array([units[0].predict([50.0])[0], units[1].predict([80.0])[0]])
    >>> np.round(comp.step(desired), 9).tolist()
    [50.0, 80.0]
    """

    def __init__(
        self,
        bank: ModelBank,
        *,
        v_min: float | ArrayLike,
        v_max: float | ArrayLike,
        slew_rate: float | ArrayLike | None = None,
        sample_rate: float | None = None,
        domain: Domain = "charge",
        gain: float | ArrayLike | None = None,
        allow_extrapolation: bool = False,
    ) -> None:
        if not isinstance(bank, ModelBank):
            msg = f"BankCompensator needs a fitted ModelBank. Got {type(bank).__name__}."
            raise ParameterError(msg)
        models = bank.complete_models()
        c = len(models)
        lows = per_channel(v_min, c, "v_min")
        highs = per_channel(v_max, c, "v_max")
        slews = per_channel(slew_rate, c, "slew_rate")
        gains = per_channel(gain, c, "gain")
        channels: list[Compensator] = []
        narrowed = 0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            for i, m in enumerate(models):
                try:
                    comp = Compensator(
                        m,
                        v_min=lows[i],
                        v_max=highs[i],
                        slew_rate=slews[i],
                        sample_rate=sample_rate,
                        domain=domain,
                        gain=gains[i],
                        allow_extrapolation=allow_extrapolation,
                    )
                except ParameterError as exc:
                    raise ParameterError(f"channel {i}: {exc}") from None
                narrowed += comp.requested_limits is not None
                channels.append(comp)
        if narrowed:
            warnings.warn(
                f"Compensator limits narrowed on {narrowed} of {c} channels to the voltages "
                "each was identified on (pass allow_extrapolation=True to keep them; "
                "v_min/v_max show the limits in force).",
                UserWarning,
                stacklevel=3,
            )
        self.bank = bank
        self._channels = channels
        #: True when all channels run in the one parallel kernel
        self.fused = all(ch.plain for ch in channels)
        if self.fused:
            # one array per quantity; each channel's compensator keeps views of its row,
            # so channel(i) stays live and identical to the bank's state
            self.tables = np.ascontiguousarray(np.stack([ch.tables for ch in channels]))
            self.config = np.ascontiguousarray(np.stack([ch.config for ch in channels]))
            self._state = np.ascontiguousarray(np.stack([ch.kernel_state for ch in channels]))
            for i, ch in enumerate(channels):
                ch.share(self.tables[i], self.config[i], self._state[i])

    def __len__(self) -> int:
        return len(self._channels)

    def channel(self, index: int) -> Compensator:
        """Channel ``index``'s compensator: live, sharing the bank's state.

        Parameters
        ----------
        index : int

        Returns
        -------
        Compensator
        """
        return self._channels[index]

    @property
    def v_min(self) -> FloatArray:
        """Lower limits in force, per channel (V)."""
        return np.array([ch.v_min for ch in self._channels])

    @property
    def v_max(self) -> FloatArray:
        """Upper limits in force, per channel (V)."""
        return np.array([ch.v_max for ch in self._channels])

    @property
    def last_command(self) -> FloatArray:
        """The last command of every channel (V)."""
        return np.array([ch.last_command for ch in self._channels])

    @property
    def nonfinite_count(self) -> NDArray[np.int64]:
        """Per channel: desired values that were NaN or infinite (the last command held)."""
        return np.array([ch.nonfinite_count for ch in self._channels], dtype=np.int64)

    @property
    def saturated_count(self) -> NDArray[np.int64]:
        """Per channel: commands clipped to the limits."""
        return np.array([ch.saturated_count for ch in self._channels], dtype=np.int64)

    def reset(self, *, voltage: float | ArrayLike | None = None) -> None:
        """Every channel back to its model's initial state, or settled at ``voltage`` (per channel).

        Parameters
        ----------
        voltage : float or array_like of C, optional
        """
        volts = per_channel(voltage, len(self), "voltage")
        for ch, v in zip(self._channels, volts, strict=True):
            ch.reset(voltage=v)

    def precondition(self, samples: int = 1000) -> FloatArray:
        """Every channel's preconditioning cycle (see :meth:`Compensator.precondition`).

        Parameters
        ----------
        samples : int, default 1000
            Samples in each channel's cycle (more where a slew limit needs them).

        Returns
        -------
        ndarray, shape (samples', C)
            Commands to send first; a channel whose cycle is shorter (wider
            slew limit) holds its last command to the end.
        """
        cycles = [ch.precondition(samples) for ch in self._channels]
        m = max(cy.size for cy in cycles)
        out = np.empty((m, len(cycles)))
        for c, cy in enumerate(cycles):
            out[: cy.size, c] = cy
            out[cy.size :, c] = cy[-1]
        return out

    def _desired(self, desired: ArrayLike, ndim: int) -> FloatArray:
        d = np.ascontiguousarray(desired, dtype=np.float64)
        c = len(self._channels)
        if d.ndim != ndim or d.shape[-1] != c:
            want = f"({c},)" if ndim == 1 else f"(samples, {c})"
            msg = f"'desired' must have shape {want}, one value per channel. Got {d.shape}."
            raise ShapeError(msg)
        return d

    def step(self, desired: ArrayLike, out: FloatArray | None = None) -> FloatArray:
        """One command per channel.

        Parameters
        ----------
        desired : array_like, shape (C,)
            Desired output per channel; NaN or infinity holds that channel's
            last command (counted).
        out : ndarray, shape (C,), optional
            Written in place (a float64 array): nothing is allocated.

        Returns
        -------
        ndarray, shape (C,)
            Commands (V), each inside its channel's limits.
        """
        d = self._desired(desired, 1)
        if out is None:
            out = np.empty(d.shape[0])
        elif out.shape != d.shape or out.dtype != np.float64:
            msg = f"'out' must be a float64 array of shape {d.shape}. Got {out.dtype} {out.shape}."
            raise ShapeError(msg)
        if self.fused:
            K.bank_step(d, self.tables, self.config, self._state, out)
        else:
            for i, ch in enumerate(self._channels):
                out[i] = ch.step(float(d[i]))
        return out

    def process(self, desired: ArrayLike) -> FloatArray:
        """Commands for a block: equal to :meth:`step` on each row.

        Parameters
        ----------
        desired : array_like, shape (samples, C)

        Returns
        -------
        ndarray, shape (samples, C)
        """
        d = self._desired(desired, 2)
        out = np.empty_like(d)
        if self.fused:
            K.bank_process(d, self.tables, self.config, self._state, out)
        else:
            for i, ch in enumerate(self._channels):
                out[:, i] = ch.process(np.ascontiguousarray(d[:, i]))
        return out
