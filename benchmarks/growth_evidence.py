"""The domain's growth terms by evidence (``growth_terms="domain"``, issue 55 item 2): kept
unless the record's own later part says they forecast far worse (``RAMP_MARGIN``).

Run: ``python benchmarks/growth_evidence.py [charge|displacement|measured DATA_DIR]``.

* ``charge``: on the validation matrix's charge records (the ``excite`` design and 40 s of
  ``decaying``, every plant, batch units 4-6, as ``growth_choice.py``), how often the rule
  drops the leak's integral, with the proxy's held-out scores (none / with): a charge record
  leaks, so a drop there is a regression to look at.
* ``displacement``: each plant's *displacement* written without units (what a lab's file
  without a header gives: the models take it for a charge), unipolar 0-140 V, three records
  (``excite``, ``decaying``, a fixed 10 Hz sine), units 4-5; each packed preset fitted on the
  first 60 % with the integral forced (the old default) and by evidence (the new), scored on
  the last 40 % (NRMSE %).
* ``measured DATA_DIR``: the SmartHysteresis actuator (bipolar, 1 Hz) and the
  micromanipulator's identification run (unipolar, amplitude-decaying 1 Hz loops) as files
  without units: every default on the first 60 %, scored on the last 40 %, and each default
  over the best.

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

import piezohyst as ph
from piezohyst.io.blocks import array_blocks
from piezohyst.model.cores.play import subset_label
from piezohyst.model.fit_record import growth_by_evidence
from piezohyst.simulation import PLANTS, batch_unit, make_signal
from piezohyst.workflows.excitation import excitation

warnings.simplefilter("ignore")
PACKED = {"Preisach": ph.PreisachModel, "Bouc-Wen": ph.BoucWenModel, "Duhem": ph.DuhemModel}


def _decision(x: np.ndarray, y: np.ndarray, t: np.ndarray) -> tuple[bool, float, float]:
    """(kept, proxy score without, with) of the rule on one record."""
    model = ph.PreisachModel()
    sm_range = np.array([x.min(), x.max()])
    terms, _ = model.terms_to_fit(sm_range, model.check_params())
    kept, selection = growth_by_evidence(array_blocks(x, y, t), terms, "rest")
    assert selection is not None
    scores = selection[0]
    base = tuple(j for j, tm in enumerate(terms) if not tm.removed)
    without = scores[subset_label(terms, base)]
    with_growth = scores[subset_label(terms, tuple(range(len(terms))))]
    return any(tm.removed for tm in kept), without, with_growth


def charge() -> None:
    played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
    designs = {
        "excite": lambda p, u: ph.simulate(played.voltage, played.t, preset=p, seed=u),
        "decaying": lambda p, u: ph.simulate(preset=p, signal="decaying", duration=40.0, seed=u),
    }
    dropped = total = 0
    for design, make in designs.items():
        for plant in PLANTS:
            cells = []
            for u in (4, 5, 6):
                rec = make(batch_unit(PLANTS[plant], u), u)
                kept, without, with_growth = _decision(rec.voltage, rec.charge, rec.t)
                dropped += not kept
                total += 1
                cells.append(f"unit {u}: {'kept' if kept else 'DROPPED'} "
                             f"({without:.3g} / {with_growth:.3g} C)")  # fmt: skip
            print(f"{design:9s} {plant:19s} " + "; ".join(cells), flush=True)
    print(f"the integral dropped on {dropped} of {total} charge records")


def _held_out(cls: type, growth: object, x: np.ndarray, y: np.ndarray, t: np.ndarray) -> float:
    cut = int(0.6 * x.size)
    m = cls(growth_terms=growth).fit(x[:cut], y[:cut], t=t[:cut])
    p = m.predict(x, t=t)
    return 100 * float(np.sqrt(np.mean((p[cut:] - y[cut:]) ** 2)) / np.ptp(y[cut:]))


def displacement() -> None:
    played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
    t10, v10 = make_signal("fixed", amplitude=140.0, frequency=10.0, duration=20.0)
    designs = {
        "excite": lambda p, u: ph.simulate(played.voltage, played.t, preset=p, seed=u),
        "decaying": lambda p, u: ph.simulate(preset=p, signal="decaying", duration=40.0, seed=u),
        "10 Hz": lambda p, u: ph.simulate(v10, t10, preset=p, seed=u),
    }
    worst = {name: 0.0 for name in PACKED}
    for design, make in designs.items():
        for plant in PLANTS:
            row = []
            for name, cls in PACKED.items():
                pairs = []
                for u in (4, 5):
                    rec = make(batch_unit(PLANTS[plant], u), u)
                    y = rec.displacement * 1e6  # um, the file says nothing
                    old = _held_out(cls, ("integral",), rec.voltage, y, rec.t)
                    new = _held_out(cls, "domain", rec.voltage, y, rec.t)
                    pairs.append((old, new))
                    worst[name] = max(worst[name], new / old)
                row.append(f"{name} {np.mean([a for a, _ in pairs]):.2f} / "
                           f"{np.mean([b for _, b in pairs]):.2f}")  # fmt: skip
            print(f"{design:9s} {plant:19s} " + " | ".join(row), flush=True)
    print("largest new/old per model:", {k: round(v, 3) for k, v in worst.items()})


def measured(folder: Path) -> None:
    d = np.genfromtxt(folder / "piezo_actuator_smarthysteresis" / "hysteresis_v_150_1hz.csv",
                      delimiter=",")[:, 1:]  # fmt: skip
    keep = d[:, 0] >= 3.3  # the drive starts at 3.26 s
    m = np.loadtxt(folder / "piezo_micromanipulator_dbo" / "Model_Vi_Do.dat")
    records = {
        "SmartHysteresis (bipolar, 1 Hz)": (d[keep, 2], d[keep, 1], d[keep, 0]),
        "micromanipulator (unipolar, decaying)": (m[:, 0], m[:, 4], np.arange(len(m)) / 200.0),
    }
    defaults = {**PACKED, "ActivePI": lambda **_: ph.ActivePI(10),
                "ClassicalPI": lambda **_: ph.ClassicalPI(10),
                "GeneralizedPI": lambda **_: ph.GeneralizedPI(10)}  # fmt: skip
    for label, (x, y, t) in records.items():
        scores = {}
        for name, cls in defaults.items():
            t0 = time.perf_counter()
            scores[name] = (
                _held_out(cls, "domain", x, y, t)
                if name in PACKED
                else _held_out(lambda growth_terms=None, c=cls: c(), None, x, y, t)
            )
            if name in PACKED:
                scores[name + " (integral)"] = _held_out(cls, ("integral",), x, y, t)
            print(f"  {label}: {name} {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        best = min(v for k, v in scores.items() if "(integral)" not in k)
        print(label)
        for name, value in scores.items():
            print(f"  {name:24s} {value:8.3f} %  ({value / best:.2f}x the best default)")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "charge"
    if what == "charge":
        charge()
    elif what == "displacement":
        displacement()
    else:
        measured(Path(sys.argv[2]))
