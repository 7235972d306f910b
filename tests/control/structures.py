"""A structure of two shared modes whose zeros lie outside the unit circle, each actuator's
play operators in the loop, as a fitted StructureModel, and a raster for it: what the
structure compensator's tests and its hosts' (C, MEX, FMU) share."""

from __future__ import annotations

import numpy as np

from piezohyst.model import structure_fit as sf
from piezohyst.model.persistence import signed
from piezohyst.model.structure import STRUCTURE_FORMAT, StructureModel

FS = 1000.0
RISE = 300  # samples of the ramp from rest that starts every target


def structure(e_gain: float = 0.1) -> sf.Structure:
    """Two actuators, two shared modes (|poles| 0.97 and 0.95), two outputs read through
    both modes with opposite signs: two transmission zeros outside the unit circle; each
    actuator's two play operators act on the modes with ``e_gain`` (0.1: the tracker's loop
    stays stable where every operator sticks, pole radius 0.97)."""
    rot = lambda rad, th: rad * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])  # noqa: E731
    a = np.zeros((4, 4))
    a[:2, :2], a[2:, 2:] = rot(0.97, 0.3), rot(0.95, 0.7)
    b = 10.0 * np.array([[0.05, 0.01], [0.0, 0.015], [0.005, 0.05], [0.02, 0.0]])
    c = -np.array([[1.0, -0.9, 0.3, 0.1], [0.2, 0.1, 1.0, -0.8]])
    d = np.zeros((2, 2))
    t = np.linalg.pinv(d + c @ np.linalg.solve(np.eye(4) - a, b))
    r = np.array([[0.3, 1.0], [0.2, 0.8]])
    e = e_gain * np.array([[1.0, 0.5, 0.0, 0.0], [0.3, 0.0, 0.0, 0.2], [0.0, 0.0, 1.0, 0.6],
                           [0.0, 0.2, 0.4, 0.0]])  # fmt: skip
    return sf.Structure(a, b, c, d, e, t, r, np.array([0.5, -0.2]))


def model_of(structure: sf.Structure) -> StructureModel:
    """A fitted StructureModel holding ``structure``, through its file format."""
    body = {
        "format": STRUCTURE_FORMAT,
        "version": 1,
        "params": {**StructureModel(order=structure.order).get_params(), "widths": [0.003, 0.3]},
        "sample_rate": FS,
        "orders": {},
        "operators_kept": structure.r.shape[1],
        "held_nrmse": None,
        "output_nrmse": 0.0,
        "refinement": None,
        **{k: getattr(structure, k).tolist() for k in ("a", "b", "c", "d", "e", "t", "r", "off")},
    }
    return StructureModel.from_dict(signed(body))


def raster(model: StructureModel, n: int = 3000, rate: float = 2.0) -> np.ndarray:
    """A triangle on output 0 (40-60 % of its span at 0-100 V, ``rate`` Hz), output 1 held
    at mid-span, after a ramp from rest."""
    lo = model.predict(np.zeros((8, 2)))[0]
    hi = model.structure_.dc_gain() @ np.full(2, 100.0) + model.structure_.off
    k = np.arange(n)
    tri = np.abs((k / FS * rate) % 1.0 * 2 - 1)
    target = np.column_stack([lo[0] + (hi[0] - lo[0]) * (0.4 + 0.2 * tri),
                              np.full(n, 0.5 * (lo[1] + hi[1]))])  # fmt: skip
    ramp = np.linspace(0.0, 1.0, RISE)[:, None]
    return np.vstack([lo + ramp * (target[0] - lo), target])


def error(model: StructureModel, cmd: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Each output's RMS tracking error after the ramp, in its span over the targets."""
    got = model.predict(cmd)[RISE:]
    return np.sqrt(np.mean((got - target[RISE:]) ** 2, axis=0)) / np.ptp(target, axis=0).clip(
        np.ptp(target[:, 0])
    )
