"""The ``"python"`` engine: any core, by a bracketed root search on
:meth:`~piezohyst.model.cores.base.Core.propagate` (a core defined outside the library: no
compiled step, no C)."""

from __future__ import annotations

import math

import numpy as np

from ..._validation import FloatArray, as_signal
from ...errors import ParameterError, ShapeError
from ...model.cores.base import Core
from ...model.inverse_spec import InverseSpec
from .base import CompensatorState, Inverse, State, finite_number

__all__ = ["PythonInverse"]


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

    def slots(self) -> tuple[int, int]:
        return 1, 0

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
