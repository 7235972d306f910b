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
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from . import _kernels
from ._validation import FloatArray, as_signal
from .errors import ParameterError, ShapeError
from .generalized import GeneralizedPI
from .hysteresis import PIHysteresis
from .models import ClassicalPI

__all__ = ["Compensator"]

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


class Compensator:
    r"""Feedforward hysteresis compensator for a fitted ClassicalPI or ActivePI.

    Parameters
    ----------
    model : ClassicalPI, ActivePI or GeneralizedPI
        A fitted model; growth terms are dropped (leaked charge moves nothing)
        and the hysteresis part is inverted: analytically (eq. 18) for the
        classical and active models, exactly by a safeguarded Newton solve per
        sample for :class:`~piezohyst.GeneralizedPI` (whose creep operators
        need ``sample_rate``).
    v_min, v_max : float
        The actuator's voltage limits (V). Every command lies inside them.
    slew_rate : float, optional
        Largest command change in V/s; needs ``sample_rate``.
    sample_rate : float, optional
        Samples per second (Hz) of the control loop, for ``slew_rate``.
    domain : {"charge", "displacement"}
        Units of the desired values: the model's output units, or metres.
    gain : float, optional
        Displacement per model output unit (m/C), required for
        ``domain="displacement"`` (eq. 6-7: S = g·Q). Displacement 0 is the
        actuator at rest in the model's initial state.

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
    """

    def __init__(
        self,
        model: ClassicalPI,
        *,
        v_min: float,
        v_max: float,
        slew_rate: float | None = None,
        sample_rate: float | None = None,
        domain: Domain = "charge",
        gain: float | None = None,
    ) -> None:
        if not isinstance(model, ClassicalPI):
            msg = (
                "The 'model' parameter of Compensator must be a fitted ClassicalPI or ActivePI. "
                f"Got {type(model).__name__} instead."
            )
            raise ParameterError(msg)
        model._check_fitted()
        op: PIHysteresis = model.operator_
        self._numeric = isinstance(model, GeneralizedPI)
        if not op.is_invertible:
            op.inverse()  # raises NotInvertibleError with the reason
        self.v_min = _finite_number(v_min, "v_min")
        self.v_max = _finite_number(v_max, "v_max")
        if not self.v_min < self.v_max:
            msg = f"Compensator needs v_min < v_max. Got v_min={v_min!r}, v_max={v_max!r}."
            raise ParameterError(msg)
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
        scale = 1.0
        if domain == "displacement":
            if gain is None:
                msg = "domain='displacement' needs the gain (m per model output unit). Got None."
                raise ParameterError(msg)
            g = _finite_number(gain, "gain")
            if g == 0.0:
                msg = "The 'gain' parameter of Compensator must be non-zero. Got 0."
                raise ParameterError(msg)
            scale = 1.0 / g
        self.model = model
        self.domain: Domain = domain
        self.gain = gain
        self.slew_rate = slew_rate
        self.sample_rate = sample_rate
        n = op.n_operators
        reach = max(abs(self.v_min), abs(self.v_max)) + float(op.thresholds[-1])
        if self._numeric:
            assert isinstance(model, GeneralizedPI)
            taus = model.creep_taus_
            if taus.size and sample_rate is None:
                msg = "A GeneralizedPI with creep needs the loop's sample_rate (Hz). Got None."
                raise ParameterError(msg)
            dt = 0.0 if sample_rate is None else 1.0 / float(sample_rate)
            self._pi = np.vstack([op.thresholds, op.weights])
            self._static = np.vstack([model.knots_, model.static_up_, model.static_down_])
            self._creep = np.vstack([taus, model.creep_gains_, 1.0 - np.exp(-dt / taus)])
            self._config = np.array(
                [op.offset, self.v_min, self.v_max, max_step, scale, 0.0, model.static_scale_, 0.0]
            )
            self._state = np.zeros(n + taus.size + 3)
            self._last_index = n + taus.size
            if domain == "displacement":  # displacement 0 = output at rest in the initial state
                x0 = float(op.initial_state[0])
                self._state[:n] = op.initial_state
                self._state[n : n + taus.size] = x0
                self._config[5] = _kernels._generalized_output(
                    x0, self._pi, self._static, self._creep, self._config, self._state
                )[0]
        else:
            inv = op.inverse()
            self._params = np.zeros((6, n))
            self._params[0] = op.thresholds
            self._params[1] = op.weights
            self._params[2] = op.loading_slopes
            self._params[3] = inv.thresholds
            self._params[4] = inv.weights
            # displacement 0 = the model's output at rest in its initial state
            reference = 0.0
            if domain == "displacement":
                reference = op.offset + float(op.weights @ op.initial_state)
            bound = 2.0 * float(np.abs(op.weights).sum()) * reach + 1.0
            self._config = np.array(
                [op.offset, inv.offset, self.v_min, self.v_max, max_step, scale, reference, bound]
            )
            self._state = np.zeros(2 * n + 3)
            self._last_index = 2 * n
        self.reset()

    # ----------------------------------------------------------------- state
    @property
    def n_operators(self) -> int:
        return int(self.model.operator_.n_operators)

    def _refresh(self) -> None:
        """Derived state after the forward states changed (inverse states, analytic path)."""
        if not self._numeric:
            _kernels.inverse_states(self._params, self._config, self._state)

    @property
    def state(self) -> FloatArray:
        """Forward operator states (V) followed by the last command (V); a read-only copy."""
        n = self.n_operators
        extra = self._last_index - n if self._numeric else 0  # creep lag states
        out = np.concatenate([self._state[: n + extra], self._state[self._last_index :][:1]])
        out.flags.writeable = False
        return out

    @property
    def nonfinite_count(self) -> int:
        """Desired values that were NaN or infinite (the last command was held)."""
        return int(self._state[self._last_index + 1])

    @property
    def saturated_count(self) -> int:
        """Samples whose command was clipped to ``[v_min, v_max]``."""
        return int(self._state[self._last_index + 2])

    def reset(self, state: ArrayLike | None = None, *, voltage: float | None = None) -> None:
        """Start again from a known actuator condition; counters go back to 0.

        * ``reset()``: the model's initial state (the training record's start);
          if the limits exclude that voltage, the last command starts at the
          nearest limit.
        * ``reset(voltage=v)``: the actuator now sits at ``v`` volts; the
          model's initial state is projected onto it (eq. 10: each operator
          clamped into ``[v - r_i, v + r_i]``). Use this after an unknown history
          only with :meth:`precondition`, which erases that history.
        * ``reset(state)``: explicit forward operator states (V), e.g. a
          :attr:`state` saved earlier (its last element is the last command).
        """
        n = self.n_operators
        lags = self._last_index - n if self._numeric else 0
        op = self.model.operator_
        if state is not None:
            z = as_signal(state, "state")
            if z.size not in (n + lags, n + lags + 1):
                msg = (
                    f"'state' must hold {n} operator states{f', {lags} lag states' if lags else ''}"
                    f" (and the last command). Got {z.size}."
                )
                raise ShapeError(msg)
            ops = z[: n + lags]
            last = (
                float(z[-1])
                if z.size == n + lags + 1
                else float(np.clip(ops[0], self.v_min, self.v_max))
            )
        elif voltage is None:
            # the model's own start; if the limits exclude it, the first command steps in
            x0 = float(op.initial_state[0])
            ops = np.concatenate([op.initial_state, np.full(lags, x0)])
            last = float(np.clip(x0, self.v_min, self.v_max))
        else:
            v = _finite_number(voltage, "voltage")
            ops = np.concatenate(
                [np.clip(op.initial_state, v - op.thresholds, v + op.thresholds), np.full(lags, v)]
            )
            last = v
        if not self.v_min <= last <= self.v_max:
            msg = (
                f"The actuator's voltage {last!r} V is outside the limits "
                f"[{self.v_min}, {self.v_max}] V."
            )
            raise ParameterError(msg)
        self._state[: n + lags] = ops
        self._state[self._last_index] = last
        self._state[self._last_index + 1 :] = 0.0
        self._refresh()

    @property
    def _max_step(self) -> float:
        return float(self._config[3] if self._numeric else self._config[4])

    def precondition(self, samples: int = 1000) -> FloatArray:
        """The preconditioning cycle to send first: last command → v_max → v_min → back.

        A full-amplitude cycle wipes out the actuator's unknown history (the
        remanence problem: a fresh model assumes a known state). The returned
        voltages (V, ``samples`` in all) must be sent to the amplifier before
        the first :meth:`step`; the compensator's state is advanced as if they
        had been. With a slew-rate limit the cycle gets as many samples as it
        needs to reach both limits.
        """
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 3:
            msg = f"'samples' must be an int >= 3. Got {samples!r}."
            raise ParameterError(msg)
        n = self.n_operators
        start = float(self._state[self._last_index])
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
        cycle = np.concatenate(pieces)
        op = self.model.operator_
        z = self._state[:n]
        lag = self._state[n : self._last_index] if self._numeric else np.empty(0)
        alpha = self._creep[2] if self._numeric else np.empty(0)
        out = np.empty_like(cycle)
        last = start
        for k, v_target in enumerate(cycle):
            v = min(max(v_target, last - step), last + step)
            z[:] = np.clip(z, v - op.thresholds, v + op.thresholds)
            lag += alpha * (v - lag)
            out[k] = last = v
        self._state[self._last_index] = last
        self._refresh()
        return out

    # -------------------------------------------------------------- commands
    def step(self, desired: float) -> float:
        """The command (V) for one desired value (model output units, or m)."""
        if self._numeric:
            return float(
                _kernels.generalized_step(
                    float(desired), self._pi, self._static, self._creep, self._config, self._state
                )
            )
        return float(
            _kernels.compensator_step(float(desired), self._params, self._config, self._state)
        )

    def process(self, desired: ArrayLike) -> FloatArray:
        """Commands (V) for a block of desired values; equal to calling :meth:`step` on each.

        NaN and infinite values are allowed here (they hold the last command).
        """
        d = np.ascontiguousarray(desired, dtype=np.float64)
        if d.ndim != 1:
            msg = f"'desired' must be a 1-D array. Got shape {d.shape}."
            raise ShapeError(msg)
        out = np.empty_like(d)
        if self._numeric:
            _kernels.generalized_process(
                d, self._pi, self._static, self._creep, self._config, self._state, out
            )
        else:
            _kernels.compensator_process(d, self._params, self._config, self._state, out)
        return out
