"""Input dynamics: what lies between the logged command and the hysteresis.

An amplifier driving a capacitive load, or a DAQ that logs the *commanded*
voltage, puts a lag between the voltage in the record and the voltage on
the piezo. At one drive frequency a lag widens the loop exactly like
hysteresis does; at another it does not, so a rate-independent model that
absorbed a lag is wrong the moment the frequency changes. An
:class:`InputDynamics` — a delay (integer and fractional samples) and/or a
first-order lag — turns the command ``x`` into the piezo voltage ``u`` that
the hysteresis model sees; models identify it jointly with the hysteresis
(``input_dynamics=`` on every model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _kernels
from ._validation import FloatArray
from .errors import ParameterError

__all__ = ["KINDS", "InputDynamics"]

KINDS = ("none", "delay", "first-order", "delay+first-order")


@dataclass(frozen=True)
class InputDynamics:
    """A delay and a first-order lag between command and piezo voltage.

    Attributes
    ----------
    kind : str
        One of ``"none"``, ``"delay"``, ``"first-order"``, ``"delay+first-order"``.
    tau : float
        First-order lag time constant (s); 0 for none.
    delay : float
        Pure delay (s); 0 for none. Applied in samples of ``sample_interval``
        (integer part exact, fraction by linear interpolation): the record is
        assumed uniformly sampled.
    sample_interval : float
        The training record's median sample interval (s).

    Examples
    --------
    >>> dyn = InputDynamics("delay", delay=0.002, sample_interval=0.001)
    >>> u, _ = dyn.apply([0.0, 1.0, 2.0, 3.0], dt=[0.0, 1e-3, 1e-3, 1e-3])
    >>> u.tolist()
    [0.0, 0.0, 0.0, 1.0]
    """

    kind: str = "none"
    tau: float = 0.0
    delay: float = 0.0
    sample_interval: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            msg = f"input dynamics kind must be one of {KINDS}. Got {self.kind!r}."
            raise ParameterError(msg)
        for name in ("tau", "delay", "sample_interval"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                msg = f"input dynamics {name!r} must be a finite number >= 0 (s). Got {value!r}."
                raise ParameterError(msg)
        if self.delay > 0 and self.sample_interval <= 0:
            msg = "a delay needs the record's sample interval (s) to count its samples"
            raise ParameterError(msg)

    @property
    def active(self) -> bool:
        """True when the command is changed at all."""
        return self.tau > 0 or self.delay > 0

    @property
    def delay_samples(self) -> float:
        """The delay in samples of ``sample_interval``."""
        return self.delay / self.sample_interval if self.delay > 0 else 0.0

    def _split(self) -> tuple[int, float]:
        d = self.delay_samples
        whole = math.floor(d + 1e-9)
        return whole, max(d - whole, 0.0)

    def rest_state(self, x0: float) -> FloatArray:
        """The filter resting at command ``x0`` (every delayed and lagged value there).

        Parameters
        ----------
        x0 : float

        Returns
        -------
        ndarray
        """
        whole, _ = self._split()
        state = np.full(3 + whole + 2, float(x0))
        state[0] = 0.0
        state[2] = 0.0
        return state

    def apply(
        self, x: Any, dt: Any, state: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """The piezo voltage for commands ``x`` held over sample intervals ``dt``.

        Parameters
        ----------
        x : array_like, shape (N,)
            Commands (input units).
        dt : array_like, shape (N,)
            Each sample's interval (s; the first of a record is 0).
        state : ndarray, optional
            From :meth:`rest_state` or an earlier call (updated in place);
            default at rest at ``x[0]``.

        Returns
        -------
        tuple of ndarray
            ``u`` and the state.
        """
        xs = np.ascontiguousarray(x, dtype=np.float64)
        ds = np.ascontiguousarray(dt, dtype=np.float64)
        st = self.rest_state(float(xs[0]) if xs.size else 0.0) if state is None else state
        out = np.empty_like(xs)
        if not self.active:
            out[:] = xs
            return out, st
        whole, frac = self._split()
        if st.size != 3 + whole + 2:
            msg = f"the input dynamics state must hold {3 + whole + 2} values. Got {st.size}."
            raise ParameterError(msg)
        _kernels.input_filter(xs, ds, whole, frac, float(self.tau), st, out)
        return out, st

    def to_dict(self) -> dict[str, Any]:
        """``kind``, ``tau`` (s), ``delay`` (s), ``sample_interval`` (s).

        Returns
        -------
        dict
        """
        return {
            "kind": self.kind,
            "tau": self.tau,
            "delay": self.delay,
            "sample_interval": self.sample_interval,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> InputDynamics:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict

        Returns
        -------
        InputDynamics
        """
        return cls(
            str(data.get("kind", "none")),
            float(data.get("tau", 0.0)),
            float(data.get("delay", 0.0)),
            float(data.get("sample_interval", 0.0)),
        )
