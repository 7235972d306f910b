"""Held-out error of a preset identified on a short record: each plant of the validation
matrix, units 4-6 of its batch, trained on what ``piezohyst excite`` writes, on 40 s or on
12 s of the ``decaying`` signal, tested on 12 s of ``multi`` from rest (as
``docs/validation.md``'s matrix, which uses units 1-3 and no 12 s record).

Run: ``python benchmarks/short_records.py [CLASS] [UNITS]`` (default ``DuhemModel`` and
``4,5,6``). Prints the mean held-out NRMSE (%) and its range over the units per record.
``CLASS`` ``select``: what ``select_model`` chooses on each 12 s record instead, and its
held-out NRMSE.

Not a test: nothing here asserts a time.
"""

import sys
import warnings

import numpy as np

import piezohyst as ph
from piezohyst.simulation import PLANTS, batch_unit
from piezohyst.workflows.excitation import excitation

warnings.simplefilter("ignore")  # the test drives past the training region: noted, not shown
units = [int(u) for u in (sys.argv[2] if len(sys.argv) > 2 else "4,5,6").split(",")]
if len(sys.argv) > 1 and sys.argv[1] == "select":
    for plant in PLANTS:
        for u in units:
            p = batch_unit(PLANTS[plant], u)
            train = ph.simulate(preset=p, signal="decaying", duration=12.0, seed=u)
            test = ph.simulate(preset=p, signal="multi", duration=12.0, seed=u + 100)
            chosen = ph.select_model(train.voltage, train.charge, t=train.t)
            predicted = chosen.model.predict(test.voltage, t=test.t)
            error = 100 * ph.metrics.nrmse(test.charge, predicted)
            print(f"| {plant} | unit {u} | {chosen.name} | {error:.2f} |", flush=True)
    sys.exit()
cls = getattr(ph, sys.argv[1]) if len(sys.argv) > 1 else ph.DuhemModel
played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
designs = {
    "excite": lambda p, u: ph.simulate(played.voltage, played.t, preset=p, seed=u),
    "decaying 40 s": lambda p, u: ph.simulate(preset=p, signal="decaying", duration=40.0, seed=u),
    "decaying 12 s": lambda p, u: ph.simulate(preset=p, signal="decaying", duration=12.0, seed=u),
}
print(f"{cls.__name__}, units {units}: held-out NRMSE on 12 s of multi, mean [range] %")
for design, record in designs.items():
    for plant in PLANTS:
        errors = []
        for u in units:
            p = batch_unit(PLANTS[plant], u)
            train = record(p, u)
            test = ph.simulate(preset=p, signal="multi", duration=12.0, seed=u + 100)
            model = cls().fit(train.voltage, train.charge, t=train.t)
            predicted = model.predict(test.voltage, t=test.t)
            errors.append(100 * ph.metrics.nrmse(test.charge, predicted))
        spread = f"{min(errors):.2f}-{max(errors):.2f}"
        print(f"| {design} | {plant} | {np.mean(errors):.2f} [{spread}] |", flush=True)
