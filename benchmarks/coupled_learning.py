"""Learning a repeated scan on coupled stages, of the development physics and of others.

``ph.CoupledLearningCompensator`` (issue 57) puts one learner per actuator behind the
identified coupling's inverse. Scored here with nothing tuned (the learners' defaults; each
stage identified as ``benchmarks/coupled_dynamics_other_physics.py`` does it: ``ClassicalPI(16)``
with ``input_dynamics="first-order"`` and ``output_dynamics="second-order"`` per actuator, on
12 s of three-rate signals per axis) on the development stage (``simulation.XY_DYNAMIC``)
and the three stages of that script: Bouc-Wen and Duhem actuators behind lags with modes of
their own; the bench's actuators with modes after the coupling (the positions ring); the
same with an 8 % / -6 % coupling.

Per stage, twelve trials (the first is the learners' lead-in from rest, the second the
feedforward's own scan) of a 10 Hz raster line on x with y held (1 s a trial) and of a
10 : 7.5 Hz Lissajous (0.8 s): the fast axis's NRMSE and loop width and the held axis's
motion (the raster), each axis's NRMSE (the Lissajous), of the true positions, in % of what
each actuator alone reaches. The stage runs every trial from rest again with all the
commands sent so far (the simulator is a batch one), so its state carries across trials.

Run: ``python benchmarks/coupled_learning.py``.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from coupled_dynamics_other_physics import FS, KW, STAGES, run, three_rates

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import PRESETS, XY_COUPLING, XY_DYNAMIC

TRIALS = 12
ALL = {"development stage (XY_DYNAMIC)": ((PRESETS[XY_DYNAMIC[0]], PRESETS[XY_DYNAMIC[1]]),
                                          XY_COUPLING, None), **STAGES}  # fmt: skip


def scans(reach: np.ndarray) -> dict[str, np.ndarray]:
    (x0, x1), (y0, y1) = reach
    k = np.arange(1000)
    tri = np.abs((k / FS * 10.0) % 1.0 * 2 - 1)
    raster = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri), np.full(k.size, 0.5 * (y0 + y1))])
    phase = 2 * np.pi * np.arange(800) / FS
    liss = np.column_stack([x0 + (x1 - x0) * (0.5 + 0.3 * np.sin(10 * phase)),
                            y0 + (y1 - y0) * (0.5 + 0.3 * np.sin(7.5 * phase + 0.5))])  # fmt: skip
    return {"raster": raster, "lissajous": liss}


def learn(model: ph.CoupledModel, stage: tuple, scan: np.ndarray) -> list[np.ndarray]:  # type: ignore[type-arg]
    """Each trial's true positions over the scan."""
    limits = {"v_min": [c.input_range_[0] for c in model.channels_],
              "v_max": [c.input_range_[1] for c in model.channels_]}  # fmt: skip
    ilc = ph.CoupledLearningCompensator(model, **limits, sample_rate=FS, slew_rate=None)
    sent = [np.zeros((1, 2))]  # at rest at 0 V (the simulator's first sample is its rest)
    out = []
    for _ in range(TRIALS):
        sent.append(ilc.command(scan))
        true, read = run(np.vstack(sent), stage, seed=5)
        ilc.learn(read[-scan.shape[0] :])
        out.append(true[-scan.shape[0] :])
    return out


def main() -> None:
    warnings.simplefilter("ignore")
    t, ident = three_rates()
    print("| stage | trial | raster NRMSE | width | held | Lissajous NRMSE x / y |")
    print("|---|---|---|---|---|---|")
    for name, stage in ALL.items():
        _, measured = run(ident, stage, seed=0)
        model = ph.CoupledModel([ph.ClassicalPI(16, **KW), ph.ClassicalPI(16, **KW)])
        model.fit(ident, measured, t=t)
        reach = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS).reach
        span = reach[:, 1] - reach[:, 0]
        start = time.perf_counter()
        got = {case: learn(model, stage, scan) for case, scan in scans(reach).items()}
        took = time.perf_counter() - start
        for trial in (1, 4, 8, TRIALS - 1):
            figs = []
            for case, scan in scans(reach).items():
                moved = got[case][trial]
                err = np.sqrt(np.mean((moved - scan) ** 2, axis=0)) / span
                if case == "raster":
                    width = hysteresis_width(scan[:, 0], moved[:, 0])
                    figs += [f"{100 * err[0]:.2f} %", f"{100 * width:.2f} %",
                             f"{100 * np.ptp(moved[:, 1]) / span[1]:.2f} %"]  # fmt: skip
                else:
                    figs.append(f"{100 * err[0]:.2f} / {100 * err[1]:.2f} %")
            label = "1 (feedforward)" if trial == 1 else str(trial)
            print(f"| {name} | {label} | " + " | ".join(figs) + " |", flush=True)
        print(f"<!-- {name}: {2 * TRIALS} trials in {took:.0f} s -->", flush=True)


if __name__ == "__main__":
    main()
