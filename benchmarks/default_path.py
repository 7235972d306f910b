"""The default path learns at 40 Hz (issue 55, item 4): what a lab gets without reading the
docs. It records what ``piezohyst excite`` plays on a plant behind a 4 ms amplifier, fits the
default model (``ActivePI(10)``) as ``piezohyst fit`` does, with its default
``--input-dynamics record`` (identified where the record drives several rates and the fit can
tell them from hysteresis: ``piezohyst.workflows.dynamics_by_record``), and
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
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.control.learning_rigs import make_rig, scan

import piezohyst as ph
from piezohyst.simulation import PLANTS, PRESETS
from piezohyst.workflows import fit_file

warnings.simplefilter("ignore")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument(
        "--plants", default="bench," + ",".join(p for p in PLANTS if p != "preisach")
    )
    args = parser.parse_args()
    for name in args.plants.split(","):
        base = PRESETS["T226-H4-203X-amp4ms"] if name == "bench" else PLANTS[name]
        plant = replace(base, amp_tau=4e-3)
        for seed in (int(s) for s in args.seeds.split(",")):
            t0 = time.perf_counter()
            rig = make_rig(replace(plant, name=f"{name}-{seed}"), lambda: ph.ActivePI(10))
            ident = rig.ident  # what `piezohyst excite` played, measured
            with tempfile.TemporaryDirectory() as tmp:  # what `piezohyst fit` does with it
                path = Path(tmp) / "excite.csv"
                ph.write_table(path, {"time": ident.t, "voltage": ident.voltage,
                                      "charge": ident.charge})  # fmt: skip
                notes: list[str] = []
                models = {"default": fit_file(path, input_dynamics="record", say=notes.append),
                          "none": fit_file(path, input_dynamics="none")}  # fmt: skip
            kind = notes[0].split(" (")[0] if notes else "?"
            rows = []
            for label, model in models.items():
                for f in (10.0, 40.0):
                    _, scores = scan(rig, model, f, 11, law="auto", strict=False)
                    rows.append(f"{label} {f:.0f} Hz {100 * scores[-1][0]:.2f} %")
            print(f"{name} seed {seed} ({kind}; {time.perf_counter() - t0:.0f} s): "
                  + "; ".join(rows), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
