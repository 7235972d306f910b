"""What a loop timing handed to a model fitted without one does to learning (issue 55, item 4).

Two studies on the learning rig's plants behind a 4 ms amplifier (0.1 % charge noise; 10
one-second trials; width of the true displacement after the last, seed 0):

* ``--study injected``: the rig's model (``ActivePI(10)`` fitted on 30 s of multifreq without
  input dynamics) as it is, with the plant's exact 4 ms first-order lag put into it afterwards
  (as a probe that measured the lag perfectly would), and with the lag stated to the harmonic
  law (``lag=4e-3``) instead;
* ``--study record``: what ``piezohyst excite --kind multifreq`` plays (loops at 1, 10 and 40 Hz),
  fitted with ``--input-dynamics record`` (the lag kept where the fit determines it), with the
  lag kept whatever its interval (``auto``), and with the record's lag estimate stated to the
  harmonic law with its 95 % interval as the tolerance;
* ``--study auto``: the same record, the model chosen by ``piezohyst fit --model auto
  --input-dynamics auto`` (every candidate identified with its lag), learned with the default law.

Run: ``python benchmarks/timing_handed.py --study injected [--plants bench,duhem]``.
Uses the tests' learning rig (tests/control/learning_rigs.py). Not a test: nothing here
asserts a time.
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TypeVar

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.control.learning_rigs import Rig, make_rig, scan

import piezohyst as ph
from piezohyst.model.dynamics import InputDynamics
from piezohyst.simulation import PLANTS, PRESETS
from piezohyst.workflows import fit_file, select_file
from piezohyst.workflows.excitation import excitation

warnings.simplefilter("ignore")
TAU = 4e-3
T = TypeVar("T")
TRIALS = 11  # the lead-in, then 10 learned


def width(rig: Rig, model: ph.HysteresisModel, f: float, **kw: object) -> str:
    _, scores = scan(rig, model, f, TRIALS, strict=False, **kw)  # type: ignore[arg-type]
    return f"{100 * scores[-1][0]:.2f}"


def injected(rig: Rig) -> str:
    lagged = copy.deepcopy(rig.model)
    lagged.input_dynamics_ = InputDynamics("first-order", tau=TAU, sample_interval=1e-3)  # type: ignore[attr-defined]
    return "; ".join(
        f"{f:.0f} Hz: none {width(rig, rig.model, f, law='auto')}, injected "
        f"{width(rig, lagged, f, law='auto')}, stated "
        f"{width(rig, rig.model, f, law='harmonic', lag=TAU)} %"
        for f in (10.0, 40.0)
    )


def fitted_on_excite(rig: Rig, fit: Callable[[Path], T]) -> T:
    """``fit`` of the file a lab records when it plays ``piezohyst excite --kind multifreq``
    (loops at 1, 10 and 40 Hz) on the rig's plant."""
    played = excitation("multifreq", v_min=0.0, v_max=140.0, sample_rate=1000.0)
    ident = ph.simulate(played.voltage, played.t, preset=rig.preset, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "excite.csv"
        ph.write_table(path, {"time": ident.t, "voltage": ident.voltage, "charge": ident.charge})
        return fit(path)


def record(rig: Rig) -> str:
    kept, auto, none = fitted_on_excite(
        rig, lambda p: [fit_file(p, input_dynamics=how) for how in ("record", "auto", "none")]
    )
    dyn = auto.input_dynamics_
    cov = np.array(dyn.covariance).reshape(2, 2) if dyn.covariance else np.zeros((2, 2))
    lag = dyn.tau + dyn.delay
    half = 1.96 * math.sqrt(max(float(cov.sum()), 0.0))
    tolerance = min(half / lag, 0.95) if lag > 0 else 0.0
    rows = [f"lag {1e3 * lag:.2f} +- {1e3 * half:.2f} ms, record keeps "
            f"{kept.input_dynamics_.kind}"]  # fmt: skip
    for f in (10.0, 40.0):
        rows.append(
            f"{f:.0f} Hz: record {width(rig, kept, f, law='auto')}, kept anyway "
            f"{width(rig, auto, f, law='auto')}, stated {_stated(rig, none, f, lag, tolerance)} %"
        )
    return "; ".join(rows)


def auto(rig: Rig) -> str:
    model = fitted_on_excite(rig, lambda p: select_file(p, input_dynamics="auto").model)
    dyn = model.input_dynamics_
    return f"chose {type(model).__name__}, {dyn.kind} (lag {1e3 * dyn.tau:.2f} ms, delay " + (
        f"{1e3 * dyn.delay:.2f} ms); "
        + "; ".join(f"{f:.0f} Hz {width(rig, model, f, law='auto')} %" for f in (10.0, 40.0))
    )


def _stated(rig: Rig, model: ph.HysteresisModel, f: float, lag: float, tol: float) -> str:
    """The harmonic law with the record's lag stated and its interval as the tolerance."""
    import tests.control.learning_rigs as rigs

    original = rigs.ph.LearningCompensator
    rigs.ph.LearningCompensator = lambda *a, **k: original(*a, lag_tolerance=tol, **k)  # type: ignore[misc]
    try:
        return width(rig, model, f, law="harmonic", lag=lag)
    finally:
        rigs.ph.LearningCompensator = original  # type: ignore[misc]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", choices=("injected", "record", "auto"), default="injected")
    parser.add_argument(
        "--plants", default="bench," + ",".join(p for p in PLANTS if p != "preisach")
    )
    args = parser.parse_args()
    for name in args.plants.split(","):
        base = PRESETS["T226-H4-203X-amp4ms"] if name == "bench" else PLANTS[name]
        t0 = time.perf_counter()
        rig = make_rig(replace(base, amp_tau=TAU, name=f"{name}-0"), lambda: ph.ActivePI(10))
        said = {"injected": injected, "record": record, "auto": auto}[args.study](rig)
        print(f"{name} ({time.perf_counter() - t0:.0f} s): {said}", flush=True)


if __name__ == "__main__":
    main()
