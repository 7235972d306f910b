"""A lab's own model standing in for its actuator in a loop (issue 55, item 6): simulate-loop
drove only the built-in bench, and printed "tracking NRMSE 619 %" for a lab's model without
saying the bench is another actuator."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.simulation import ModelPlant, run_on_model

from ..helpers import run

RATE = 1000.0


@pytest.fixture(scope="module")
def fitted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, ph.HysteresisModel, object]:
    d = tmp_path_factory.mktemp("plant")
    rec = ph.simulate(signal="decaying", duration=10.0, seed=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's own notes are not under test
        model = ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)
    model.save(d / "model.json")
    lo, hi = model.input_range_
    t = np.arange(4000) / RATE
    v = lo + (hi - lo) * (0.1 + 0.4 * (1 - np.cos(2 * np.pi * 0.25 * t)))  # within its slew
    desired = model.hysteresis_.predict(v)  # outputs a slow scan reaches
    ph.write_table(d / "target.csv", {"time": t, "desired": desired},
                   units={"time": "s", "desired": "C"})  # fmt: skip
    return d, model, desired


def test_a_model_is_the_exact_plant_of_its_own_compensator(fitted: tuple) -> None:
    """The feedforward compensator of a model, run on that model: the hysteresis part follows
    the target to rounding (the compensator inverts exactly what the plant computes)."""
    _, model, desired = fitted
    lo, hi = model.input_range_
    comp = ph.Compensator(model, v_min=lo, v_max=hi, sample_rate=RATE)
    plant = ModelPlant(model, RATE, voltage=comp.last_command)
    out = run_on_model(comp, desired, plant)
    assert comp.saturated_count == 0
    span = float(np.ptp(desired))
    arrived = comp.sent_count - comp.command_count  # the ramp from rest at the slew limit
    assert 0 < arrived < 200
    # tol: eq. 18's inverse and the forward sum round per sample, 1e-12 of the span each
    assert np.max(np.abs(out.hysteresis[arrived:] - desired[arrived:])) <= 1e-9 * span
    assert np.all(np.isnan(out.displacement))  # a charge model without a gain: no metres
    assert np.max(np.abs(out.charge - out.hysteresis)) > 1e-3 * span  # the leak's growth


def test_sample_by_sample_equals_one_run(fitted: tuple) -> None:
    _, model, _ = fitted
    v = np.linspace(0, 1, 400) ** 2 * 0.9 * model.input_range_[1]
    one = ModelPlant(model, RATE, gain=2.0e3).run(v)
    plant = ModelPlant(model, RATE, gain=2.0e3)
    rows = [plant.apply(float(x)) for x in v]
    for name in ("t", "charge", "hysteresis", "displacement"):
        each = np.concatenate([getattr(r, name) for r in rows])
        # tol: the same arithmetic, one sample at a time; states carried exactly
        assert np.allclose(each, getattr(one, name), rtol=1e-12, atol=0), name
    assert np.allclose(one.displacement, 2.0e3 * one.hysteresis, rtol=1e-15, atol=0)


def test_a_displacement_model_cannot_feed_the_self_sensing_loop(fitted: tuple) -> None:
    _, model, _ = fitted
    rec = ph.simulate(signal="decaying", duration=10.0, seed=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        disp = ph.ClassicalPI(8, output_unit="m").fit(rec.voltage, rec.displacement)
    leak = ph.Leakage.from_model(model)
    lo, hi = model.input_range_
    ctl = ph.SelfSensingController(model, v_min=lo, v_max=hi, sample_rate=RATE, leakage=leak)
    with pytest.raises(ph.ParameterError, match="gives no charge for the self-sensing loop"):
        run_on_model(ctl, np.zeros(10), ModelPlant(disp, RATE))


def test_simulate_loop_says_which_actuator_it_ran(fitted: tuple) -> None:
    d, model, _ = fitted
    lo, hi = model.input_range_
    limits = ["--v-min", f"{lo:.6g}", "--v-max", f"{hi:.6g}", "--feedforward"]
    bench = run("simulate-loop", d / "model.json", d / "target.csv", *limits, "-o", d / "b.csv")
    assert bench.exit_code == 0, bench.output
    assert "simulated actuator: the built-in bench" in bench.output
    assert "another actuator than yours" in bench.output
    own = run("simulate-loop", d / "model.json", d / "target.csv", *limits,
              "--plant", d / "model.json", "-o", d / "p.csv")  # fmt: skip
    assert own.exit_code == 0, own.output
    assert "simulated actuator: model.json, your model ActivePI" in own.output
    width = float(own.output.split("width desired->displacement ")[1].split(" %")[0])
    assert width < 1e-6  # its own plant: exact, where the bench (another actuator) is not
    ph.write_table(d / "untimed.csv", {"desired": ph.read_table(d / "target.csv").get("desired")})
    res = run("simulate-loop", d / "model.json", d / "untimed.csv", *limits,
              "--plant", d / "model.json", "-o", d / "u.csv")  # fmt: skip
    assert res.exit_code == 1 and "no time column: give the loop's rate" in res.output
