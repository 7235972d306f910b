"""The ``"play"`` engine: eq. 18 on play operators (Newton beside kept static or creep
terms), the play kernels of :mod:`piezohyst._kernels.play`."""

from __future__ import annotations

from typing import cast

import numpy as np

from ..._kernels import play as K
from ..._validation import FloatArray, as_signal, frozen
from ...errors import ParameterError, ShapeError
from ...model.cores.play import PIHysteresis
from ...model.inverse_spec import InverseSpec
from ..c_text import CParts, CText
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
            u = K.advance_dynamics(v, last, self.dyn, self.dstate) if self.dynamic else v
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
                frozen(d), self.tables, self.static, self.lags, self.config, self.kernel_state, out
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

    def controller_step(self, d: float, m: float, loop: Loop, target: float | None = None) -> float:
        if self.dynamic:  # the lags inverted per sample; ``target`` the delay's preview
            return float(K.dynamic_controller_step(
                d, d if target is None else target, m, self.tables, loop[0], self.kernel_state,
                loop[1], loop[2], self.dyn, self.dstate))  # fmt: skip
        return float(K.controller_step(d, m, self.tables, loop[0], self.kernel_state,
                                       loop[1], loop[2]))  # fmt: skip

    def controller_process(self, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray) -> None:
        if self.dynamic:
            K.dynamic_controller_process(d, self.delay_samples, m, self.tables, loop[0],
                                         self.kernel_state, loop[1], loop[2], self.dyn,
                                         self.dstate, out)  # fmt: skip
            return
        K.controller_process(d, m, self.tables, loop[0], self.kernel_state, loop[1], loop[2], out)

    # ------------------------------------------------------------------ the C
    def c_parts(self, c: CText, fold: tuple[float, float] | None, loop: Loop | None) -> CParts:
        """See :meth:`~piezohyst.control.engines.base.Inverse.c_parts`."""
        if self.spec.operator.c_source != "play.c":
            return super().c_parts(c, fold, loop)
        if not self.analytic:
            return self._numeric_c(c, fold)
        config = self._folded(self.config, fold, K.CFG_REFERENCE, K.CFG_INV_GAIN)
        state, tables = self.state(), self.tables
        step = float(config[K.CFG_MAX_STEP])
        has_slew = int(np.isfinite(step))
        lines = [
            f"#define N {c.upper}_N",
            f"#define HAS_SLEW {has_slew}",
            f"#define DYNAMIC {int(self.dynamic)}",
            f"#define MODE {int(self.settings.mode_active)}",
            f"#define CONTROLLER {int(loop is not None)}",
            *(c.table(name, "N", values) for name, values in (
                ("R", tables[K.TAB_R]), ("W", tables[K.TAB_W]), ("S", tables[K.TAB_S]),
                ("RI", tables[K.TAB_RI]), ("WI", tables[K.TAB_WI]), ("Z0", state.operators))),
            *c.constants(OFFSET=config[K.CFG_OFFSET], INV_OFFSET=config[K.CFG_INV_OFFSET],
                         V_MIN=config[K.CFG_V_MIN], V_MAX=config[K.CFG_V_MAX]),
        ]  # fmt: skip
        if has_slew:
            lines += c.constants(MAX_STEP=step)
        lines += c.constants(SCALE=config[K.CFG_INV_GAIN], REFERENCE=config[K.CFG_REFERENCE],
                             BOUND=config[K.CFG_BOUND], SAT_TOL=1e-12 * (self.v_max - self.v_min),
                             LAST0=state.command)  # fmt: skip
        init = [] if loop is None else _feedback_init(loop[2], c)
        files = ["ieee.c", "play.c"]
        if self.dynamic:
            more, lag_init = self._dynamics_c(c)
            lines += more
            init = [*init, *lag_init]
            files.append("play_dynamic.c")
        if loop is not None:
            ctl = loop[1]
            lines += c.constants(**{name: ctl[getattr(K, f"CTL_{name}")] for name in (
                "KP", "KI", "G0", "G1", "INV_SCALE", "DT", "TOL", "HOLD_TOL", "HOLD_SAMPLES",
                "REFRESH", "DISCHARGE")})  # fmt: skip
            files.append("play_controller.c")
        fields: dict[str, object] = {
            "title": "feedforward hysteresis compensator" if loop is None
            else "self-sensing controller (feedforward + charge feedback)",
            "n": self.n_operators(), "controller": int(loop is not None),
            "kind": "compensator" if loop is None else "controller", "lag_state": "",
        }  # fmt: skip
        return CParts(lines, init, files, "play.h", fields)

    def _numeric_c(self, c: CText, fold: tuple[float, float] | None) -> CParts:
        """Play operators beside kept asymmetry or creep terms (GeneralizedPI): the bracketed
        Newton step of ``_kernels.play.numeric_step`` (``play_numeric.c``)."""
        if self.settings.mode_active:
            msg = (
                "C export of a model with asymmetry or creep takes no output mode yet: pass the "
                "pre-inverted target (OutputDynamics.invert) or fit without the mode"
            )
            raise ParameterError(msg)
        config = self._folded(self.config, fold, K.CFG_REFERENCE, K.CFG_INV_GAIN)
        state = self.state()
        n_static, n_lags = int(self.static.shape[1]), int(self.lags.shape[1])
        step = float(config[K.CFG_MAX_STEP])
        has_slew = int(np.isfinite(step))
        lines = [
            f"#define N {c.upper}_N",
            f"#define N_STATIC {n_static}",
            f"#define N_LAGS {n_lags}",
            f"#define HAS_SLEW {has_slew}",
            f"#define DYNAMIC {int(self.dynamic)}",
            "#define MODE 0",
            c.table("R", "N", self.tables[K.TAB_R]),
            c.table("W", "N", self.tables[K.TAB_W]),
            c.table("Z0", "N", state.operators),
            *c.constants(OFFSET=config[K.CFG_OFFSET], V_MIN=config[K.CFG_V_MIN],
                         V_MAX=config[K.CFG_V_MAX], SCALE=config[K.CFG_INV_GAIN],
                         REFERENCE=config[K.CFG_REFERENCE], LAST0=state.command),
        ]  # fmt: skip
        if has_slew:
            lines += c.constants(MAX_STEP=step)
        if n_static:
            lines += [
                c.table("STATIC_KNOT", "N_STATIC", self.static[0]),
                c.table("STATIC_UP", "N_STATIC", self.static[1]),
                c.table("STATIC_DOWN", "N_STATIC", self.static[2]),
                *c.constants(STATIC_SCALE=config[K.CFG_STATIC_SCALE]),
            ]
        if n_lags:
            lines += [
                c.table("LAG_G", "N_LAGS", self.lags[1]),
                c.table("LAG_A", "N_LAGS", self.lags[2]),
                c.table("C0", "N_LAGS", state.lags),
            ]
        init: list[str] = []
        if self.dynamic:  # the input lags inverted before the Newton step (play_numeric.c)
            more, init = self._dynamics_c(c)
            lines += more
        lag_state = (
            f"\n    {c.prefix}_real c[{n_lags}];     /* creep lag states, V */" if n_lags else ""
        )
        fields: dict[str, object] = {
            "title": "feedforward hysteresis compensator (play operators with asymmetry or creep)",
            "n": self.n_operators(), "controller": 0, "kind": "compensator", "lag_state": lag_state,
        }  # fmt: skip
        return CParts(lines, init, ["ieee.c", "play_numeric.c"], "play.h", fields)


