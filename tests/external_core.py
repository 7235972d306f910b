"""A core defined outside the library, in this file only: one backlash beside a linear term.

y = a x + b z + c, where z is one play operator of width r (a tenth of the training range).
Linear in (a, b, c) once r is fixed, so its identification step is one least-squares solve.
It follows the Core contract and nothing else: kind, state, propagation, identification,
min_slope, file form. It has no compiled inverse step and no C source.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

import piezohyst as ph
from piezohyst.model.cores.base import CoreFit, FitJob, Propagation


@dataclass(frozen=True, eq=False)
class BacklashCore(ph.Core):
    """y = a x + b z + c with one play operator z of width r."""

    r: float
    a: float
    b: float
    c: float
    initial_state: np.ndarray
    kind: ClassVar[str] = "test-backlash"

    def propagate(self, x: ArrayLike, state: ArrayLike | None = None) -> Propagation[np.ndarray]:
        xs = np.asarray(x, dtype=np.float64)
        z = float(np.asarray(self.initial_state if state is None else state)[0])
        y = np.empty_like(xs)
        for k, v in enumerate(xs):  # the play operator, eq. 10
            z = min(max(z, v - self.r), v + self.r)
            y[k] = self.a * v + self.b * z + self.c
        return Propagation(y, np.array([z]))

    def rest_state(self, x0: float) -> np.ndarray:
        return np.array([float(x0)])

    @property
    def min_slope(self) -> float:
        return self.a + min(self.b, 0.0)

    @classmethod
    def identify(cls, job: FitJob) -> CoreFit:
        x = np.concatenate([b[0] for b in job.blocks()])
        y = np.concatenate([b[1] for b in job.blocks()])
        if job.terms:
            raise ph.ParameterError("the backlash core fits no terms beside it")
        r = 0.1 * float(np.ptp(x))
        probe = cls(r, 0.0, 1.0, 0.0, np.array([x[0]]))
        z = probe.predict(x)
        cols = np.column_stack([x, z, np.ones_like(x)])
        a, b, c = np.linalg.lstsq(cols, y, rcond=None)[0]
        return CoreFit(cls(r, float(a), float(b), float(c), np.array([x[0]])), (), ())

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        return [("backlash width", f"{self.r:.4g} {input_unit}")]

    def to_dict(self) -> dict[str, Any]:
        return {"r": self.r, "a": self.a, "b": self.b, "c": self.c,
                "initial_state": self.initial_state.tolist()}  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BacklashCore:
        return cls(float(data["r"]), float(data["a"]), float(data["b"]), float(data["c"]),
                   np.asarray(data["initial_state"], dtype=np.float64))  # fmt: skip
