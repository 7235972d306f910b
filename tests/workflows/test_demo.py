"""`piezohyst demo`: the main job meets the issue's targets, run as a user runs it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from piezohyst.cli import main


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("demo") / "report"
    result = CliRunner().invoke(main, ["demo", "--out", str(out)])
    assert result.exit_code == 0, result.output
    (out.parent / "console.txt").write_text(result.output)  # what the user saw
    return out, json.loads((out / "metrics.json").read_text())


def test_demo_writes_report_and_figures(demo_run: tuple[Path, dict[str, Any]]) -> None:
    out, _ = demo_run
    for name in (
        "fig2_active_hysteresis.png",
        "fig7_estimation.png",
        "fig8_growth_removed.png",
        "fig9_compensation_charge.png",
        "fig10_compensation_displacement.png",
        "metrics.json",
        "report.md",
    ):
        path = out / name
        assert path.stat().st_size > 1000 if name.endswith(".png") else path.stat().st_size > 0
    report = (out / "report.md").read_text()
    assert "| active PI NRMSE" in report and "hysteresis width" in report


def test_demo_identification_targets(demo_run: tuple[Path, dict[str, Any]]) -> None:
    _, m = demo_run
    ident = m["identification"]
    assert ident["active_nrmse_pct"] <= 1.0
    assert ident["classical_nrmse_pct"] >= 3 * ident["active_nrmse_pct"]
    assert abs(m["leakage"]["error_pct"]) <= 10.0


def test_demo_compensation_targets(demo_run: tuple[Path, dict[str, Any]]) -> None:
    _, m = demo_run
    c = m["compensation_fixed"]
    assert c["width_before_V_to_Q_pct"] >= 10.0
    assert c["width_before_V_to_S_pct"] >= 10.0
    assert c["width_after_Q_pct"] <= 1.5
    assert c["width_after_S_pct"] <= 1.5
    assert c["tracking_nrmse_after_S_pct"] < c["tracking_nrmse_before_S_pct"] / 3
    lo, hi = c["command_range_V"]
    assert 0.0 <= lo and hi <= 140.0


def test_demo_compares_the_models(demo_run: tuple[Path, dict[str, Any]]) -> None:
    out, m = demo_run
    rows = m["model_comparison"]
    assert {(r["model"], r["excitation"]) for r in rows} == {
        (model, exc)
        for model in ("classical PI", "active PI (paper)", "generalized PI")
        for exc in ("hold", "levels")
    }
    by = {(r["model"], r["excitation"]): r for r in rows}
    # the active family beats the classical model, and every active-family model compensates
    for exc in ("hold", "levels"):
        for model in ("active PI (paper)", "generalized PI"):
            assert (
                by[(model, exc)]["heldout_nrmse_pct"]
                < by[("classical PI", exc)]["heldout_nrmse_pct"] / 3
            )
            assert by[(model, exc)]["width_after_S_pct"] <= 1.5
    assert "## Model comparison" in (out / "report.md").read_text()


def test_the_limits_that_bite_name_the_model_they_bit(
    demo_run: tuple[Path, dict[str, Any]],
) -> None:
    """The classical model's charge drifts, so its compensator asks for voltages beyond the
    bench's: the report's column counts what the limits held, and the console's warnings say
    whose commands they were."""
    out, m = demo_run
    by = {(r["model"], r["excitation"]): r for r in m["model_comparison"]}
    for exc in ("hold", "levels"):
        classical = by[("classical PI", exc)]
        assert classical["held_voltage_pct"] + classical["held_slew_pct"] > 1.0  # it bit
        for model in ("active PI (paper)", "generalized PI"):
            assert by[(model, exc)]["held_voltage_pct"] + by[(model, exc)]["held_slew_pct"] < 1.0
    assert "held: voltage / slew" in (out / "report.md").read_text()
    said = [line for line in (out.parent / "console.txt").read_text().splitlines()
            if "limit" in line and "held" in line]  # fmt: skip
    assert said  # a limit that bites says so
    assert all(line.startswith("warning: classical PI, identified on ") for line in said), said
    # and every warning the demo prints names what it is about (the extrapolations too)
    warned = [line for line in (out.parent / "console.txt").read_text().splitlines()
              if line.startswith("warning:")]  # fmt: skip
    named = ("warning: classical PI, identified on ", "warning: minor loops, ")
    assert all(line.startswith(named) for line in warned), warned


def test_demo_goes_beyond_pi_on_minor_loops(demo_run: tuple[Path, dict[str, Any]]) -> None:
    """Issue 11: a model identified on loops of many sizes compensates decaying minor loops
    of the non-PI (Preisach) capacitor to <= 1 % width, better than the paper's model."""
    out, m = demo_run
    rows = {r["model"]: r for r in m["minor_loops"]["rows"]}
    assert set(rows) == {"active PI (paper)", "Preisach", "Duhem", "Bouc-Wen"}
    preisach, active = rows["Preisach"], rows["active PI (paper)"]
    assert preisach["width_decaying_S_pct"] <= 1.0
    # 0.80 % against 1.09 %: 0.69 % when the fit's first rise followed a branch, before the
    # initial loading curve (the bench's own rest: demagnetised at 0 V) became the default on
    # a tie. With it the model predicts the held-out loops better (0.44 % against 0.53 %), and
    # its own major loop, which sets each model's desired range here, ends higher
    assert preisach["width_decaying_S_pct"] < 0.8 * active["width_decaying_S_pct"]
    assert preisach["train_nrmse_pct"] < active["train_nrmse_pct"]
    for r in rows.values():
        assert r["heldout_nrmse_pct"] < 3.0 and r["width_steady_S_pct"] < 3.0
    assert "## Beyond Prandtl-Ishlinskii" in (out / "report.md").read_text()


