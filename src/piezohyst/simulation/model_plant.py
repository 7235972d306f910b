"""A lab's own fitted model standing in for its actuator, for loops run before the rig.

The built-in bench (:class:`~piezohyst.simulation.Bench`) is another actuator: a loop
run on it scores the controller against that actuator's physics, not the lab's. A
:class:`ModelPlant` runs the lab's model forward instead (no noise, no sensor): voltage
in, the model's output (charge, with its growth terms) and its displacement out: the
model's own output where it is a displacement, else the hysteresis charge (growth
removed, eq. 19) through the gain or output map (eq. 6-7), if one is given.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal
from ..control.contract import Controller
from ..errors import ParameterError
from ..model.calibrations.output_map import OutputMap
from ..model.model import HysteresisModel
from ..units import is_length

__all__ = ["ModelPlant", "PlantRun", "run_on_model"]


@dataclass(frozen=True)
class PlantRun:
    """One run of a :class:`ModelPlant`, one row per command.

    Attributes
    ----------
    t : ndarray
        Time at the end of each sample (s).
    voltage : ndarray
        The command (V).
    charge : ndarray
        The model's output with its growth terms (its output unit); NaN for a model of the
        displacement.
    displacement : ndarray
        m; NaN for a charge model run without a gain.
    hysteresis : ndarray
        The hysteresis part alone (the model's output unit): what a loop width is read from.
    """

    t: FloatArray
    voltage: FloatArray
    charge: FloatArray
    displacement: FloatArray
    hysteresis: FloatArray


class ModelPlant:
    """A fitted model as the plant of a loop (see the module's notes).

    Parameters
    ----------
    model : HysteresisModel
        Fitted: the lab's model of its actuator (or another model standing in for it).
    sample_rate : float
        Hz; one command per sample.
    voltage : float, default 0.0
        Where the actuator rests when the run starts (V): memory wiped there.
    gain : float or OutputMap, optional
        Displacement per charge (m/C), or a map, for a charge model's displacement.
    """

    def __init__(
        self,
        model: HysteresisModel,
        sample_rate: float,
        *,
        voltage: float = 0.0,
        gain: float | OutputMap | None = None,
    ) -> None:
        if not (np.isfinite(sample_rate) and sample_rate > 0):
            msg = f"'sample_rate' must be a positive number of Hz. Got {sample_rate!r}."
            raise ParameterError(msg)
        self.model = model
        self.rate = float(sample_rate)
        self.gain = gain
        self.of_displacement = is_length(model.output_unit)
        self._pure = model.hysteresis_
        self._k = 0
        self._states: list[Any] = [model.rest_state(float(voltage)),
                                   self._pure.rest_state(float(voltage))]  # fmt: skip
        with warnings.catch_warnings():  # the rest's displacement is not read: no map warning
            warnings.simplefilter("ignore")
            self.charge = float(self._run(np.array([float(voltage)]), advance=False).charge[0])

    @property
    def sample_rate(self) -> float:
        """Samples per second (Hz)."""
        return self.rate

    def describe(self) -> str:
        """What actuator this plant is, in a line.

        Returns
        -------
        str
        """
        return (
            f"your model {type(self.model).__name__} (its output {self.model.output_unit}, "
            "no noise): the loop is scored against what it predicts, not a rig"
        )

    def displacement_of(self, pure: FloatArray) -> FloatArray:
        """The displacement of a hysteresis output (m; NaN without a gain for a charge model).

        Parameters
        ----------
        pure : ndarray
            The model's hysteresis part (growth removed).

        Returns
        -------
        ndarray
        """
        if self.of_displacement:
            return pure
        if isinstance(self.gain, OutputMap):
            return np.asarray(self.gain.predict(pure), dtype=np.float64)
        if self.gain is None:
            return np.full(pure.size, np.nan)
        return float(self.gain) * pure

    def _run(self, v: FloatArray, *, advance: bool = True, mapped: bool = True) -> PlantRun:
        k0 = self._k + (1 if advance else 0)
        t = (k0 + np.arange(v.size)) / self.rate
        out = self.model.propagate(v, t, self._states[0])
        pure = self._pure.propagate(v, t, self._states[1])
        if advance:
            self._states = [out.state, pure.state]
            self._k += v.size
        y, h = np.asarray(out.output, np.float64), np.asarray(pure.output, np.float64)
        charge = np.full(v.size, np.nan) if self.of_displacement else y
        s = self.displacement_of(h) if mapped else np.full(v.size, np.nan)
        return PlantRun(t, v.copy(), charge, s, h)

    def apply(self, voltage: float, *, mapped: bool = True) -> PlantRun:
        """Send ``voltage`` for one sample; that sample's row.

        Parameters
        ----------
        voltage : float
            V.
        mapped : bool, default True
            Compute the displacement (False: NaN, for a caller that maps a whole run at
            once, and says a map's extrapolation once).

        Returns
        -------
        PlantRun
        """
        row = self._run(np.array([float(voltage)]), mapped=mapped)
        self.charge = float(row.charge[0])
        return row

    def run(self, voltages: ArrayLike) -> PlantRun:
        """Send voltages, one per sample.

        Parameters
        ----------
        voltages : array_like
            V.

        Returns
        -------
        PlantRun
        """
        run = self._run(as_signal(voltages, "voltages"))
        self.charge = float(run.charge[-1])
        return run


def run_on_model(controller: Controller, desired: ArrayLike, plant: ModelPlant) -> PlantRun:
    """Drive ``plant`` with ``controller`` over a desired trajectory, as
    :func:`~piezohyst.simulation.run_loop` drives the bench: the self-sensing controller
    gets, each sample, the charge the plant gave after the previous command.

    Parameters
    ----------
    controller : Controller
        Any controller of the one contract (:mod:`~piezohyst.control.contract`).
    desired : array_like, shape (N,)
        Desired values (the controller's units); NaN holds the last command.
    plant : ModelPlant

    Returns
    -------
    PlantRun

    Raises
    ------
    ParameterError
        A self-sensing controller on a plant whose model gives no charge (a displacement
        model).
    """
    d = np.ascontiguousarray(desired, dtype=np.float64)
    as_signal(np.nan_to_num(d), "desired")
    if not controller.reads:
        return plant.run(controller.process(d))
    if plant.of_displacement:
        msg = (
            "a model of the displacement gives no charge for the self-sensing loop to read: "
            "stand a charge model in for the actuator, or run the feedforward alone"
        )
        raise ParameterError(msg)
    rows = [plant.apply(controller.step(float(x), plant.charge), mapped=False) for x in d]
    t, v, q, h = (np.concatenate([getattr(r, f) for r in rows])
                  for f in ("t", "voltage", "charge", "hysteresis"))  # fmt: skip
    return PlantRun(t, v, q, plant.displacement_of(h), h)
