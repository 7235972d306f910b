"""How the compensator inverts each family of cores, one sample at a time.

A core's :meth:`~piezohyst.model.cores.base.Core.inverse_plan` names its engine;
:class:`~piezohyst.Compensator` looks it up in :data:`INVERSES` and builds one
from the model's :class:`~piezohyst.model.model.InverseSpec` and its
:class:`EngineSettings`. The engine owns its kernel arrays (the tables, the
config and the state the compiled step updates in place): it runs the step
(``inner_step``, ``inner_process``, and the self-sensing loop's
``controller_step``, which takes the loop's own arrays and returns the
command), and reads, resets and advances its state. The compensator and the
controller hold an engine; an engine knows neither.

* ``"play"``: eq. 18 on play operators (Newton beside kept static or creep
  terms), the play kernels of :mod:`piezohyst._kernels`;
* ``"packed"``: the Preisach, Duhem and Bouc-Wen cores' bracketed Newton step
  (:mod:`piezohyst._kernels.packed`), with creep lags and a relaxing core;
* ``"python"``: any core, by a bracketed root search on
  :meth:`~piezohyst.model.cores.base.Core.propagate` (a core defined outside the
  library: no compiled step, no C).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from .._kernels import packed as P
from .._kernels import play as K
from .._validation import FloatArray, as_signal
from ..errors import ParameterError, ShapeError
from ..model.cores.base import Core, PackedCore
from ..model.cores.play import PIHysteresis
from ..model.model import InverseSpec

__all__ = ["INVERSES", "CompensatorState", "EngineSettings", "Inverse", "finite_number"]

#: What a compensator can be reset to: a saved state, the core's states (and last command)
State = Any
#: The self-sensing loop's arrays: the compensator's config seen by the loop, its settings
#: (``_kernels.CTL_*``) and its feedback state (``CS_*``)
Loop = tuple[FloatArray, FloatArray, FloatArray]


def finite_number(value: object, name: str) -> float:
    """``value`` as a float, or a one-line ParameterError naming the Compensator's parameter."""
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
        The core's states (play operators: V) after the commands sent so far.
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


@dataclass(frozen=True)
class EngineSettings:
    """What an engine needs from its compensator, fixed when it is built.

    Attributes
    ----------
    v_min, v_max : float
        The voltage limits (V).
    max_step : float
        The slew limit per sample (V; inf: none).
    inv_gain : float
        Model output units per desired unit (1/g for displacement).
    sample_rate : float or None
        The loop's rate (Hz).
    domain : {"charge", "displacement"}
    allow_extrapolation : bool
        Send commands beyond the identified region (packed cores).
    mode_active : bool
        The compensator inverts an output mode before the engine.
    delay_samples : int
        Whole samples of input delay (handled by preview).
    delay_fraction : float
        The delay's fraction of a sample inverted per sample (``_kernels.DYN_FRACTION``).
    lag_gain : float
        The input lag's gain per sample (``_kernels.DYN_GAIN_B``; 0: none).
    dynamic : bool
        The model has input dynamics.
    """

    v_min: float
    v_max: float
    max_step: float
    inv_gain: float
    sample_rate: float | None
    domain: str
    allow_extrapolation: bool
    mode_active: bool = False
    delay_samples: int = 0
    delay_fraction: float = 0.0
    lag_gain: float = 0.0
    dynamic: bool = False


def _play(spec: InverseSpec) -> PIHysteresis:
    """The play operators of a spec (the play engine inverts nothing else)."""
    return cast(PIHysteresis, spec.operator)


