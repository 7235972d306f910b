"""What the host tests share (the shared library, the MEX gateway, the FMU): one record, every
model kind issue 41 names fitted on it, and a desired trajectory inside each one's region."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

import piezohyst as ph
from piezohyst.simulation import make_signal

#: Every kind issue 41 names, by the name the tests use
KINDS: dict[str, Callable[[], ph.HysteresisModel]] = {
    "active-pi": lambda: ph.ActivePI(20),
    "generalized-pi+creep": lambda: ph.GeneralizedPI(
        12, growth_terms=("integral",), creep=(0.05, 0.5, 5.0)
    ),
    "preisach": lambda: ph.PreisachModel(),
    "preisach+relaxation": lambda: ph.PreisachModel(relaxation=0.1, relaxation_nodes=8),
    "duhem": lambda: ph.DuhemModel(),
    "bouc-wen": lambda: ph.BoucWenModel(),
}


def record() -> Any:
    """12 s of decaying loops on the bench."""
    return ph.simulate(signal="decaying", duration=12.0, seed=3)


def fitted(rec: Any, names: list[str] | None = None) -> dict[str, ph.HysteresisModel]:
    """The kinds fitted on ``rec`` (the fits' own notes are not under test)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {
            name: KINDS[name]().fit(rec.voltage, rec.charge, t=rec.t)
            for name in (names or list(KINDS))
        }


def desired(model: ph.HysteresisModel, n: int = 3000, fs: float = 1000.0) -> np.ndarray:
    """Decaying loops inside the identified region, a NaN now and then (held)."""
    lo, hi = model.input_range_
    _, shape = make_signal("decaying", amplitude=1.0, duration=n / fs)
    v = lo + (hi - lo) * (0.5 + 0.45 * shape / np.abs(shape).max())
    d = model.hysteresis_.predict(v, t=np.arange(v.size) / fs)
    d[::89] = np.nan
    return np.ascontiguousarray(d[:n])
