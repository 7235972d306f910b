"""A rule for choosing a model, judged on plants drawn at random (issue 55, item 5).

``python benchmarks/selection_random.py [--dev N] [--test N] [-o docs/selection-study.md]``
(about 15 minutes for 20 + 20 plants on a 2-core Xeon, 3 minutes for 60 on a 2-core EPYC;
``-o`` rewrites the tables between the page's second pair of markers).

The matrix's plants (``benchmarks/selection_study.py``) are five fixed designs and their
production spread. Here each plant is *drawn*: a family (the simulator's Preisach,
Bouc-Wen, Duhem, two-state and Bouc-Wen-with-creep capacitors, and a Jiles-Atherton-type
capacitor written below and nowhere in the package), then its parameters (the law's, the
capacitance, the leakage and its rise with the voltage, an op-amp's bias current, an
amplifier's lag on half of the plants, dielectric relaxation on some), then what the lab
records to fit on (what ``piezohyst excite`` plays, or 40 s of decaying loops), then a test
it never sees (12 s of the ``multi`` signal, another noise draw). Plants ``0 .. dev-1`` of
the draw are the **development set** a rule may be chosen on; plants ``1000 ..`` are the
**held-out set**, drawn the same way, scored once the rule is chosen.

Each plant: ``select_model`` on the record (its folds, the margins' standard errors, the
candidates it cannot tell apart), and every candidate fitted on the whole record and scored
on the test. A rule's figure on a plant is the test NRMSE of what it chose over the best
candidate's ("within 1.25x of the best default"). Every rule is scored from the same fits.
"""

from __future__ import annotations

import argparse
import math
import os
import time
import warnings
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

# one BLAS thread per worker: the two workers fill the two cores (with BLAS's own threads on
# top, select_model took 16-84 s a plant instead of 3-5 s)
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import piezohyst as ph  # noqa: E402
from piezohyst.analysis.selection import (  # noqa: E402
    CANDIDATES,
    TIE,
    candidate_model,
    chosen,
    undecided,
    with_margins,
)

FAMILIES = ("preisach", "bouc-wen", "duhem", "two-state", "bouc-wen-creep", "jiles-atherton")
DEV_SEED, TEST_SEED = 0, 1000
Run = dict[str, Any]


# ------------------------------------------------------------------ the draw
def _logn(rng: np.random.Generator, value: float, spread: float) -> float:
    return float(value * math.exp(spread * rng.standard_normal()))


def draw(seed: int) -> dict[str, Any]:
    """A plant: its family, parameters and training design, all from ``seed``."""
    rng = np.random.default_rng([0x5E1EC7, seed])
    family = FAMILIES[int(rng.integers(len(FAMILIES)))]
    plant: dict[str, Any] = {
        "seed": seed,
        "family": family,
        "design": ("excite", "decaying")[int(rng.integers(2))],
        "c0": _logn(rng, 12e-9, 0.2),
        "g_leak": float(10 ** rng.uniform(-10.0, -8.8)),
        "leak_voltage_coeff": float(rng.uniform(0.0, 1.5)),
        "i_bias": float(rng.uniform(-25e-12, 25e-12)),
        "amp_tau": float(rng.uniform(1e-3, 4e-3)) if rng.random() < 0.5 else 0.0,
    }
    if family == "preisach":
        plant["preisach"] = {k: _logn(rng, 1.0, s) for k, s in
                             (("q_irr", 0.2), ("field_center", 0.3), ("field_spread", 0.3),
                              ("coercive_scale", 0.3))}  # fmt: skip
    elif family == "jiles-atherton":
        plant["ja"] = {
            "a": float(rng.uniform(15.0, 45.0)),  # V, the anhysteretic curve's width
            "k": float(rng.uniform(8.0, 30.0)),  # V, the pinning (coercive) scale
            "alpha": float(rng.uniform(0.0, 0.3)),  # the mean-field coupling, of k
            "c": float(rng.uniform(0.1, 0.5)),  # the reversible share
            "centre": float(rng.uniform(50.0, 90.0)),  # V, where the domains are balanced
            "qs": _logn(rng, 0.6e-6, 0.4),  # C, the switching charge at saturation
        }
    else:
        plant["law"] = float(rng.standard_normal()), rng.standard_normal(5)
        relax = family == "bouc-wen-creep" or rng.random() < 0.3
        plant["relax"] = (
            (float(rng.uniform(0.1, 0.5)), float(rng.uniform(2.0, 8.0))),
            (_logn(rng, 1.2e-9, 0.4), _logn(rng, 1.0e-9, 0.4)),
        ) if relax else None  # fmt: skip
    return plant


