"""The engine contract: :class:`Inverse`, what it is built with (:class:`EngineSettings`)
and what it saves (:class:`CompensatorState`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..._kernels import play as K
from ..._validation import FloatArray
from ...errors import ParameterError
from ...model.inverse_spec import InverseSpec
from ..c_text import CParts, CText

__all__ = ["CompensatorState", "EngineSettings", "Inverse", "Loop", "State", "finite_number"]

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


class Inverse:
    """The engine contract (see the module documentation).

    Parameters
    ----------
    spec : InverseSpec
        What to invert (the model's :meth:`~piezohyst.model.presets.HysteresisModel.inversion`).
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

    def c_parts(self, c: CText, fold: tuple[float, float] | None, loop: Loop | None) -> CParts:
        """This engine's part of the exported C: the constants of its own arrays, its
        ``init`` statements, the shipped files its step needs and its header's fields
        (:mod:`~piezohyst.control.c_text`).

        Parameters
        ----------
        c : CText
            The precision's literals.
        fold : tuple of float, optional
            A linear output map folded into the step: (scale, reference) of the desired
            value, in place of the engine's own.
        loop : tuple of ndarray, optional
            The self-sensing loop's arrays (config, settings, feedback state) to export the
            controller; None for the compensator.

        Returns
        -------
        CParts

        Raises
        ------
        ParameterError
            The engine or core has no C (a core defined outside the library).
        """
        msg = (
            "C export covers play operators and the Preisach, Duhem and Bouc-Wen cores; a "
            f"{type(self.spec.operator).__name__} core runs in Python (ph.Compensator) only."
        )
        raise ParameterError(msg)

    def _dynamics_c(self, c: CText) -> tuple[list[str], list[str]]:
        """The input dynamics' constants and ``init`` statements (its filter state now)."""
        lines = c.constants(FRACTION=self.dyn[K.DYN_FRACTION], GAIN_B=self.dyn[K.DYN_GAIN_B])
        init = [f"s->w = {c.literal(self.dstate[0])};", f"s->u = {c.literal(self.dstate[1])};"]
        return lines, init

    @staticmethod
    def _folded(
        config: FloatArray, fold: tuple[float, float] | None, ref: int, scale: int
    ) -> FloatArray:
        """``config`` with a linear output map's (scale, reference) in place of its own."""
        if fold is None:
            return config
        out = config.copy()
        out[scale], out[ref] = fold
        return out

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

    def controller_step(self, d: float, m: float, loop: Loop, target: float | None = None) -> float:
        """One sample of the self-sensing loop around this inverse (``target``: with an input
        delay, the output the command must bring, ``d`` the output wanted now)."""
        raise NotImplementedError

    def controller_process(self, d: FloatArray, m: FloatArray, loop: Loop, out: FloatArray) -> None:
        """The self-sensing loop over a block."""
        raise NotImplementedError
