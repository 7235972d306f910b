"""A coupled stage on the simulated bench: several actuators moving one structure.

Each actuator is a bench of its own (its hysteresis, leakage, Sawyer-Tower charge and noise;
:class:`~piezohyst.simulation.Bench`), and the structure couples their displacements: the
stage's position is ``coupling @ [s_1, ..., s_n]`` (a flexure moving x moves y by a few per
cent). A laser per axis reads the position. The charges stay each actuator's own, as on a
rig: the coupling is mechanical.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import ParameterError, ShapeError
from .bench import DEFAULT_PRESET, PLANTS, PRESETS, BenchPreset, simulate

__all__ = ["XY_COUPLING", "XY_DYNAMIC", "StageRecord", "simulate_stage"]

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
    names = presets or (DEFAULT_PRESET,) * v.shape[1]
    if len(names) != v.shape[1]:
        msg = f"one preset per actuator: {v.shape[1]} actuators, {len(names)} presets"
        raise ParameterError(msg)
    ts = np.arange(v.shape[0]) / 1000.0 if t is None else np.asarray(t, dtype=np.float64)
    chosen = []
    for name in names:
        if isinstance(name, str) and name not in PRESETS and name not in PLANTS:
            msg = f"unknown actuator {name!r}; available: {', '.join([*PRESETS, *PLANTS])}"
            raise ParameterError(msg)
        chosen.append(PLANTS[name] if isinstance(name, str) and name not in PRESETS else name)
    runs = [
        simulate(np.ascontiguousarray(v[:, i]), ts, preset=chosen[i], seed=seed + i)
        for i in range(v.shape[1])
    ]
    read = np.column_stack([r.displacement for r in runs])
    true = np.column_stack([r.true_displacement for r in runs])
    return StageRecord(ts, v, np.column_stack([r.charge for r in runs]), read @ c.T, true @ c.T, c)
