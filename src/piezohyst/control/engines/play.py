"""The ``"play"`` engine: eq. 18 on play operators (Newton beside kept static or creep
terms), the play kernels of :mod:`piezohyst._kernels.play`."""

from __future__ import annotations

from typing import cast

import numpy as np

from ..._kernels import play as K
from ..._validation import FloatArray, as_signal
from ...errors import ParameterError, ShapeError
from ...model.cores.play import PIHysteresis
from ...model.model import InverseSpec
from .base import CompensatorState, Inverse, Loop, State, finite_number

__all__ = ["PlayInverse"]


def _play(spec: InverseSpec) -> PIHysteresis:
    """The play operators of a spec (the play engine inverts nothing else)."""
    return cast(PIHysteresis, spec.operator)


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
        """See :meth:`~piezohyst.control.engines.base.Inverse.reset`."""
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
        """See :meth:`~piezohyst.control.engines.base.Inverse.precondition`."""
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
        """See :meth:`~piezohyst.control.engines.base.Inverse.share`."""
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