class Inverse:
    """The engine contract (see the module documentation).

    Parameters
    ----------
    spec : InverseSpec
        What to invert (the model's :meth:`~piezohyst.model.models.HysteresisModel.inversion`).
    settings : EngineSettings
        The compensator's limits, gain and timing.

    Attributes
    ----------
    kernel_state : ndarray
        The state the compiled step updates in place (the core's states, then the
        last command and the counters).
    config : ndarray
        The step's settings (limits, slew, gain, reference).
    dyn, dstate : ndarray
        Input dynamics' settings and state (and the packed cores' creep lags).
    analytic : bool
        Eq. 18 runs (no Newton solve).
    plain : bool
        One analytic kernel call per step (no input dynamics, no mode).
    """

    name = ""
    # the kernel arrays an engine lays out (``_layout``); which ones depends on the engine
    tables: FloatArray
    config: FloatArray
    kernel_state: FloatArray
    static: FloatArray
    lags: FloatArray
    params: FloatArray
    region: FloatArray
    trial: FloatArray
    slow: FloatArray
    core: Any

    def __init__(self, spec: InverseSpec, settings: EngineSettings) -> None:
        self.spec = spec
        self.settings = settings
        self.v_min, self.v_max = settings.v_min, settings.v_max
        self.max_step = settings.max_step
        self.sample_rate = settings.sample_rate
        self.domain = settings.domain
        self.allow_extrapolation = settings.allow_extrapolation
        self.dynamic = settings.dynamic
        self.delay_samples = settings.delay_samples
        self.dyn = np.zeros(2)
        self.dyn[K.DYN_FRACTION] = settings.delay_fraction
        self.dyn[K.DYN_GAIN_B] = settings.lag_gain
        self.dstate = np.zeros(2)
        self.analytic = False
        self.plain = False
        self._layout(spec, settings.max_step, settings.inv_gain)

    def _layout(self, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        """Lay out the kernel arrays for ``spec``."""
        raise NotImplementedError

    def _inside(self, last: float) -> None:
        """A reset's last command must lie inside the limits."""
        if not self.v_min <= last <= self.v_max:
            msg = (
                f"The actuator's voltage {last!r} V is outside the limits "
                f"[{self.v_min}, {self.v_max}] V."
            )
            raise ParameterError(msg)

    def closed_loop(self) -> bool:
        """Whether the self-sensing controller can run this inverse in its loop."""
        return False

    def n_operators(self) -> int:
        """Values in the core's state."""
        raise NotImplementedError

    def state(self) -> CompensatorState:
        """The forward states and the last command (copies)."""
        raise NotImplementedError

    def _slot(self, name: str) -> int:
        """Where a status value lives in the state array (play and Python engines: its end,
        as ``_kernels.ST_*``)."""
        return {"last": -3, "nonfinite": -2, "saturated": -1}[name]

    def last_command(self) -> float:
        """The command sent last (V)."""
        return float(self.kernel_state[self._slot("last")])

    def nonfinite_count(self) -> int:
        """Desired values that were NaN or infinite (the last command held)."""
        return int(self.kernel_state[self._slot("nonfinite")])

    def saturated_count(self) -> int:
        """Desired values out of reach (the nearer limit sent)."""
        return int(self.kernel_state[self._slot("saturated")])

    def reset(self, state: State, voltage: float | None) -> None:
        """Start again from a known condition (see :meth:`Compensator.reset`)."""
        raise NotImplementedError

    def precondition(self, cycle: FloatArray) -> FloatArray:
        """Advance the state along ``cycle`` as if it had been sent; return it."""
        raise NotImplementedError

    def inner_step(self, target: float) -> float:
        """The command for the hysteresis output ``target``."""
        raise NotImplementedError

    def inner_process(self, d: FloatArray, out: FloatArray) -> None:
        """Commands for a block of hysteresis outputs, into ``out``."""
        raise NotImplementedError

    def outside_count(self) -> int:
        """Commands that would have left the identified region."""
        return 0

    def share(self, tables: FloatArray, config: FloatArray, state: FloatArray) -> None:
        """Run on arrays owned by a multi-channel container (the play engine only)."""
        msg = f"a compensator on a {self.name} inverse runs on its own arrays"
        raise ParameterError(msg)

    def slots(self) -> tuple[int, int]:
        """Where ``config`` holds the displacement reference and the inverse gain."""
        raise NotImplementedError

    def controller_step(self, d: float, m: float, loop: Loop) -> float:
        """One sample of the self-sensing loop around this inverse."""
        raise NotImplementedError

    def controller_process(self, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray) -> None:
        """The self-sensing loop over a block."""
        raise NotImplementedError


class PlayInverse(Inverse):
    """Eq. 18 on play operators; Newton beside kept static or creep terms."""

    name = "play"

    def _layout(self, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        sample_rate, domain = self.sample_rate, self.domain
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
        #: True when eq. 18's analytic inverse runs (no Newton solve); fixed by the model
        self.analytic = spec.analytic
        self.plain = spec.analytic and not dyn.active and not self.settings.mode_active
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
        self.kernel_state = np.zeros(n + n_aux + 3)
        self._n_aux = n_aux
        if domain == "displacement":  # displacement 0 = output at rest in the initial state
            if spec.analytic:
                self.config[K.CFG_REFERENCE] = op.offset + float(op.weights @ op.initial_state)
            else:
                self._set_forward(self._initial_forward())
                self.config[K.CFG_REFERENCE] = self._output_now(float(op.initial_state[0]))

    def n_operators(self) -> int:
        """Number of play operators of the inverted model."""
        return int(self.tables.shape[1])

    def _initial_forward(self) -> tuple[FloatArray, FloatArray]:
        op = _play(self.spec)
        x0 = float(op.initial_state[0])
        return op.initial_state.copy(), np.full(self.lags.shape[1], x0)

    def _set_forward(self, forward: tuple[FloatArray, FloatArray]) -> None:
        n = self.n_operators()
        self.kernel_state[:n] = forward[0]
        if not self.analytic:
            self.kernel_state[n : n + self._n_aux] = forward[1]
        else:
            K.inverse_states(self.tables, self.config, self.kernel_state)

    def _output_now(self, v: float) -> float:
        """The hysteresis part's output (model units) if ``v`` were sent from the current state."""
        y, _ = K.hysteresis_output(
            v, self.tables, self.static, self.lags, self.config, self.kernel_state
        )
        return float(y)

    def state(self) -> CompensatorState:
        """The forward states and the last command (copies; see :meth:`reset`)."""
        n = self.n_operators()
        lags = self.kernel_state[n : n + self._n_aux] if not self.analytic else np.zeros(0)
        return CompensatorState(
            self.kernel_state[:n].copy(),
            lags.copy(),
            float(self.kernel_state[K.ST_LAST]),
            self.dstate.copy() if self.dynamic else np.zeros(0),
        )

    def reset(self, state: State, voltage: float | None) -> None:
        """See :meth:`~piezohyst.control.inverses.Inverse.reset`."""
        n = self.n_operators()
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
            v = finite_number(voltage, "voltage")
            ops = np.clip(op.initial_state, v - op.thresholds, v + op.thresholds)
            lags = np.full(m, v)
            last = v
        self._inside(last)
        self._set_forward((np.array(ops, dtype=np.float64), np.array(lags, dtype=np.float64)))
        self.dstate[:] = last  # the piezo settled at the last command
        if isinstance(state, CompensatorState) and state.dynamics.size == 2 and self.dynamic:
            self.dstate[:] = state.dynamics
        self.kernel_state[K.ST_LAST] = last
        self.kernel_state[K.ST_NONFINITE] = 0.0
        self.kernel_state[K.ST_SATURATED] = 0.0

    def precondition(self, cycle: FloatArray) -> FloatArray:
        """See :meth:`~piezohyst.control.inverses.Inverse.precondition`."""
        n = self.n_operators()
        r = self.tables[K.TAB_R]
        z = self.kernel_state[:n]
        lag = self.kernel_state[n : n + self._n_aux] if not self.analytic else np.empty(0)
        alpha = self.lags[2]
        out = np.empty_like(cycle)
        last = self.last_command()
        step = self.max_step
        for k, v_target in enumerate(cycle):
            v = min(max(v_target, last - step), last + step)
            u = K._advance_dynamics(v, last, self.dyn, self.dstate) if self.dynamic else v
            z[:] = np.clip(z, u - r, u + r)
            lag += alpha * (u - lag)
            out[k] = last = v
        self.kernel_state[K.ST_LAST] = last
        if self.analytic:
            K.inverse_states(self.tables, self.config, self.kernel_state)
        return out

    def inner_step(self, target: float) -> float:
        """The kernel's command for the hysteresis output ``target`` (after mode and delay)."""
        if self.dynamic and not self.analytic:
            return float(K.numeric_dynamic_step(target, self.tables, self.static, self.lags,
                                                self.config, self.kernel_state, self.dyn,
                                                self.dstate))  # fmt: skip
        if self.dynamic:
            return float(
                K.dynamic_step(
                    target, self.tables, self.config, self.kernel_state, self.dyn, self.dstate
                )
            )
        if self.analytic:
            return float(K.compensator_step(target, self.tables, self.config, self.kernel_state))
        return float(
            K.numeric_step(
                target, self.tables, self.static, self.lags, self.config, self.kernel_state
            )
        )

    def inner_process(self, d: FloatArray, out: FloatArray) -> None:
        """The kernel over a block of hysteresis outputs (after the mode)."""
        if self.dynamic and not self.analytic:
            K.numeric_dynamic_process(d, self.delay_samples, self.tables, self.static, self.lags,
                                      self.config, self.kernel_state, self.dyn, self.dstate,
                                      out)  # fmt: skip
        elif self.dynamic:
            K.dynamic_process(
                d,
                self.delay_samples,
                self.tables,
                self.config,
                self.kernel_state,
                self.dyn,
                self.dstate,
                out,
            )
        elif self.analytic:
            K.compensator_process(d, self.tables, self.config, self.kernel_state, out)
        else:
            K.numeric_process(
                d, self.tables, self.static, self.lags, self.config, self.kernel_state, out
            )

    def closed_loop(self) -> bool:
        return bool(self.analytic)

    def share(self, tables: FloatArray, config: FloatArray, state: FloatArray) -> None:
        """See :meth:`~piezohyst.control.inverses.Inverse.share`."""
        if not (
            np.array_equal(tables, self.tables)
            and np.array_equal(config, self.config)
            and np.array_equal(state, self.kernel_state)
        ):
            msg = "shared arrays must hold the compensator's current tables, config and state"
            raise ParameterError(msg)
        self.tables, self.config, self.kernel_state = tables, config, state

    def slots(self) -> tuple[int, int]:
        return int(K.CFG_REFERENCE), int(K.CFG_INV_GAIN)

    def controller_step(self, d: float, m: float, loop: Loop) -> float:
        return float(K.controller_step(d, m, self.tables, loop[0], self.kernel_state,
                                       loop[1], loop[2]))  # fmt: skip

    def controller_process(self, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray) -> None:
        K.controller_process(d, m, self.tables, loop[0], self.kernel_state, loop[1], loop[2], out)


class PackedInverse(Inverse):
    r"""The packed cores (Preisach, Duhem, Bouc-Wen): a bracketed Newton step per sample.

    The same limits, slew limit, NaN handling, counters, input dynamics (lags
    inverted per sample, an integer delay by preview) and output mode as the
    play engine. Each sample inverts the core's step from the actuator's
    state: explicitly for Duhem within a step, by a safeguarded Newton solve
    (at most ``_kernels.packed.NEWTON_MAX`` iterations) otherwise; the state then
    advances with the command actually sent.

    Beyond the (voltage, output) region the model was identified on (its
    ``region_tolerance``), a command that would move the actuator further out
    is not sent: the command stops at the region's edge (with input dynamics:
    the last command is held) and is counted in ``outside_count``, unless
    ``allow_extrapolation=True`` (then it is sent and counted). Moves back
    towards the region always pass.
    """

    name = "packed"

    def _layout(self, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        sample_rate, domain = self.sample_rate, self.domain
        core = cast(PackedCore, spec.operator)
        self.core = core
        self.analytic = False
        self.plain = False
        self.params = np.array(core.packed)
        self.config = np.zeros(P.CC_SIZE)
        self.config[P.CC_V_MIN] = self.v_min
        self.config[P.CC_V_MAX] = self.v_max
        self.config[P.CC_MAX_STEP] = max_step
        self.config[P.CC_INV_GAIN] = inv_gain
        self.config[P.CC_REFUSE] = 0.0 if self.allow_extrapolation else 1.0
        region = core.region
        if region is None:
            self.config[P.CC_TOL] = math.inf
            self.region = np.zeros((2, 0))
        else:
            self.config[P.CC_TOL] = spec.region_tolerance * region.span
            self.config[P.CC_RV_LO] = region.v_lo
            self.config[P.CC_RV_HI] = region.v_hi
            self.region = region.array
        if domain == "displacement":  # displacement 0 = the output in the initial state
            self.config[P.CC_REF] = core.output(core.initial_state)
        fs = float(sample_rate or 0.0)  # given whenever lags or a slow core need it (_settings)
        lg = spec.lags
        if lg is not None:  # kept creep lags: affine in each sample's voltage, solved with it
            alphas = 1.0 - np.exp(-1.0 / (fs * np.asarray(lg.taus)))
            self.lags = np.vstack([lg.taus, lg.gains, alphas])
            pairs = np.column_stack([lg.gains, alphas]).ravel()
            self.dyn = np.concatenate([self.dyn[: P.DYN_LAGS], pairs])
            self.dstate = np.zeros(P.DYN_LAGS + alphas.size)
        else:
            self.lags = np.zeros((3, 0))
        ns = core.n_states
        self.config[P.CC_NS] = ns
        slow = spec.relaxation
        if slow is not None:  # a slow Preisach core after the main one: params and state
            self.config[P.CC_SLOW_AT] = self.params.size
            self.config[P.CC_SLOW_A] = 1.0 - math.exp(-1.0 / (fs * slow.tau))
            self.params = np.concatenate([self.params, slow.packed])
            ns += P.RV_SIZE
        #: the slow core's packed parameters (empty without a relaxation term)
        self.slow = np.zeros(0) if slow is None else np.array(slow.packed)
        self._ns = ns
        self.kernel_state = np.zeros(self._ns + P.DS_STATUS)
        #: scratch for the kernel's trial steps (the core's state after a candidate command)
        self.trial = np.zeros(self._ns)

    def n_operators(self) -> int:
        """Values in the core's state (the last voltage, the internal variable, ...)."""
        return self._ns

    def state(self) -> CompensatorState:
        """The core's state ``[v, x, ...]`` as ``operators``, and the last command (copies)."""
        return CompensatorState(
            self.kernel_state[: self._ns].copy(),
            self.dstate[P.DYN_LAGS :].copy(),
            float(self.kernel_state[self._ns + P.DS_STATUS + P.DS_LAST]),
            self.dstate[: P.DYN_LAGS].copy() if self.dynamic else np.zeros(0),
        )

    def _slot(self, name: str) -> int:
        """The status values follow the core's state (``_kernels.packed.DS_*``)."""
        at = {"last": P.DS_LAST, "nonfinite": P.DS_NONFINITE, "saturated": P.DS_SATURATED,
              "outside": P.DS_OUTSIDE}[name]  # fmt: skip
        return int(self._ns + P.DS_STATUS + at)

    def outside_count(self) -> int:
        """Commands that would have left the identified region (held unless extrapolating)."""
        return int(self.kernel_state[self._slot("outside")])

    def _with_slow(self, z: FloatArray) -> FloatArray:
        """The core's state, then the slow core's at rest at the same voltage (if any)."""
        if not self.slow.size:
            return z
        rest = np.zeros(P.RV_SIZE)
        rest[0] = rest[P.RV_R] = float(z[0])
        rest[P.RV_K] = 1.0
        return np.concatenate([z, rest])

    def _moved(self, start: FloatArray, v: float) -> FloatArray:
        """The core's state after the voltage moves from ``start`` to ``v`` in small steps."""
        v0 = float(start[0])
        span = max(self.v_max - self.v_min, 1e-300)
        steps = max(2, math.ceil(abs(v - v0) / (span / 400.0)) + 1)
        return np.asarray(self.core.propagate(np.linspace(v0, v, steps), start).state)

    def reset(self, state: State, voltage: float | None) -> None:
        """See :meth:`~piezohyst.control.inverses.Inverse.reset`."""
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
            last = finite_number(voltage, "voltage")
            z = self._with_slow(self._moved(np.array(core.initial_state), last))
        self._inside(last)
        self.kernel_state[:] = 0.0
        self.kernel_state[: self._ns] = z
        self.kernel_state[self._ns + P.DS_STATUS + P.DS_LAST] = last
        self.dstate[:] = last  # the piezo and every creep lag settled at the last command
        if isinstance(state, CompensatorState):
            if state.dynamics.size == P.DYN_LAGS and self.dynamic:
                self.dstate[: P.DYN_LAGS] = state.dynamics
            lags = as_signal(state.lags, "state.lags", allow_empty=True)
            if lags.size == self.lags.shape[1]:
                self.dstate[P.DYN_LAGS :] = lags
            elif lags.size:
                msg = (
                    f"'state.lags' must hold the model's {self.lags.shape[1]} creep lag "
                    f"states. Got {lags.size}."
                )
                raise ShapeError(msg)

    def precondition(self, cycle: FloatArray) -> FloatArray:
        """See :meth:`~piezohyst.control.inverses.Inverse.precondition`."""
        u = np.empty_like(cycle)
        alphas = self.lags[2]
        ns = int(self.config[P.CC_NS])
        slow = self.kernel_state[ns : self._ns]  # a view: the slow core moves in place
        a = float(self.config[P.CC_SLOW_A])
        last = self.last_command()
        for k, v in enumerate(cycle):
            u[k] = K._advance_dynamics(v, last, self.dyn, self.dstate) if self.dynamic else v
            last = v
            self.dstate[P.DYN_LAGS :] += alphas * (u[k] - self.dstate[P.DYN_LAGS :])
            if slow.size:
                c = float(slow[0])
                P.rev_move(self.slow, slow, c + a * (u[k] - c), True, np.zeros(0), False)
        self.kernel_state[:ns] = self.core.propagate(u, self.kernel_state[:ns]).state
        self.kernel_state[self._ns + P.DS_STATUS + P.DS_LAST] = cycle[-1]
        return cycle

    def inner_step(self, target: float) -> float:
        return float(
            P.core_step(
                target,
                self.params,
                self.config,
                self.kernel_state,
                self.region,
                self.dyn,
                self.dstate,
                self.trial,
            )
        )

    def inner_process(self, d: FloatArray, out: FloatArray) -> None:
        P.core_process(d, self.delay_samples, self.params, self.config, self.kernel_state,
                       self.region, self.dyn, self.dstate, self.trial, out)  # fmt: skip

    def closed_loop(self) -> bool:
        return True

    def slots(self) -> tuple[int, int]:
        return int(P.CC_REF), int(P.CC_INV_GAIN)

    def controller_step(self, d: float, m: float, loop: Loop) -> float:
        return float(P.core_controller_step(d, m, self.params, loop[0], self.kernel_state,
                                            self.region, self.dyn, self.dstate, self.trial,
                                            loop[1], loop[2]))  # fmt: skip

    def controller_process(self, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray) -> None:
        a = (
            self.params,
            loop[0],
            self.kernel_state,
            self.region,
            self.dyn,
            self.dstate,
            self.trial,
        )
        P.core_controller_process(d, m, *a, loop[1], loop[2], out)


class PythonInverse(Inverse):
    """Any core: a bracketed root search on :meth:`Core.propagate`, one sample at a time.

    For a core without a compiled step (one defined outside the library).
    The step's output is increasing in the new voltage (the core's
    ``min_slope`` > 0), so the command is the root of ``output(v) - target``
    inside the sample's reachable interval (limits and slew), found by
    Brent's method to 1e-12 of the interval; a target beyond it sends the
    nearer end (counted as saturated). Kept terms and input dynamics are
    refused; slow, but exact.
    """

    name = "python"
    _LAST, _NONFINITE, _SATURATED = -3, -2, -1

    def _layout(self, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        if not spec.analytic or spec.dynamics.active:
            msg = (
                f"a {type(spec.operator).__name__} core (no compiled inverse step) is compensated "
                "without kept terms or input dynamics: fit it without them"
            )
            raise ParameterError(msg)
        core = spec.operator
        self.analytic = False
        self.plain = False
        self.core = core
        self.config = np.array([inv_gain, 0.0])  # inverse gain, output meaning desired 0
        if self.domain == "displacement":
            self.config[1] = core.output(core.initial_state)
        self.lags = np.zeros((3, 0))
        self.kernel_state = np.zeros(np.asarray(core.initial_state).size + 3)

    def n_operators(self) -> int:
        return int(self.kernel_state.size - 3)

    def state(self) -> CompensatorState:
        n = self.n_operators()
        return CompensatorState(self.kernel_state[:n].copy(), np.zeros(0), self.last_command())

    def reset(self, state: State, voltage: float | None) -> None:
        core: Core = self.core
        n = self.n_operators()
        if isinstance(state, CompensatorState):
            z, last = as_signal(state.operators, "state.operators"), float(state.command)
        elif state is not None:
            z = as_signal(state, "state")
            last = float(z[n]) if z.size == n + 1 else float(np.clip(z[0], self.v_min, self.v_max))
            z = z[:n]
        elif voltage is None:
            z = np.array(core.initial_state, dtype=np.float64)
            last = float(np.clip(z[0], self.v_min, self.v_max))
        else:
            last = finite_number(voltage, "voltage")
            z = np.asarray(core.history_state([float(np.asarray(core.initial_state)[0]), last]))
        if z.size != n:
            msg = f"'state' must hold the core's {n} values (and the last command). Got {z.size}."
            raise ShapeError(msg)
        self._inside(last)
        self.kernel_state[:] = 0.0
        self.kernel_state[:n] = z
        self.kernel_state[self._LAST] = last

    def precondition(self, cycle: FloatArray) -> FloatArray:
        n = self.n_operators()
        self.kernel_state[:n] = self.core.propagate(cycle, self.kernel_state[:n]).state
        self.kernel_state[self._LAST] = cycle[-1]
        return cycle

    def inner_step(self, target: float) -> float:
        from scipy.optimize import brentq

        n = self.n_operators()
        st = self.kernel_state
        last = float(st[self._LAST])
        if not math.isfinite(target):
            st[self._NONFINITE] += 1
            return last
        y = float(self.config[1] + target * self.config[0])
        lo = max(self.v_min, last - self.max_step)
        hi = min(self.v_max, last + self.max_step)
        z = st[:n].copy()

        def gap(v: float) -> float:
            return float(self.core.propagate(np.array([v]), z).output[0]) - y

        g_lo, g_hi = gap(lo), gap(hi)
        if g_lo >= 0.0 or g_hi <= 0.0:  # out of reach this sample: the nearer end
            v = lo if g_lo >= 0.0 else hi
            st[self._SATURATED] += (g_lo > 0.0) or (g_hi < 0.0)
        else:
            v = float(brentq(gap, lo, hi, xtol=1e-12 * max(hi - lo, 1e-300), rtol=1e-15))
        st[:n] = self.core.propagate(np.array([v]), z).state
        st[self._LAST] = v
        return v

    def inner_process(self, d: FloatArray, out: FloatArray) -> None:
        for k, target in enumerate(d):
            out[k] = self.inner_step(float(target))


#: The compensator's engine for each inverse plan (a core's ``inverse_plan().engine``)
INVERSES: dict[str, type[Inverse]] = {
    PlayInverse.name: PlayInverse,
    PackedInverse.name: PackedInverse,
    PythonInverse.name: PythonInverse,
}
