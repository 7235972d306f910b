"""How well does a rule for choosing a model do on data it was not tuned on?

``python benchmarks/selection_study.py [DATA_DIR] [-o docs/selection-study.md]`` (about 50
minutes on two cores; ``-o`` rewrites the tables between the page's markers).

The question behind ``select_model``'s folds. A rule for scoring candidates inside a record
(forward chaining from some origins, an aggregate, a tie rule) is tried on the matrix's plants
(``docs/validation.md``): trained on what ``piezohyst excite`` writes or on 40 s of decaying
loops, scored on 12 s of the ``multi`` signal the rule never sees. Units 4-6 of each plant's
batch are the development set a rule may be chosen on; units 1-3 (the matrix's) are held out
to check the choice. With DATA_DIR, the two measured sets of the matrix are added.

Each candidate is fitted once per origin (the first 30, 40, ... 90 % of the record, and the
current folds' 50 and 75 %) and run over the whole record from its start, so every rule is
scored from the same fits. A rule's result on a row is the mean held-out NRMSE of what it
chose over the units, divided by the best candidate's mean: what the matrix reports.
"""

from __future__ import annotations

import argparse
import math
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

import piezohyst as ph
from piezohyst.analysis.selection import CANDIDATES, TIE, candidate_model

#: Fit origins (fractions of the record); every rule's folds start at one of them
ORIGINS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.75, 0.8, 0.9)
DEV_UNITS, HELD_UNITS = (4, 5, 6), (1, 2, 3)
Run = dict[str, Any]


def _record(design: str, plant: str, unit: int) -> tuple[Any, Any]:
    from piezohyst.simulation import PLANTS, batch_unit
    from piezohyst.workflows.excitation import excitation

    p = batch_unit(PLANTS[plant], unit)
    if design == "excite":
        played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
        tr = ph.simulate(played.voltage, played.t, preset=p, seed=unit)
    else:
        tr = ph.simulate(preset=p, signal="decaying", duration=40.0, seed=unit)
    te = ph.simulate(preset=p, signal="multi", duration=12.0, seed=unit + 100)
    return (tr.voltage, tr.charge, tr.t, "C"), (te.voltage, te.charge, te.t, 0)


def _measured(data: Path, name: str) -> tuple[Any, Any]:
    if name == "SmartHysteresis":
        act = ph.read_table(data / "piezo_actuator_smarthysteresis" / "hysteresis_v_150_1hz.csv")
        t, d, v = act.get("col1"), act.get("col2") * 1e-6, act.get("col3")
        a = int(np.searchsorted(t, 3.3))
        stop = round(0.7 * (t.size - a))
        return (v[a : a + stop], d[a : a + stop], t[a : a + stop], "m"), (v[a:], d[a:], t[a:], stop)
    folder = data / "piezo_micromanipulator_dbo"
    mm, nr = np.loadtxt(folder / "Model_Vi_Do.dat"), np.loadtxt(folder / "Test_Vi_Do_Di.dat")
    tm, tn = np.arange(mm.shape[0]) / 200.0, np.arange(nr.shape[0]) / 200.0
    return (mm[:, 0], mm[:, 4] * 1e-6, tm, "m"), (nr[:, 0], nr[:, 4] * 1e-6, tn, 0)


def measure(job: tuple[str, str, int, str | None]) -> Run:
    """Every candidate: its held-out NRMSE, and its prediction of the record from each origin."""
    design, plant, unit, data = job
    if data is None:
        (x, y, t, unit_out), (xt, yt, tt, scored) = _record(design, plant, unit)
    else:
        (x, y, t, unit_out), (xt, yt, tt, scored) = _measured(Path(data), plant)
    run: Run = {"design": design, "plant": plant, "unit": unit, "y": y, "test": {}, "pred": {}}
    for name in CANDIDATES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                m = candidate_model(name, 10, ("V", unit_out), t).fit(x, y, t=t)
                p = m.predict(xt, t=tt)
                run["test"][name] = float(ph.metrics.nrmse(yt[scored:], p[scored:]))
            except ph.PiezohystError:
                run["test"][name] = math.inf
            preds = {}
            for a in ORIGINS:
                n = round(a * x.size)
                try:
                    m = candidate_model(name, 10, ("V", unit_out), t[:n]).fit(x[:n], y[:n], t=t[:n])
                    preds[a] = m.predict(x, t=t)
                except ph.PiezohystError:
                    preds[a] = None
            run["pred"][name] = preds
    print(f"  {design} {plant} {unit}", flush=True)
    return run


