"""A coupled stage on the simulated bench: several actuators moving one structure.

Each actuator is a bench of its own (its hysteresis, leakage, Sawyer-Tower charge and noise;
:class:`~piezohyst.simulation.Bench`), and the structure couples their displacements: the
stage's position is ``coupling @ [s_1, ..., s_n]`` (a flexure moving x moves y by a few per
cent). A laser per axis reads the position. The charges stay each actuator's own, as on a
rig: the coupling is mechanical.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import ParameterError, ShapeError
from .bench import DEFAULT_PRESET, PLANTS, PRESETS, Bench, BenchPreset, simulate

__all__ = [
    "XY_COUPLING",
    "XY_DYNAMIC",
    "Stage",
    "StageReading",
    "StageRecord",
    "run_stage_loop",
    "simulate_stage",
]

#: The default XY stage's coupling: x moves y by 4 %, y moves x by -3 %
XY_COUPLING = np.array([[1.0, -0.03], [0.04, 1.0]])
#: An XY stage with dynamics (``simulate_stage(v, t, presets=XY_DYNAMIC)``): each axis's
#: actuator behind its own amplifier's lag (4 ms, 3 ms) with a lightly damped mode (150 Hz
#: at 5 %, 120 Hz at 4 %) between its hysteresis and its motion; the flexure couples the
#: moving axes (kinematic coupling: y's laser sees x's motion, mode and all)
XY_DYNAMIC = ("T226-H4-203X-mode", "T226-H4-203X-mode-y")


@dataclass(frozen=True)
class StageRecord:
    """One run of the coupled stage: measured channels and the hidden truth.

    Attributes
    ----------
    t : ndarray, shape (N,)
        s.
    voltage : ndarray, shape (N, n)
        The commands, one column per actuator (V).
    charge : ndarray, shape (N, n)
        Each actuator's Sawyer-Tower charge (C).
    position : ndarray, shape (N, m)
        The lasers' readings of the stage (m).
    true_position : ndarray, shape (N, m)
        The stage's position without the lasers' noise (m).
    coupling : ndarray, shape (m, n)
        Actuator displacement to stage position.
    """

    t: FloatArray
    voltage: FloatArray
    charge: FloatArray
    position: FloatArray
    true_position: FloatArray
    coupling: FloatArray


def simulate_stage(
    voltage: ArrayLike,
    t: ArrayLike | None = None,
    *,
    coupling: ArrayLike = XY_COUPLING,
    presets: tuple[str | BenchPreset, ...] | None = None,
    seed: int = 0,
) -> StageRecord:
    """Run the coupled stage on one command column per actuator.

    Parameters
    ----------
    voltage : array_like, shape (N, n)
        The commands (V), inside each actuator's limits (its bench refuses others).
    t : array_like, shape (N,), optional
        Time stamps (s); default 1 kHz from 0.
    coupling : array_like, shape (m, n), default :data:`XY_COUPLING`
        Actuator displacement to stage position.
    presets : tuple of (str or BenchPreset), optional
        One actuator per column: a bench preset (:data:`PRESETS`) or an actuator of other
        physics (:data:`PLANTS`: ``"bouc-wen"``, ``"duhem"``, ...); default the paper's
        bimorph for every one (each with its own noise).
    seed : int
        Seeds the noise (actuator ``i`` gets ``seed + i``).

    Returns
    -------
    StageRecord

    Raises
    ------
    ShapeError
        ``voltage`` not (samples, actuators), or a coupling of another width.
    """
    v = np.asarray(voltage, dtype=np.float64)
    if v.ndim != 2 or v.shape[0] < 2:
        msg = f"'voltage' must be (samples, actuators). Got shape {v.shape}."
        raise ShapeError(msg)
    c = np.asarray(coupling, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != v.shape[1] or not np.all(np.isfinite(c)):
        msg = f"'coupling' must be finite, (outputs, {v.shape[1]}). Got shape {c.shape}."
        raise ShapeError(msg)
    chosen = _actuators(presets, v.shape[1])
    ts = np.arange(v.shape[0]) / 1000.0 if t is None else np.asarray(t, dtype=np.float64)
    runs = [
        simulate(np.ascontiguousarray(v[:, i]), ts, preset=chosen[i], seed=seed + i)
        for i in range(v.shape[1])
    ]
    read = np.column_stack([r.displacement for r in runs])
    true = np.column_stack([r.true_displacement for r in runs])
    return StageRecord(ts, v, np.column_stack([r.charge for r in runs]), read @ c.T, true @ c.T, c)


def _actuators(presets: tuple[str | BenchPreset, ...] | None, n: int) -> list[Any]:
    """One bench preset per actuator (a name of :data:`PRESETS` or :data:`PLANTS`, or a
    preset), the paper's bimorph by default."""
    names = presets or (DEFAULT_PRESET,) * n
    if len(names) != n:
        msg = f"one preset per actuator: {n} actuators, {len(names)} presets"
        raise ParameterError(msg)
    chosen = []
    for name in names:
        if isinstance(name, str) and name not in PRESETS and name not in PLANTS:
            msg = f"unknown actuator {name!r}; available: {', '.join([*PRESETS, *PLANTS])}"
            raise ParameterError(msg)
        chosen.append(PLANTS[name] if isinstance(name, str) and name not in PRESETS else name)
    return chosen


