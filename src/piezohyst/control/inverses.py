"""How the compensator inverts each family of cores, one sample at a time.

A core's :meth:`~piezohyst.model.cores.base.Core.inverse_plan` names its engine;
:class:`~piezohyst.Compensator` looks it up in :data:`INVERSES` and hands it
its arrays. An engine is a strategy without state of its own: it lays out the
compensator's kernel arrays (``setup``), runs the compiled step
(``inner_step``, ``inner_process``, and the self-sensing loop's
``controller_step``), and reads, resets and advances the state.

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
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .._lazy import LazyModule
from .._validation import FloatArray, as_signal
from ..errors import ParameterError, ShapeError
from ..model.cores.base import Core, PackedCore
from ..model.cores.play import PIHysteresis
from ..model.model import InverseSpec

if TYPE_CHECKING:
    from .._kernels import packed as D
    from .._kernels import play as K
    from .compensator import Compensator
else:  # numba loads when a model first runs (see _lazy)
    D = LazyModule("piezohyst._kernels.packed", globals(), "D")
    K = LazyModule("piezohyst._kernels.play", globals(), "K")

__all__ = ["INVERSES", "CompensatorState", "Inverse"]

#: What a compensator can be reset to: a saved state, the core's states (and last command)
State = Any
#: The self-sensing loop's arrays: the compensator's config seen by the loop, its settings
#: (``_kernels.CTL_*``) and its feedback state (``CS_*``)
Loop = tuple[FloatArray, FloatArray, FloatArray]


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


def _inside(comp: Compensator, last: float) -> None:
    """A reset's last command must lie inside the limits."""
    if not comp.v_min <= last <= comp.v_max:
        msg = (
            f"The actuator's voltage {last!r} V is outside the limits "
            f"[{comp.v_min}, {comp.v_max}] V."
        )
        raise ParameterError(msg)


def _play(spec: InverseSpec) -> PIHysteresis:
    """The play operators of a spec (the play engine inverts nothing else)."""
    return cast(PIHysteresis, spec.operator)