def _preset(plant: dict[str, Any]) -> Any:
    from piezohyst.simulation import PLANTS

    family = plant["family"]
    base = PLANTS["bouc-wen" if family == "bouc-wen-creep" else family]
    common = {k: plant[k] for k in ("c0", "g_leak", "leak_voltage_coeff", "i_bias", "amp_tau")}
    p = replace(base, name=f"random {plant['seed']}", relax_taus=(), relax_gains=(), **common)
    if family == "preisach":
        return replace(p, **{k: getattr(base, k) * f for k, f in plant["preisach"].items()})
    _, z = plant["law"]
    law = np.array(base.law_params, dtype=float)
    if family == "bouc-wen" or family == "bouc-wen-creep":  # A, beta, gamma jittered, n = 1
        law[1:4] *= np.exp(0.3 * z[:3])
    elif family == "duhem":  # alpha, c_an, c_rev
        law *= np.exp(0.3 * z[:3])
    else:  # two-state: the populations' scale, rate and activation width
        law *= np.exp(0.3 * z[:3])
    p = replace(p, law_params=tuple(float(x) for x in law))
    if plant["relax"] is not None:
        p = replace(p, relax_taus=plant["relax"][0], relax_gains=plant["relax"][1])
    return p


def _lagged(t: np.ndarray, v: np.ndarray, tau: float) -> np.ndarray:
    if tau <= 0.0:
        return v
    out, y = np.empty_like(v), v[0]
    for k in range(v.size):
        y += (1.0 - math.exp(-(t[k] - t[k - 1]) / tau)) * (v[k] - y) if k else 0.0
        out[k] = y
    return out


def jiles_atherton(t: np.ndarray, v: np.ndarray, plant: dict[str, Any], seed: int) -> np.ndarray:
    """The measured charge of a Jiles-Atherton-type capacitor: ``q = c0 v + qs P`` with the
    polarization ``P`` of the JA law in the voltage (the field), plus the leakage's and the
    bias current's charge and 0.1 % noise. Written here, used nowhere in the package."""
    ja = plant["ja"]
    a, k, alpha, c, centre = ja["a"], ja["k"], ja["alpha"] * ja["k"], ja["c"], ja["centre"]
    u = _lagged(t, v, plant["amp_tau"]) - centre

    def langevin(x: float) -> float:
        return x / 3.0 if abs(x) < 1e-4 else 1.0 / math.tanh(x) - 1.0 / x

    p_pol, u_prev = 0.0, u[0]
    pol = np.empty_like(u)
    steps = 8
    for i in range(u.size):
        du = (u[i] - u_prev) / steps
        for _ in range(steps):
            if du != 0.0:
                delta = 1.0 if du > 0 else -1.0
                h = u_prev + alpha * p_pol
                an = langevin(h / a)
                gap = an - p_pol
                irr = gap / (delta * k - alpha * gap) if gap * delta > 0 else 0.0
                dan = (langevin((h + 1e-3) / a) - langevin((h - 1e-3) / a)) / 2e-3
                p_pol = min(max(p_pol + ((1.0 - c) * irr + c * dan) * du, -1.0), 1.0)
            u_prev += du
        pol[i] = p_pol
        u_prev = u[i]
    vv = u + centre
    q = plant["c0"] * vv + ja["qs"] * (pol - pol[0])
    g = plant["g_leak"] * (1.0 + plant["leak_voltage_coeff"] * np.abs(vv) / 140.0)
    current = g * vv + plant["i_bias"]
    q = q + np.concatenate(([0.0], np.cumsum(0.5 * (current[1:] + current[:-1]) * np.diff(t))))
    noise = np.random.default_rng(seed).standard_normal(q.size)
    return np.asarray(q + 1e-3 * np.ptp(q) * noise)