def _feedback_init(fb: FloatArray, c: CText) -> list[str]:
    """The self-sensing loop's feedback state as it is now, one assignment per field."""
    lines = [f"s->{name} = {c.literal(fb[idx])};" for name, idx in (
        ("integral", K.CS_INTEGRAL), ("leak", K.CS_LEAK), ("frame", K.CS_FRAME),
        ("q_last", K.CS_Q_LAST), ("error", K.CS_ERROR), ("bias", K.CS_BIAS),
        ("hold_n", K.CS_HOLD_N), ("sx", K.CS_SX), ("sy", K.CS_SY), ("sxx", K.CS_SXX),
        ("sxy", K.CS_SXY), ("sm", K.CS_SM), ("y0", K.CS_Y0))]  # fmt: skip
    for name, idx in (("d_prev", K.CS_D_PREV), ("hold_ref", K.CS_HOLD_REF)):
        value = float(fb[idx])
        lines.append(f"s->{name} = {c.literal(value if np.isfinite(value) else 0.0)};")
    lines.append(f"s->has_prev = {int(np.isfinite(fb[K.CS_D_PREV]))};")
    lines.append(f"s->has_hold = {int(np.isfinite(fb[K.CS_HOLD_REF]))};")
    lines.append(f"s->started = {int(fb[K.CS_STARTED] > 0)};")
    lines.append(f"s->faults = {int(fb[K.CS_FAULTS])}UL;")
    lines.append(f"s->refreshes = {int(fb[K.CS_REFRESHES])}UL;")
    return lines