def test_demo_closed_loop_targets(demo_run: tuple[Path, dict[str, Any]]) -> None:
    out, m = demo_run
    cl = m["closed_loop"]
    runs = cl["runs"]
    ff = runs["feedforward"]
    ident = runs["closed loop, identified leakage"]
    cal = runs["closed loop, hold-calibrated leakage"]
    # issue 10: hold-calibrated loop <= 0.3 % width and tracking, no drift; identified <= 1.2 %
    assert cal["width_S_pct"] <= 0.3 and cal["tracking_nrmse_S_pct"] <= 0.3
    # no drift: the last 20 s as good as the first, to the noise floor (benchmarks: +-0.003 %)
    assert cal["last_20s_nrmse_S_pct"] <= cal["first_20s_nrmse_S_pct"] + 0.005
    assert ident["width_S_pct"] <= 1.2
    assert cal["width_S_pct"] < ff["width_S_pct"] / 3
    assert cal["samples_saturated"] == 0
    # the calibration finds the bench's leakage, bias and reference time constant
    calibrated = cl["leakage_calibrated"]
    # tol: the conductance from the demo's 20 s holds: within 2 %
    assert calibrated["conductance"][0] == pytest.approx(cl["leakage_true_at_0V_S"], rel=0.02)
    # tol: estimates from the demo's noisy holds: the bias current is near the noise (25 %), the
    # discharge constant is seen through short holds (15 %)
    assert calibrated["bias"][0] == pytest.approx(cl["bias_A"], rel=0.25)
    # tol: estimates from the demo's noisy holds: the bias current is near the noise (25 %), the
    # discharge constant is seen through short holds (15 %)
    assert 1 / calibrated["discharge"][0] == pytest.approx(cl["true_tau_s"], rel=0.15)
    assert (out / "fig11_self_sensing_loop.png").stat().st_size > 1000
    assert "## Self-sensing closed loop" in (out / "report.md").read_text()


def test_demo_rate_targets(demo_run: tuple[Path, dict[str, Any]]) -> None:
    out, m = demo_run
    rate = m["rate"]
    # tol: a lag identified from a noisy multi-frequency record scatters by a few percent
    assert rate["identified"]["tau"] == pytest.approx(rate["bench_lag_s"], rel=0.1)
    aware = rate["runs"]["rate-aware, 0.5-20 Hz"]
    slow = rate["runs"]["identified at 1 Hz"]
    assert aware["nrmse_40Hz_pct"] <= 2.5 and aware["width_40Hz_pct"] <= 2.0
    assert slow["nrmse_40Hz_pct"] > 4 * aware["nrmse_40Hz_pct"]
    assert slow["width_40Hz_pct"] > 10 * aware["width_40Hz_pct"]
    assert (out / "fig12_rate.png").stat().st_size > 1000
