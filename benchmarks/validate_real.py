"""Validate every model on measured data, held out, and write docs/validation.md.

Run: ``python benchmarks/validate_real.py DATA_DIR [--out docs/validation.md]``
where DATA_DIR is the workplace's ``shared/data`` folder. The data are read in
place and never copied. Every model is fitted on one part of a record and
scored on another part it never saw (later cycles, or another amplitude); the
models run over the whole input so that the held-out part starts from the
state its history left, and NRMSE = RMSE / span of the measured held-out output.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import piezohyst as ph
from piezohyst.model.cores.play import default_thresholds, history_state

Factory = Callable[[], ph.HysteresisModel]


@dataclass
class Row:
    model: str
    train_nrmse: float
    test_nrmse: float
    seconds: float
    detail: str = ""


def _cpu() -> str:
    """The processor's model name (Linux), else the platform's machine type."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine() or "an unknown machine"


def describe(model: ph.HysteresisModel) -> str:
    """The model's growth and shape terms, from its public description."""
    parts = []
    growth = model.growth_coefficients()
    if "growth_terms" in model.get_params():  # a model that chooses its growth terms
        parts.append("growth: " + ("+".join(growth) or "none"))
    elif growth:
        parts.append(", ".join(f"R = {v:.3g}" for v, _ in growth.values()))
    for term in model.terms_:
        if term.kind == "creep":
            taus = term.get_params()["taus"]
            parts.append(f"creep τ = {', '.join(f'{x:g}' for x in taus)} s")
        if term.kind == "relaxation":
            sp = term.get_params()
            parts.append(f"relaxation τ = {sp['tau']:g} s, {sp['nodes']} nodes")
    if model.get_params().get("optimize_thresholds"):
        parts.append("thresholds optimised")
    if model.input_dynamics_.active:
        parts.append(f"lag {model.input_dynamics_.tau * 1e3:.1f} ms")
    if "n_operators" not in model.get_params():
        parts.append(model.operator_.summary)
    return "; ".join(parts)


def start_from(model: ph.HysteresisModel, x: np.ndarray, train: slice, n: int) -> object:
    """The initial state for a fit on ``train``: the state the input before it left."""
    start = train.start or 0
    if "n_operators" not in model.get_params():  # Preisach, Duhem, Bouc-Wen: run the history
        return ph.History(x[: start + 1]) if start > 0 else None
    thr = default_thresholds(x[train], n)
    model.thresholds = thr  # type: ignore[attr-defined]
    return history_state(x[: start + 1], thr) if start > 0 else None


def evaluate(
    factory: Factory,
    x: np.ndarray,
    y: np.ndarray,
    t: np.ndarray,
    train: slice,
    test: slice,
    n_operators: int,
) -> tuple[ph.HysteresisModel, float, float, float]:
    """Fit on ``train`` (starting from the state the earlier input left), score on ``test``."""
    model = factory()
    start = train.start or 0
    z0 = start_from(model, x, train, n_operators)
    began = time.perf_counter()
    model.fit(x[train], y[train], t=t[train], initial_state=z0)
    seconds = time.perf_counter() - began
    # run over the whole record from the training start, score the test part
    lo = start
    pred = model.predict(x[lo:], t=t[lo:])
    full = np.full(x.size, np.nan)
    full[lo:] = pred
    test_err = ph.metrics.nrmse(y[test], full[test])
    return model, model.nrmse_, test_err, seconds


def table(title: str, rows: list[Row], note: str) -> str:
    out = [f"### {title}", "", note, ""]
    out += [
        "| model | training NRMSE | held-out NRMSE | fit time | notes |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(
            f"| {r.model} | {100 * r.train_nrmse:.3f} % | **{100 * r.test_nrmse:.3f} %** | "
            f"{r.seconds:.2f} s | {r.detail} |"
        )
    return "\n".join(out) + "\n"


def run_models(
    models: list[tuple[str, Factory]], x: np.ndarray, y: np.ndarray, t: np.ndarray,
    train: slice, test: slice, n: int,
) -> list[Row]:  # fmt: skip
    rows = []
    for name, factory in models:
        model, tr, te, sec = evaluate(factory, x, y, t, train, test, n)
        rows.append(Row(name, tr, te, sec, describe(model)))
        print(f"  {name:45s} train {100 * tr:7.3f} %  held-out {100 * te:7.3f} %  ({sec:.2f} s)")
    return rows


def actuator(data: Path) -> str:
    path = data / "piezo_actuator_smarthysteresis" / "hysteresis_v_150_1hz.csv"
    table_ = ph.read_table(path)
    t, d, v = table_.get("col1"), table_.get("col2"), table_.get("col3")
    train = slice(int(np.searchsorted(t, 3.3)), int(np.searchsorted(t, 7.0)))
    test = slice(int(np.searchsorted(t, 7.0)), t.size)
    n = 20
    print(f"actuator: {path.name}")
    models: list[tuple[str, Factory]] = [
        ("classical PI", lambda: ph.ClassicalPI(n, output_unit="um")),
        ("active PI (paper)", lambda: ph.ActivePI(n, output_unit="um")),
        ("generalized PI (auto growth, asymmetry)", lambda: ph.GeneralizedPI(n, output_unit="um")),
        ("generalized PI + creep", lambda: ph.GeneralizedPI(n, output_unit="um",
                                                            creep=(0.02, 0.2, 2.0))),
        ("generalized PI + creep, thresholds optimised",
         lambda: ph.GeneralizedPI(n, output_unit="um", creep=(0.02, 0.2, 2.0),
                                  optimize_thresholds=True)),
        ("Preisach, 24 nodes (integral)", lambda: ph.PreisachModel(24, output_unit="um")),
        ("Preisach, 24 nodes (integral), first rise on a branch", lambda: ph.PreisachModel(
            24, output_unit="um", rest="branch")),
        ("Preisach, 24 nodes + lag", lambda: ph.PreisachModel(
            24, output_unit="um", growth_terms=(), input_dynamics="first-order")),
        ("Preisach, 24 nodes + creep", lambda: ph.PreisachModel(
            24, output_unit="um", creep=SMART_CREEP)),
        ("Preisach, 24 nodes + relaxation", lambda: ph.PreisachModel(
            24, output_unit="um", relaxation=0.1)),
        ("Preisach, 24 nodes + relaxation 0.3 s", lambda: ph.PreisachModel(
            24, output_unit="um", relaxation=0.3)),
        ("Preisach, 24 nodes + relaxation + creep", lambda: ph.PreisachModel(
            24, output_unit="um", relaxation=0.1, creep=SMART_CREEP)),
        ("Duhem", lambda: ph.DuhemModel(output_unit="um", growth_terms=())),
        ("Bouc-Wen", lambda: ph.BoucWenModel(output_unit="um", growth_terms=())),
        ("Bouc-Wen + lag", lambda: ph.BoucWenModel(
            output_unit="um", growth_terms=(), input_dynamics="first-order")),
    ]  # fmt: skip
    rows = run_models(models, v, d, t, train, test, n)
    text = table(
        "Piezo actuator, voltage → displacement (SmartHysteresis; 1 Hz, ±150 V, 5 kHz)",
        rows,
        "Fitted on 3.3–7 s (the cycles after the drive starts), scored on 7–10 s. "
        "Output span 39.5 µm. Sensor noise floor ≈ 0.12 % of the span; the published "
        "sparse-ODE model reaches 0.23 % on its own training window (NOTES.txt).",
    )
    # the same on a shorter training part (3.3-6.3 s), and what any model could reach
    short = slice(train.start, int(np.searchsorted(t, 6.3)))
    later = slice(short.stop, t.size)
    print("actuator, fitted on 3.3-6.3 s")
    rows = run_models([m for m in models if m[0] in SHORT_SPLIT], v, d, t, short, later, n)
    text += "\n" + table(
        "Piezo actuator, fitted on 3.3–6.3 s, scored on 6.3–10 s",
        rows,
        "A shorter training part: one cycle less seen, 0.7 s more to predict.",
    )
    named = dict(models)
    gpi = periodic_bound(named["generalized PI + creep"], v, d, t, train, test)
    pre = periodic_bound(named["Preisach, 24 nodes + relaxation + creep"], v, d, t, train, test)
    text += (
        "\nWhat repeats with the drive: a model's residual averaged over the last three "
        "training cycles (phase-locked to the 1 Hz drive, smoothed over 10 ms) and added to "
        "its held-out prediction. The generalized PI with creep goes from "
        f"{100 * gpi[0]:.4f} % to {100 * gpi[1]:.4f} % that way: its residual repeats. The "
        f"relaxing Preisach model with creep goes from {100 * pre[0]:.4f} % to "
        f"{100 * pre[1]:.4f} %: nothing that repeats is left. The rest does not repeat with "
        "the drive (the sensor's noise, 0.124 % of the span before the drive starts, with a "
        "4.5 Hz disturbance in it) and no model of the input can predict it.\n"
    )
    return text