def records(plant: dict[str, Any]) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
    """(voltage, charge, t) of the training record and of the test."""
    from piezohyst.simulation import make_signal
    from piezohyst.workflows.excitation import excitation

    seed = plant["seed"]
    if plant["design"] == "excite":
        played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
        t, v = played.t, played.voltage
    else:
        t, v = make_signal("decaying", duration=40.0)
    tt, vt = make_signal("multi", duration=12.0)
    if plant["family"] == "jiles-atherton":
        return (v, jiles_atherton(t, v, plant, seed), t), (
            vt,
            jiles_atherton(tt, vt, plant, seed + 7),
            tt,
        )
    p = _preset(plant)
    tr, te = ph.simulate(v, t, preset=p, seed=seed), ph.simulate(vt, tt, preset=p, seed=seed + 7)
    return (tr.voltage, tr.charge, tr.t), (te.voltage, te.charge, te.t)


# ------------------------------------------------------------------ measuring
def probe(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Loops from the bottom of the record's range (to all of it, then 3/4, 1/2 and 1/4 of
    it, 1 s each, 1 kHz): what a record that never comes back low does not show. No truth
    is read on it: the candidates' predictions are compared with one another."""
    lo, hi = float(np.min(v)), float(np.max(v))
    k = np.arange(1000) / 1000.0
    tri = 1.0 - np.abs(2.0 * k - 1.0)  # 0 -> 1 -> 0
    volts = np.concatenate([lo + (hi - lo) * a * tri for a in (1.0, 0.75, 0.5, 0.25)])
    return np.arange(volts.size) / 1000.0, volts


def measure(seed: int) -> Run:
    """``select_model``'s table on the record, and every candidate's test error."""
    plant = draw(seed)
    (x, y, t), (xt, yt, tt) = records(plant)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sel = ph.select_model(x, y, t=t)
    seconds = time.perf_counter() - start
    test: dict[str, float] = {}
    preds: dict[str, np.ndarray] = {}
    probes: dict[str, np.ndarray] = {}
    tp, vp = probe(x)
    for name in CANDIDATES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                m = candidate_model(name, 10, ("V", "C"), t).fit(x, y, t=t)
                preds[name] = m.predict(xt, t=tt)
                test[name] = float(ph.metrics.nrmse(yt, preds[name]))
                probes[name] = m.predict(vp, t=tp)
            except ph.PiezohystError:
                test[name] = math.inf
    rows = {r.name: (tuple(r.folds), r.score) for r in sel.rows}
    # the choice by the score alone, and what the record does not tell from it, recomputed
    # from the table: ``select_model`` itself now goes on to the latest part among those
    ordered = sorted(sel.rows, key=lambda r: CANDIDATES.index(r.name))
    first = chosen([r for r in ordered if math.isfinite(r.score)])
    close = undecided(with_margins(ordered, first), first.name)
    combined = {}
    for label, names in (("undecided", (first.name, *close)),):
        got = [preds[n] for n in names if n in preds and math.isfinite(test[n])]
        combined[label] = float(ph.metrics.nrmse(yt, np.mean(got, axis=0)))
    lag = f"lag {1e3 * plant['amp_tau']:.1f} ms"
    best = min(test, key=lambda n: test[n])
    print(f"  plant {seed}: {plant['family']} ({plant['design']}, {lag}) chose {sel.name}, "
          f"best {best}", flush=True)  # fmt: skip
    return {
        "plant": plant,
        "chosen": first.name,
        "selected": sel.name,
        "undecided": tuple(close),
        "rows": rows,
        "table": ordered,
        "notes": sel.notes,
        "test": test,
        "combined": combined,
        "probes": {n: p for n, p in probes.items() if np.all(np.isfinite(p))},
        "seconds": seconds,
    }


# ------------------------------------------------------------------ the rules
def _simplest(scores: dict[str, float]) -> str:
    best = min(scores.values())
    return next(n for n in CANDIDATES if n in scores and scores[n] <= best * (1 + TIE))


def _finite(run: Run) -> dict[str, tuple[float, ...]]:
    return {n: f for n, (f, s) in run["rows"].items() if math.isfinite(s)}


def _latest_of_undecided(run: Run) -> float:
    names = [n for n in (run["chosen"], *run["undecided"]) if n in _finite(run)]
    folds = _finite(run)
    return run["test"][_simplest({n: folds[n][-1] for n in names})]


#: Candidates whose hysteresis is a grid fitted cell by cell (their small loops near an end
#: the record did not return to are the fit's smoothing, not the data)
GRIDS = ("preisach", "duhem")


