"""The demo's report: Markdown from the metrics :func:`~piezohyst.workflows.demo.run_demo`
writes (kept apart from the experiment, which it only reads)."""

from __future__ import annotations

from typing import Any

from .demo_learning import learning_report

__all__ = ["render_report"]


def render_report(m: dict[str, Any]) -> str:
    """The Markdown report for a metrics dictionary from :func:`run_demo`."""
    ident, leak = m["identification"], m["leakage"]
    cf, cm = m["compensation_fixed"], m["compensation_multi"]
    lines = [
        "# piezohyst demo: sensorless hysteresis compensation on the simulated bench",
        "",
        f"piezohyst {m['piezohyst_version']}, preset {m['preset']}, {m['n_operators']} play "
        f"operators, seed {m['seed']}, {m['runtime_s']:.1f} s. Identification used voltage and "
        "charge only; the laser was read once, for the charge-to-displacement gain.",
        "",
        "## Results",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| classical PI NRMSE, training / held-out | {ident['classical_nrmse_pct']:.2f} % / "
        f"{ident['classical_validation_nrmse_pct']:.2f} % |",
        f"| active PI NRMSE, training / held-out | {ident['active_nrmse_pct']:.3f} % / "
        f"{ident['active_validation_nrmse_pct']:.3f} % |",
        f"| leakage R identified / true (effective) | {leak['identified_S']:.4g} S / "
        f"{leak['true_effective_S']:.4g} S ({leak['error_pct']:+.2f} %) |",
        f"| growth-removed charge vs true capacitor charge, NRMSE | "
        f"{leak['growth_removed_vs_true_capacitor_nrmse_pct']:.3f} % |",
        f"| hysteresis width V→Q before compensation | {cf['width_before_V_to_Q_pct']:.1f} % |",
        f"| hysteresis width V→S before compensation | {cf['width_before_V_to_S_pct']:.1f} % |",
        f"| hysteresis width desired→actual Q after | {cf['width_after_Q_pct']:.2f} % |",
        f"| hysteresis width desired→actual S after | {cf['width_after_S_pct']:.2f} % |",
        f"| displacement tracking NRMSE before / after | {cf['tracking_nrmse_before_S_pct']:.2f} %"
        f" / {cf['tracking_nrmse_after_S_pct']:.2f} % |",
        f"| largest displacement error before / after | {cf['max_error_before_S_um']:.1f} µm / "
        f"{cf['max_error_after_S_um']:.1f} µm |",
        "",
        f"On the held-out multi-amplitude record the hysteresis part is off by "
        f"{ident['active_validation_hysteresis_part_pct']:.2f} % of span and the leakage part by "
        f"{ident['active_validation_leakage_part_pct']:.2f} %: the bench's leakage conductance "
        "depends on the voltage (as the paper reports for real piezos), so the one constant R "
        f"found at full amplitude ({leak['identified_S']:.3g} S) overstates a smaller drive's "
        f"({ident['validation_true_effective_S']:.3g} S).",
        "",
        "Widths are the largest gap between rising and falling branches as a percentage of the "
        "output span, for a fixed-amplitude desired trajectory (Figs. 9-10, left). For the "
        f"multi-amplitude trajectory (right): V→S {cm['width_before_V_to_S_pct']:.1f} % before, "
        f"desired→S {cm['width_after_S_pct']:.2f} % and desired→Q "
        f"{cm['width_after_Q_pct']:.2f} % after.",
        "",
        "![Fig. 10](fig10_compensation_displacement.png)",
        "",
        "## Which excitation identifies the leakage",
        "",
        "Hysteresis is rate independent, leakage is not. Identified growth rate error against the "
        "bench's true effective leakage conductance (seed 3):",
        "",
        "| excitation | 5 s | 10 s | 20 s |",
        "|---|---|---|---|",
    ]
    study = m["excitation_study"]
    for signal in dict.fromkeys(r["signal"] for r in study):
        cells = [f"{r['growth_rate_error_pct']:+.2f} %" for r in study if r["signal"] == signal]
        lines.append(f"| {signal} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Model comparison",
        "",
        "Each model identified from voltage and charge on an identification record, scored on "
        "the held-out multi-amplitude record, then used through `Compensator` to drive the "
        "fixed-amplitude desired displacement on the bench (laser for checking only). "
        "`levels` holds at several voltages, which lets the generalized model tell "
        "voltage-dependent leakage from ohmic leakage. 'Held': the commands the voltage "
        "limits (0 V, the bench's maximum) and the slew limit (by default the training "
        "record's fastest change) held back, of all the compensator gave: a model whose "
        "charge drifts asks for voltages beyond them.",
        "",
        "| model | identified on | training NRMSE | held-out NRMSE | compensated width S "
        "| tracking NRMSE S | held: voltage / slew | growth |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in m["model_comparison"]:
        lines.append(
            f"| {r['model']} | {r['excitation']} | {r['train_nrmse_pct']:.3f} % | "
            f"{r['heldout_nrmse_pct']:.3f} % | {r['width_after_S_pct']:.2f} % | "
            f"{r['tracking_nrmse_after_S_pct']:.2f} % | {r['held_voltage_pct']:.1f} % / "
            f"{r['held_slew_pct']:.1f} % | {r['growth']} |"
        )
    ml = m["minor_loops"]
    lines += [
        "",
        "## Beyond Prandtl-Ishlinskii: minor loops",
        "",
        "A PI model's minor loops are congruent copies fixed by its major loop; the bench's "
        "Preisach capacitor's are not. Each model identified on 40 s of `decaying` loops (loops "
        "of many sizes at several places in the major loop), scored on another 40 s at 90 % of "
        "the amplitude, then compensating 20 s of decaying loops and 20 s of a steady 1 Hz loop "
        "between 20 and 80 % of the span after its first two cycles (desired displacement; laser "
        "for checking only).",
        "",
        "| model | training NRMSE | held-out NRMSE | width, decaying loops | width, steady loop "
        "| fit time |",
        "|---|---|---|---|---|---|",
    ]
    for r in ml["rows"]:
        lines.append(
            f"| {r['model']} | {r['train_nrmse_pct']:.3f} % | {r['heldout_nrmse_pct']:.3f} % | "
            f"{r['width_decaying_S_pct']:.2f} % | {r['width_steady_S_pct']:.2f} % | "
            f"{r['fit_s']:.2f} s |"
        )
    lines += [
        "",
        "Preisach learns where in the major loop each minor loop sits (its loops close, and "
        "are not copies of each other) and halves the paper's model's width on the decaying "
        "loops; a steady loop far larger than most the record holds is interpolated between the "
        "reversal pairs it saw, and every model leaves about the same there. The Duhem and "
        "Bouc-Wen models fit less well on this capacitor (see `docs/validation.md` for where "
        "they win).",
    ]
    rt = m["rate"]
    lines += [
        "",
        "## Rate: the amplifier's lag",
        "",
        f"On `{rt['preset']}` the amplifier charges the piezo with a "
        f"{rt['bench_lag_s'] * 1e3:g} ms lag and the record logs the command. A model identified "
        'at 1 Hz folds the lag into its hysteresis; `input_dynamics="auto"` on 30 s at '
        f"0.5, 5 and 20 Hz found a {rt['identified']['kind']} lag of "
        f"{rt['identified']['tau'] * 1e3:.3f} ms (delay {rt['identified']['delay'] * 1e3:.3f} ms).",
        "",
        "| model | new 40 Hz record, NRMSE | 40 Hz compensation, width (25-75 % of span) |",
        "|---|---|---|",
    ]
    for name, run in rt["runs"].items():
        lines.append(f"| {name} | {run['nrmse_40Hz_pct']:.2f} % | {run['width_40Hz_pct']:.2f} % |")
    lines += ["", "![Fig. 12](fig12_rate.png)"]
    cl = m["closed_loop"]
    lines += [
        "",
        "## Self-sensing closed loop",
        "",
        "Feedforward is limited by the model class: a PI model's minor loops are congruent, the "
        "bench's are not. `SelfSensingController` adds feedback on the measured charge minus the "
        "leaked charge (no position sensor). The loop's bench has a bias current "
        f"{cl['extra_bias_A'] * 1e12:.0f} pA larger than the identification's; a hold record "
        f"(holds at {', '.join(f'{v:g}' for v in cl['calibration_levels_V'])} V, "
        f"{cl['calibration_hold_s']:g} s each) on "
        "that bench calibrates the leakage. Desired: 60 s of loops decaying around moving "
        "centres (`decaying`); the laser only checks. The first and last 20 s are scored "
        "against the whole trajectory's span (the first 20 s also rise from rest).",
        "",
        "| run | width desired→S | tracking NRMSE S | RMS error, first 20 s | last 20 s |",
        "|---|---|---|---|---|",
    ]
    for name, run in cl["runs"].items():
        lines.append(
            f"| {name} | {run['width_S_pct']:.3f} % | {run['tracking_nrmse_S_pct']:.3f} % | "
            f"{run['first_20s_nrmse_S_pct']:.3f} % | {run['last_20s_nrmse_S_pct']:.3f} % |"
        )
    ci, cc = cl["leakage_identified"], cl["leakage_calibrated"]
    lines += [
        "",
        f"Leakage identified by the model from cycling: {ci['conductance'][0]:.4g} S, no bias "
        f"term; calibrated from the holds: {cc['conductance'][0]:.4g} S + "
        f"{cc['quadratic'][0]:.4g} S·v|v|/s + {cc['bias'][0] * 1e12:.1f} pA"
        + (f" - q/{1 / cc['discharge'][0]:.3g} s" if cc["discharge"][0] > 0 else ", no discharge")
        + f" (the bench: {cl['leakage_true_at_0V_S']:.3g} S at 0 V "
        f"+ {cl['leakage_true_quadratic_S']:.3g} S·v|v|/s, {cl['bias_A'] * 1e12:.0f} pA bias, "
        f"reference capacitor discharging in {cl['true_tau_s']:.3g} s). With the identified "
        "leakage the loop holds the "
        "*corrected* charge exactly, so the unseen bias current integrates into a drift of the "
        "real position: the loops stay thin but wander. Hence the leakage from holds.",
        "",
        "![Fig. 11](fig11_self_sensing_loop.png)",
        *(learning_report(m["learning"]) if "learning" in m else []),
        "",
        "## Figures",
        "",
        "- `fig2_active_hysteresis.png` — measured voltage→charge (Fig. 2)",
        "- `fig7_estimation.png` — classical vs active PI, fixed and multi-amplitude (Fig. 7)",
        "- `fig8_growth_removed.png` — growth removal, eq. 19 (Fig. 8)",
        "- `fig9_compensation_charge.png` — compensation, electrical domain (Fig. 9)",
        "- `fig10_compensation_displacement.png` — compensation, mechanical domain (Fig. 10)",
        "- `fig11_self_sensing_loop.png` — feedforward vs the self-sensing closed loop",
        "- `fig12_rate.png` — an amplifier's lag at 40 Hz, folded into hysteresis or identified",
        "- `fig13_learning.png` — a repeated scan learned from the charge, trial by trial",
        "",
    ]
    return "\n".join(lines)
