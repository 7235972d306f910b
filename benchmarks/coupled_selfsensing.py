"""A coupled stage on its actuators' charges alone: the stage's self-sensing loop.

``ph.CoupledSelfSensingController`` (issue 57) closes each actuator's loop on its own
Sawyer-Tower charge behind the coupling's inverse; the stage's lasers are used once, to
calibrate its positions from the charges (``ph.calibrate_stage``), and here to score. With
nothing tuned (the loop's default gains), two ways to get each actuator's model from its
own voltage -> charge: the paper's ``ActivePI(10)``, and the one ``ph.select_model`` chooses
for it with its input dynamics (``input_dynamics="auto"``), among every candidate and among
the loop's (``LOOP_CANDIDATES``, what a self-sensing loop is documented to take): each
actuator's charge is its own, so the choice needs no decoupling; and the single loop's
documented protocol, the loop's candidates with each actuator's leakage calibrated on its own
holds (``piezohyst excite --kind holds``). Beside them: the ActivePI models and map as
feedforward alone (``ki=0``), and a linear voltage map (least squares of the positions on
the voltages).

Stages: the development stage (two of the paper's bimorphs, the default XY coupling), and
stages of other physics and couplings; ``--held-back`` runs two more, defined before any
was scored and run once when the controller was done.

Per stage: identified on 12 s of three-rate signals per axis (as ``piezohyst excite``
plays; 2.5 and 1.9 Hz bases), then from rest a 10 Hz raster line on x with y held and a
10 : 7.5 Hz Lissajous (3 s each, scored over the last 1.5 s), and decaying loops on x with
y held (3 s, scored after 0.5 s: the minor loops a Prandtl-Ishlinskii model makes
congruent): the true positions, in % of what each actuator alone moves.

Run: ``python benchmarks/coupled_selfsensing.py [--held-back]``.
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

import numpy as np

import piezohyst as ph
from piezohyst.analysis.selection import LOOP_CANDIDATES
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import (
    DEFAULT_PRESET,
    PLANTS,
    PRESETS,
    XY_COUPLING,
    Stage,
    make_signal,
    run_stage_loop,
    simulate_stage,
)
from piezohyst.workflows.excitation import excitation

FS = 1000.0
BIMORPH = PRESETS[DEFAULT_PRESET]
STAGES = {
    "development stage (bimorphs, XY coupling)": ((BIMORPH, BIMORPH), XY_COUPLING),
    "Bouc-Wen x + Duhem y": ((PLANTS["bouc-wen"], PLANTS["duhem"]), XY_COUPLING),
    "two-state x + Bouc-Wen-creep y": ((PLANTS["two-state"], PLANTS["bouc-wen-creep-lag"]),
                                       XY_COUPLING),
    "bimorphs, coupling 8 % / -6 %": ((BIMORPH, BIMORPH), np.array([[1.0, 0.08], [-0.06, 1.0]])),
}  # fmt: skip
#: Defined before any stage was scored, run once when the controller was done
HELD_BACK = {
    "Duhem x + two-state y, coupling 6 % / -5 %": ((PLANTS["duhem"], PLANTS["two-state"]),
                                                  np.array([[1.0, -0.05], [0.06, 1.0]])),
    "Bouc-Wen-creep x (4 ms lag) + bimorph y": ((PLANTS["bouc-wen-creep-lag"], BIMORPH),
                                                XY_COUPLING),
}  # fmt: skip


class Linear:
    """A linear voltage map: positions = A v + b by least squares, inverted (feedforward)."""

    reads = False

    def __init__(self, v: np.ndarray, y: np.ndarray) -> None:
        coef, *_ = np.linalg.lstsq(np.column_stack([v, np.ones(v.shape[0])]), y, rcond=None)
        self.a, self.b = coef[:-1].T, coef[-1]

    def process(self, d: np.ndarray) -> np.ndarray:
        return np.clip((d - self.b) @ np.linalg.inv(self.a).T, 0.0, 140.0)  # type: ignore[no-any-return]


def scans(ctl: ph.CoupledSelfSensingController) -> dict[str, np.ndarray]:
    """Desired positions: a 10 Hz raster line (x 20-80 % of what it moves, y held mid), a
    10 : 7.5 Hz Lissajous, in the stage's frame."""
    (x0, x1), (y0, y1) = ctl.reach
    k = np.arange(3000)
    tri = np.abs((k / FS * 10.0) % 1.0 * 2 - 1)
    own = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri), np.full(k.size, 0.5 * (y0 + y1))])
    raster = own @ ctl.stage.coupling.T + ctl.stage.offset
    raster[:, 1] = raster[0, 1]
    ph_ = 2 * np.pi * k / FS
    own = np.column_stack([x0 + (x1 - x0) * (0.5 + 0.3 * np.sin(10 * ph_)),
                           y0 + (y1 - y0) * (0.5 + 0.3 * np.sin(7.5 * ph_ + 0.5))])  # fmt: skip
    liss = own @ ctl.stage.coupling.T + ctl.stage.offset
    _, shape = make_signal("decaying", amplitude=1.0, duration=3.0)
    own = np.column_stack(
        [x0 + (x1 - x0) * (0.05 + 0.9 * shape), np.full(shape.size, 0.5 * (y0 + y1))]
    )
    decaying = own @ ctl.stage.coupling.T + ctl.stage.offset
    decaying[:, 1] = decaying[0, 1]
    return {"raster": raster, "lissajous": liss, "decaying": decaying}