def _no_grid_where_an_end_is_unseen(run: Run) -> float:
    """``select_model``'s rule; where its notes say the record reaches an end of its range
    before its first turn only, the same rule among the candidates that are not grids."""
    if not any("never comes back" in n for n in run["notes"]):
        return run["test"][run["selected"]]
    rows = [r for r in run["table"] if r.name not in GRIDS and math.isfinite(r.score)]
    first = chosen(rows)
    names = [n for n in (first.name, *undecided(with_margins(rows, first), first.name))
             if n in _finite(run)]  # fmt: skip
    return run["test"][_simplest({n: _finite(run)[n][-1] for n in names})]


def _consensus(run: Run, within: float) -> float:
    """``select_model``'s rule; where its notes say the record never comes back to an end
    of its range, the candidate (among those scoring within ``within`` times the best)
    whose loops from the bottom lie nearest the candidates' median there."""
    if not any("never comes back" in n for n in run["notes"]):
        return run["test"][run["selected"]]
    folds = {n: s for n, (f, s) in run["rows"].items() if math.isfinite(s)}
    best = min(folds.values())
    names = [
        n for n in CANDIDATES if n in run["probes"] and folds.get(n, math.inf) <= within * best
    ]
    if len(names) < 3:
        return run["test"][run["selected"]]
    stack = np.array([run["probes"][n] for n in names])
    median = np.median(stack, axis=0)
    far = {n: float(np.sqrt(np.mean((p - median) ** 2))) for n, p in zip(names, stack, strict=True)}
    return run["test"][min(far, key=lambda n: far[n])]


def _creep_where_undecided(run: Run) -> float:
    """``select_model``'s choice; where its variant with creep operators is among the
    candidates the record does not tell from the score's choice, that variant: a record that
    cannot tell them apart cannot show the rates where creep matters, and a creep term the
    actuator does not need fits small."""
    name = run["selected"]
    close = {run["chosen"], *run["undecided"]}
    variant = name if name.endswith("+creep") else f"{name}+creep"
    if variant != name and variant in close and math.isfinite(run["test"].get(variant, math.inf)):
        return run["test"][variant]
    return run["test"][name]


RULES: dict[str, Callable[[Run], float]] = {
    "the mean of the two parts (select_model until this study)": lambda r: r["test"][r["chosen"]],
    "the latest part among those not told apart": _latest_of_undecided,
    "the latest part alone": lambda r: r["test"][
        _simplest({n: f[-1] for n, f in _finite(r).items()})
    ],
    "the worst part": lambda r: r["test"][_simplest({n: max(f) for n, f in _finite(r).items()})],
    "the mean of those not told apart": lambda r: r["combined"]["undecided"],
    "select_model as it is": lambda r: r["test"][r.get("selected", r["chosen"])],
    "select_model, no grid where an end is unseen": _no_grid_where_an_end_is_unseen,
    "select_model, the median's nearest where an end is unseen": lambda r: _consensus(r, math.inf),
    "... among those within 1.5x of the best score": lambda r: _consensus(r, 1.5),
    "select_model, its creep variant where not told apart": _creep_where_undecided,
}


def table(runs: list[Run]) -> list[str]:
    heads = ("rule | within 1.25x of the best default | excite records | decaying records | "
             "median ratio | worst ratio | worst plant")  # fmt: skip
    lines = [f"| {heads} |", "|---|---|---|---|---|---|---|"]
    designs = np.array([r["plant"]["design"] for r in runs])
    for label, rule in RULES.items():
        ratios = np.array([rule(r) / min(r["test"].values()) for r in runs])
        worst = runs[int(np.argmax(ratios))]["plant"]
        by = [f"{int(np.sum(ratios[designs == d] <= 1.25))} of {int(np.sum(designs == d))}"
              for d in ("excite", "decaying")]  # fmt: skip
        lines.append(
            f"| {label} | {int(np.sum(ratios <= 1.25))} of {ratios.size} | {by[0]} | {by[1]} | "
            f"{np.median(ratios):.2f} | {ratios.max():.2f} | "
            f"{worst['family']} ({worst['design']}, {worst['seed']}) |"
        )
    return lines


