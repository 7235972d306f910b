"""A fast stage on its actuators' charges alone: the modes between the charges and the stage.

A charge does not ring; the stage does. So each actuator's mode goes into its output map
(``ph.calibrate_stage`` with ``output_dynamics="auto"``, each map's mode by evidence), and the
stage's self-sensing loop inverts it from the desired trajectory before each actuator's
charge loop. Developed on ``simulation.XY_DYNAMIC`` (the bench's actuators behind 4 and 3 ms
with modes at 150 and 120 Hz, before the coupling); scored, with nothing tuned, on the stages
with lags and modes of ``coupled_dynamics_other_physics.py`` (never run through the charge
loops before): Bouc-Wen and Duhem actuators with their own lags and modes, and the bench's
actuators whose structure rings *after* the coupling (a shared structure's modes, which each
actuator's own mode only approximates), at two couplings.

Per stage: each actuator's model on its own voltage -> charge, the paper's
``ActivePI(10)`` with its amplifier's lag, or the one ``ph.select_model`` chooses among the
loop's candidates (``LOOP_CANDIDATES``) with ``input_dynamics="auto"``; the stage map with
each actuator's mode, and without (``output_dynamics="none"``); the loop's default gains.
Identified on 12 s of three-rate signals per axis; from rest a 10 Hz raster line on x with y
held and a 10 : 7.5 Hz Lissajous, scored over their last 1.5 s (true positions, % of what
each actuator alone moves), as ``coupled_selfsensing.py`` scores.

Run: ``python benchmarks/coupled_selfsensing_modes.py [--relay-grid N]`` (``--relay-grid N``:
every stage's Preisach actuators with N relay fields instead of 120, the same density in
finer steps; docs/bench.md says why).
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np
from coupled_dynamics_other_physics import STAGES as OTHER
from coupled_dynamics_other_physics import three_rates, with_grid
from coupled_selfsensing import scans, score

import piezohyst as ph
from piezohyst.analysis.selection import LOOP_CANDIDATES
from piezohyst.simulation import (
    PRESETS,
    XY_COUPLING,
    XY_DYNAMIC,
    Stage,
    run_stage_loop,
    simulate_stage,
)

FS = 1000.0
STAGES: dict[str, tuple[Any, ...]] = {
    "development (XY_DYNAMIC: modes per actuator)": (
        tuple(PRESETS[n] for n in XY_DYNAMIC), XY_COUPLING, None),
    **OTHER,
}  # fmt: skip


def ring(positions: np.ndarray, after: Any) -> np.ndarray:
    """The positions through a structure's modes after the coupling (none: as they are)."""
    if after is None:
        return positions
    return np.column_stack([m.apply(positions[:, i])[0] for i, m in enumerate(after)])


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("--relay-grid", type=int, default=0,
                    help="the bench's actuators with this many relay fields (default: as "
                         "they are, 120)")  # fmt: skip
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    stages = with_grid(OTHER, args.relay_grid) if args.relay_grid else STAGES
    t, ident = three_rates()
    print("| stage | models | map | raster NRMSE | width | held | Lissajous NRMSE x / y |")
    print("|---|---|---|---|---|---|---|")
    for name, (presets, coupling, after) in stages.items():
        rec = simulate_stage(ident, t, presets=presets, coupling=coupling, seed=0)
        u, q, y = rec.voltage, rec.charge, ring(rec.position, after)
        start = time.perf_counter()
        sets = {
            "ActivePI + lag": [ph.ActivePI(10, input_dynamics="first-order").fit(
                u[:, i], q[:, i], t=rec.t) for i in range(2)],
            "chosen (loop's)": [ph.select_model(u[:, i], q[:, i], rec.t, input_dynamics="auto",
                                                candidates=LOOP_CANDIDATES).model
                                for i in range(2)],
        }  # fmt: skip
        took = time.perf_counter() - start
        ref = None
        notes = []
        for label, models in sets.items():
            for mode in ("auto", "none"):
                stage = ph.calibrate_stage(models, u, q, y, rec.t, output_dynamics=mode)
                ctl = ph.CoupledSelfSensingController(
                    models, stage, sample_rate=FS, slew_rate=None,
                    v_min=[m.input_range_[0] for m in models],
                    v_max=[m.input_range_[1] for m in models],
                )  # fmt: skip
                ref = ref or ctl  # every row scored on the first's scans and reach
                span = ref.reach[:, 1] - ref.reach[:, 0]
                figs = []
                for case, d in scans(ref).items():
                    if case == "decaying":
                        continue
                    ctl.reset()
                    out = run_stage_loop(ctl, d, Stage(presets, coupling=coupling, seed=5))
                    moved = ring(out.true_position, after)
                    out = ph.simulation.StageRecord(out.t, out.voltage, out.charge, out.position,
                                                    moved, out.coupling)  # fmt: skip
                    figs += score(case, d, out, span)
                said = "with each actuator's mode" if mode == "auto" else "without modes"
                print(f"| {name} | {label} | {said} | " + " | ".join(figs) + " |", flush=True)
                if mode == "auto":
                    modes = ", ".join(
                        f"{om.mode_f0:.1f} Hz / {om.mode_zeta:.3f}" if om.mode.active else "none"
                        for om in stage.maps
                    )
                    kinds = ", ".join(type(m).__name__ for m in models)
                    notes.append(f"{label} ({kinds}): modes {modes}")
        print(f"<!-- {name}: models in {took:.1f} s; " + "; ".join(notes) + " -->", flush=True)


if __name__ == "__main__":
    main()