def fold_score(run: Run, name: str, a: float, b: float) -> float:
    """NRMSE over [a, b) of the record of the candidate fitted on [0, a)."""
    p = run["pred"][name][a]
    if p is None:
        return math.inf
    y = run["y"]
    i, j = round(a * y.size), round(b * y.size)
    err = float(np.sqrt(np.mean((p[i:j] - y[i:j]) ** 2)) / np.ptp(y[i:j]))
    return err if math.isfinite(err) else math.inf


def rule(folds: Sequence[tuple[float, float]], one_se: bool) -> Callable[[Run], str]:
    """Mean over ``folds``; the simplest within 2 % of the best (and, ``one_se``, within one
    standard error of the best's mean over the folds)."""

    def choose(run: Run) -> str:
        scores = {n: np.array([fold_score(run, n, a, b) for a, b in folds]) for n in CANDIDATES}
        mean = {n: float(np.mean(s)) if np.all(np.isfinite(s)) else math.inf
                for n, s in scores.items()}  # fmt: skip
        best = min(mean, key=lambda n: mean[n])
        bar = mean[best] * (1 + TIE)
        if one_se:
            se = float(np.std(scores[best], ddof=1) / math.sqrt(len(folds)))
            bar = max(bar, mean[best] + se)
        return next(n for n in CANDIDATES if mean[n] <= bar)

    return choose


BEGIN, END = "<!-- tables: benchmarks/selection_study.py -->", "<!-- end of tables -->"
ROLLING = tuple((k / 10, (k + 1) / 10) for k in range(3, 10))
RULES = {
    "2 folds (select_model)": rule(((0.5, 0.75), (0.75, 1.0)), one_se=False),
    "2 folds, one standard error": rule(((0.5, 0.75), (0.75, 1.0)), one_se=True),
    "7 rolling origins": rule(ROLLING, one_se=False),
    "7 rolling origins, one standard error": rule(ROLLING, one_se=True),
}


def table(runs: list[Run], units: tuple[int, ...]) -> list[str]:
    """One row per rule: the ratio on each record kind, how many within 1.25x, the worst."""
    keys = sorted({(r["design"], r["plant"]) for r in runs if r["unit"] in units})
    heads = [f"{p} ({d})" for d, p in keys]
    lines = [f"| rule | {' | '.join(heads)} | within 1.25x | worst |",
             "|---" * (len(keys) + 3) + "|"]  # fmt: skip
    for label, choose in RULES.items():
        ratios = []
        for key in keys:
            rr = [r for r in runs if (r["design"], r["plant"]) == key and r["unit"] in units]
            means = {n: float(np.mean([r["test"][n] for r in rr])) for n in CANDIDATES}
            got = float(np.mean([r["test"][choose(r)] for r in rr]))
            ratios.append(got / min(means.values()))
        cells = " | ".join(f"{x:.2f}" for x in ratios)
        within = sum(x <= 1.25 for x in ratios)
        lines.append(f"| {label} | {cells} | {within} of {len(ratios)} | {max(ratios):.2f} |")
    return lines


def main() -> None:
    from piezohyst.simulation import PLANTS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?", type=Path, help="the shared data folder (optional)")
    ap.add_argument("-o", "--out", type=Path, default=None, help="write the tables here (.md)")
    args = ap.parse_args()
    jobs: list[tuple[str, str, int, str | None]] = [
        (design, plant, unit, None)
        for design in ("excite", "decaying")
        for plant in PLANTS
        for unit in (*DEV_UNITS, *HELD_UNITS)
    ]
    if args.data is not None:
        jobs += [("measured", name, 0, str(args.data))
                 for name in ("SmartHysteresis", "micromanipulator")]  # fmt: skip
    with ProcessPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(measure, jobs))
    out = ["## Development units (4-6): a rule may be chosen here", "", *table(runs, DEV_UNITS)]
    out += ["", "## Held-out units (1-3, the matrix's): the check", "", *table(runs, HELD_UNITS)]
    if args.data is not None:
        out += ["", "## Measured sets (the matrix's splits)", "", *table(runs, (0,))]
    text = "\n".join(out)
    print(text)
    if args.out is not None:
        write_between(args.out, BEGIN, END, text)


def write_between(out: Path, begin: str, end: str, text: str) -> None:
    """``text`` between the markers of an existing page, else a page of its own."""
    page = out.read_text() if out.exists() else f"{begin}\n{end}\n"
    if begin not in page or end not in page:
        raise SystemExit(f"{out} lacks the markers {begin} and {end}")
    head, rest = page.split(begin, 1)
    out.write_text(f"{head}{begin}\n{text}\n{end}{rest.split(end, 1)[1]}")


if __name__ == "__main__":
    main()
