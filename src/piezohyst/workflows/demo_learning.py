"""The demo's learning stage (issue 27): a repeated scan learned from the charge alone.

The demo's ActivePI model and the leakage calibrated from holds on the loop's bench (its
bias current never identified) drive ten one-second trials of a 10 Hz scan; the laser
only checks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..control.learning import LearningCompensator
from ..metrics import hysteresis_width, rmse
from ..model.calibrations.leakage import Leakage
from ..model.presets import HysteresisModel
from ..plotting import save_panels
from ..simulation import Bench, BenchPreset

UM = 1e6
TRIALS = 10


def learning_study(
    model: HysteresisModel,
    leakage: Leakage,
    *,
    preset: BenchPreset,
    gain: float,
    slew_rate: float,
    seed: int,
) -> dict[str, Any]:
    """Ten trials of a 10 Hz scan over 30-70 % of the model's major loop, learned from the
    charge; per trial the error the learner saw and the laser's width and offset-free NRMSE."""
    n = round(preset.rate)  # one-second trials
    top, bottom = (float(q) for q in model.hysteresis_.predict(np.array([preset.v_max, 0.0])))
    scan = 0.5 - 0.5 * np.cos(2 * np.pi * 10 * np.arange(n) / n)
    desired = gain * (bottom + (top - bottom) * (0.3 + 0.4 * scan))
    ilc = LearningCompensator(model, v_min=0.0, v_max=preset.v_max, sample_rate=preset.rate,
                              leakage=leakage, domain="displacement", gain=gain,
                              slew_rate=slew_rate)  # fmt: skip
    bench = Bench(preset, seed=seed, voltage=ilc.last_command)
    rows, loops = [], []
    span = float(np.ptp(desired))
    for _ in range(TRIALS + 1):
        rec = bench.run(ilc.command(desired))
        trial = ilc.learn(rec.charge)
        s, d = rec.displacement[n // 10 :], desired[n // 10 :]  # after the first scan: trial
        rows.append({                                          # 0 ramps in from rest there
            "error_seen_pct": 100 * trial.error,
            "width_S_pct": 100 * hysteresis_width(d, s),
            "nrmse_S_pct": 100 * rmse(d - d.mean(), s - s.mean()) / span,
        })  # fmt: skip
        loops.append(s)
    assert ilc.design is not None
    return {"desired": desired, "first": loops[0], "last": loops[-1], "rows": rows,
            "design": ilc.describe(), "rollbacks": ilc.rollbacks}  # fmt: skip


def learning_figure(out: Path, study: dict[str, Any]) -> Path:
    """Error per trial, and one scan's loop before and after learning."""
    rows = study["rows"]
    k = np.arange(len(rows), dtype=float)
    d = (study["desired"] - study["desired"].mean()) * UM
    cut = slice(-100, None)  # the last scan of the ten in a trial
    first, last = (s - s.mean() for s in (study["first"], study["last"]))
    panels: list[dict[str, object]] = [
        {
            "curves": [
                (
                    k,
                    np.array([r["error_seen_pct"] for r in rows]),
                    "charge, leakage removed (what the learner sees)",
                    {"marker": "o", "color": "C0"},
                ),
                (
                    k,
                    np.array([r["nrmse_S_pct"] for r in rows]),
                    "laser (check only)",
                    {"marker": "s", "color": "C2"},
                ),
            ],
            "xlabel": "trial",
            "ylabel": "RMS error, offset removed (% of span)",
            "title": "error per trial",
        },
        {
            "curves": [
                (
                    d[cut],
                    first[cut] * UM,
                    f"trial 0: width {rows[0]['width_S_pct']:.2f} %",
                    {"lw": 0.8, "color": "C3"},
                ),
                (
                    d[cut],
                    last[cut] * UM,
                    f"trial {len(rows) - 1}: width {rows[-1]['width_S_pct']:.2f} %",
                    {"lw": 0.8, "color": "C0"},
                ),
            ],
            "xlabel": "desired displacement, offset removed (µm)",
            "ylabel": "laser displacement, offset removed (µm)",
            "title": "one 10 Hz scan, before and after",
            "identity": True,
        },
    ]
    return save_panels(
        out / "fig13_learning.png",
        panels,
        suptitle="Fig. 13 — learning a repeated 10 Hz scan from the charge alone (no sensor)",
    )


def learning_report(study: dict[str, Any]) -> list[str]:
    """The report's section."""
    rows = study["rows"]
    lines = [
        "",
        "## Learning from repetition",
        "",
        "A scan repeats, and so does its error: `LearningCompensator` learns it from the "
        "measured charge minus the leakage calibrated from holds (the loop's bench above, its "
        "bias current never identified), trial after trial, without a sensor; the laser only "
        "checks. Ten scans of 10 Hz per one-second trial; trial 0, the lead-in, brings the "
        "actuator from rest into the scan and is not learned from; the laser is scored after "
        f"each trial's first scan. The law: {study['design']}. "
        f"Rollbacks: {study['rollbacks']}.",
        "",
        "| trial | error the learner saw | laser: width | laser: NRMSE, offset removed |",
        "|---|---|---|---|",
    ]
    for j, r in enumerate(rows):
        if j in (0, 1, 2, 3, 5, len(rows) - 1):
            lines.append(f"| {j} | {r['error_seen_pct']:.3f} % | {r['width_S_pct']:.3f} % | "
                         f"{r['nrmse_S_pct']:.3f} % |")  # fmt: skip
    lines += ["", "![Fig. 13](fig13_learning.png)"]
    return lines
