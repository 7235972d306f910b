"""Coupled stages of other physics than the bench, scored after the coupled model was built.

The coupled model and compensator (issue 57) were developed on the simulated XY stage of two
of the bench's Preisach actuators with the default coupling. Here the same procedure, with
nothing tuned: actuators of other physics (``simulation.PLANTS``: Bouc-Wen, Duhem, two-state,
Bouc-Wen with creep and an amplifier lag) and another coupling. Per stage: identify on one
record (x decaying loops, y a 1.3 Hz triangle), then compensate a 2 Hz raster on x with y
held, and a 1.5 x 2 Hz Lissajous; print the fast axis's tracking NRMSE and loop width, the
held axis's motion, beside a linear voltage map fitted on the same record.

Run: ``python benchmarks/coupled_other_physics.py``.
"""

from __future__ import annotations

import warnings

import numpy as np

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import make_signal, simulate_stage

FS = 1000.0
STAGES = {
    "bouc-wen + duhem, default coupling": (("bouc-wen", "duhem"), None),
    "two-state + bouc-wen-creep-lag": (("two-state", "bouc-wen-creep-lag"), None),
    "bench x2, stronger coupling (6 %, -5 %)": (None, np.array([[1.0, 0.06], [-0.05, 1.0]])),
}


def main() -> None:
    warnings.simplefilter("ignore")
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    ident_v = np.column_stack([np.clip(2 * a, 0.0, 140.0), b])
    k = np.arange(4000)
    tt = k / FS
    s = slice(1000, None)
    print(f"{'stage':42s} {'case':10s} {'fast NRMSE':>11s} {'width':>7s} {'held':>7s}"
          f" {'lin NRMSE':>10s} {'lin width':>9s} {'lin held':>8s}")  # fmt: skip
    for name, (plants, coupling) in STAGES.items():
        kw = {} if coupling is None else {"coupling": coupling}
        rec = simulate_stage(ident_v, t, presets=plants, seed=0, **kw)
        model = ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)
        lin = np.linalg.lstsq(np.column_stack([rec.voltage, np.ones(t.size)]), rec.position,
                              rcond=None)[0]  # fmt: skip
        comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS,
                                     slew_rate=None)  # fmt: skip
        (x0, x1), (y0, y1) = comp.reach
        raster = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * np.abs((tt * 2.0) % 1.0 * 2 - 1)),
                                  np.full(k.size, 0.5 * (y0 + y1))])  # fmt: skip
        fast, slow = np.sin(2 * np.pi * 1.5 * tt), np.sin(2 * np.pi * 2 * tt + 0.3)
        liss = np.column_stack([x0 + (x1 - x0) * (0.5 + 0.3 * fast),
                                y0 + (y1 - y0) * (0.5 + 0.3 * slow)])  # fmt: skip
        for case, desired in (("raster", raster), ("lissajous", liss)):
            comp.reset()
            v = comp.process(desired)
            v_lin = np.clip((desired - lin[2]) @ np.linalg.inv(lin[:2]), 0.0, 140.0)
            figs = []
            for volts in (v, v_lin):
                p = simulate_stage(volts, tt, presets=plants, seed=5, **kw).true_position
                e = p[s, 0] - desired[s, 0]
                nrmse = float(np.sqrt(np.mean((e - e.mean()) ** 2))) / float(np.ptp(desired[s, 0]))
                width = hysteresis_width(desired[s, 0], p[s, 0])
                if case == "raster":
                    held = float(np.ptp(p[s, 1])) / (y1 - y0)
                else:
                    e1 = p[s, 1] - desired[s, 1]
                    held = float(np.sqrt(np.mean((e1 - e1.mean()) ** 2))) / float(
                        np.ptp(desired[s, 1])
                    )
                figs += [nrmse, width, held]
            print(f"{name:42s} {case:10s} " + " ".join(f"{100 * x:8.2f} %" for x in figs))
    print("held: the raster's y motion over its range; the Lissajous' y NRMSE")


if __name__ == "__main__":
    main()
