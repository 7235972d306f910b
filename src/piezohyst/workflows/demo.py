"""The main job: the paper's experiment end to end on the simulated bench.

:func:`run_demo` identifies the classical and the active PI model from
voltage and *charge* only, removes the leakage growth (eq. 19, Fig. 8),
inverts the hysteresis (eq. 18), compensates a desired displacement
trajectory through S = g·Q_C (sensorless: the laser is read once, at one
calibration point), runs the command through the bench and measures the
result in both domains (Figs. 9-10). It writes PNG figures, ``metrics.json``
and ``report.md``.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray, check_int
from .._version import __version__
from ..control.compensator import Compensator
from ..control.selfsensing import SelfSensingController
from ..errors import ExtrapolationWarning, warn
from ..io import atomic_write_text
from ..metrics import hysteresis_width, nrmse, rmse
from ..model.calibrations import Leakage, calibrate_leakage
from ..model.presets import (
    ActivePI,
    BoucWenModel,
    ClassicalPI,
    DuhemModel,
    GeneralizedPI,
    HysteresisModel,
    PreisachModel,
)
from ..plotting import save_grid, save_panels
from ..simulation import (
    DEFAULT_PRESET,
    PRESETS,
    Bench,
    BenchRecord,
    make_signal,
    run_loop,
    simulate,
)
from ._base import check_folder
from .demo_learning import learning_figure, learning_study
from .demo_report import render_report

__all__ = ["DemoResult", "run_demo"]

UC = 1e6  # C -> uC for plots
UN = 1e9  # C -> nC for residuals
UM = 1e6  # m -> um

Step = Callable[[str], None]


@dataclass(frozen=True)
class DemoResult:
    """What :func:`run_demo` produced: the metrics and the files it wrote."""

    metrics: dict[str, Any]
    files: list[Path]


def _desired_charge(
    model: ActivePI, shape: FloatArray, t: FloatArray, frequency: float, v_max: float
) -> tuple[FloatArray, float]:
    """A desired charge inside the major loop, starting at rest (0 V) like a first move.

    Returns the trajectory (C) and the model's charge at rest, ``q0``.
    """
    h = model.hysteresis_
    q0, q_top, q_rem = (float(q) for q in h.predict(np.array([0.0, v_max, 0.0])))
    lo = q_rem + 0.03 * (q_top - q_rem)
    hi = q_top - 0.03 * (q_top - q_rem)
    q = lo + (hi - lo) * shape
    first = t < 0.5 / frequency  # the first rise starts from rest, not from the loop bottom
    q[first] = q0 + (hi - q0) * shape[first]
    return q, q0


def _compensation_run(
    model: ActivePI,
    signal: str,
    *,
    gain: float,
    static_gain: float,
    seed: int,
    preset: str,
) -> dict[str, Any]:
    """Compensated and uncompensated runs for one desired displacement trajectory."""
    p = PRESETS[preset]
    frequency = 0.5
    t, shape = make_signal(signal, amplitude=1.0, frequency=frequency, duration=12.0, rate=p.rate)
    q_des, q0 = _desired_charge(model, shape, t, frequency, p.v_max)
    d_des = gain * (q_des - q0)
    # the paper's unipolar drive: 0..v_max; the compensator never leaves it
    compensator = Compensator(model, v_min=0.0, v_max=p.v_max, domain="displacement", gain=gain)
    command = compensator.process(d_des)
    clipped = compensator.saturated_count
    comp = simulate(command, t, preset=preset, seed=seed)
    linear = np.clip(d_des / static_gain, 0.0, p.v_max)  # what one does without a model
    base = simulate(linear, t, preset=preset, seed=seed + 1)
    q_comp = model.remove_growth(comp.voltage, comp.charge, t=comp.t) + q0
    q_base = model.remove_growth(base.voltage, base.charge, t=base.t) + q0
    return {
        "t": t,
        "q_des": q_des,
        "d_des": d_des,
        "command": command,
        "comp": comp,
        "base": base,
        "q_comp": q_comp,
        "q_base": q_base,
        "linear": linear,
        "metrics": {
            "width_before_V_to_Q_pct": 100 * hysteresis_width(linear, q_base),
            "width_before_V_to_S_pct": 100 * hysteresis_width(linear, base.displacement),
            "width_after_Q_pct": 100 * hysteresis_width(q_des, q_comp),
            "width_after_S_pct": 100 * hysteresis_width(d_des, comp.displacement),
            "tracking_nrmse_before_S_pct": 100 * nrmse(d_des, base.displacement),
            "tracking_nrmse_after_S_pct": 100 * nrmse(d_des, comp.displacement),
            "tracking_nrmse_after_Q_pct": 100 * nrmse(q_des, q_comp),
            "max_error_after_S_um": float(np.max(np.abs(comp.displacement - d_des))) * UM,
            "max_error_before_S_um": float(np.max(np.abs(base.displacement - d_des))) * UM,
            "command_range_V": [float(command.min()), float(command.max())],
            "samples_saturated": clipped,
        },
    }


LOOP_EXTRA_BIAS = 40e-12  # A: the charge amplifier's bias on the day of the loop, never identified
CALIBRATION_LEVELS = (0.0, 35.0, 70.0, 105.0, 140.0, 105.0, 70.0, 35.0, 0.0)  # V, up and down
CALIBRATION_HOLD = 20.0  # s per level
#: V/s: the amplifier's slew rate, said where commands start from rest with a jump or run
#: faster than any training record (the compensator's default is the training's fastest)
AMP_SLEW = 30e3


def _closed_loop_study(
    model: ActivePI, *, gain: float, seed: int, preset: str, ki: float = 0.5
) -> dict[str, Any]:
    """Feedforward vs the self-sensing loop on a 60 s decaying trajectory, unseen bias current.

    The bench of the loop has a bias current the identification never saw.
    Runs: feedforward (Compensator); closed loop with the leakage the model
    identified from cycling; closed loop with the leakage calibrated from a
    hold record taken on the loop's bench.
    """
    base = PRESETS[preset]
    p = dataclasses.replace(base, i_bias=base.i_bias + LOOP_EXTRA_BIAS)
    v_cal = np.repeat(np.array(CALIBRATION_LEVELS), round(CALIBRATION_HOLD * p.rate))
    cal = Bench(p, seed=seed).run(v_cal)
    calibrated = calibrate_leakage(cal.t, cal.voltage, cal.charge)
    t, shape = make_signal("decaying", amplitude=1.0, frequency=0.5, duration=60.0, rate=p.rate)
    h = model.hysteresis_
    q0, q_top, q_rem = (float(q) for q in h.predict(np.array([0.0, p.v_max, 0.0])))
    lo, hi = q_rem + 0.03 * (q_top - q_rem), q_top - 0.03 * (q_top - q_rem)
    d_des = gain * (lo + (hi - lo) * shape - q0)
    settings: dict[str, Any] = {"domain": "displacement", "gain": gain, "slew_rate": AMP_SLEW}
    runs: dict[str, Any] = {}
    identified = Leakage.from_model(model)
    cases: list[tuple[str, Leakage | None]] = [
        ("feedforward", None),
        ("closed loop, identified leakage", identified),
        ("closed loop, hold-calibrated leakage", calibrated),
    ]
    third = t.size // 3
    span = float(np.ptp(d_des))
    for name, leakage in cases:
        ctl: Compensator | SelfSensingController
        if leakage is None:
            ctl = Compensator(model, v_min=0.0, v_max=p.v_max, sample_rate=p.rate, **settings)
        else:
            ctl = SelfSensingController(
                model,
                v_min=0.0,
                v_max=p.v_max,
                sample_rate=p.rate,
                leakage=leakage,
                ki=ki,
                **settings,
            )
        bench = Bench(p, seed=seed + 1, voltage=ctl.last_command)
        rec = run_loop(ctl, d_des, bench)
        s = rec.displacement
        runs[name] = {
            "record": rec,
            "width_S_pct": 100 * hysteresis_width(d_des, s),
            "tracking_nrmse_S_pct": 100 * nrmse(d_des, s),
            # both thirds over the whole trajectory's span (the first holds the rise from rest)
            "first_20s_nrmse_S_pct": 100 * rmse(d_des[:third], s[:third]) / span,
            "last_20s_nrmse_S_pct": 100 * rmse(d_des[-third:], s[-third:]) / span,
            "samples_saturated": ctl.saturated_count,
        }
    return {
        "t": t,
        "d_des": d_des,
        "runs": runs,
        "extra_bias_A": LOOP_EXTRA_BIAS,
        "bias_A": p.i_bias,
        "calibration_levels_V": list(CALIBRATION_LEVELS),
        "identified": identified,
        "calibrated": calibrated,
        "true": {
            "conductance": p.g_leak,
            "quadratic": p.g_leak * p.leak_voltage_coeff,
            "tau": p.r_ref * p.c_ref,
        },
    }


RATE_PRESET = "T226-H4-203X-amp4ms"


def _rate_study(seed: int, n_operators: int) -> dict[str, Any]:
    """A model identified at 1 Hz against one identified over 0.5-20 Hz, used at 40 Hz.

    The bench's amplifier lags 4 ms and the record logs the command (as the
    measured 1 Hz sets do). Both models predict a new 40 Hz record and
    compensate a 40 Hz trajectory (25-75 % of the charge span).
    """
    slow_rec = simulate(signal="hold", frequency=1.0, duration=20.0, preset=RATE_PRESET, seed=seed)
    slow = ActivePI(n_operators).fit(slow_rec.voltage, slow_rec.charge, t=slow_rec.t)
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=30.0)
    multi_rec = simulate(v, t, preset=RATE_PRESET, seed=seed + 1)
    aware = ActivePI(n_operators, input_dynamics="auto").fit(
        multi_rec.voltage, multi_rec.charge, t=multi_rec.t
    )
    tt, vv = make_signal("multi", amplitude=140.0, frequency=40.0, duration=3.0)
    check = simulate(vv, tt, preset=RATE_PRESET, seed=seed + 2)
    ts, shape = make_signal("fixed", amplitude=1.0, frequency=40.0, duration=3.0)
    top, bottom = (float(q) for q in aware.operator_.predict(np.array([140.0, 0.0])))
    desired = bottom + (top - bottom) * (0.25 + 0.5 * shape)
    keep = ts >= 1.0
    rows: dict[str, Any] = {}
    for name, model in (("identified at 1 Hz", slow), ("rate-aware, 0.5-20 Hz", aware)):
        predicted = model.predict(check.voltage, t=check.t)
        lo, hi = aware.input_range_
        # 40 Hz asks for faster commands than the training records had (the default
        # limit): the amplifier's own slew rate, 30 V/ms, is said instead
        comp = Compensator(model, v_min=lo, v_max=hi, sample_rate=1000.0, slew_rate=AMP_SLEW,
                           allow_extrapolation=True)  # fmt: skip
        run = simulate(comp.process(desired), ts, preset=RATE_PRESET, seed=seed + 3)
        rows[name] = {
            "predicted": predicted,
            "displacement": run.true_displacement,
            "nrmse_40Hz_pct": 100 * nrmse(check.charge, predicted),
            "width_40Hz_pct": 100 * hysteresis_width(desired[keep], run.true_displacement[keep]),
        }
    dyn = aware.input_dynamics_
    return {
        "check": check,
        "desired": desired,
        "keep": keep,
        "rows": rows,
        "dynamics": dyn.to_dict(),
        "bench_lag_s": PRESETS[RATE_PRESET].amp_tau,
    }


def _model_comparison(
    fixed: dict[str, Any],
    valid: BenchRecord,
    *,
    gain: float,
    n_operators: int,
    seed: int,
    preset: str,
) -> list[dict[str, Any]]:
    """Every model, identified on two excitations, scored held out and used to compensate.

    Each model drives the same desired displacement through its own
    :class:`Compensator` (charge only; the laser checks), with the bench's limits.
    """
    p = PRESETS[preset]
    records = {
        "hold": simulate(preset=preset, signal="hold", duration=20.0, seed=seed),
        "levels": simulate(preset=preset, signal="levels", duration=30.0, seed=seed + 50),
    }
    makers: list[tuple[str, Callable[[], HysteresisModel]]] = [
        ("classical PI", lambda: ClassicalPI(n_operators)),
        ("active PI (paper)", lambda: ActivePI(n_operators)),
        ("generalized PI", lambda: GeneralizedPI(n_operators)),
    ]
    t, d_des = fixed["t"], fixed["d_des"]
    rows = []
    for excitation, rec in records.items():
        for name, make in makers:
            model = make().fit(rec.voltage, rec.charge, t=rec.t)
            comp = Compensator(model, v_min=0.0, v_max=p.v_max, domain="displacement", gain=gain,
                               sample_rate=p.rate)  # fmt: skip
            command = _said_by(f"{name}, identified on {excitation}", comp.process, d_des)
            run = simulate(command, t, preset=preset, seed=seed + 400)
            rows.append(
                {
                    "model": name,
                    "excitation": excitation,
                    "train_nrmse_pct": 100 * model.nrmse_,
                    "heldout_nrmse_pct": 100
                    * nrmse(valid.charge, model.predict(valid.voltage, t=valid.t)),
                    "width_after_S_pct": 100 * hysteresis_width(d_des, run.displacement),
                    "tracking_nrmse_after_S_pct": 100 * nrmse(d_des, run.displacement),
                    "held_voltage_pct": 100 * comp.saturated_count / max(comp.sent_count, 1),
                    "held_slew_pct": 100 * comp.slew_limited_count / max(comp.command_count, 1),
                    "growth": _growth_text(model),
                }
            )
    return rows


def _said_by(who: str, work: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``work(*args, **kwargs)``, each warning it gives said again with ``who`` in front (a report
    runs many compensators: a limit that bites names the one it bit)."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        out = work(*args, **kwargs)
    for w in said:
        warn(f"{who}: {w.message}", w.category)
    return out


def _minor_loop_study(*, gain: float, seed: int, preset: str) -> dict[str, Any]:
    """Beyond PI: each model identified on 40 s of decaying loops (loops of many sizes),
    held out on another 40 s at a smaller amplitude, then compensating 20 s of decaying
    loops on the bench (desired displacement, laser for checking only) and a steady loop.

    Prandtl-Ishlinskii minor loops are congruent copies fixed by the major loop; the
    bench's Preisach capacitor's are not. The bench starts at rest at 0 V, where every
    model's training record started too.
    """
    p = PRESETS[preset]
    train = simulate(preset=preset, signal="decaying", duration=40.0, seed=seed)
    held = simulate(preset=preset, signal="decaying", duration=40.0, seed=seed + 1,
                    amplitude=0.9 * p.v_max)  # fmt: skip
    _, shape = make_signal("decaying", amplitude=1.0, duration=20.0, rate=p.rate)
    _, steady = make_signal("fixed", amplitude=1.0, frequency=1.0, duration=20.0, rate=p.rate)
    makers: list[tuple[str, Callable[[], HysteresisModel]]] = [
        ("active PI (paper)", lambda: ActivePI(20)),
        ("Preisach", lambda: PreisachModel()),
        ("Duhem", lambda: DuhemModel()),
        ("Bouc-Wen", lambda: BoucWenModel()),
    ]
    rows = []
    for name, make in makers:
        began = time.perf_counter()
        model = make().fit(train.voltage, train.charge, t=train.t)
        seconds = time.perf_counter() - began
        hi = model.input_range_[1]
        with warnings.catch_warnings():  # the major loop's low end lies beyond decaying loops
            warnings.simplefilter("ignore", ExtrapolationWarning)
            sweep = np.concatenate([np.linspace(0.0, hi, 2000), np.linspace(hi, 0.0, 2000)])
            ramp = model.hysteresis_.predict(sweep)
        top, bottom = float(ramp[1999]), float(ramp[-1])
        widths: dict[str, float] = {}
        outside: dict[str, int] = {}
        for label, form in (("decaying", shape), ("steady", 0.5 + 0.3 * steady)):
            q_des = bottom + (top - bottom) * (0.05 + 0.9 * form)
            comp = Compensator(model, v_min=0.0, v_max=hi, domain="displacement", gain=gain)
            command = comp.process(gain * q_des)
            run = simulate(np.concatenate([[0.0], command]), np.arange(command.size + 1) / p.rate,
                           preset=preset, seed=seed + 2)  # fmt: skip
            keep = slice(0, None) if label == "decaying" else slice(int(2 * p.rate), None)
            widths[label] = 100 * hysteresis_width(gain * q_des[keep], run.displacement[1:][keep])
            outside[label] = int(getattr(comp, "outside_count", 0))
        predicted = _said_by(f"minor loops, {name} on the held-out record", model.predict,
                             held.voltage, t=held.t)  # fmt: skip
        rows.append(
            {
                "model": name,
                "train_nrmse_pct": 100 * model.nrmse_,
                "heldout_nrmse_pct": 100 * nrmse(held.charge, predicted),
                "width_decaying_S_pct": widths["decaying"],
                "width_steady_S_pct": widths["steady"],
                "outside_region": outside,
                "fit_s": seconds,
            }
        )
    return {"rows": rows, "train_signal": "decaying", "train_duration_s": 40.0}


def _growth_text(model: HysteresisModel) -> str:
    growth = model.growth_coefficients()
    return ", ".join(f"{k} {v:.3g} {u}" for k, (v, u) in growth.items()) or "none"


def _excitation_study(preset: str, n_operators: int) -> list[dict[str, Any]]:
    """Identified vs true leakage for each excitation and record length."""
    rows = []
    for duration in (5.0, 10.0, 20.0):
        for signal in ("fixed", "multi", "triangle", "two-rate", "hold"):
            rec = simulate(preset=preset, signal=signal, duration=duration, seed=3)
            model = ActivePI(n_operators).fit(rec.voltage, rec.charge, t=rec.t)
            rows.append(
                {
                    "signal": signal,
                    "duration_s": duration,
                    "growth_rate_error_pct": 100 * (model.growth_rate_ / rec.true_growth_rate - 1),
                    "nrmse_pct": 100 * model.nrmse_,
                }
            )
    return rows


def _validation_split(model: ActivePI, rec: BenchRecord) -> dict[str, float]:
    """Held-out error of the hysteresis part and of the leakage part (% of span).

    Uses the bench's hidden truth: the capacitor charge and the leaked charge.
    """
    span = float(np.ptp(rec.charge))
    hyst = model.hysteresis_.predict(rec.voltage)
    err_h = (hyst - hyst[0]) - (rec.capacitor_charge - rec.capacitor_charge[0])
    err_g = model.growth(rec.voltage, t=rec.t) - rec.leak_charge
    return {
        "active_validation_hysteresis_part_pct": 100 * float(np.std(err_h)) / span,
        "active_validation_leakage_part_pct": 100 * float(np.sqrt(np.mean(err_g**2))) / span,
        "validation_true_effective_S": rec.true_growth_rate,
    }


def _calibration_gain(rec: BenchRecord, pure: FloatArray) -> float:
    """g (m/C) from one laser reading: the first hold at full voltage vs rest."""
    top = rec.voltage >= rec.preset.v_max - 1e-9
    first_hold = top & (np.cumsum(np.diff(top.astype(int), prepend=0) > 0) == 1)
    return float(np.mean(rec.displacement[first_hold]) / np.mean(pure[first_hold] - pure[0]))


def run_demo(
    out: str | Path = "demo-report",
    *,
    n_operators: int = 20,
    seed: int = 0,
    step: Step | None = None,
) -> DemoResult:
    """Run the paper's experiment on the built-in bench and write the report to ``out``.

    Parameters
    ----------
    out : path
        Folder for the figures, ``metrics.json`` and ``report.md`` (created).
    n_operators : int
        Play operators of both models.
    seed : int
        Seeds the bench's measurement noise.
    step : callable, optional
        Called with a short description before each stage (progress display).
    """
    n_operators = check_int(n_operators, "n_operators", "run_demo", 1, 1000)
    seed = check_int(seed, "seed", "run_demo", 0, 2**32 - 1)
    say: Step = step or (lambda _msg: None)
    started = time.perf_counter()
    out_dir = check_folder(out, "the figures, metrics.json and report.md")
    out_dir.mkdir(parents=True, exist_ok=True)
    preset = DEFAULT_PRESET
    p = PRESETS[preset]

    say("simulating the bench (identification and validation records)")
    ident = simulate(preset=preset, signal="hold", duration=20.0, seed=seed)
    valid = simulate(preset=preset, signal="multi", duration=12.0, seed=seed + 100)

    say("identifying ClassicalPI and ActivePI from voltage and charge")
    classical = ClassicalPI(n_operators).fit(ident.voltage, ident.charge)
    active = ActivePI(n_operators).fit(ident.voltage, ident.charge, t=ident.t)
    pred_c = classical.predict(valid.voltage)
    pred_a = active.predict(valid.voltage, t=valid.t)

    say("removing the leakage growth (eq. 19)")
    pure = active.remove_growth(ident.voltage, ident.charge, t=ident.t)
    true_qc = ident.capacitor_charge - ident.capacitor_charge[0]
    gain = _calibration_gain(ident, pure)
    static_gain = float(np.mean(ident.displacement[ident.voltage >= p.v_max - 1e-9]) / p.v_max)

    say("compensating a desired displacement through the inverse (eq. 18)")
    fixed = _compensation_run(
        active, "fixed", gain=gain, static_gain=static_gain, seed=seed + 200, preset=preset
    )
    multi = _compensation_run(
        active, "multi", gain=gain, static_gain=static_gain, seed=seed + 300, preset=preset
    )

    say("closing the loop on the measured charge (60 s, unseen bias current)")
    loop = _closed_loop_study(active, gain=gain, seed=seed + 700, preset=preset)

    say("identifying the amplifier's lag over several frequencies (rate)")
    rate = _rate_study(seed + 900, n_operators)

    say("learning a repeated scan from the charge (10 trials)")
    p_loop = dataclasses.replace(p, i_bias=p.i_bias + LOOP_EXTRA_BIAS)  # the loop's bench
    learned = learning_study(active, loop["calibrated"], preset=p_loop, gain=gain,
                             slew_rate=AMP_SLEW, seed=seed + 1300)  # fmt: skip

    say("comparing excitations and models")
    study = _excitation_study(preset, n_operators)
    comparison = _model_comparison(
        fixed, valid, gain=gain, n_operators=n_operators, seed=seed + 500, preset=preset
    )
    say("beyond PI: Preisach, Duhem and Bouc-Wen on loops of many sizes")
    minor = _minor_loop_study(gain=gain, seed=seed + 1100, preset=preset)

    metrics: dict[str, Any] = {
        "piezohyst_version": __version__,
        "preset": preset,
        "n_operators": n_operators,
        "seed": seed,
        "identification": {
            "signal": "hold",
            "duration_s": float(ident.t[-1] + 1 / p.rate),
            "classical_nrmse_pct": 100 * classical.nrmse_,
            "active_nrmse_pct": 100 * active.nrmse_,
            "validation_signal": "multi",
            "classical_validation_nrmse_pct": 100 * nrmse(valid.charge, pred_c),
            "active_validation_nrmse_pct": 100 * nrmse(valid.charge, pred_a),
            **_validation_split(active, valid),
        },
        "leakage": {
            "identified_S": active.growth_rate_,
            "true_effective_S": ident.true_growth_rate,
            "nominal_at_0V_S": p.g_leak,
            "error_pct": 100 * (active.growth_rate_ / ident.true_growth_rate - 1),
            "growth_removed_vs_true_capacitor_nrmse_pct": 100 * nrmse(true_qc, pure),
        },
        "calibration": {"gain_m_per_C": gain, "true_gain_m_per_C": p.gain},
        "compensation_fixed": fixed["metrics"],
        "compensation_multi": multi["metrics"],
        "excitation_study": study,
        "model_comparison": comparison,
        "minor_loops": minor,
        "rate": {
            "preset": RATE_PRESET,
            "bench_lag_s": rate["bench_lag_s"],
            "identified": rate["dynamics"],
            "runs": {
                name: {k: v for k, v in row.items() if k.endswith("_pct")}
                for name, row in rate["rows"].items()
            },
        },
        "closed_loop": {
            "trajectory": "decaying, 60 s, 0.5 Hz",
            "extra_bias_A": loop["extra_bias_A"],
            "calibration_levels_V": loop["calibration_levels_V"],
            "calibration_hold_s": CALIBRATION_HOLD,
            "leakage_identified": loop["identified"].coefficients(),
            "leakage_calibrated": loop["calibrated"].coefficients(),
            "leakage_true_at_0V_S": loop["true"]["conductance"],
            "leakage_true_quadratic_S": loop["true"]["quadratic"],
            "bias_A": loop["bias_A"],
            "true_tau_s": loop["true"]["tau"],
            "calibration_residual_A": loop["calibrated"].residual,
            "runs": {
                name: {k: v for k, v in run.items() if k != "record"}
                for name, run in loop["runs"].items()
            },
        },
    }

    say("writing figures and report")
    files = _figures(out_dir, ident, valid, classical, active, pred_c, pred_a, pure, fixed, multi)
    files.append(_loop_figure(out_dir, loop))
    files.append(_rate_figure(out_dir, rate))
    files.append(learning_figure(out_dir, learned))
    metrics["learning"] = {k: learned[k] for k in ("rows", "design", "rollbacks")}
    metrics["runtime_s"] = time.perf_counter() - started
    mpath = out_dir / "metrics.json"
    atomic_write_text(mpath, json.dumps(metrics, indent=2) + "\n")
    rpath = out_dir / "report.md"
    atomic_write_text(rpath, render_report(metrics))
    return DemoResult(metrics=metrics, files=[*files, mpath, rpath])


def _figures(
    out: Path,
    ident: BenchRecord,
    valid: BenchRecord,
    classical: ClassicalPI,
    active: ActivePI,
    pred_c: FloatArray,
    pred_a: FloatArray,
    pure: FloatArray,
    fixed: dict[str, Any],
    multi: dict[str, Any],
) -> list[Path]:
    v, vv = ident.voltage, valid.voltage
    meas = {"color": "0.6", "lw": 2.2}
    dashed = {"lw": 1.0, "ls": "--", "color": "C1"}
    dotted = {"lw": 1.1, "ls": ":", "color": "C0"}
    files = [
        save_panels(
            out / "fig2_active_hysteresis.png",
            [
                {
                    "curves": [(v, ident.charge * UC, "measured charge", {"lw": 0.9})],
                    "xlabel": "voltage (V)",
                    "ylabel": "charge (µC)",
                    "title": "voltage → measured charge: loops climb with leakage",
                },
                {
                    "curves": [(ident.t, ident.charge * UC, "measured charge", {"lw": 0.9})],
                    "xlabel": "time (s)",
                    "ylabel": "charge (µC)",
                    "title": "identification record (hold excitation)",
                },
            ],
            suptitle="Fig. 2 — active hysteresis in the electrical domain (simulated T226-H4-203X)",
        ),
        save_grid(
            out / "fig7_estimation.png",
            [
                [
                    {
                        "curves": [
                            (v, ident.charge * UC, "measured", meas),
                            (v, classical.predict(v) * UC, "classical PI", dotted),
                            (v, active.predict(v, t=ident.t) * UC, "active PI", dashed),
                        ],
                        "xlabel": "voltage (V)",
                        "ylabel": "charge (µC)",
                        "title": "fixed amplitude 140 V (training record)",
                    },
                    {
                        "curves": [
                            (vv, valid.charge * UC, "measured", meas),
                            (vv, pred_c * UC, "classical PI", dotted),
                            (vv, pred_a * UC, "active PI", dashed),
                        ],
                        "xlabel": "voltage (V)",
                        "ylabel": "charge (µC)",
                        "title": "multi-amplitude (held-out record)",
                    },
                ],
                [
                    {
                        "curves": [
                            (
                                ident.t,
                                (ident.charge - classical.predict(v)) * UN,
                                "classical PI",
                                {**dotted, "lw": 0.8},
                            ),
                            (
                                ident.t,
                                (ident.charge - active.predict(v, t=ident.t)) * UN,
                                "active PI",
                                {**dashed, "ls": "-", "lw": 0.6},
                            ),
                        ],
                        "xlabel": "time (s)",
                        "ylabel": "measured - model (nC)",
                        "title": "residuals, training record",
                    },
                    {
                        "curves": [
                            (
                                valid.t,
                                (valid.charge - pred_c) * UN,
                                "classical PI",
                                {**dotted, "lw": 0.8},
                            ),
                            (
                                valid.t,
                                (valid.charge - pred_a) * UN,
                                "active PI",
                                {**dashed, "ls": "-", "lw": 0.6},
                            ),
                        ],
                        "xlabel": "time (s)",
                        "ylabel": "measured - model (nC)",
                        "title": "residuals, held-out record",
                    },
                ],
            ],
            suptitle="Fig. 7 — active hysteresis estimation (measured grey, models over it)",
            height_ratios=[2.0, 1.2],
        ),
        save_panels(
            out / "fig8_growth_removed.png",
            [
                {
                    "curves": [
                        (v, ident.charge * UC, "measured (with leakage)", {"lw": 0.7}),
                        (v, pure * UC, "growth removed, eq. 19", {"lw": 1.2}),
                        (
                            v,
                            (ident.capacitor_charge - ident.capacitor_charge[0]) * UC,
                            "true capacitor charge",
                            {"lw": 0.8, "ls": ":", "color": "k"},
                        ),
                    ],
                    "xlabel": "voltage (V)",
                    "ylabel": "charge (µC)",
                    "title": "identified growth R·∫V dt removed",
                }
            ],
            suptitle="Fig. 8 — numerically compensated growth rate",
        ),
    ]
    pairs = (("fig9_compensation_charge.png", "Q"), ("fig10_compensation_displacement.png", "S"))
    for name, domain in pairs:
        panels = []
        for run, label in ((fixed, "fixed amplitude"), (multi, "multi-amplitude")):
            if domain == "Q":
                des, after, before = run["q_des"] * UC, run["q_comp"] * UC, run["q_base"] * UC
                unit = "charge (µC)"
            else:
                des = run["d_des"] * UM
                after = run["comp"].displacement * UM
                before = run["base"].displacement * UM
                unit = "displacement (µm)"
            panels.append(
                {
                    "curves": [
                        (des, before, "uncompensated (linear command)", {"lw": 0.8, "color": "C3"}),
                        (des, after, "compensated (inverse active PI)", {"lw": 1.0, "color": "C0"}),
                    ],
                    "xlabel": f"desired {unit}",
                    "ylabel": f"actual {unit}",
                    "title": label,
                    "identity": True,
                }
            )
        title = (
            "Fig. 9 — hysteresis compensation in the electrical domain (growth removed)"
            if domain == "Q"
            else "Fig. 10 — compensated hysteresis in the mechanical domain (laser, check only)"
        )
        files.append(save_panels(out / name, panels, suptitle=title))
    return files


def _loop_figure(out: Path, loop: dict[str, Any]) -> Path:
    """Desired vs actual displacement for each run, and the tracking error over time."""
    d_des = loop["d_des"] * UM
    colours = {"feedforward": "C3", "closed loop, identified leakage": "C1"}
    loops: list[dict[str, object]] = []
    errors = []
    for name, run in loop["runs"].items():
        s = run["record"].displacement * UM
        colour = colours.get(name, "C0")
        loops.append(
            {
                "curves": [(d_des, s, name, {"lw": 0.6, "color": colour})],
                "xlabel": "desired displacement (µm)",
                "ylabel": "actual displacement (µm)",
                "title": f"{name}: width {run['width_S_pct']:.2f} %",
                "identity": True,
            }
        )
        errors.append((loop["t"], s - d_des, name, {"lw": 0.6, "color": colour}))
    error_row: list[dict[str, object]] = [
        {
            "curves": errors,
            "xlabel": "time (s)",
            "ylabel": "actual - desired (µm)",
            "title": "tracking error (the identified leakage misses the bias current: drift)",
        },
        {
            "curves": errors[2:],
            "xlabel": "time (s)",
            "ylabel": "actual - desired (µm)",
            "title": "tracking error, hold-calibrated loop alone",
        },
        {
            "curves": [errors[0]],
            "xlabel": "time (s)",
            "ylabel": "actual - desired (µm)",
            "title": "tracking error, feedforward alone",
        },
    ]
    return save_grid(
        out / "fig11_self_sensing_loop.png",
        [loops, error_row],
        suptitle=(
            "Fig. 11 — self-sensing closed loop on the measured charge (laser for checking only), "
            f"60 s decaying loops, +{loop['extra_bias_A'] * 1e12:.0f} pA bias never identified"
        ),
        height_ratios=[2.0, 1.2],
    )


def _rate_figure(out: Path, rate: dict[str, Any]) -> Path:
    """40 Hz: predicted charge loops, and compensated displacement, for both models."""
    check = rate["check"]
    keep = rate["keep"]
    desired = rate["desired"][keep] * UC
    colours = {"identified at 1 Hz": "C3", "rate-aware, 0.5-20 Hz": "C0"}
    measured = (check.voltage, check.charge * UC, "measured", {"color": "0.6", "lw": 2.0})
    predicted = []
    compensated = []
    for name, row in rate["rows"].items():
        dashed = {"color": colours[name], "lw": 0.8, "ls": "--"}
        predicted.append(
            (check.voltage, row["predicted"] * UC, f"{name}: {row['nrmse_40Hz_pct']:.1f} %", dashed)
        )
        label = f"{name}: width {row['width_40Hz_pct']:.1f} %"
        solid = {"color": colours[name], "lw": 0.8}
        moved = row["displacement"][keep]
        compensated.append((desired, (moved - moved.mean()) * UM, label, solid))
    predict_panel: dict[str, object] = {
        "curves": [measured, *predicted],
        "xlabel": "commanded voltage (V)",
        "ylabel": "charge (µC)",
        "title": "a new 40 Hz record, predicted (NRMSE)",
    }
    comp_panel: dict[str, object] = {
        "curves": compensated,
        "xlabel": "desired charge (µC)",
        "ylabel": "actual displacement, mean removed (µm)",
        "title": "compensated 40 Hz trajectory (laser, check only)",
    }
    dyn = rate["dynamics"]
    return save_panels(
        out / "fig12_rate.png",
        [predict_panel, comp_panel],
        suptitle=(
            f"Fig. 12 — a 4 ms amplifier lag at 40 Hz: found {dyn['tau'] * 1e3:.2f} ms from "
            "0.5-20 Hz data; a 1 Hz model folds it into its hysteresis"
        ),
    )