def score(case: str, d: np.ndarray, rec: ph.simulation.StageRecord, span: np.ndarray) -> list[str]:
    keep = slice(500 if case == "decaying" else 1500, None)
    p, dk = rec.true_position[keep], d[keep]
    err = np.sqrt(np.mean((p - dk) ** 2, axis=0)) / span
    w = f"{100 * hysteresis_width(dk[:, 0], p[:, 0]):.2f} %"
    held = f"{100 * np.ptp(p[:, 1]) / span[1]:.2f} %"
    if case == "raster":
        return [f"{100 * err[0]:.2f} %", w, held]
    if case == "decaying":
        return [f"{w} / {held}"]
    return [f"{100 * err[0]:.2f} / {100 * err[1]:.2f} %"]


def holds_leakage(presets: tuple[Any, ...], coupling: np.ndarray) -> list[ph.Leakage]:
    """Each actuator's leakage from its own holds (``piezohyst excite --kind holds``, 10 s
    each; the other actuator at rest: its charge is its own), as the single loop takes it."""
    played = excitation("holds", v_min=0.0, v_max=140.0, sample_rate=FS, hold=10.0)
    leaks = []
    for i in range(len(presets)):
        u = np.zeros((played.voltage.size, len(presets)))
        u[:, i] = played.voltage
        rec = simulate_stage(u, played.t, presets=presets, coupling=coupling, seed=2 + i)
        leaks.append(ph.calibrate_leakage(rec.t, rec.voltage[:, i], rec.charge[:, i]))
    return leaks


def run(
    controller: Any,
    presets: tuple[Any, ...],
    coupling: np.ndarray,
    ref: ph.CoupledSelfSensingController,
) -> list[str]:
    """The three scans through ``controller`` on the stage (scored in ``ref``'s frame)."""
    span = ref.reach[:, 1] - ref.reach[:, 0]
    figs = []
    for case, d in scans(ref).items():
        if hasattr(controller, "reset"):
            controller.reset()
        out = run_stage_loop(controller, d, Stage(presets, coupling=coupling, seed=5))
        figs += score(case, d, out, span)
    return figs


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--held-back", action="store_true", help="the stages kept back")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
    _, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=12.0)
    ident = np.column_stack([a, b])
    print("| stage | controller | raster NRMSE | width | held | Lissajous NRMSE x / y | "
          "decaying loops: width / held |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for name, (presets, coupling) in (HELD_BACK if args.held_back else STAGES).items():
        rec = simulate_stage(ident, t, presets=presets, coupling=coupling, seed=0)
        u, q = rec.voltage, rec.charge
        start = time.perf_counter()
        paper = [ph.ActivePI(10).fit(u[:, i], q[:, i], t=rec.t) for i in range(2)]
        took = {"ActivePI": time.perf_counter() - start}
        start = time.perf_counter()
        chosen = [ph.select_model(u[:, i], q[:, i], rec.t, input_dynamics="auto").model
                  for i in range(2)]  # fmt: skip
        took["chosen"] = time.perf_counter() - start
        start = time.perf_counter()
        looped = [ph.select_model(u[:, i], q[:, i], rec.t, input_dynamics="auto",
                                  candidates=LOOP_CANDIDATES).model for i in range(2)]  # fmt: skip
        took["loop"] = time.perf_counter() - start
        leaks = holds_leakage(presets, coupling)
        rows, ref = {}, None
        for label, models, ki, leak in (
            ("charge loops, ActivePI", paper, 0.5, None),
            ("feedforward (ki = 0), ActivePI", paper, 0.0, None),
            ("charge loops, chosen per actuator", chosen, 0.5, None),
            ("charge loops, chosen among the loop's candidates", looped, 0.5, None),
            ("the same, each actuator's leakage from its holds", looped, 0.5, leaks),
        ):
            stage = ph.calibrate_stage(models, u, q, rec.position, rec.t)
            lim = {"v_min": [m.input_range_[0] for m in models],
                   "v_max": [m.input_range_[1] for m in models]}  # fmt: skip
            ctl = ph.CoupledSelfSensingController(
                models, stage, v_min=lim["v_min"], v_max=lim["v_max"], sample_rate=FS,
                slew_rate=None, ki=ki, leakage=leak,
            )  # fmt: skip
            ref = ref or ctl  # every row scored on the first's scans and reach
            rows[label] = run(ctl, presets, coupling, ref)
        assert ref is not None
        rows["linear voltage map"] = run(Linear(u, rec.position), presets, coupling, ref)
        for label, figs in rows.items():
            print(f"| {name} | {label} | " + " | ".join(figs) + " |", flush=True)
        kinds = ", ".join(type(m).__name__ for m in chosen)
        loop_kinds = ", ".join(type(m).__name__ for m in looped)
        print(f"<!-- {name}: ActivePI fitted in {took['ActivePI']:.2f} s, chosen ({kinds}) in "
              f"{took['chosen']:.1f} s, among the loop's ({loop_kinds}) in {took['loop']:.1f} s; "
              f"coupling {np.round(ref.stage.coupling, 4).tolist()} for "
              f"{coupling.tolist()} -->", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
