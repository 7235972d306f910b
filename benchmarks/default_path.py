"""The default path learns at 40 Hz (issue 55, item 4): what a lab gets without reading the
docs. It records what ``piezohyst excite`` plays on a plant behind a 4 ms amplifier, fits the
default model (``ActivePI(10)``) as ``piezohyst fit`` does, with its default
``--input-dynamics record`` (identified where the record drives several rates and the fit can
tell them from hysteresis: ``piezohyst.workflows.dynamics_by_record``), and
learns a 40 Hz (and a 10 Hz) scan from the charge for 10 one-second trials after the lead-in
with the learner's defaults; loop width of the true displacement after the last trial, per
plant and seed, beside the same learner with ``measure_lag=False`` (what it did before the
trial after the lead-in measured the loop's lag: ``control/learning/timing.py``).

Run: ``python benchmarks/default_path.py [--seeds 0,1,2] [--plants preisach,duhem,...]
[--amp-tau 0.004]``;
``--random 3000-3011`` instead runs plants drawn at random as ``benchmarks/selection_random.py``
draws them (the families of the simulator's zoo with their parameters, leakage and relaxation
jittered; its Jiles-Atherton capacitor is not a bench that runs trials, and is left out),
each behind the same amplifier (``--amp-tau``, s; 0: none). Uses the tests' learning rig
(tests/control/learning_rigs.py); ``--seeds`` draws the rig's noise.

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
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from tests.control.learning_rigs import make_rig, scan

import piezohyst as ph
from piezohyst.simulation import PLANTS, PRESETS
from piezohyst.workflows import fit_file

warnings.simplefilter("ignore")


def plants(args: argparse.Namespace) -> list[tuple[str, Any, list[int]]]:
    """(name, plant behind a 4 ms amplifier, rig seeds) to run."""
    seeds = [int(s) for s in args.seeds.split(",")]
    if not args.random:
        base = {**PLANTS, "bench": PRESETS["T226-H4-203X-amp4ms"]}
        amp = args.amp_tau
        return [(name, replace(base[name], amp_tau=amp), seeds) for name in args.plants.split(",")]
    from selection_random import _preset, draw

    first, last = (int(s) for s in args.random.split("-"))
    out = []
    for seed in range(first, last + 1):
        drawn = draw(seed)
        if drawn["family"] == "jiles-atherton":
            print(f"random {seed}: a Jiles-Atherton capacitor (no bench for trials): left out")
            continue
        out.append((f"random {seed} ({drawn['family']})",
                    replace(_preset(drawn), amp_tau=args.amp_tau), [0]))  # fmt: skip
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument(
        "--plants", default="bench," + ",".join(p for p in PLANTS if p != "preisach")
    )
    parser.add_argument("--random", default="", help="plants drawn at random: FIRST-LAST")
    parser.add_argument("--amp-tau", type=float, default=4e-3, help="the amplifier's lag (s)")
    args = parser.parse_args()
    for name, plant, seeds in plants(args):
        for seed in seeds:
            t0 = time.perf_counter()
            rig = make_rig(replace(plant, name=f"{name}-{seed}"), lambda: ph.ActivePI(10), seed)
            ident = rig.ident  # what `piezohyst excite` played, measured
            with tempfile.TemporaryDirectory() as tmp:  # what `piezohyst fit` does with it
                path = Path(tmp) / "excite.csv"
                ph.write_table(path, {"time": ident.t, "voltage": ident.voltage,
                                      "charge": ident.charge})  # fmt: skip
                notes: list[str] = []
                model = fit_file(path, input_dynamics="record", say=notes.append)
            kind = notes[0].split(" (")[0] if notes else "?"
            rows = []
            # the defaults, and the lag not measured: what the learner did before the trial
            # after the lead-in measured it (control/learning/timing.py)
            for label, measure in (("default", True), ("no lag measured", False)):
                for f in (10.0, 40.0):
                    ilc, scores = scan(rig, model, f, 11, law="auto", strict=False,
                                       measure_lag=measure)  # fmt: skip
                    lag = ilc.timing.lag if ilc.timing else 0.0
                    said = f" (lag {1e3 * lag:.2f} ms)" if lag else ""
                    rows.append(f"{label} {f:.0f} Hz {100 * scores[-1][0]:.2f} %{said}")
            print(f"{name} seed {seed} ({kind}; {time.perf_counter() - t0:.0f} s): "
                  + "; ".join(rows), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