def plants_table(runs: list[Run]) -> list[str]:
    heads = "plant | family | record | lag | chosen by the mean | not told apart | best on the test"
    lines = [f"| {heads} | ratio | ratio, select_model |", "|---|---|---|---|---|---|---|---|---|"]
    kept = RULES["select_model as it is"]
    for r in runs:
        p, best = r["plant"], min(r["test"], key=lambda n: r["test"][n])
        lines.append(
            f"| {p['seed']} | {p['family']} | {p['design']} | {1e3 * p['amp_tau']:.1f} ms | "
            f"{r['chosen']} | {', '.join(r['undecided']) or '-'} | {best} "
            f"({100 * r['test'][best]:.2f} %) | {r['test'][r['chosen']] / r['test'][best]:.2f} | "
            f"{kept(r) / r['test'][best]:.2f} |"
        )
    return lines


def limits(runs: list[Run]) -> list[str]:
    """Where ``select_model`` misses, what the record held: was a candidate within 1.25x of
    the test's best among those the record cannot tell from its choice (then no rule on the
    record can tell which), or did the record score every such candidate worse beyond its
    noise (then the record points away from it)? And how the record's scores rank the
    candidates against the test's errors (Spearman, per plant, the median)."""
    from scipy.stats import spearmanr

    heads = (
        "record | plants | within 1.25x | best within 1.25x among those not told apart | "
        "misses: one was among them | misses: the record scored all of them worse "
        "beyond its noise | record score against test error, rank correlation (median)"
    )
    lines = [f"| {heads} |", "|---|---|---|---|---|---|---|"]
    kept = RULES["select_model as it is"]
    for design in ("excite", "decaying"):
        part = [r for r in runs if r["plant"]["design"] == design]
        if not part:
            continue
        hit = among = tie = away = 0
        rhos = []
        for r in part:
            best = min(r["test"].values())
            good = {n for n, e in r["test"].items() if e <= 1.25 * best}
            close = {r["chosen"], *r["undecided"]}
            ok = kept(r) <= 1.25 * best
            hit += ok
            among += bool(good & close)
            tie += (not ok) and bool(good & close)
            away += (not ok) and not (good & close)
            test = r["test"]
            names = [n for n, (_, sc) in r["rows"].items()
                     if math.isfinite(sc) and math.isfinite(test.get(n, math.inf))]  # fmt: skip
            rho = spearmanr([r["rows"][n][1] for n in names], [test[n] for n in names])[0]
            if math.isfinite(rho):
                rhos.append(rho)
        lines.append(
            f"| {design} | {len(part)} | {hit} | {among} | {tie} | {away} | "
            f"{np.median(rhos):.2f} ({np.min(rhos):.2f} to {np.max(rhos):.2f}) |"
        )
    return lines


BEGIN, END = (
    "<!-- random plants: benchmarks/selection_random.py -->",
    "<!-- end of random plants -->",
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dev", type=int, default=20, help="development plants (seeds 0 ..)")
    ap.add_argument("--test", type=int, default=0, help="held-out plants (seeds 1000 ..)")
    ap.add_argument("--test-from", type=int, default=TEST_SEED, help="the first held-out seed")
    ap.add_argument("-o", "--out", type=Path, default=None, help="write the tables here (.md)")
    ap.add_argument("--limits", action="store_true",
                    help="also what the record held where the choice missed")  # fmt: skip
    args = ap.parse_args()
    seeds = [DEV_SEED + k for k in range(args.dev)]
    seeds += [args.test_from + k for k in range(args.test)]
    with ProcessPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(measure, seeds))
    dev = [r for r in runs if r["plant"]["seed"] < TEST_SEED]
    held = [r for r in runs if r["plant"]["seed"] >= TEST_SEED]
    out = []
    for label, part in (("Development plants", dev), ("Held-out plants", held)):
        if part:
            secs = [r["seconds"] for r in part]
            out += [f"### {label} ({len(part)}; `select_model` {min(secs):.0f}-{max(secs):.0f} s "
                    "each)", "", *table(part), "", *plants_table(part), ""]  # fmt: skip
            if args.limits:
                out += ["What the record held where it missed:", "", *limits(part), ""]
    text = "\n".join(out).rstrip()
    print(text)
    if args.out is not None:
        from selection_study import write_between  # beside this script

        write_between(args.out, BEGIN, END, text)


if __name__ == "__main__":
    main()
