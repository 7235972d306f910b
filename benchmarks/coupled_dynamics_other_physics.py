"""Coupled stages with dynamics, of other physics than the one the method was built on.

The stage's lags and modes (issue 57) were developed on ``simulation.XY_DYNAMIC``: two of
the bench's Preisach actuators behind their amplifiers, each moving through its own mode,
coupled kinematically (y's laser sees x's motion, mode and all). Scored here, with nothing
tuned (the same model, ``ClassicalPI(16)`` with ``input_dynamics="first-order"`` and
``output_dynamics="second-order"`` per actuator, the same records: 12 s of three-rate
signals per axis, 2.5 Hz and 1.9 Hz bases):

- actuators of other physics (Bouc-Wen, Duhem) behind lags of 3 and 5 ms with modes at
  180 and 110 Hz;
- a structure whose modes come *after* the coupling (the positions, not the actuators,
  ring: a mode the model's structure does not hold), on the bench's actuators;
- the same with a stronger coupling (8 %, -6 %).

Per stage: a 10 Hz raster on x with y held, and a 10 : 7.5 Hz Lissajous; the fast axis's
tracking NRMSE and loop width, the held axis's motion, beside the static model fitted on
the same record.

Run: ``python benchmarks/coupled_dynamics_other_physics.py [--centred] [--relay-grid N]``
(``--centred``: identified on a record that also holds loops decaying about the middle of
the range, with the development stage first; ``--relay-grid N``: the bench's actuators
with a Preisach plane of N relay fields instead of 120, the same density in finer steps,
with the development stage first; docs/bench.md says why).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import replace
from typing import Any

import numpy as np

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.model.dynamics import OutputDynamics
from piezohyst.simulation import (
    PLANTS,
    PRESETS,
    XY_COUPLING,
    XY_DYNAMIC,
    make_signal,
    simulate_stage,
)

FS = 1000.0
KW = {"output_unit": "m", "input_dynamics": "first-order", "output_dynamics": "second-order"}
BOUC = replace(PLANTS["bouc-wen"], amp_tau=3e-3, mech_f0=180.0, mech_zeta=0.03)
DUHEM = replace(PLANTS["duhem"], amp_tau=5e-3, mech_f0=110.0, mech_zeta=0.05)
LAGGED = PRESETS["T226-H4-203X-amp4ms"]  # the bench's actuator behind 4 ms, no mode of its own
AFTER = (OutputDynamics(160.0, 0.04, 1 / FS), OutputDynamics(130.0, 0.03, 1 / FS))
STAGES = {
    "Bouc-Wen + Duhem, lags and modes": ((BOUC, DUHEM), XY_COUPLING, None),
    "bench x2, modes after the coupling": ((LAGGED, LAGGED), XY_COUPLING, AFTER),
    "the same, coupling 8 % / -6 %": ((LAGGED, LAGGED), np.array([[1.0, 0.08], [-0.06, 1.0]]),
                                      AFTER),
}  # fmt: skip


#: The development stage (``simulation.XY_DYNAMIC``), put first by ``--centred`` and
#: ``--relay-grid``
DEVELOPMENT = {
    "development (XY_DYNAMIC)": (tuple(PRESETS[p] for p in XY_DYNAMIC), XY_COUPLING, None)
}


def with_grid(stages: dict[str, Any], n: int) -> dict[str, Any]:
    """The stages with every actuator's Preisach plane at ``n`` relay fields (the development
    stage first): the same plants but for the bench's discretisation."""
    return {
        f"{name}, relay grid {n}": (tuple(replace(p, relay_grid=n) for p in presets), c, after)
        for name, (presets, c, after) in {**DEVELOPMENT, **stages}.items()
    }


def three_rates() -> tuple[np.ndarray, np.ndarray]:
    """The identification record's times and commands: 12 s of three-rate signals per axis
    (2.5 and 1.9 Hz bases: the two inputs do not move together)."""
    t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
    _, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=12.0)
    return t, np.column_stack([a, b])


def with_centred_loops() -> tuple[np.ndarray, np.ndarray]:
    """Another record: 8 s of the three rates, then 8 s of loops decaying about the middle
    of each axis's range (2.5 and 1.9 Hz): the minor loops away from 0 V that a raster runs,
    which the three rates' loops (each from 0 V) do not hold."""
    _, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=8.0)
    _, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=8.0)
    _, c = make_signal("decaying", amplitude=140.0, frequency=2.5, duration=8.0)
    _, e = make_signal("decaying", amplitude=140.0, frequency=1.9, duration=8.0)
    u = np.vstack([np.column_stack([a, b]), np.column_stack([c, e])[1:]])
    return np.arange(u.shape[0]) / FS, u


