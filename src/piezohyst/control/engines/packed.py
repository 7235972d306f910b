"""The ``"packed"`` engine: the Preisach, Duhem and Bouc-Wen cores' bracketed Newton step
(:mod:`piezohyst._kernels.packed`), with creep lags and a relaxing core."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import numpy as np

from ..._kernels import packed as P
from ..._kernels import play as K
from ..._validation import FloatArray, as_signal
from ...errors import ParameterError, ShapeError
from ...model.cores.base import PackedCore
from ...model.inverse_spec import InverseSpec
from ..c_text import CParts, CText
from .base import CompensatorState, Inverse, Loop, State, finite_number

__all__ = ["PackedInverse"]


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
        """See :meth:`~piezohyst.control.engines.base.Inverse.reset`."""
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
        """See :meth:`~piezohyst.control.engines.base.Inverse.precondition`."""
        u = np.empty_like(cycle)
        alphas = self.lags[2]
        ns = int(self.config[P.CC_NS])
        slow = self.kernel_state[ns : self._ns]  # a view: the slow core moves in place
        a = float(self.config[P.CC_SLOW_A])
        last = self.last_command()
        for k, v in enumerate(cycle):
            u[k] = K.advance_dynamics(v, last, self.dyn, self.dstate) if self.dynamic else v
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

    def controller_step(self, d: float, m: float, loop: Loop, target: float | None = None) -> float:
        return float(P.core_controller_step(d, d if target is None else target, m, self.params,
                                            loop[0], self.kernel_state, self.region, self.dyn,
                                            self.dstate, self.trial, loop[1], loop[2]))  # fmt: skip

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
        P.core_controller_process(d, self.delay_samples, m, *a, loop[1], loop[2], out)

    # ------------------------------------------------------------------ the C
    def c_parts(self, c: CText, fold: tuple[float, float] | None, loop: Loop | None) -> CParts:
        """See :meth:`~piezohyst.control.engines.base.Inverse.c_parts`: ``_kernels.packed.
        core_step`` in C, the same arithmetic as the kernel (Newton inside a bracket, at most
        ``NEWTON_MAX`` iterations: a bounded time per sample)."""
        if self.spec.operator.c_source != "packed.c":
            return super().c_parts(c, fold, loop)
        if loop is not None:
            msg = (
                "C export of the self-sensing controller covers play-operator models; on a "
                f"{CORES[int(self.params[0])].name} core the loop runs in Python "
                "(ph.SelfSensingController), and the feedforward compensator exports alone"
            )
            raise ParameterError(msg)
        params, state = self.params, self.state()
        cfg = self._folded(self.config, fold, P.CC_REF, P.CC_INV_GAIN)
        kind = int(params[0])
        n_lags = int(self.lags.shape[1])
        has_slow = int(self.slow.size > 0)
        step = float(cfg[P.CC_MAX_STEP])
        has_slew = int(np.isfinite(step))
        region = self.region
        has_region = int(region.shape[1] > 0 and np.isfinite(cfg[P.CC_TOL]))
        lines = [
            f"#define NS {c.upper}_NS",
            f"#define KIND {kind} /* 0 Duhem, 1 Bouc-Wen, 2 Preisach */",
            f"#define HAS_SLEW {has_slew}",
            f"#define DYNAMIC {int(self.dynamic)}",
            f"#define MODE {int(self.settings.mode_active)}",
            f"#define HAS_REGION {has_region}",
            f"#define N_LAGS {n_lags} /* kept creep lags beside the core */",
            f"#define SLOW {has_slow} /* a slow (relaxing) Preisach core behind a lag */",
            f"#define NS_MAIN {int(cfg[P.CC_NS])} /* the core values in st; the slow core next */",
            f"#define NEWTON_MAX {P.NEWTON_MAX}",
            f"#define HOLD_RES {P.HOLD_RES!r}",
            f"#define REGION_BISECTIONS {P.REGION_BISECTIONS}",
            f"#define STACK {P.STACK}",
        ]
        core = CORES[kind]
        files = ["ieee.c", "packed_util.c"]
        lines += core.constants(params, c)
        files += core.files
        if has_slow:  # the slow core: the Preisach grid functions again, on its own grid
            lines.append(_preisach_constants(self.slow, c, "SLOW_"))
            lines += c.constants(SLOW_A=cfg[P.CC_SLOW_A])
            files += ["relaxation_begin.h", "preisach_grid.c", "relaxation_end.h"]
        if has_region:
            bins = region.shape[1]
            lines += [c.table("REGION_LO", str(bins), region[0]),
                      c.table("REGION_HI", str(bins), region[1])]  # fmt: skip
            lines += c.constants(RV_LO=cfg[P.CC_RV_LO], RV_HI=cfg[P.CC_RV_HI], TOL=cfg[P.CC_TOL])
            lines += [f"#define REGION_BINS {bins}", f"#define REFUSE {int(cfg[P.CC_REFUSE] > 0)}"]
        lines += c.constants(V_MIN=cfg[P.CC_V_MIN], V_MAX=cfg[P.CC_V_MAX])
        if has_slew:
            lines += c.constants(MAX_STEP=step)
        lines += c.constants(SCALE=cfg[P.CC_INV_GAIN], REFERENCE=cfg[P.CC_REF])
        lines.append(c.table("ST0", "NS", state.operators))
        lines += c.constants(LAST0=state.command)
        init: list[str] = []
        if self.dynamic:
            more, init = self._dynamics_c(c)
            lines += more
        if n_lags:  # gains and 1 - exp(-dt / tau) at the loop's sample rate
            lines += [c.table("LAG_G", "N_LAGS", self.lags[1]),
                      c.table("LAG_A", "N_LAGS", self.lags[2])]  # fmt: skip
            init += [f"s->c[{k}] = {c.literal(float(self.dstate[P.DYN_LAGS + k]))};"
                     for k in range(n_lags)]  # fmt: skip
        files.append("packed.c")
        fields: dict[str, object] = {
            "core": core.name, "newton_max": P.NEWTON_MAX, "ns": self.n_operators(),
            "n_lags": n_lags, "libm": core.libm, "kind": "compensator",
        }  # fmt: skip
        return CParts(lines, init, files, "packed.h", fields)


@dataclass(frozen=True)
class _CoreC:
    """What a packed core's kind adds to the C: its constants, files and the header's words."""

    name: str
    files: tuple[str, ...]
    constants: Callable[[FloatArray, CText], list[str]]
    libm: str = ""


def _bouc_wen_constants(params: FloatArray, c: CText) -> list[str]:
    return c.constants(**{n: params[getattr(P, f"BW_{n if n != 'NEXP' else 'N'}")]
                          for n in ("C0", "ALPHA", "BETA", "GAMMA", "NEXP", "OFFSET",
                                    "DV_MAX", "G_MAX", "S_MIN")})  # fmt: skip


def _duhem_constants(params: FloatArray, c: CText) -> list[str]:
    nv, nq = int(params[P.DU_NV]), int(params[P.DU_NQ])
    cells = nv * nq
    return [
        f"#define NV {nv}",
        f"#define NQ {nq}",
        *c.constants(V_LO=params[P.DU_V_LO], V_STEP=params[P.DU_V_STEP],
                     Q_LO=params[P.DU_Q_LO], Q_STEP=params[P.DU_Q_STEP],
                     DV_MAX=params[P.DU_DV_MAX], S_MIN=params[P.DU_F_MIN]),
        c.table("UP", "NV * NQ", params[P.DU_UP : P.DU_UP + cells]),
        c.table("DOWN", "NV * NQ", params[P.DU_UP + cells : P.DU_UP + 2 * cells]),
    ]  # fmt: skip


def _preisach_constants(packed: FloatArray, c: CText, prefix: str = "") -> str:
    """A Preisach core's grid and Everett table as C constants (names after ``prefix``)."""
    n = int(packed[P.DU_NV])
    lit = [c.literal(float(packed[k])) for k in (P.DU_V_LO, P.DU_V_STEP, P.DU_F_MIN)]
    # the smallest slope bounds the main core's bracket; a slow core's is not needed
    bracket = [] if prefix else [f"static const real_t S_MIN = {lit[2]};"]
    return "\n".join(
        [
            f"enum {{ {prefix}NN = {n} }};",
            f"static const real_t {prefix}V_LO = {lit[0]};",
            f"static const real_t {prefix}H = {lit[1]};",
            *bracket,
            f"static const real_t {prefix}EV[{prefix}NN * {prefix}NN] = "
            f"{c.array(packed[P.DU_UP : P.DU_UP + n * n])};",
        ]
    )


#: Each packed kind's C (``_kernels.packed.KIND_*``)
CORES: dict[int, _CoreC] = {
    int(P.KIND_DUHEM): _CoreC("Duhem", ("duhem.c",), _duhem_constants),
    int(P.KIND_BOUC_WEN): _CoreC(
        "Bouc-Wen",
        ("boucwen.c",),
        _bouc_wen_constants,
        " Needs pow() from <math.h> (link with -lm).",
    ),
    int(P.KIND_PREISACH): _CoreC(
        "Preisach",
        ("preisach_grid.c", "preisach.c"),
        lambda params, c: [_preisach_constants(params, c)],
    ),
}
