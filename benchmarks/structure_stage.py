"""The structure's inverse on a hysteretic XY stage: where a linear structure is not the model.

``simulation.XY_DYNAMIC`` (the bench's actuators, each through its own mode) identified as
one structure (``StructureModel``, with and without the loop's operators) from 12 s of slow
full-range sines with a multisine (every line to 300 Hz, 8 V RMS) on top, then compensated
(``StructureCompensator``) on a 10 Hz raster (x over 30-70 % of the record's range, y held
at mid-range) from rest at 0 V. Prints each model's tracking NRMSE, loop width and the held
axis's motion (in % of the raster's and the range's spans), and how far the model itself is
from the stage on the commands sent (the inverse is as good as the model it inverts).

Run: ``python benchmarks/structure_stage.py``.
"""

from __future__ import annotations

import warnings

import numpy as np

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import XY_DYNAMIC, simulate_stage

FS = 1000.0


def main() -> None:
    warnings.simplefilter("ignore")  # the limits' counts are printed
    rng = np.random.default_rng(0)
    n = 12000
    spec = np.zeros((n // 2 + 1, 2), complex)
    spec[1:3600] = np.exp(2j * np.pi * rng.random((3599, 2)))
    ms = np.fft.irfft(spec, n=n, axis=0)
    k = np.arange(n)
    slow = np.column_stack([70 + 55 * np.sin(2 * np.pi * 0.5 * k / FS),
                            70 + 55 * np.sin(2 * np.pi * 0.37 * k / FS + 1)])  # fmt: skip
    u = np.clip(slow + 8 * ms / ms.std(axis=0), 0, 140)
    rec = simulate_stage(u, k / FS, presets=XY_DYNAMIC)
    lo, hi = rec.position.min(axis=0), rec.position.max(axis=0)
    span = hi - lo
    kk = np.arange(3000)
    tri = np.abs((kk / FS * 10.0) % 1.0 * 2 - 1)
    target = np.column_stack([lo[0] + span[0] * (0.3 + 0.4 * tri),
                              np.full(kk.size, lo[1] + 0.5 * span[1])])  # fmt: skip
    keep = slice(2000, None)
    print("| model | raster NRMSE | width | held | the model off the stage | at a limit |")
    print("|---|---|---|---|---|---|")
    for ops in (0, 6):
        model = ph.StructureModel(operators=ops).fit(u, rec.position, sample_rate=FS)
        comp = ph.StructureCompensator(model, v_min=0.0, v_max=140.0)
        ramp = np.linspace(0.0, 1.0, 500)[:, None]
        wanted = np.vstack([comp.output + ramp * (target[0] - comp.output), target])
        cmd = comp.process(wanted)
        pos = simulate_stage(cmd, np.arange(len(cmd)) / FS, presets=XY_DYNAMIC,
                             seed=5).true_position  # fmt: skip
        err = np.sqrt(np.mean((pos[keep, 0] - wanted[keep, 0]) ** 2)) / (0.4 * span[0])
        width = hysteresis_width(wanted[keep, 0], pos[keep, 0])
        held = np.ptp(pos[keep, 1]) / span[1]
        off = np.mean(model.predict(cmd)[keep, 0] - pos[keep, 0])
        print(f"| order {model.order_}, {model.operators_} operators per actuator | "
              f"{100 * err:.1f} % | {100 * width:.2f} % | {100 * held:.2f} % | "
              f"{1e6 * off:.0f} um | {comp.saturated_count.tolist()} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