def run(volts: np.ndarray, stage: tuple, seed: int) -> np.ndarray:  # type: ignore[type-arg]
    """The stage's true positions (and its lasers' readings) for the commands."""
    presets, coupling, after = stage
    t = np.arange(volts.shape[0]) / FS
    rec = simulate_stage(volts, t, presets=presets, coupling=coupling, seed=seed)
    if after is None:
        return rec.true_position, rec.position
    ring = [np.column_stack([m.apply(p[:, i])[0] for i, m in enumerate(after)])
            for p in (rec.true_position, rec.position)]  # fmt: skip
    return ring[0], ring[1]


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("--centred", action="store_true",
                    help="identify on the record with centred loops too (and the development "
                         "stage first)")  # fmt: skip
    ap.add_argument("--relay-grid", type=int, default=0,
                    help="the bench's actuators with this many relay fields (default: as "
                         "they are, 120)")  # fmt: skip
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    t, ident = with_centred_loops() if args.centred else three_rates()
    stages = STAGES
    if args.centred:
        stages = {**DEVELOPMENT, **STAGES}
    if args.relay_grid:
        stages = with_grid(stages, args.relay_grid)
    k = np.arange(3000)
    tri = np.abs((k / FS * 10.0) % 1.0 * 2 - 1)
    phase = 2 * np.pi * k / FS
    keep = slice(1500, None)
    print("| stage | model | fit | raster NRMSE | width | held | Lissajous NRMSE x / y |")
    print("|---|---|---|---|---|---|---|")
    for name, stage in stages.items():
        _, measured = run(ident, stage, seed=0)
        models = [("lags and modes", ph.CoupledModel([ph.ClassicalPI(16, **KW),
                                                      ph.ClassicalPI(16, **KW)])),
                  ("static", ph.CoupledModel()),
                  ("Bouc-Wen per actuator, lags and modes",
                   ph.CoupledModel([ph.BoucWenModel(**KW), ph.BoucWenModel(**KW)]))]  # fmt: skip
        for label, model in models:
            start = time.perf_counter()
            model.fit(ident, measured, t=t)
            took = time.perf_counter() - start
            limits = {"v_min": [c.input_range_[0] for c in model.channels_],
                      "v_max": [c.input_range_[1] for c in model.channels_]}  # fmt: skip
            comp = ph.CoupledCompensator(model, **limits, sample_rate=FS, slew_rate=None)
            (x0, x1), (y0, y1) = comp.reach
            span = np.array([x1 - x0, y1 - y0])
            rest = model.predict(np.zeros((2, 2)), t=np.array([0.0, 1 / FS]))[0]
            ramp = np.linspace(0.0, 1.0, 500)[:, None]
            figs = []
            for case in ("raster", "lissajous"):
                if case == "raster":
                    target = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri),
                                              np.full(k.size, 0.5 * (y0 + y1))])  # fmt: skip
                else:
                    target = np.column_stack([x0 + (x1 - x0) * (0.5 + 0.3 * np.sin(10 * phase)),
                                              y0 + (y1 - y0) * (0.5 + 0.3 * np.sin(7.5 * phase + 0.5))])  # fmt: skip  # noqa: E501
                wanted = np.vstack([rest + ramp * (target[0] - rest), target])
                comp.reset()
                moved, _ = run(comp.process(wanted), stage, seed=5)
                err = np.sqrt(np.mean((moved[keep] - wanted[keep]) ** 2, axis=0)) / span
                if case == "raster":
                    width = hysteresis_width(wanted[keep, 0], moved[keep, 0])
                    figs += [f"{100 * err[0]:.2f} %", f"{100 * width:.2f} %",
                             f"{100 * np.ptp(moved[keep, 1]) / span[1]:.2f} %"]  # fmt: skip
                else:
                    figs.append(f"{100 * err[0]:.2f} / {100 * err[1]:.2f} %")
            print(f"| {name} | {label} | {took:.1f} s | " + " | ".join(figs) + " |", flush=True)


if __name__ == "__main__":
    main()