@dataclass(frozen=True)
class StageReading:
    """What a stage's DAQ reads at the end of one sample.

    Attributes
    ----------
    t : float
        s.
    voltage : ndarray, shape (n,)
        The commands held over the sample (V).
    charge : ndarray, shape (n,)
        Each actuator's Sawyer-Tower charge (C).
    position : ndarray, shape (m,)
        The lasers' readings (m).
    true_position : ndarray, shape (m,)
        The stage's position without the lasers' noise (m).
    """

    t: float
    voltage: FloatArray
    charge: FloatArray
    position: FloatArray
    true_position: FloatArray


class Stage:
    """The coupled stage driven one sample at a time: a plant for a stage's closed loops.

    Each actuator is a :class:`~piezohyst.simulation.Bench` of its own, stepped together;
    the structure couples their displacements as :func:`simulate_stage` does.

    Parameters
    ----------
    presets : tuple of (str or BenchPreset), optional
        One actuator per column, as for :func:`simulate_stage`.
    coupling : array_like, shape (m, n), default :data:`XY_COUPLING`
    voltage : float or array_like, default 0.0
        Where the actuators rest at t = 0 (V): one for all, or one each.
    seed : int
        Actuator ``i``'s noise is seeded ``seed + i``.

    Examples
    --------
    >>> rig = Stage(seed=1)
    >>> r = rig.apply([70.0, 20.0])
    >>> r.charge.shape, r.position.shape
    ((2,), (2,))
    """

    def __init__(
        self,
        presets: tuple[str | BenchPreset, ...] | None = None,
        *,
        coupling: ArrayLike = XY_COUPLING,
        voltage: float | ArrayLike = 0.0,
        seed: int = 0,
    ) -> None:
        c = np.asarray(coupling, dtype=np.float64)
        if c.ndim != 2 or not np.all(np.isfinite(c)):
            msg = f"'coupling' must be finite, (outputs, actuators). Got shape {c.shape}."
            raise ShapeError(msg)
        n = c.shape[1]
        chosen = _actuators(presets, n)
        given = np.asarray(voltage, dtype=np.float64).reshape(-1)
        if given.size not in (1, n):
            msg = f"'voltage' must be one number or one per actuator ({n}). Got {given.size}."
            raise ShapeError(msg)
        v0 = np.broadcast_to(given, (n,))
        self.coupling = c
        self.benches = [Bench(p, voltage=float(v0[i]), seed=seed + i) for i, p in enumerate(chosen)]
        self.reading = self._read()

    def _read(self) -> StageReading:
        rs = [b.reading for b in self.benches]
        s = np.array([r.displacement for r in rs])
        s_true = np.array([r.true_displacement for r in rs])
        return StageReading(
            rs[0].t,
            np.array([r.voltage for r in rs]),
            np.array([r.charge for r in rs]),
            self.coupling @ s,
            self.coupling @ s_true,
        )

    def apply(self, voltages: ArrayLike) -> StageReading:
        """Send one command per actuator for one sample; the DAQ's reading at its end.

        Parameters
        ----------
        voltages : array_like, shape (n,)
            V, each inside its actuator's limits (its amplifier refuses others).

        Returns
        -------
        StageReading
        """
        v = np.asarray(voltages, dtype=np.float64).reshape(-1)
        if v.size != len(self.benches):
            msg = f"one command per actuator ({len(self.benches)}). Got {v.size}."
            raise ShapeError(msg)
        for b, x in zip(self.benches, v, strict=True):
            b.apply(float(x))
        self.reading = self._read()
        return self.reading


def run_stage_loop(controller: Any, desired: ArrayLike, stage: Stage) -> StageRecord:
    """Drive ``stage`` with ``controller`` over desired positions, one sample at a time.

    A controller that reads gets, each sample, what the stage read after the previous
    commands: each actuator's charge for one that senses charge (the stage's self-sensing
    loop), the positions otherwise; a feedforward one is sent the whole block at once. Row
    ``k`` of the result is what the stage read after commands ``k``.

    Parameters
    ----------
    controller : object
        :class:`~piezohyst.CoupledCompensator`, :class:`~piezohyst.CoupledSelfSensingController`
        or another of the one contract (``reads``, ``step``, ``process``).
    desired : array_like, shape (N, m)
        The stage's desired positions (NaN holds).
    stage : Stage
        The plant, continuing from its present state.

    Returns
    -------
    StageRecord
    """
    d = np.asarray(desired, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] < 1:
        msg = f"'desired' must be (samples, outputs). Got shape {d.shape}."
        raise ShapeError(msg)
    rows = []
    if not controller.reads:
        volts = controller.process(d)
        rows = [stage.apply(v) for v in volts]
    else:
        charge = getattr(controller, "senses", "position") == "charge"
        ahead = int(getattr(controller, "previews", 0))  # a planned trajectory's next rows
        for k in range(d.shape[0]):
            seen = stage.reading.charge if charge else stage.reading.position
            if ahead:
                c = controller.step(d[k], seen, d[k + 1 : k + 1 + ahead])
            else:
                c = controller.step(d[k], seen)
            rows.append(stage.apply(c))
    return StageRecord(
        np.array([r.t for r in rows]),
        np.array([r.voltage for r in rows]),
        np.array([r.charge for r in rows]),
        np.array([r.position for r in rows]),
        np.array([r.true_position for r in rows]),
        stage.coupling.copy(),
    )
