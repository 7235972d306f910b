r"""A coupled stage without position sensors: each actuator's charge loop, behind the
coupling's inverse.

A stage's sensors are calibrated once against its actuators' charges
(:func:`~piezohyst.calibrate_stage`: ``y = C g(q) + c``, each actuator's capacitor charge to
what it moves, then the coupling). After that the stage runs on its charges alone: the
desired positions become what each actuator alone must move (the coupling's inverse, its
reach a parallelogram: :func:`~piezohyst.control.coupled.stage_targets`), and each actuator's
own :class:`~piezohyst.SelfSensingController` closes its loop on its own charge (the
leakage removed, eq. 19; its output map turns the displacement it must move into the charge
it must hold). The charges are each actuator's own, so the loops are independent: the
coupling enters through the targets alone::

    desired y ──► C⁻¹ (y − c) ──► d₁ ──► loop 1 (model 1, map 1) ──► v₁ ──► actuator 1 ──► q₁ ─┐
                               └─► d₂ ──► loop 2 (model 2, map 2) ──► v₂ ──► actuator 2 ──► q₂ ─┤
                                          ▲                                                    │
                                          └──────────── each loop reads its own charge ◄───────┘

What the loops cannot correct: an error of the coupling (no loop sees the positions), and a
charge that is not the actuator's motion (the flexure's load on a stack, a mode between a
stack and the stage); the calibration's misfit says how large those were when it was made.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import FloatArray
from ..errors import ParameterError, ShapeError
from ..model.calibrations.leakage import Leakage
from ..model.calibrations.stage_map import StageMap
from .coupled import _per_actuator, actuator_reach, stage_targets
from .selfsensing import SelfSensingController

__all__ = ["CoupledSelfSensingController"]


class CoupledSelfSensingController:
    """Self-sensing control of a coupled stage: desired positions in, one command per
    actuator out, each actuator's loop closed on its own measured charge.

    Parameters
    ----------
    models : sequence of HysteresisModel
        One per actuator, each fitted on its own voltage -> charge (as the
        :class:`~piezohyst.SelfSensingController` takes it).
    stage : StageMap
        The stage's positions from the actuators' charges (:func:`~piezohyst.calibrate_stage`),
        calibrated through these models.
    v_min, v_max : float or array_like
        Each actuator's voltage limits (V): one number for all, or one per actuator.
    sample_rate : float
        Hz, of the loop.
    leakage : Leakage or sequence of Leakage, optional
        Per actuator (one for all, or one each); default each model's growth terms.
    ki, kp : float
        Each loop's integral and proportional gains (see
        :class:`~piezohyst.SelfSensingController`).
    slew_rate : float, "trained" or None, default "trained"
        Per actuator, as for :class:`~piezohyst.Compensator`.
    allow_extrapolation : bool, default False
    flat_guard : bool, default False
        As for :class:`~piezohyst.SelfSensingController`.

    Attributes
    ----------
    loops : list of SelfSensingController
        One per actuator, in its own axis's units (its output map's).
    reach : ndarray, shape (actuators, 2)
        What each actuator alone moves over its limits (its axis's units).
    outside_count, off_plane_count : int
        Desired positions out of the stage's reach since the reset (counted and said once, as
        :class:`~piezohyst.CoupledCompensator` does).

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> from piezohyst.simulation import Stage, make_signal, simulate_stage
    >>> t, a = make_signal("decaying", duration=8.0)
    >>> _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    >>> rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t)
    >>> models = [ph.ActivePI(10).fit(rec.voltage[:, i], rec.charge[:, i], t=rec.t)
    ...           for i in range(2)]
    >>> stage = ph.calibrate_stage(models, rec.voltage, rec.charge, rec.position, rec.t)
    >>> ctl = ph.CoupledSelfSensingController(models, stage, v_min=0.0, v_max=140.0,
    ...                                       sample_rate=1000.0)
    >>> rig = Stage(seed=3)
    >>> volts = ctl.step(stage.predict([[1e-7, 1e-7]])[0], rig.reading.charge)
    >>> volts.shape, bool(np.all((volts >= 0) & (volts <= 140)))
    ((2,), True)
    """

    #: True: each command depends on the readings before it (the controllers' one contract)
    reads = True
    #: What it reads: each actuator's charge (a stage loop sends ``Stage.reading.charge``)
    senses = "charge"
    #: Who its warnings name
    owner = "CoupledSelfSensingController"

    def __init__(
        self,
        models: Sequence[Any],
        stage: StageMap,
        *,
        v_min: float | ArrayLike,
        v_max: float | ArrayLike,
        sample_rate: float,
        leakage: Leakage | Sequence[Leakage] | None = None,
        ki: float = 0.5,
        kp: float = 0.0,
        slew_rate: float | Literal["trained"] | None = "trained",
        allow_extrapolation: bool = False,
        flat_guard: bool = False,
    ) -> None:
        if not isinstance(stage, StageMap):
            msg = (
                "CoupledSelfSensingController takes a StageMap (ph.calibrate_stage) for the "
                f"stage's positions from its charges. Got {type(stage).__name__}."
            )
            raise ParameterError(msg)
        n = len(stage.maps)
        if len(models) != n:
            msg = f"one model per actuator: the stage map has {n}, got {len(models)} models"
            raise ParameterError(msg)
        lo, hi = _per_actuator(v_min, n, "v_min"), _per_actuator(v_max, n, "v_max")
        leaks = self._leakages(leakage, n)
        self.models = list(models)
        self.stage = stage
        self.loops = []
        for i, model in enumerate(self.models):
            loop = SelfSensingController(
                model, v_min=float(lo[i]), v_max=float(hi[i]), sample_rate=sample_rate,
                leakage=leaks[i], ki=ki, kp=kp, slew_rate=slew_rate, output_map=stage.maps[i],
                allow_extrapolation=allow_extrapolation, flat_guard=flat_guard,
            )  # fmt: skip
            loop.owner = f"{self.owner}, actuator {i}"
            self.loops.append(loop)
        self.inverse = stage.inverse
        self.reach = np.array([self._reach(loop) for loop in self.loops])
        self.outside_count = self.off_plane_count = 0
        self._outside_said = self._off_said = False

    @staticmethod
    def _leakages(leakage: Any, n: int) -> list[Leakage | None]:
        if leakage is None or isinstance(leakage, Leakage):
            return [leakage] * n
        leaks = list(leakage)
        if len(leaks) != n or not all(isinstance(v, Leakage) for v in leaks):
            msg = f"'leakage' must be a Leakage or one per actuator ({n}). Got {leakage!r}."
            raise ParameterError(msg)
        return leaks

    @staticmethod
    def _reach(loop: SelfSensingController) -> tuple[float, float]:
        """What an actuator moves over its limits: its hysteresis's charges through its map."""
        q = actuator_reach(loop.compensator)
        assert loop.compensator.output_map is not None
        with warnings.catch_warnings():  # the map extended past its calibrated charges
            warnings.simplefilter("ignore")
            s = loop.compensator.output_map.predict(np.array(q))
        return float(np.min(s)), float(np.max(s))

    # ------------------------------------------------------------------ counts
    @property
    def last_command(self) -> FloatArray:
        """The last commands sent, one per actuator (V)."""
        return np.array([loop.last_command for loop in self.loops])

    def _counts(self, name: str) -> NDArray[np.int64]:
        return np.array([getattr(loop, name) for loop in self.loops], dtype=np.int64)

    @property
    def saturated_count(self) -> NDArray[np.int64]:
        """Per actuator, commands sent at a voltage limit because its loop asked beyond it."""
        return self._counts("saturated_count")

    @property
    def slew_limited_count(self) -> NDArray[np.int64]:
        """Per actuator, commands the slew limit held back."""
        return self._counts("slew_limited_count")

    @property
    def nonfinite_count(self) -> NDArray[np.int64]:
        """Per actuator, samples held because a desired value was NaN or infinite."""
        return self._counts("nonfinite_count")

    @property
    def measurement_faults(self) -> NDArray[np.int64]:
        """Per actuator, samples whose charge reading was missing (feedforward alone)."""
        return self._counts("measurement_faults")

    def describe(self) -> str:
        """One line per actuator (its limits, gains and map) and the coupling.

        Returns
        -------
        str
        """
        lines = [f"coupling inverse of {self.stage.coupling.shape[0]} outputs x "
                 f"{len(self.loops)} actuators; each loop closed on its own charge"]  # fmt: skip
        for i, loop in enumerate(self.loops):
            lo, hi = self.reach[i]
            lines.append(
                f"actuator {i}: {type(loop.model).__name__}, [{loop.v_min:g}, {loop.v_max:g}] V, "
                f"ki {loop.ki_used:g}, kp {loop.kp:g}, moves [{lo:.4g}, {hi:.4g}] "
                f"{self.stage.output_unit}"
            )
        return "\n".join(lines)

    def reset(self, *, voltage: float | ArrayLike | None = None) -> None:
        """Every loop back to its initial state (or ``voltage``), the counts to zero; the
        next finite charges set each loop's frame again.

        Parameters
        ----------
        voltage : float or array_like, optional
            Where the actuators sit now (V).
        """
        v = None if voltage is None else _per_actuator(voltage, len(self.loops), "voltage")
        for i, loop in enumerate(self.loops):
            loop.reset(voltage=None if v is None else float(v[i]))
        self.outside_count = self.off_plane_count = 0
        self._outside_said = self._off_said = False

    def precondition(self, samples: int = 1000) -> FloatArray:
        """Each actuator's full-range cycle, to send first (its loop's frame restarts after).

        Parameters
        ----------
        samples : int, default 1000

        Returns
        -------
        ndarray, shape (samples', actuators)
            Voltages (V); the actuators' cycles padded to one length by holding their end.
        """
        cycles = [loop.precondition(samples) for loop in self.loops]
        size = max(c.size for c in cycles)
        return np.column_stack([np.pad(c, (0, size - c.size), mode="edge") for c in cycles])

    # ---------------------------------------------------------------- commands
    def actuator_targets(self, desired: FloatArray) -> FloatArray:
        """What each actuator alone must move for the desired positions; the rows out of the
        stage's reach counted (:attr:`outside_count`) and said once.

        Parameters
        ----------
        desired : ndarray, shape (N, outputs)
            The stage's positions (the map's units).

        Returns
        -------
        ndarray, shape (N, actuators)
            Each actuator's own share, in its axis's units.
        """
        return stage_targets(self, desired, self.stage.coupling, self.stage.offset)

    def _readings(self, measured: Any, shape: tuple[int, ...]) -> FloatArray:
        n = len(self.loops)
        if measured is None:
            return np.full((*shape[:-1], n), math.nan)
        m = np.asarray(measured, dtype=np.float64)
        if m.shape != (*shape[:-1], n):
            msg = f"'measured' must hold {n} charges per sample. Got shape {m.shape}."
            raise ShapeError(msg)
        return m

    @property
    def previews(self) -> int:
        """The next desired positions :meth:`step` uses where a planned trajectory gives
        them (``preview``): one where an actuator's map holds a mode; 0: none."""
        return max(loop.previews for loop in self.loops)

    def step(
        self, desired: ArrayLike, measured: ArrayLike | None = None,
        preview: ArrayLike | None = None,
    ) -> FloatArray:  # fmt: skip
        """The commands for one sample.

        Parameters
        ----------
        desired : array_like, shape (outputs,)
            The stage's desired position (the map's units); NaN holds.
        measured : array_like, shape (actuators,), optional
            Each actuator's charge read at this sample, before these commands act (its
            model's units); None or NaN: that loop runs on feedforward for this sample.
        preview : array_like, shape (k, outputs), optional
            The next desired positions, for actuators whose maps hold a mode (the
            trajectory's derivatives; extrapolated from the last two without them; with
            them, ``step`` equals ``process`` to the bit). Not counted: each is counted
            when its own sample comes.

        Returns
        -------
        ndarray, shape (actuators,)
            Commands (V), each finite and inside its actuator's limits.
        """
        m_out = self.stage.coupling.shape[0]
        d = np.asarray(desired, dtype=np.float64).reshape(1, -1)
        if d.shape[1] != m_out:
            msg = f"'desired' must hold {m_out} positions. Got {d.size}."
            raise ShapeError(msg)
        q = self._readings(measured, (len(self.loops),))
        own = self.actuator_targets(d)[0]
        ahead = None
        if preview is not None and self.previews:
            p = np.asarray(preview, dtype=np.float64).reshape(-1, m_out)
            ahead = ((p - self.stage.offset)[:, None, :] * self.inverse[None, :, :]).sum(axis=2)
        return np.array([
            loop.step(float(own[i]), float(q[i]), None if ahead is None else ahead[:, i])
            for i, loop in enumerate(self.loops)
        ])  # fmt: skip

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """Commands for recorded blocks; equal to :meth:`step` on each row (the loops are
        each actuator's own).

        Parameters
        ----------
        desired : array_like, shape (N, outputs)
        measured : array_like, shape (N, actuators), optional

        Returns
        -------
        ndarray, shape (N, actuators)
        """
        d = np.asarray(desired, dtype=np.float64)
        if d.ndim != 2 or d.shape[1] != self.stage.coupling.shape[0]:
            msg = (
                f"'desired' must be (samples, {self.stage.coupling.shape[0]}). Got shape {d.shape}."
            )
            raise ShapeError(msg)
        q = self._readings(measured, (d.shape[0], len(self.loops)))
        own = self.actuator_targets(d)
        return np.column_stack([
            loop.process(np.ascontiguousarray(own[:, i]), np.ascontiguousarray(q[:, i]))
            for i, loop in enumerate(self.loops)
        ])  # fmt: skip
