"""The default path learns at 40 Hz (issue 55, item 4): what a lab gets without reading the
docs. It records what ``piezohyst excite`` plays on a plant behind a 4 ms amplifier, fits the
default model (``ActivePI(10)``) with the default ``--input-dynamics record`` (identified
where the record drives several rates: ``piezohyst.workflows.dynamics_by_record``), and
learns a 40 Hz (and a 10 Hz) scan from the charge for 10 one-second trials with the default
law; loop width of the true displacement after the last trial, per plant and seed, beside
the same model fitted without input dynamics (the old default).

Run: ``python benchmarks/default_path.py [--seeds 0,1,2] [--plants preisach,duhem,...]``.
Uses the tests' learning rig (tests/control/learning_rigs.py).

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import piezohyst as ph  # noqa: E402
from piezohyst.simulation import PLANTS, PRESETS  # noqa: E402
from piezohyst.workflows import dynamics_by_record  # noqa: E402
from tests.control.learning_rigs import make_rig, scan  # noqa: E402

warnings.simplefilter("ignore")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--plants", default="bench," + ",".join(p for p in PLANTS if p != "preisach"))
    args = parser.parse_args()
    for name in args.plants.split(","):
        base = PRESETS["T226-H4-203X-amp4ms"] if name == "bench" else PLANTS[name]
        plant = replace(base, amp_tau=4e-3)
        for seed in (int(s) for s in args.seeds.split(",")):
            t0 = time.perf_counter()
            rig = make_rig(replace(plant, name=f"{name}-{seed}"), lambda: ph.ActivePI(10))
            ident = rig.ident  # what `piezohyst excite` played, measured
            kind, note = dynamics_by_record(ident.voltage, ident.t)
            rows = []
            for label, dyn in (("default", kind), ("none", "none")):
                model = ph.ActivePI(10, input_dynamics=dyn).fit(ident.voltage, ident.charge,
                                                                  t=ident.t)  # fmt: skip
                for f in (10.0, 40.0):
                    _, scores = scan(rig, model, f, 11, law="auto", strict=False)
                    rows.append(f"{label} {f:.0f} Hz {100 * scores[-1][0]:.2f} %")
            print(f"{name} seed {seed} ({kind}; {time.perf_counter() - t0:.0f} s): "
                  + "; ".join(rows), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