SMART_CREEP = (0.005, 0.02, 0.05, 0.2, 0.5, 2.0, 5.0)
SHORT_SPLIT = (
    "generalized PI + creep",
    "Preisach, 24 nodes + creep",
    "Preisach, 24 nodes + relaxation",
    "Preisach, 24 nodes + relaxation + creep",
)


def periodic_bound(
    factory: Factory, v: np.ndarray, d: np.ndarray, t: np.ndarray, train: slice, test: slice
) -> tuple[float, float]:
    """Held-out NRMSE of a model, and of the model plus its mean residual over the last
    three training cycles of the 1 Hz drive (what repeats with the drive, learnt from the
    training part): if the second is not lower, the model left nothing that repeats."""
    from scipy.ndimage import uniform_filter1d

    model, _, err, _ = evaluate(factory, v, d, t, train, test, 20)
    lo = train.start or 0
    pred = np.full(t.size, np.nan)
    pred[lo:] = model.predict(v[lo:], t=t[lo:])
    period = round(1.0 / float(np.median(np.diff(t))))  # samples per 1 Hz cycle
    first = int(test.start) - 3 * period
    resid = (d - pred)[first : int(test.start)].reshape(3, period).mean(axis=0)
    resid = uniform_filter1d(resid, max(1, period // 100), mode="wrap")
    k = np.arange(int(test.start), t.size)
    return err, float(ph.metrics.nrmse(d[test], pred[k] + resid[(k - first) % period]))


def pzt_creep(data: Path) -> str:
    folder = data / "pnzt_ceramic_aixacct" / "derived_csv"
    out = []
    n = 20
    for name in ("CREEP_T04_CREEP_1400V_1000V_1400S", "CREEP_T03_CREEP_1400V_1000V_105S"):
        tb = ph.read_table(folder / f"{name}.csv")
        t, v, p = tb.get("time_s"), tb.get("voltage_V"), tb.get("polarization_uC_per_cm2")
        half = int(np.searchsorted(t, 0.5 * t[-1]))
        print(f"PZT {name}")
        models: list[tuple[str, Factory]] = [
            ("classical PI", lambda: ph.ClassicalPI(n, output_unit="uC/cm2")),
            ("active PI (paper)", lambda: ph.ActivePI(n, output_unit="uC/cm2")),
            ("generalized PI (auto growth, asymmetry)",
             lambda: ph.GeneralizedPI(n, output_unit="uC/cm2")),
            ("generalized PI + creep τ = 1, 10, 100, 1000 s",
             lambda: ph.GeneralizedPI(n, output_unit="uC/cm2", creep=(1.0, 10.0, 100.0, 1000.0))),
            ("Preisach (auto growth)",
             lambda: ph.PreisachModel(output_unit="uC/cm2", growth_terms="auto")),
            ("Preisach (time)",
             lambda: ph.PreisachModel(output_unit="uC/cm2", growth_terms=("time",))),
            ("Duhem (integral)", lambda: ph.DuhemModel(output_unit="uC/cm2")),
            ("Duhem (time)", lambda: ph.DuhemModel(output_unit="uC/cm2", growth_terms=("time",))),
            ("Bouc-Wen (time)",
             lambda: ph.BoucWenModel(output_unit="uC/cm2", growth_terms=("time",))),
            ("generalized PI (integral) + creep τ = 10 s",
             lambda: ph.GeneralizedPI(n, output_unit="uC/cm2", growth_terms=("integral",),
                                      creep=(10.0,))),
            ("Duhem (integral) + creep τ = 10 s",
             lambda: ph.DuhemModel(output_unit="uC/cm2", creep=(10.0,))),
            ("Preisach (integral) + relaxation τ = 1 s",
             lambda: ph.PreisachModel(output_unit="uC/cm2", relaxation=1.0)),
        ]  # fmt: skip
        tau, scores = creep_chosen_in_training(v, p, t, half)
        models.append((
            f"Duhem (integral) + creep, τ chosen inside the first half ({tau:g} s)",
            lambda tau=tau: ph.DuhemModel(output_unit="uC/cm2", creep=(tau,)),
        ))  # fmt: skip
        rows = run_models(models, v, p, t, slice(0, half), slice(half, t.size), n)
        rows[-1].detail = "validation inside the first half: " + ", ".join(
            f"{k:g} s {100 * e:.2f} %" for k, e in scores.items()
        )
        for row, (_, factory) in zip(rows, models, strict=True):
            whole = factory().fit(v, p, t=t)
            row.detail = f"whole record: {100 * whole.nrmse_:.3f} %; {row.detail}"
        out.append(table(
            f"PZT ceramic, voltage → polarisation, {name} ({t[-1]:.0f} s, {t.size} samples)",
            rows,
            "Fitted on the first half of the record, scored on the second half (the hold, "
            "where leakage drift dominates); 'whole record' is the NRMSE of a fit on the whole "
            "record. No licence on this data: numbers only.",
        ))  # fmt: skip
    return "\n".join(out)


def creep_chosen_in_training(
    v: np.ndarray, p: np.ndarray, t: np.ndarray, half: int
) -> tuple[float, dict[float, float]]:
    """The Duhem model's creep constant chosen without the held-out half: fitted on the
    first 70 % of the training half, scored on the rest of it (forward validation)."""
    inner = int(0.7 * half)
    scores = {}
    for tau in (1.0, 10.0, 100.0):
        _, _, err, _ = evaluate(
            lambda tau=tau: ph.DuhemModel(output_unit="uC/cm2", creep=(tau,)),
            v[:half], p[:half], t[:half], slice(0, inner), slice(inner, half), 20,
        )  # fmt: skip
        scores[tau] = err
    return min(scores, key=lambda k: scores[k]), scores


def _chained(folder: Path, names: list[str]) -> tuple[np.ndarray, ...]:
    """Records measured one after another, joined into one history.

    Time continues (one sample step between records) and each record's
    polarisation, integrated from its own zero, is shifted to continue from the
    previous record's last value (the voltage is back at 0 V between records).
    """
    ts, vs, ps, idx = [], [], [], []
    t_end, p_end, start = 0.0, 0.0, 0
    for name in names:
        tb = ph.read_table(folder / f"{name}.csv")
        t, v, p = tb.get("time_s"), tb.get("voltage_V"), tb.get("polarization_uC_per_cm2")
        step = float(np.median(np.diff(t)))
        ts.append(t - t[0] + t_end + (step if ts else 0.0))
        vs.append(v)
        ps.append(p - p[0] + p_end)
        idx.append(slice(start, start + t.size))
        t_end, p_end, start = float(ts[-1][-1]), float(ps[-1][-1]), start + t.size
    return np.concatenate(ts), np.concatenate(vs), np.concatenate(ps), idx


def pzt_amplitudes(data: Path) -> str:
    folder = data / "pnzt_ceramic_aixacct" / "derived_csv"
    n = 20
    names = ["SLOW_T03_TEST_800V", "SLOW_T04_TEST_1000V", "SLOW_T05_TEST_1200V",
             "SLOW_T06_TEST_1400V"]  # fmt: skip
    t, v, p, parts = _chained(folder, names)
    print("PZT amplitudes: fit 1400 V, predict 1200 V and 1000 V")
    factories: list[tuple[str, Factory]] = [
        ("classical PI", lambda: ph.ClassicalPI(n, output_unit="uC/cm2")),
        ("active PI (paper)", lambda: ph.ActivePI(n, output_unit="uC/cm2")),
        ("generalized PI (auto growth, asymmetry)",
         lambda: ph.GeneralizedPI(n, output_unit="uC/cm2")),
        ("Preisach", lambda: ph.PreisachModel(output_unit="uC/cm2", growth_terms=())),
        ("Duhem", lambda: ph.DuhemModel(output_unit="uC/cm2", growth_terms=())),
        ("Bouc-Wen", lambda: ph.BoucWenModel(output_unit="uC/cm2", growth_terms=())),
    ]  # fmt: skip
    train = parts[3]
    lines = [
        "### PZT ceramic, one amplitude → smaller ones (SLOW set, 1 Hz bipolar triangles)",
        "",
        "The 800, 1000, 1200 and 1400 V periods (T03-T06) were measured one after another; "
        "they are joined into one history (see `_chained`). Fitted on the 1400 V period with "
        "the operators started from the state the earlier periods left, then run from the "
        "start of the history and scored on the 1200 V and 1000 V periods. Each period's "
        "polarisation zero is arbitrary (the instrument integrates from zero per record), so "
        "each held-out period is compared after removing its mean offset. 1000 V is below "
        "the coercive voltage (≈ 1.1 kV).",
        "",
        "| model | training NRMSE (1400 V) | 1200 V | 1000 V | fit time | notes |",
        "|---|---|---|---|---|---|",
    ]
    for name, factory in factories:
        model = factory()
        z0 = start_from(model, v, train, n)
        began = time.perf_counter()
        model.fit(v[train], p[train], t=t[train], initial_state=z0)
        sec = time.perf_counter() - began
        pred = model.predict(v, t=t)
        errs = []
        for part in (parts[2], parts[1]):
            diff = pred[part] - p[part]
            errs.append(float(np.std(diff)) / float(np.ptp(p[part])))
        print(f"  {name:45s} train {100 * model.nrmse_:7.3f} %  1200 V {100 * errs[0]:7.3f} %  "
              f"1000 V {100 * errs[1]:7.3f} %")  # fmt: skip
        lines.append(f"| {name} | {100 * model.nrmse_:.3f} % | **{100 * errs[0]:.2f} %** | "
                     f"**{100 * errs[1]:.2f} %** | {sec:.2f} s | {describe(model)} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def pzt_displacement_map(data: Path) -> str:
    """Displacement from the charge (issue 40): the map calibrated on one period, the
    displacement predicted from the voltage through the charge model on the others."""
    folder = data / "pnzt_ceramic_aixacct" / "derived_csv"
    names = ["SLOW_T03_TEST_800V", "SLOW_T04_TEST_1000V", "SLOW_T05_TEST_1200V",
             "SLOW_T06_TEST_1400V"]  # fmt: skip
    t, v, p, parts = _chained(folder, names)
    d = np.concatenate([ph.read_table(folder / f"{name}.csv").get("displacement_nm")
                        for name in names])  # fmt: skip
    for part in parts[1:]:  # each record's displacement from its own zero: continue it
        d[part] += d[part.start - 1] - d[part.start]
    volts = ("800 V", "1000 V", "1200 V", "1400 V")
    print("PZT displacement from charge: map calibrated on one period")
    lines = [
        "### PZT ceramic: displacement from the charge, across amplitudes (issue 40)",
        "",
        "The sensor once: the charge → displacement map (`calibrate_gain`) is calibrated on "
        "one period, then the displacement of every other period is predicted from the "
        "voltage alone, through the charge model (a Preisach model of voltage → polarisation "
        "fitted on the calibration period, started from the state the earlier periods left) "
        "and the map. Beside it, the displacement-only fit: the same model fitted on voltage "
        "→ displacement directly on the calibration period (with the displacement's sign "
        "turned where it falls as the voltage rises, as it does below the coercive field: a "
        "model rises with its input, and refuses a falling record). Periods joined as above; each "
        "held-out period compared after removing its mean offset (the instrument's zero per "
        "record). The map's order is chosen by evidence (a term kept at 5 standard errors).",
        "",
        "| calibrated on | map | through the charge: " + " | ".join(volts) +
        " | displacement-only fit: " + " | ".join(volts) + " |",
        "|---|---|" + "---|" * 8,
    ]  # fmt: skip
    for cal in (3, 0):
        train = parts[cal]
        charge = ph.PreisachModel(output_unit="uC/cm2", growth_terms=())
        charge.fit(v[train], p[train], t=t[train], initial_state=start_from(charge, v, train, 0))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the butterfly is named in the table
            om = ph.calibrate_gain(charge, v[train], p[train], d[train], t[train],
                                   output_unit="nm")  # fmt: skip
        through = om.predict(charge.predict(v, t=t))
        # below the coercive field this sample's displacement falls as the voltage rises
        # (a model rises with its input, and refuses it): fitted with its sign turned
        dv, dd = np.diff(v[train]), np.diff(d[train])
        sign = -1.0 if float(dv @ dd) < 0 else 1.0
        direct = ph.PreisachModel(output_unit="nm", growth_terms=())
        direct.fit(v[train], sign * d[train], t=t[train],
                   initial_state=start_from(direct, v, train, 0))  # fmt: skip
        alone = sign * direct.predict(v, t=t)
        cells: list[str] = []
        for pred in (through, alone):
            for k, part in enumerate(parts):
                diff = pred[part] - d[part]
                err = float(np.std(diff)) / float(np.ptp(d[part]))
                mark = "training " if k == cal else ""
                cells.append(f"{mark}{100 * err:.2f} %" if k == cal else f"**{100 * err:.2f} %**")
        shape = "linear" if om.order == 1 else f"order {om.order}"
        turns = "" if om.monotone else ", turns (butterfly)"
        print(f"  {volts[cal]}: map {shape}{turns}, g {om.gain:.4g} nm/(uC/cm2); "
              + " ".join(cells))  # fmt: skip
        lines.append(f"| {volts[cal]} | {shape}{turns} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def pzt_periodic(data: Path) -> str:
    """Each period on its own: 1000 V fitted, 800 V predicted, from rest or periodic."""
    folder = data / "pnzt_ceramic_aixacct" / "derived_csv"
    n = 20

    def load(name: str) -> tuple[np.ndarray, ...]:
        tb = ph.read_table(folder / f"{name}.csv")
        return tb.get("time_s"), tb.get("voltage_V"), tb.get("polarization_uC_per_cm2")

    t1, v1, p1 = load("SLOW_T04_TEST_1000V")
    t0, v0, p0 = load("SLOW_T03_TEST_800V")
    print("PZT periods on their own: fit 1000 V, predict 800 V, from rest or periodic")
    lines = [
        "### PZT ceramic, 1000 V → 800 V, each period on its own (initial state)",
        "",
        "Each record is one period of a 1 Hz bipolar triangle that had been running, and "
        f"starts mid-cycle (at {v1[0]:.0f} V and {v0[0]:.0f} V). Fitted on the 1000 V period, "
        "then the 800 V period predicted, both starting at rest (the models' default) or in "
        'the periodic steady state (`initial_state="periodic"`, `predict(..., '
        'state="periodic")`). NRMSE after removing one offset (the instrument\'s '
        "polarisation zero is arbitrary per record).",
        "",
        "| model | start | training NRMSE (1000 V) | 800 V | fit time |",
        "|---|---|---|---|---|",
    ]
    models: list[tuple[str, Factory]] = [
        ("classical PI", lambda: ph.ClassicalPI(n, output_unit="uC/cm2")),
        ("active PI (paper)", lambda: ph.ActivePI(n, output_unit="uC/cm2")),
        ("generalized PI (auto growth, asymmetry)",
         lambda: ph.GeneralizedPI(n, output_unit="uC/cm2")),
        ("Preisach", lambda: ph.PreisachModel(output_unit="uC/cm2", growth_terms=())),
        ("Duhem", lambda: ph.DuhemModel(output_unit="uC/cm2", growth_terms=())),
        ("Bouc-Wen", lambda: ph.BoucWenModel(output_unit="uC/cm2", growth_terms=())),
    ]  # fmt: skip
    for name, factory in models:
        for start in ("rest", "periodic"):
            began = time.perf_counter()
            model = factory().fit(v1, p1, t=t1, initial_state=start)
            sec = time.perf_counter() - began
            try:
                diff = model.predict(v0, t=t0, state=start) - p0
            except ph.NumericRangeError:  # a Duhem loop that never settles on this input
                print(f"  {name:45s} {start:9s} no periodic steady state")
                lines.append(f"| {name} | {start} | {100 * model.nrmse_:.2f} % | no periodic "
                             f"steady state | {sec:.2f} s |")  # fmt: skip
                continue
            err = float(np.std(diff)) / float(np.ptp(p0))
            print(f"  {name:45s} {start:9s} train {100 * model.nrmse_:6.2f} %  "
                  f"800 V {100 * err:6.2f} %")  # fmt: skip
            lines.append(f"| {name} | {start} | {100 * model.nrmse_:.2f} % | "
                         f"**{100 * err:.2f} %** | {sec:.2f} s |")  # fmt: skip
    return "\n".join(lines) + "\n"


def boucwen(data: Path) -> str:
    """The Bouc-Wen benchmark (force -> displacement, 750 Hz): PI with and without a mode."""
    import h5py

    folder = data / "boucwen_benchmark"
    with h5py.File(folder / "train_dynonet_generated.h5", "r") as f:
        u, y = f["multisine/u"][:, 0], f["multisine/y"][:, 0]
        fs = float(np.ravel(f["multisine/fs"][()])[0])
    with h5py.File(folder / "test_dynonet_h5copy.h5", "r") as f:
        um, ym = np.ravel(f["multisine/u"][()]), np.ravel(f["multisine/y"][()])
        us, ys = np.ravel(f["sinesweep/u"][()]), np.ravel(f["sinesweep/y"][()])
    t = np.arange(u.size) / fs
    print("Bouc-Wen benchmark: PI with and without a second-order mode")
    lines = [
        "### Bouc-Wen benchmark (nonlinearbenchmark.org; force → displacement, 750 Hz)",
        "",
        "A mass-spring system whose restoring force is hysteretic (NOTES.txt): the hysteresis "
        "sits inside the mechanical feedback loop. Fitted on the generated 5-period multisine "
        "(training set), simulated on the benchmark's test sets: the multisine period started "
        "in its periodic steady state (two periods run, the second scored), the sine sweep from "
        "rest. Figure of merit e_RMS in m. For scale (NOTES.txt): zero predictor 6.67e-4 / "
        "6.64e-4, a linear ARX(4,4) 1.77e-4 / 1.65e-4, dynoNet 4.52e-5 (multisine).",
        "",
        "| model | multisine e_RMS | sweep e_RMS | fit time | notes |",
        "|---|---|---|---|---|",
    ]
    makers: list[tuple[str, Callable[..., ph.HysteresisModel], dict[str, str]]] = [
        ("classical PI", lambda **kw: ph.ClassicalPI(20, **kw), {}),
        ("classical PI + second-order mode", lambda **kw: ph.ClassicalPI(20, **kw),
         {"output_dynamics": "second-order"}),
        ("Bouc-Wen", lambda **kw: ph.BoucWenModel(growth_terms=(), **kw), {}),
        ("Bouc-Wen + second-order mode", lambda **kw: ph.BoucWenModel(growth_terms=(), **kw),
         {"output_dynamics": "second-order"}),
    ]  # fmt: skip
    for name, make, kw in makers:
        began = time.perf_counter()
        model = make(input_unit="N", output_unit="m", **kw).fit(u, y, t=t)
        sec = time.perf_counter() - began
        two = np.tile(um, 2)
        pm = model.predict(two, t=np.arange(two.size) / fs, state="periodic")[um.size :]
        ps = model.predict(us, t=np.arange(us.size) / fs, state="rest")
        e_m = float(np.sqrt(np.mean((pm - ym) ** 2)))
        e_s = float(np.sqrt(np.mean((ps - ys) ** 2)))
        mode = model.output_dynamics_
        note = f"mode {mode.f0:.1f} Hz, damping {mode.zeta:.3f}" if mode.active else ""
        print(f"  {name:35s} multisine {e_m:.3g} m  sweep {e_s:.3g} m  {note}")
        lines.append(f"| {name} | **{e_m:.3g}** | **{e_s:.3g}** | {sec:.2f} s | {note} |")
    return "\n".join(lines) + "\n"


def rate(data: Path) -> str:
    """What a lag model absorbs on the two 1 Hz sets that log the *commanded* voltage."""
    from piezohyst.io.blocks import block_dt
    from piezohyst.metrics import hysteresis_width

    act = ph.read_table(data / "piezo_actuator_smarthysteresis" / "hysteresis_v_150_1hz.csv")
    mm = np.loadtxt(data / "piezo_micromanipulator_dbo" / "Model_Vi_Do.dat")
    sets = [
        ("SmartHysteresis actuator (5 kHz)", act.get("col1"), act.get("col3"), act.get("col2"),
         3.3, 7.0),
        ("micromanipulator (200 Hz)", np.arange(mm.shape[0]) / 200.0, mm[:, 0], mm[:, 4],
         2.0, 28.0),
    ]  # fmt: skip
    lines = [
        "## Rate: what a lag absorbs at one frequency",
        "",
        "Both 1 Hz sets log the commanded voltage. At one frequency a lag and hysteresis cannot "
        "be told apart, so a model with `input_dynamics` takes as much of the loop as a lag "
        "explains: the numbers say how much, not that it is a lag. Fitted (ActivePI, 20 "
        "operators) on the first part, scored on the rest; width = the largest gap between the "
        "branches, in % of the output span, of output against the command and against the "
        "piezo voltage the model infers.",
        "",
        "| set | input dynamics | found | held-out NRMSE | loop width vs command | "
        "vs inferred voltage |",
        "|---|---|---|---|---|---|",
    ]
    print("rate: lag absorbed at one frequency")
    for name, t, v, y, t0, t1 in sets:
        train = slice(int(np.searchsorted(t, t0)), int(np.searchsorted(t, t1)))
        test = slice(train.stop, t.size)
        steady = slice(train.start, t.size)
        for kind in ("none", "delay", "first-order"):
            model = ph.ActivePI(20, output_unit="um", input_dynamics=kind)
            model.fit(v[train], y[train], t=t[train])
            pred = model.predict(v[train.start :], t=t[train.start :])
            err = ph.metrics.nrmse(y[test], pred[test.start - train.start :])
            dyn = model.input_dynamics_
            u, _ = dyn.apply(v[steady], block_dt(t[steady], 0, t[steady].size, None))
            w_cmd = hysteresis_width(v[steady], y[steady])
            w_u = hysteresis_width(u, y[steady])
            found = (
                "—" if not dyn.active
                else f"lag {dyn.tau * 1e3:.1f} ms" if kind == "first-order"
                else f"delay {dyn.delay * 1e3:.1f} ms"
            )  # fmt: skip
            lines.append(
                f"| {name} | {kind} | {found} | {100 * err:.3f} % | {100 * w_cmd:.1f} % | "
                f"{100 * w_u:.1f} % |"
            )
            print(f"  {name:34s} {kind:12s} {found:14s} held-out {100 * err:6.3f} %  width "
                  f"{100 * w_cmd:5.1f} % -> {100 * w_u:5.1f} %")  # fmt: skip
    lines += [
        "",
        "Neither set can say whether the gap it takes away is a lag: only records at several "
        "drive frequencies can (see `docs/bench.md`, the lagged bench preset). If the amplifier "
        "or the sensor lags, a model that absorbed the lag as hysteresis compensates wrongly at "
        'any other frequency; record 2-3 frequencies and let `input_dynamics="auto"` decide.',
        "",
    ]
    return "\n".join(lines)


MATRIX_UNITS = (1, 2, 3)


def _matrix_row(
    candidates: tuple[str, ...],
    train: tuple[np.ndarray, np.ndarray, np.ndarray],
    test: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    unit: str,
) -> dict[str, float | str]:
    """Held-out NRMSE of every default and of select_model's choice on one split.

    ``test`` None: the record's last 30 % is held out, predicted on from the fit's start;
    else a record of its own, started at rest."""
    from piezohyst.analysis.selection import candidate_model

    x, y, t = train
    if test is None:
        stop = round(0.7 * x.size)
        fit_part, (xt, yt, tt) = slice(0, stop), (x, y, t)
    else:
        fit_part, (xt, yt, tt) = slice(0, x.size), test
    row: dict[str, float | str] = {}
    for name in candidates:
        model = candidate_model(name, 10, ("V", unit), None if t is None else t[fit_part])
        try:
            model.fit(x[fit_part], y[fit_part], t=t[fit_part])
            pred = model.predict(xt, t=tt)
            scored = slice(stop, None) if test is None else slice(None)
            err = ph.metrics.nrmse(yt[scored], pred[scored])
            row[name] = err if np.isfinite(err) else np.inf
        except ph.PiezohystError:
            row[name] = np.inf
    sel = ph.select_model(x[fit_part], y[fit_part], t[fit_part], candidates=candidates,
                          output_unit=unit)  # fmt: skip
    row["chosen"] = sel.name
    row["select_model"] = row[sel.name]  # the same defaults, fitted on the same part
    # what the record itself said of the model that did best held out: its margin over the
    # chosen one inside the record, with the paired jackknife's standard error
    best = min(candidates, key=lambda n: float(row[n]))
    said = next(r for r in sel.rows if r.name == best)
    row["best"], row["margin"], row["margin_se"] = best, said.margin, said.margin_stderr
    row["notes"] = " ".join(sel.notes)
    return row


def _evidence(rows: list[tuple[str, list[dict[str, float | str]]]]) -> list[str]:
    """Per unit: the model that did best held out, and what the training record said of
    it (its margin over select_model's choice inside the record, ± the paired jackknife's
    standard error); then how often a miss was the record's own clear evidence."""
    out = [
        "What each training record said of the model that did best on the test (per unit): "
        "its score inside the record minus the chosen model's, ± the paired block-jackknife "
        "standard error (`SelectionRow.margin`, `margin_stderr`); 'clear' where beyond 2 of "
        "them, the record's own evidence against it. Where the chosen model is the best, "
        "nothing is said. The last column: what `Selection.notes` says the record cannot "
        "test.\n",
        "| record | held-out best per unit: in-record margin over the chosen | notes |",
        "|---|---|---|",
    ]
    misses = clear = 0
    for label, runs in rows:
        cells = []
        for r in runs:
            if r["best"] == r["chosen"]:
                cells.append(f"{r['best']} (chosen)")
                continue
            margin, se = float(r["margin"]), float(r["margin_se"])
            decided = abs(margin) > 2.0 * se
            cells.append(f"{r['best']}: {100 * margin:+.3g} ± {100 * se:.2g} %"
                         + (" clear" if decided else ""))  # fmt: skip
            if float(r["select_model"]) > 1.25 * float(r[str(r["best"])]):
                misses += 1
                clear += decided and margin > 0
        notes = "; ".join(sorted({str(r["notes"]) for r in runs if r["notes"]})) or "-"
        out.append(f"| {label} | " + "; ".join(cells) + f" | {notes} |")
    out += [
        "",
        f"Of the {misses} units where the chosen model's held-out error was more than 1.25x "
        f"the unit's best, the training record's own evidence put that best clearly behind "
        f"(beyond 2 standard errors) on {clear}: there a rule that follows the record "
        "chooses against the test, whichever score it uses.",
    ]
    return out


def matrix(data: Path) -> str:
    """Every model's defaults and select_model, held out, on every plant and measured set."""
    from piezohyst.analysis.selection import CANDIDATES
    from piezohyst.simulation import PLANTS, batch_unit
    from piezohyst.workflows.excitation import excitation

    print("matrix: defaults and select_model on plants and measured sets")
    # what piezohyst excite writes for a 0-140 V actuator: the full range, holds, loops of
    # many sizes at 1 and 10 Hz (the excitation the docs tell a lab to record)
    played = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
    rows: list[tuple[str, list[dict[str, float | str]]]] = []
    designs = {  # two training records, both reported: neither chosen by its scores
        "excite 50 s": lambda p, unit: ph.simulate(played.voltage, played.t, preset=p, seed=unit),
        "decaying 40 s": lambda p, unit: ph.simulate(
            preset=p, signal="decaying", duration=40.0, seed=unit
        ),
    }
    for design, record in designs.items():
        for plant in PLANTS:
            runs = []
            for unit in MATRIX_UNITS:  # actuators of one batch: their physics differ, not noise
                p = batch_unit(PLANTS[plant], unit)
                tr = record(p, unit)
                te = ph.simulate(preset=p, signal="multi", duration=12.0, seed=unit + 100)
                runs.append(_matrix_row(CANDIDATES, (tr.voltage, tr.charge, tr.t),
                                        (te.voltage, te.charge, te.t), "C"))  # fmt: skip
            rows.append((f"plant `{plant}` ({design} -> multi 12 s)", runs))
            print(f"  {plant}, {design}: chosen {[r['chosen'] for r in runs]}")
    act = ph.read_table(data / "piezo_actuator_smarthysteresis" / "hysteresis_v_150_1hz.csv")
    t, d, v = act.get("col1"), act.get("col2") * 1e-6, act.get("col3")
    a = int(np.searchsorted(t, 3.3))
    rows.append(("SmartHysteresis actuator (3.3-10 s, last 30 %)",
                 [_matrix_row(CANDIDATES, (v[a:], d[a:], t[a:]), None, "m")]))  # fmt: skip
    folder = data / "piezo_micromanipulator_dbo"
    mm, nr = np.loadtxt(folder / "Model_Vi_Do.dat"), np.loadtxt(folder / "Test_Vi_Do_Di.dat")
    tm, tn = np.arange(mm.shape[0]) / 200.0, np.arange(nr.shape[0]) / 200.0
    train = (mm[:, 0], mm[:, 4] * 1e-6, tm)
    test = (nr[:, 0], nr[:, 4] * 1e-6, tn)
    rows.append(("micromanipulator, Model run -> Test runs (from rest)",
                 [_matrix_row(CANDIDATES, train, test, "m")]))  # fmt: skip
    names = [*CANDIDATES, "select_model"]
    lines = [
        "## The matrix: every default and `select_model`, held out (issue 26)\n",
        "Each model with its defaults (10 operators where it has them), fitted on a training "
        "record and scored on data it never saw; `select_model` chooses among the same "
        "defaults by forward chaining inside the training record alone. Plants: trained on "
        "what `piezohyst excite --v-min 0 --v-max 140` writes (50 s: holds, a full-range "
        "cycle, decaying loops at 1 and 10 Hz) or on 40 s of the `decaying` signal (which "
        "reaches 132.5 V, not 140), tested on 12 s of the `multi` signal from rest, on units "
        f"{', '.join(map(str, MATRIX_UNITS))} of a batch of each (`batch_unit`: capacitance, "
        "loop, leakage and bias drawn around the plant's): the mean held-out NRMSE and, in "
        "brackets, the range over the units. Measured sets: the last 30 % held out, "
        "predicted on from the fit's start (the micromanipulator: its Model run trains, its "
        "Test runs, started at rest, test). Bold: the best in the row; 'ratio' is "
        "select_model's error over it.\n",
        "| record | " + " | ".join(names) + " | chosen | ratio |",
        "|---" * (len(names) + 3) + "|",
    ]
    ratios, worst_default, flagged, own = [], [], [], []
    classes = {
        "preisach": "preisach",
        "bouc-wen": "bouc-wen",
        "duhem": "duhem",
        "bouc-wen-creep-lag": "bouc-wen+creep",
    }  # a plant's own class among the defaults
    for label, runs in rows:
        cells = []
        means = {n: float(np.mean([float(r[n]) for r in runs])) for n in names}
        best = min(means[n] for n in CANDIDATES)
        for n in names:
            vals = [float(r[n]) for r in runs]
            text = "fails" if not np.isfinite(means[n]) else f"{100 * means[n]:.3g} %"
            if len(vals) > 1 and np.all(np.isfinite(vals)):
                text += f" [{100 * min(vals):.3g}-{100 * max(vals):.3g}]"
            cells.append(f"**{text}**" if means[n] == best else text)
        chosen = ", ".join(sorted({str(r["chosen"]) for r in runs}))
        ratio = means["select_model"] / best
        ratios.append(ratio)
        worst_default.append(max(means[n] for n in CANDIDATES if n != "classical-pi") / best)
        flagged.append(any(r["notes"] for r in runs))
        plant = label.split("`")[1] if label.startswith("plant `") else ""
        if plant in classes:
            own.append(f"{classes[plant]} on `{plant}` ({label.split('(')[1].split(' ->')[0]}) "
                       f"{means[classes[plant]] / best:.2f}x")  # fmt: skip
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {chosen} | {ratio:.2f} |")
    lines += ["", *_evidence(rows)]
    lines += [
        "",
        f"`select_model` within 1.25x the best on {sum(r <= 1.25 for r in ratios)} of "
        f"{len(ratios)} rows (worst {max(ratios):.2f}x). Issue 40's reframing, on the rows "
        "whose training records hold the kind of loops the test drives (no unit's record "
        "drew a note from `Selection.notes`): within 1.25x on "
        f"{sum(r <= 1.25 for r, f in zip(ratios, flagged, strict=True) if not f)} of "
        f"{sum(not f for f in flagged)} (worst "
        f"{max([r for r, f in zip(ratios, flagged, strict=True) if not f] or [np.nan]):.2f}x); "
        f"the notes flag {sum(flagged)} rows (one frequency, or no minor loops). Each default "
        f"on the plants of its own class, over the row's best: {'; '.join(own)} (issue 40 "
        "asks at most 3x). The worst default besides classical "
        f"PI is {max(worst_default):.1f}x the best of its row (issue 26 asks at most 3x). "
        "The plants' parameters were set before any model was fitted to them, and the "
        "defaults predate the plants, with one exception: the Preisach model's choice of a "
        'signed density (`signed="auto"`, kept where it halves the fit\'s RMSE) was added '
        "after its column here showed 7-11 % on the Bouc-Wen plants, and its bar was set "
        "after seeing the ratios on these plants' training records (0.18-0.32 where the "
        "density >= 0 fails, 0.86-0.98 elsewhere); and the growth selection's rule that "
        "`abs_integral` comes only beside `integral` was added after generalized PI's column "
        "here showed 7.7 % on the two-state plant (it picked `abs_integral` alone). The "
        "Duhem fit keeps its output-error polish only where the polished loops close on "
        "full-range cycling as well as the linear fit's: added after `select_model`'s folds on "
        "the creep-lag plant's training record scored the polished Duhem at 56 % (its loops "
        "ratcheted by 55 % of the span a cycle), before this matrix was rerun. The Preisach "
        "fit's rest state and the cells below the lowest voltage a record fell to after its "
        "first fall were changed after its column here showed 6.4 % on the Preisach plant's "
        "decaying record: the initial loading curve is now kept on a tie (a branch was), and "
        "those cells share the widths of the cells beyond the range; both were chosen on units "
        "4-6 of each batch, which this table does not use, and checked here: the Preisach "
        "column on the decaying rows went 6.41 -> 1.45 % (Preisach plant), 3.28 -> 1.55 % "
        "(Duhem), 5.55 -> 2.3 % (two-state), and 4.97 -> 5.89 %, 4.2 -> 4.91 % on the Bouc-Wen "
        "plants; select_model's worst ratio 3.17 -> 1.92, within 1.25x on one row fewer (on "
        "the Duhem plant's decaying record it now takes Preisach on one unit: 1.65 % where "
        "Bouc-Wen leaves 0.44 %). select_model's score weighs its two parts by how much of "
        "the record each fit saw (0.4, 0.6; it was their plain mean), chosen on units 4-6 "
        "against three other scores after the Preisach plant's excite row here showed it "
        "taking ActivePI (`docs/selection-study.md`); here it moved 5 -> 6 rows within "
        "1.25x, the Preisach plant's excite row 1.92 -> 1.39x. Its folds are now placed by "
        "the input's turns, not its seconds (fit on half the turns, score to three "
        "quarters; fit to three quarters, score the rest), and the score is the parts' "
        "plain mean again: chosen on units 4-6 against the same three other scores "
        "(`docs/selection-study.md`), after the rows here showed `excite`'s first fit "
        "scored on fast loops it had never seen; here 6 -> 8 of 12 rows within 1.25x. The "
        "Preisach, Bouc-Wen and Duhem defaults on a charge record take the leak's rise with "
        "the voltage (`abs_integral`) beside the integral where the record's holds show it "
        "beyond three standard errors (`holds_show_rise`): added after the Preisach column "
        "here showed 3.5x its row's best on its own plant's excite record, chosen on units "
        '4-6 (`docs/benchmarks.md`, "The rise where the holds show it") and checked here: '
        "the excite rows moved (the decaying records have no holds), the Preisach plant's "
        "Preisach 2.3 -> 0.127 %, the Bouc-Wen plant's Bouc-Wen 1.08 -> 0.0325 %, the Duhem "
        "plant's Duhem 1.2 -> 0.863 %; select_model 7 of 12 rows within 1.25x (6 before), "
        "the rows without a note 5 of 5 (4 of 5); the Preisach column on the creep-lag "
        "plant went 3.12 -> 3.57 %; the worst default's ratio grew because the Bouc-Wen "
        "plant's best fell to 0.0325 %. The Preisach model's continuation beyond its grid now "
        "keeps each branch's own slope at the edge (it was the smallest reversible slope "
        "counted from the edge, under which a turn above the grid stayed flat and each "
        'excursion ratcheted up; `docs/benchmarks.md`, "The Preisach model beyond its grid"): '
        "changed after a compensator divided by that flat branch's zero slope, not for this "
        "table, and checked here: the Preisach column on the decaying rows (trained to 132.5 "
        "V, tested to 140 V) went 1.45 -> 1.26 % (Preisach plant), 5.89 -> 4.18 % and 4.91 "
        "-> 3.89 % (Bouc-Wen plants), 1.55 -> 1.27 % (Duhem) and 2.3 -> 3.49 % (two-state); "
        "select_model's worst ratio 2.08 -> 2.13x; the PZT table's 800 V row, far beyond its "
        "grid, 4.29 / 11.76 / 44.57 -> 8.43 / 8.78 / 58.49 % through the charge. Classical "
        "PI has no growth term: on a "
        "leaking capacitor's charge it drifts by design (the paper's baseline). Other rules "
        "for the choice, tried on other units of the same batches and checked here: "
        "`docs/selection-study.md`. The choice among the candidates a record cannot tell "
        "apart now goes to the one that forecast the record's latest part "
        "(`selection.latest_of_close`), chosen on plants drawn at random, not on these "
        '(`docs/selection-study.md`, "Plants drawn at random"); this table was not '
        "rerun for it.\n",
        _minor_loops_close(),
    ]
    return "\n".join(lines)


def _minor_loops_close() -> str:
    """Why no model with return-point memory is within 3x on the Bouc-Wen plants: how far
    each plant's minor loop fails to close, cycle by cycle (leak, bias and noise off)."""
    import dataclasses

    from piezohyst.simulation import PLANTS, batch_unit

    up, down = np.linspace(0.0, 140.0, 1000), np.linspace(140.0, 40.0, 700)
    tri = np.concatenate([np.linspace(40.0, 80.0, 500), np.linspace(80.0, 40.0, 500)])
    v = np.concatenate([up, down, np.tile(tri, 6)])
    drifts = {}
    for plant in PLANTS:
        p = dataclasses.replace(batch_unit(PLANTS[plant], 1), g_leak=0.0, leak_voltage_coeff=0.0,
                                i_bias=0.0, amp_noise=0.0, laser_noise=0.0)  # fmt: skip
        d = ph.simulate(v, np.arange(v.size) / 1000.0, preset=p, seed=0).displacement
        ends = d[1700 + 1000 * np.arange(7) - 1][1:]  # after each minor loop
        drifts[plant] = 100 * np.diff(ends) / float(np.ptp(d))
    text = "; ".join(f"{plant} {' / '.join(f'{x:+.2f}' for x in drifts[plant][:3])}"
                     for plant in drifts)  # fmt: skip
    return (
        "Why the PI family and the Preisach model stay behind on the Bouc-Wen plants: their "
        "minor loops close (return-point memory), and a Bouc-Wen capacitor's do not. Six "
        "40-80 V cycles after a full rise and a fall to 40 V (unit 1, leakage, bias and noise "
        "off), the displacement at the end of each cycle moves by (% of the span, first three "
        f"cycles): {text}. A model whose minor loops close cannot draw that accommodation: "
        "on the Bouc-Wen rows the 3x bar asks the PI family and the Preisach model for what "
        "their class lacks. The two-state plant's relaxation drifts too, less but longer.\n"
    )


def _cli(*args: str | Path) -> tuple[str, str]:
    """A piezohyst command as a user types it: its stdout and stderr."""
    import subprocess
    import sys

    exe = Path(sys.executable).with_name("piezohyst")
    done = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, check=True)
    return done.stdout, done.stderr


def _said_nrmse(text: str) -> float:
    """The first 'NRMSE x %' a command printed, as a fraction."""
    return float(text.split("NRMSE ")[1].split(" %")[0]) / 100


def cli_windows(data: Path) -> str:
    """The command line on a window of the actuator record, against the API's split."""
    import tempfile

    path = data / "piezo_actuator_smarthysteresis" / "hysteresis_v_150_1hz.csv"
    cols = ["--input", "3", "--output", "2", "--time", "1", "--output-unit", "um"]
    print(f"command line on a window: {path.name}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / "m.json"
        for name in ("classical-pi", "active-pi", "preisach"):
            out, _ = _cli("fit", path, *cols, "--model", name, "--t-start", "3.3", "--t-stop",
                          "7", "-o", model)  # fmt: skip
            fit = _said_nrmse(out)
            same, _ = _cli("predict", model, path, *cols, "--t-start", "3.3", "--t-stop", "7",
                           "-o", Path(tmp) / "same.csv")  # fmt: skip
            later, _ = _cli("predict", model, path, *cols, "--t-start", "7",
                            "-o", Path(tmp) / "later.csv")  # fmt: skip
            table_ = ph.read_table(path)
            t, y, x = table_.get("col1"), table_.get("col2") * 1e-6, table_.get("col3")
            a, b = np.searchsorted(t, [3.3, 7.0])
            m = ph.load_model(model)
            api = m.predict(x[a:], t=t[a:])  # the training window from its start, then on
            rows.append((name, fit, _said_nrmse(same), _said_nrmse(later),
                         ph.metrics.nrmse(y[b:], api[b - a:])))  # fmt: skip
    lines = [
        "### The command line on a window (issue 25)\n",
        "`piezohyst fit --t-start 3.3 --t-stop 7`, then `predict` on the same window and on "
        "7-10 s, against the Python API's forward split (`model.predict` over 3.3-10 s from "
        "the model's own start, scored on 7-10 s). The same window gives the fit's number; the "
        "held-out window the API's.\n",
        "| model | fit (CLI) | predict, same window | predict, 7-10 s | API, 7-10 s |",
        "|---|---|---|---|---|",
    ]
    lines += [f"| {n} | {f:.4%} | {s:.4%} | **{h:.4%}** | {api:.4%} |" for n, f, s, h, api in rows]
    return "\n".join(lines).replace("%", " %") + "\n"


def main() -> None:
    # held-out inputs beyond what a Preisach, Duhem or Bouc-Wen fit saw are the point here
    warnings.simplefilter("ignore", ph.ExtrapolationWarning)
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("data", type=Path, help="the shared/data folder")
    parser.add_argument("--out", type=Path, default=Path("docs/validation.md"))
    args = parser.parse_args()
    sections = [
        actuator(args.data),
        cli_windows(args.data),
        pzt_creep(args.data),
        pzt_amplitudes(args.data),
        pzt_displacement_map(args.data),
        pzt_periodic(args.data),
        boucwen(args.data),
        rate(args.data),
        matrix(args.data),
    ]
    header = (
        "# Validation on measured data\n\n"
        "Written by `benchmarks/validate_real.py DATA_DIR` (DATA_DIR = the workplace's "
        "`shared/data`, read in place; no data is copied here). piezohyst "
        f"{ph.__version__}, Python {platform.python_version()}, NumPy {np.__version__}, "
        f"on {_cpu()} ({os.cpu_count()} cores; fit times are wall clock there). "
        "Every number below is held out unless marked training: the model never saw it.\n\n"
    )
    reading = """
### Reading the tables

- **Actuator.** Every extension helps on cycles the model never saw. This is a displacement
  record (µm), so by default no model fits a growth term (the displacement does not see leaked
  charge, issue 40): the paper's integrator is left out and ActivePI is ClassicalPI here
  (0.316 %; with its integrator, before, 0.154 %: it stood in for creep), while every model
  that takes creep gets three creep operators timed by the record (generalized PI 0.146 %,
  Preisach 0.131 %); the generalized model with creep at 0.02-2 s holds 0.141 %. What it
  leaves repeats with the
  drive — even harmonics up to 14 Hz: the rising and falling branches differ in shape beyond
  a mirror image, which a play-operator model cannot represent, and the loop depends on the
  rate. The Preisach model represents the first (any branch shape): started in the
  demagnetised state the drive began from, its first rise on the initial loading curve
  (`rest="auto"` chose it), it holds 0.131 % with the default creep (0.134 % when that
  rise follows a branch); seven creep lags beside it 0.129 %, and a relaxing part — a second
  Preisach density on the voltage through a 0.1 s lag — the rest: 0.128 % (0.127 % with
  creep), where nothing that
  repeats with the drive is left (the line under the tables). The time constant is not
  critical (0.3 s: 0.127 %); on a shorter training part (3.3–6.3 s) the relaxing models hold
  0.129-0.130 % and the generalized PI with creep 0.144 %.
- **Long holds (1400 s).** Classical PI cannot follow the drift at all. The extra terms fit the
  first half far better than the paper's one-term model but extrapolate 700 s of drift worse:
  the drift slows during the hold, which no constant-rate term describes, and the automatic
  choice (forward-chaining folds of at least two reversals; this record's hold has too few, so
  one test block, the last 30 % of the training part) looks a shorter horizon ahead than the
  test. Creep operators with long time constants do not help (1000 s trades with the
  integral: 3.1 %). A short one does: the polarisation relaxes for some seconds after the step
  down to the hold, and a model without creep reads that relaxation as part of the leak. With
  creep at 10 s the integral models predict the second half to 0.99 % (Duhem) and 1.03 %
  (generalized PI), a relaxing Preisach part at 1 s to 0.93 %. But these time constants were
  picked here with the second half in view: chosen by forward validation inside the first
  half (fit on its first 70 %, score the rest), the Duhem model's creep constant comes out at
  1 s and the second half at 1.24 % — the same as without creep — and the same settings on
  the 105 s record are far off (18-59 %). Extrapolating 700 s of drift from 700 s remains
  beyond what these records can decide.
- **Short hold (105 s).** Polarisation relaxes after the excursion; only the creep operators
  follow it, and still with a large held-out error.
- **Smaller amplitudes.** All PI variants predict the sub-coercive 1000 V loop poorly from the
  switching 1400 V loop: a PI model's minor loops are fixed by its major loop, and ferroelectric
  switching makes the major loop a poor guide. Extra growth terms make it worse across records.
  The Preisach model (any minor loop shape) and Bouc-Wen do far better (6.1/9.8 % and
  7.9/12.2 %); still, identify at the amplitudes you will use.
- **Displacement from the charge (PZT).** Calibrated on the sub-coercive 800 V period, where the
  map is linear (and negative: this sample's displacement falls as the voltage rises there),
  the displacement of the 1000 and 1200 V periods follows from the voltage through the charge
  model to 4.3 and 11.8 %, where a model of voltage → displacement fitted on the same period
  (its sign turned) leaves 6.7 and 13.0 %: the charge carries the hysteresis, the map is
  simple. (Before models refused a falling record, the direct fit here was a flat line at
  32-33 %, which this note once read as the charge's advantage.) Past
  the coercive field (1400 V) the map turns (the butterfly, found and named by calibration;
  order 2 on evidence) and the same route leaves 24-29 % on the smaller periods, whose
  polarisation never switches: a map calibrated on switching loops is not the map of minor
  ones. Calibrate at the amplitudes you will command.
- **Records that start mid-cycle.** A record cut out of a running periodic drive does not start
  at rest: started in the periodic steady state, the 800 V loop predicted from the 1000 V one
  roughly halves its error for every model. The classical model, with no growth term to absorb
  the wrong start, gains most and is the best here.

- **Bouc-Wen benchmark.** A play-operator model with a second-order mode after it (the
  Hammerstein structure piezohyst identifies for a stage's resonance) cuts the error to a third
  of the static model's, but stays slightly worse than a linear ARX model (1.93e-4 against
  1.77e-4 m on the multisine) and far from models built for this system: here the hysteretic
  force feeds back into the mass-spring dynamics, which a hysteresis-then-mode cascade cannot
  represent (its mode comes out at 39.5 Hz and 9 % damping against the true 35.6 Hz and
  1.1 %). `BoucWenModel` does no better in the same cascade (2.0e-4 m on the multisine,
  3.1e-4 m on the sweep; 4.7e-4 and 6.0e-4 m until its core was fitted through the mode,
  issue 57): the model class is right, the structure (Bouc-Wen *inside* the mechanical loop)
  is what piezohyst lacks.

### Preisach, Duhem and Bouc-Wen: where each wins and loses

- **Preisach** (an Everett function on 16-24 nodes, one bounded least squares) is the most
  accurate model inside its range: on the actuator with creep and a relaxing part 0.127 %
  held out, the best of any model here (the generalized PI with creep 0.141 %), and it holds
  the 1400 s PZT record to 0.52 % as a whole with the `time` term. Started demagnetised (the
  joined PZT history begins at rest; `rest="auto"` put its first rise on the initial loading
  curve) it predicts the 1200 and 1000 V loops from the 1400 V one at 6.1 and 9.8 %, the
  best here (21 and 36 % in the previous version, whose first rise followed a branch: the
  state the switching loops start from is what it got wrong). Its strength is the
  non-congruent minor loops of a real capacitor: on the simulated bench it compensates
  decaying loops to 0.81 % width where ActivePI leaves 1.09 % (`docs/benchmarks.md`).
- **Bouc-Wen** (five parameters) extrapolates to *other amplitudes* well: the 800 V
  loop from the 1000 V one at 2.8 % (periodic start; PI 4.8 %), the best there; the 1200
  and 1000 V loops from the 1400 V one at 7.9 and 12.2 % (PI 14.8 and 19.7 %). A handful of physical
  parameters extrapolate where a grid of weights does not; inside its training range it is
  the least accurate (actuator 0.196 % with the lag).
- **Duhem** (slopes on a (voltage, output) grid) fits its training records well but is
  fragile beyond them: its slopes depend on the output they produce, so an input unlike the
  training drives it where no data was (186-294 % on the smaller PZT amplitudes; no periodic
  steady state on the 800 V loop, which `predict` then refuses with a clear error). Use it
  inside the region its data covered — it warns when a run leaves it.
- **Term selection** (`growth_terms="auto"` on any of them) uses the Prandtl-Ishlinskii
  proxy's forward-chaining cross-validation; on the 1400 s hold it still prefers the integral
  (1.48 % whole) to the bias term that fits the whole record better (0.52 %), as it does for PI.
"""
    text = header + "\n".join(sections) + reading
    args.out.write_text(text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