class Inverse:
    """The engine contract (see the module documentation); every method takes the compensator."""

    name = ""

    def setup(self, comp: Compensator, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        """Lay out the compensator's kernel arrays for ``spec``."""
        raise NotImplementedError

    def closed_loop(self, comp: Compensator) -> bool:
        """Whether the self-sensing controller can run this inverse in its loop."""
        return False

    def n_operators(self, comp: Compensator) -> int:
        """Values in the core's state."""
        raise NotImplementedError

    def state(self, comp: Compensator) -> CompensatorState:
        """The forward states and the last command (copies)."""
        raise NotImplementedError

    def _slot(self, comp: Compensator, name: str) -> int:
        """Where a status value lives in the state array (play and Python engines: its end,
        as ``_kernels.ST_*``)."""
        return {"last": -3, "nonfinite": -2, "saturated": -1}[name]

    def last_command(self, comp: Compensator) -> float:
        """The command sent last (V)."""
        return float(comp._state[self._slot(comp, "last")])

    def nonfinite_count(self, comp: Compensator) -> int:
        """Desired values that were NaN or infinite (the last command held)."""
        return int(comp._state[self._slot(comp, "nonfinite")])

    def saturated_count(self, comp: Compensator) -> int:
        """Desired values out of reach (the nearer limit sent)."""
        return int(comp._state[self._slot(comp, "saturated")])

    def reset(self, comp: Compensator, state: State, voltage: float | None) -> None:
        """Start again from a known condition (see :meth:`Compensator.reset`)."""
        raise NotImplementedError

    def precondition(self, comp: Compensator, cycle: FloatArray) -> FloatArray:
        """Advance the state along ``cycle`` as if it had been sent; return it."""
        raise NotImplementedError

    def inner_step(self, comp: Compensator, target: float) -> float:
        """The command for the hysteresis output ``target``."""
        raise NotImplementedError

    def inner_process(self, comp: Compensator, d: FloatArray, out: FloatArray) -> None:
        """Commands for a block of hysteresis outputs, into ``out``."""
        raise NotImplementedError

    def outside_count(self, comp: Compensator) -> int:
        """Commands that would have left the identified region."""
        return 0

    def share(
        self, comp: Compensator, tables: FloatArray, config: FloatArray, state: FloatArray
    ) -> None:
        """Run on arrays owned by a multi-channel container (the play engine only)."""
        msg = f"a compensator on a {self.name} inverse runs on its own arrays"
        raise ParameterError(msg)

    def slots(self) -> tuple[int, int]:
        """Where ``config`` holds the displacement reference and the inverse gain."""
        raise NotImplementedError

    def controller_step(self, comp: Compensator, d: float, m: float, loop: Loop) -> float:
        """One sample of the self-sensing loop around this inverse."""
        raise NotImplementedError

    def controller_process(
        self, comp: Compensator, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray
    ) -> None:
        """The self-sensing loop over a block."""
        raise NotImplementedError


class PlayInverse(Inverse):
    """Eq. 18 on play operators; Newton beside kept static or creep terms."""

    name = "play"

    def setup(self, comp: Compensator, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        sample_rate, domain = comp.sample_rate, comp.domain
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
        comp.analytic = spec.analytic
        comp._plain = spec.analytic and not dyn.active and not comp.mode.active
        n = op.n_operators
        comp.tables = np.zeros((5, n))
        comp.tables[K.TAB_R] = op.thresholds
        comp.tables[K.TAB_W] = op.weights
        comp.config = np.zeros(K.CONFIG_SIZE)
        comp.config[K.CFG_OFFSET] = op.offset
        comp.config[K.CFG_V_MIN] = comp.v_min
        comp.config[K.CFG_V_MAX] = comp.v_max
        comp.config[K.CFG_MAX_STEP] = max_step
        comp.config[K.CFG_INV_GAIN] = inv_gain
        comp.config[K.CFG_STATIC_SCALE] = 1.0
        if spec.analytic:
            inv = op.inverse()
            comp.tables[K.TAB_S] = op.loading_slopes
            comp.tables[K.TAB_RI] = inv.thresholds
            comp.tables[K.TAB_WI] = inv.weights
            comp.config[K.CFG_INV_OFFSET] = inv.offset
            reach = max(abs(comp.v_min), abs(comp.v_max)) + float(op.thresholds[-1])
            comp.config[K.CFG_BOUND] = 2.0 * float(np.abs(op.weights).sum()) * reach + 1.0
            comp.static = np.zeros((3, 0))
            comp.lags = np.zeros((3, 0))
            n_aux = n
        else:
            st = spec.static
            comp.static = np.zeros((3, 0)) if st is None else np.vstack([st.knots, st.up, st.down])
            if st is not None:
                comp.config[K.CFG_STATIC_SCALE] = st.scale
            lg = spec.lags
            if lg is None:
                comp.lags = np.zeros((3, 0))
            else:
                dt = 1.0 / float(sample_rate)  # type: ignore[arg-type]
                comp.lags = np.vstack([lg.taus, lg.gains, 1.0 - np.exp(-dt / lg.taus)])
            n_aux = comp.lags.shape[1]
        comp._state = np.zeros(n + n_aux + 3)
        comp._n_aux = n_aux
        if domain == "displacement":  # displacement 0 = output at rest in the initial state
            if spec.analytic:
                comp.config[K.CFG_REFERENCE] = op.offset + float(op.weights @ op.initial_state)
            else:
                self._set_forward(comp, self._initial_forward(comp))
                comp.config[K.CFG_REFERENCE] = self._output_now(comp, float(op.initial_state[0]))

    def n_operators(self, comp: Compensator) -> int:
        """Number of play operators of the inverted model."""
        return int(comp.tables.shape[1])

    def _initial_forward(self, comp: Compensator) -> tuple[FloatArray, FloatArray]:
        op = _play(comp.spec)
        x0 = float(op.initial_state[0])
        return op.initial_state.copy(), np.full(comp.lags.shape[1], x0)

    def _set_forward(self, comp: Compensator, forward: tuple[FloatArray, FloatArray]) -> None:
        n = comp.n_operators
        comp._state[:n] = forward[0]
        if not comp.analytic:
            comp._state[n : n + comp._n_aux] = forward[1]
        else:
            K.inverse_states(comp.tables, comp.config, comp._state)

    def _output_now(self, comp: Compensator, v: float) -> float:
        """The hysteresis part's output (model units) if ``v`` were sent from the current state."""
        y, _ = K.hysteresis_output(v, comp.tables, comp.static, comp.lags, comp.config, comp._state)
        return float(y)

    def state(self, comp: Compensator) -> CompensatorState:
        """The forward states and the last command (copies; see :meth:`reset`)."""
        n = comp.n_operators
        lags = comp._state[n : n + comp._n_aux] if not comp.analytic else np.zeros(0)
        return CompensatorState(
            comp._state[:n].copy(),
            lags.copy(),
            float(comp._state[K.ST_LAST]),
            comp.dstate.copy() if comp.dynamic else np.zeros(0),
        )

    def reset(self, comp: Compensator, state: State, voltage: float | None) -> None:
        """See :meth:`~piezohyst.control.inverses.Inverse.reset`."""
        n = comp.n_operators
        m = comp.lags.shape[1]
        op = _play(comp.spec)
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
                float(z[-1]) if z.size == n + 1 else float(np.clip(ops[0], comp.v_min, comp.v_max))
            )
        elif voltage is None:
            ops, lags = self._initial_forward(comp)
            last = float(np.clip(ops[0], comp.v_min, comp.v_max))
        else:
            v = _finite_number(voltage, "voltage")
            ops = np.clip(op.initial_state, v - op.thresholds, v + op.thresholds)
            lags = np.full(m, v)
            last = v
        _inside(comp, last)
        self._set_forward(comp, (np.array(ops, dtype=np.float64), np.array(lags, dtype=np.float64)))
        comp.dstate[:] = last  # the piezo settled at the last command
        comp._mode_history[:] = np.nan
        if isinstance(state, CompensatorState) and state.dynamics.size == 2 and comp.dynamic:
            comp.dstate[:] = state.dynamics
        comp._last_desired = math.nan
        comp._state[K.ST_LAST] = last
        comp._state[K.ST_NONFINITE] = 0.0
        comp._state[K.ST_SATURATED] = 0.0

    def precondition(self, comp: Compensator, cycle: FloatArray) -> FloatArray:
        """See :meth:`~piezohyst.control.inverses.Inverse.precondition`."""
        n = comp.n_operators
        r = comp.tables[K.TAB_R]
        z = comp._state[:n]
        lag = comp._state[n : n + comp._n_aux] if not comp.analytic else np.empty(0)
        alpha = comp.lags[2]
        out = np.empty_like(cycle)
        last = comp.last_command
        step = comp._max_step
        for k, v_target in enumerate(cycle):
            v = min(max(v_target, last - step), last + step)
            u = K._advance_dynamics(v, last, comp.dyn, comp.dstate) if comp.dynamic else v
            z[:] = np.clip(z, u - r, u + r)
            lag += alpha * (u - lag)
            out[k] = last = v
        comp._state[K.ST_LAST] = last
        if comp.analytic:
            K.inverse_states(comp.tables, comp.config, comp._state)
        return out

    def inner_step(self, comp: Compensator, target: float) -> float:
        """The kernel's command for the hysteresis output ``target`` (after mode and delay)."""
        if comp.dynamic:
            return float(
                K.dynamic_step(target, comp.tables, comp.config, comp._state, comp.dyn, comp.dstate)
            )
        if comp.analytic:
            return float(K.compensator_step(target, comp.tables, comp.config, comp._state))
        return float(
            K.numeric_step(target, comp.tables, comp.static, comp.lags, comp.config, comp._state)
        )

    def inner_process(self, comp: Compensator, d: FloatArray, out: FloatArray) -> None:
        """The kernel over a block of hysteresis outputs (after the mode)."""
        if comp.dynamic:
            K.dynamic_process(
                d,
                comp.delay_samples,
                comp.tables,
                comp.config,
                comp._state,
                comp.dyn,
                comp.dstate,
                out,
            )
        elif comp.analytic:
            K.compensator_process(d, comp.tables, comp.config, comp._state, out)
        else:
            K.numeric_process(d, comp.tables, comp.static, comp.lags, comp.config, comp._state, out)

    def closed_loop(self, comp: Compensator) -> bool:
        return bool(comp.analytic)

    def share(
        self, comp: Compensator, tables: FloatArray, config: FloatArray, state: FloatArray
    ) -> None:
        """See :meth:`~piezohyst.control.inverses.Inverse.share`."""
        if not (
            np.array_equal(tables, comp.tables)
            and np.array_equal(config, comp.config)
            and np.array_equal(state, comp._state)
        ):
            msg = "shared arrays must hold the compensator's current tables, config and state"
            raise ParameterError(msg)
        comp.tables, comp.config, comp._state = tables, config, state

    def slots(self) -> tuple[int, int]:
        return int(K.CFG_REFERENCE), int(K.CFG_INV_GAIN)

    def controller_step(self, comp: Compensator, d: float, m: float, loop: Loop) -> float:
        return float(K.controller_step(d, m, comp.tables, loop[0], comp._state,
                                       loop[1], loop[2]))  # fmt: skip

    def controller_process(
        self, comp: Compensator, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray
    ) -> None:
        K.controller_process(d, m, comp.tables, loop[0], comp._state, loop[1], loop[2], out)


class PackedInverse(Inverse):
    r"""The packed cores (Preisach, Duhem, Bouc-Wen): a bracketed Newton step per sample.

    The same limits, slew limit, NaN handling, counters, input dynamics (lags
    inverted per sample, an integer delay by preview) and output mode as the
    play engine. Each sample inverts the core's step from the actuator's
    state: explicitly for Duhem within a step, by a safeguarded Newton solve
    (at most ``_packedkernels.NEWTON_MAX`` iterations) otherwise; the state then
    advances with the command actually sent.

    Beyond the (voltage, output) region the model was identified on (its
    ``region_tolerance``), a command that would move the actuator further out
    is not sent: the command stops at the region's edge (with input dynamics:
    the last command is held) and is counted in ``outside_count``, unless
    ``allow_extrapolation=True`` (then it is sent and counted). Moves back
    towards the region always pass.
    """

    name = "packed"

    def setup(self, comp: Compensator, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        sample_rate, domain = comp.sample_rate, comp.domain
        core = cast(PackedCore, spec.operator)
        comp.core = core
        comp.analytic = False
        comp._plain = False
        comp.params = np.array(core.packed)
        comp.config = np.zeros(D.CC_SIZE)
        comp.config[D.CC_V_MIN] = comp.v_min
        comp.config[D.CC_V_MAX] = comp.v_max
        comp.config[D.CC_MAX_STEP] = max_step
        comp.config[D.CC_INV_GAIN] = inv_gain
        comp.config[D.CC_REFUSE] = 0.0 if comp.allow_extrapolation else 1.0
        region = core.region
        if region is None:
            comp.config[D.CC_TOL] = math.inf
            comp.region = np.zeros((2, 0))
        else:
            comp.config[D.CC_TOL] = spec.region_tolerance * region.span
            comp.config[D.CC_RV_LO] = region.v_lo
            comp.config[D.CC_RV_HI] = region.v_hi
            comp.region = region.array
        if domain == "displacement":  # displacement 0 = the output in the initial state
            comp.config[D.CC_REF] = core.output(core.initial_state)
        fs = float(sample_rate or 0.0)  # given whenever lags or a slow core need it (_settings)
        lg = spec.lags
        if lg is not None:  # kept creep lags: affine in each sample's voltage, solved with it
            alphas = 1.0 - np.exp(-1.0 / (fs * np.asarray(lg.taus)))
            comp.lags = np.vstack([lg.taus, lg.gains, alphas])
            pairs = np.column_stack([lg.gains, alphas]).ravel()
            comp.dyn = np.concatenate([comp.dyn[: D.DYN_LAGS], pairs])
            comp.dstate = np.zeros(D.DYN_LAGS + alphas.size)
        else:
            comp.lags = np.zeros((3, 0))
        ns = core.n_states
        comp.config[D.CC_NS] = ns
        slow = spec.relaxation
        if slow is not None:  # a slow Preisach core after the main one: params and state
            comp.config[D.CC_SLOW_AT] = comp.params.size
            comp.config[D.CC_SLOW_A] = 1.0 - math.exp(-1.0 / (fs * slow.tau))
            comp.params = np.concatenate([comp.params, slow.packed])
            ns += D.RV_SIZE
        #: the slow core's packed parameters (empty without a relaxation term)
        comp.slow = np.zeros(0) if slow is None else np.array(slow.packed)
        comp._ns = ns
        comp._state = np.zeros(comp._ns + D.DS_STATUS)
        #: scratch for the kernel's trial steps (the core's state after a candidate command)
        comp.trial = np.zeros(comp._ns)

    def n_operators(self, comp: Compensator) -> int:
        """Values in the core's state (the last voltage, the internal variable, ...)."""
        return comp._ns

    def state(self, comp: Compensator) -> CompensatorState:
        """The core's state ``[v, x, ...]`` as ``operators``, and the last command (copies)."""
        return CompensatorState(
            comp._state[: comp._ns].copy(),
            comp.dstate[D.DYN_LAGS :].copy(),
            float(comp._state[comp._ns + D.DS_STATUS + D.DS_LAST]),
            comp.dstate[: D.DYN_LAGS].copy() if comp.dynamic else np.zeros(0),
        )

    def _slot(self, comp: Compensator, name: str) -> int:
        """The status values follow the core's state (``_packedkernels.DS_*``)."""
        at = {"last": D.DS_LAST, "nonfinite": D.DS_NONFINITE, "saturated": D.DS_SATURATED,
              "outside": D.DS_OUTSIDE}[name]  # fmt: skip
        return int(comp._ns + D.DS_STATUS + at)

    def outside_count(self, comp: Compensator) -> int:
        """Commands that would have left the identified region (held unless extrapolating)."""
        return int(comp._state[self._slot(comp, "outside")])

    def _with_slow(self, comp: Compensator, z: FloatArray) -> FloatArray:
        """The core's state, then the slow core's at rest at the same voltage (if any)."""
        if not comp.slow.size:
            return z
        rest = np.zeros(D.RV_SIZE)
        rest[0] = rest[D.RV_R] = float(z[0])
        rest[D.RV_K] = 1.0
        return np.concatenate([z, rest])

    def _moved(self, comp: Compensator, start: FloatArray, v: float) -> FloatArray:
        """The core's state after the voltage moves from ``start`` to ``v`` in small steps."""
        v0 = float(start[0])
        span = max(comp.v_max - comp.v_min, 1e-300)
        steps = max(2, math.ceil(abs(v - v0) / (span / 400.0)) + 1)
        return np.asarray(comp.core.propagate(np.linspace(v0, v, steps), start).state)

    def reset(self, comp: Compensator, state: State, voltage: float | None) -> None:
        """See :meth:`~piezohyst.control.inverses.Inverse.reset`."""
        core = comp.core
        if isinstance(state, CompensatorState):
            z = as_signal(state.operators, "state.operators")
            if z.size != comp._ns:
                msg = f"'state' must hold the core's {comp._ns} values [v, x, ...]. Got {z.size}."
                raise ShapeError(msg)
            last = float(state.command)
        elif state is not None:
            z = as_signal(state, "state")
            ns = comp._ns
            if z.size not in (ns, ns + 1):
                msg = (
                    f"'state' must hold the core's {ns} values and optionally the last "
                    f"command. Got {z.size}."
                )
                raise ShapeError(msg)
            last = (
                float(z[ns]) if z.size == ns + 1 else float(np.clip(z[0], comp.v_min, comp.v_max))
            )
            z = z[:ns]
        elif voltage is None:
            z = self._with_slow(comp, np.array(core.initial_state))
            last = float(np.clip(z[0], comp.v_min, comp.v_max))
        else:
            last = _finite_number(voltage, "voltage")
            z = self._with_slow(comp, self._moved(comp, np.array(core.initial_state), last))
        _inside(comp, last)
        comp._state[:] = 0.0
        comp._state[: comp._ns] = z
        comp._state[comp._ns + D.DS_STATUS + D.DS_LAST] = last
        comp.dstate[:] = last  # the piezo and every creep lag settled at the last command
        if isinstance(state, CompensatorState):
            if state.dynamics.size == D.DYN_LAGS and comp.dynamic:
                comp.dstate[: D.DYN_LAGS] = state.dynamics
            lags = as_signal(state.lags, "state.lags", allow_empty=True)
            if lags.size == comp.lags.shape[1]:
                comp.dstate[D.DYN_LAGS :] = lags
            elif lags.size:
                msg = (
                    f"'state.lags' must hold the model's {comp.lags.shape[1]} creep lag "
                    f"states. Got {lags.size}."
                )
                raise ShapeError(msg)
        comp._mode_history[:] = np.nan
        comp._last_desired = math.nan

    def precondition(self, comp: Compensator, cycle: FloatArray) -> FloatArray:
        """See :meth:`~piezohyst.control.inverses.Inverse.precondition`."""
        u = np.empty_like(cycle)
        alphas = comp.lags[2]
        ns = int(comp.config[D.CC_NS])
        slow = comp._state[ns : comp._ns]  # a view: the slow core moves in place
        a = float(comp.config[D.CC_SLOW_A])
        last = comp.last_command
        for k, v in enumerate(cycle):
            u[k] = K._advance_dynamics(v, last, comp.dyn, comp.dstate) if comp.dynamic else v
            last = v
            comp.dstate[D.DYN_LAGS :] += alphas * (u[k] - comp.dstate[D.DYN_LAGS :])
            if slow.size:
                c = float(slow[0])
                D.rev_move(comp.slow, slow, c + a * (u[k] - c), True, np.zeros(0), False)
        comp._state[:ns] = comp.core.propagate(u, comp._state[:ns]).state
        comp._state[comp._ns + D.DS_STATUS + D.DS_LAST] = cycle[-1]
        return cycle

    def inner_step(self, comp: Compensator, target: float) -> float:
        return float(
            D.core_step(
                target,
                comp.params,
                comp.config,
                comp._state,
                comp.region,
                comp.dyn,
                comp.dstate,
                comp.trial,
            )
        )

    def inner_process(self, comp: Compensator, d: FloatArray, out: FloatArray) -> None:
        D.core_process(d, comp.delay_samples, comp.params, comp.config, comp._state, comp.region,
                       comp.dyn, comp.dstate, comp.trial, out)  # fmt: skip

    def closed_loop(self, comp: Compensator) -> bool:
        return True

    def slots(self) -> tuple[int, int]:
        return int(D.CC_REF), int(D.CC_INV_GAIN)

    def controller_step(self, comp: Compensator, d: float, m: float, loop: Loop) -> float:
        return float(D.core_controller_step(d, m, comp.params, loop[0], comp._state,
                                            comp.region, comp.dyn, comp.dstate, comp.trial,
                                            loop[1], loop[2]))  # fmt: skip

    def controller_process(
        self, comp: Compensator, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray
    ) -> None:
        a = (comp.params, loop[0], comp._state, comp.region, comp.dyn, comp.dstate, comp.trial)
        D.core_controller_process(d, m, *a, loop[1], loop[2], out)


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

    def setup(self, comp: Compensator, spec: InverseSpec, max_step: float, inv_gain: float) -> None:
        if not spec.analytic or spec.dynamics.active:
            msg = (
                f"a {type(spec.operator).__name__} core (no compiled inverse step) is compensated "
                "without kept terms or input dynamics: fit it without them"
            )
            raise ParameterError(msg)
        core = spec.operator
        comp.analytic = False
        comp._plain = False
        comp.core = core
        comp.config = np.array([inv_gain, 0.0])  # inverse gain, output meaning desired 0
        if comp.domain == "displacement":
            comp.config[1] = core.output(core.initial_state)
        comp.lags = np.zeros((3, 0))
        comp._state = np.zeros(np.asarray(core.initial_state).size + 3)

    def n_operators(self, comp: Compensator) -> int:
        return int(comp._state.size - 3)

    def state(self, comp: Compensator) -> CompensatorState:
        n = self.n_operators(comp)
        return CompensatorState(comp._state[:n].copy(), np.zeros(0), self.last_command(comp))

    def reset(self, comp: Compensator, state: State, voltage: float | None) -> None:
        core: Core = comp.core
        n = self.n_operators(comp)
        if isinstance(state, CompensatorState):
            z, last = as_signal(state.operators, "state.operators"), float(state.command)
        elif state is not None:
            z = as_signal(state, "state")
            last = float(z[n]) if z.size == n + 1 else float(np.clip(z[0], comp.v_min, comp.v_max))
            z = z[:n]
        elif voltage is None:
            z = np.array(core.initial_state, dtype=np.float64)
            last = float(np.clip(z[0], comp.v_min, comp.v_max))
        else:
            last = _finite_number(voltage, "voltage")
            z = np.asarray(core.history_state([float(np.asarray(core.initial_state)[0]), last]))
        if z.size != n:
            msg = f"'state' must hold the core's {n} values (and the last command). Got {z.size}."
            raise ShapeError(msg)
        _inside(comp, last)
        comp._state[:] = 0.0
        comp._state[:n] = z
        comp._state[self._LAST] = last
        comp._mode_history[:] = np.nan
        comp._last_desired = math.nan

    def precondition(self, comp: Compensator, cycle: FloatArray) -> FloatArray:
        n = self.n_operators(comp)
        comp._state[:n] = comp.core.propagate(cycle, comp._state[:n]).state
        comp._state[self._LAST] = cycle[-1]
        return cycle

    def inner_step(self, comp: Compensator, target: float) -> float:
        from scipy.optimize import brentq

        n = self.n_operators(comp)
        st = comp._state
        last = float(st[self._LAST])
        if not math.isfinite(target):
            st[self._NONFINITE] += 1
            return last
        y = float(comp.config[1] + target * comp.config[0])
        lo = max(comp.v_min, last - comp._max_step)
        hi = min(comp.v_max, last + comp._max_step)
        z = st[:n].copy()

        def gap(v: float) -> float:
            return float(comp.core.propagate(np.array([v]), z).output[0]) - y

        g_lo, g_hi = gap(lo), gap(hi)
        if g_lo >= 0.0 or g_hi <= 0.0:  # out of reach this sample: the nearer end
            v = lo if g_lo >= 0.0 else hi
            st[self._SATURATED] += (g_lo > 0.0) or (g_hi < 0.0)
        else:
            v = float(brentq(gap, lo, hi, xtol=1e-12 * max(hi - lo, 1e-300), rtol=1e-15))
        st[:n] = comp.core.propagate(np.array([v]), z).state
        st[self._LAST] = v
        return v

    def inner_process(self, comp: Compensator, d: FloatArray, out: FloatArray) -> None:
        for k, target in enumerate(d):
            out[k] = self.inner_step(comp, float(target))


#: The compensator's engine for each inverse plan (a core's ``inverse_plan().engine``)
INVERSES: dict[str, type[Inverse]] = {
    PlayInverse.name: PlayInverse,
    PackedInverse.name: PackedInverse,
    PythonInverse.name: PythonInverse,
}
