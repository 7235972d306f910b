"""Leakage from holds, the self-sensing controller, and the step-by-step bench."""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import PRESETS, Bench, make_signal

from ..strategies import examples

# generated signals hold one-sample jumps, which the record check names (test_records.py)
# the loop's safety tests drive it into its limits on purpose (test_records.py: the warning)
pytestmark = [
    pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning"),
    pytest.mark.kernels,
    pytest.mark.filterwarnings("ignore::piezohyst.errors.RecordWarning"),
]

FS = 1000.0


@pytest.fixture(scope="module")
def model() -> ph.ActivePI:
    rec = ph.simulate(signal="hold", duration=10.0, seed=0)
    return ph.ActivePI(12).fit(rec.voltage, rec.charge, t=rec.t)


def staircase(levels: list[float], seconds: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    v = np.concatenate([np.full(round(seconds * FS), lv) for lv in levels])
    return np.arange(v.size) / FS, v


# ------------------------------------------------------------------ bench
def test_bench_steps_equal_one_run() -> None:
    v = 10 + 60 * (1 - np.cos(np.linspace(0, 6 * np.pi, 1500)))
    one = Bench(seed=4, voltage=10.0)
    readings = [one.apply(x) for x in v]
    block = Bench(seed=4, voltage=10.0).run(v)
    np.testing.assert_array_equal([r.charge for r in readings], block.charge)
    np.testing.assert_array_equal([r.displacement for r in readings], block.displacement)
    np.testing.assert_array_equal([r.t for r in readings], block.t)
    # tol: 1500 steps of 1e-3 s summed: rounding
    assert one.reading == readings[-1] and one.reading.t == pytest.approx(1.5)
    rest = Bench(seed=4, voltage=10.0).reading
    assert rest.t == 0.0 and rest.true_displacement == 0.0
    with pytest.raises(ph.ParameterError, match="actuator's limits"):
        one.apply(200.0)
    with pytest.raises(ph.NonFiniteError, match="must be finite"):
        one.apply(math.nan)


def test_bench_charge_reads_the_previous_command() -> None:
    bench = Bench(seed=0)
    before = bench.reading.capacitor_charge
    after = bench.apply(100.0)
    assert after.capacitor_charge > before + 1e-6  # the reading after a command shows it


# ---------------------------------------------------------------- leakage
@settings(max_examples=examples(30), deadline=None)
@given(
    st.floats(1e-11, 1e-8),
    st.floats(0.0, 1e-8),
    st.floats(-1e-10, 1e-10),
)
def test_calibration_recovers_the_leakage(g0: float, g1: float, bias: float) -> None:
    t, v = staircase([0.0, 40.0, 80.0, 120.0, 60.0])
    true = ph.Leakage(g0, g1, bias, scale=120.0)
    q = 1e-6 * np.tanh(v / 50.0) + true.charge(v, t)  # hysteresis still on holds
    leak = ph.calibrate_leakage(t, v, q, scale=120.0, settle=0.0)
    assert len(leak.holds) == 5
    for name in ("conductance", "quadratic", "bias"):
        got, want = getattr(leak, name), getattr(true, name)
        # tol: noise-free holds: the calibration is a linear solve, exact to rounding times its
        # conditioning
        assert got == pytest.approx(want, rel=1e-6, abs=1e-6 * (abs(g0) * 120 + 1e-12))


def test_calibration_refuses_what_holds_cannot_tell(tmp_path: Path) -> None:
    t, v = staircase([70.0, 70.0])
    q = np.cumsum(1e-9 * v) / FS
    with pytest.raises(ph.InsufficientDataError, match=r"1 distinct voltage\(s\) \(70 V\)"):
        ph.calibrate_leakage(t, v, q, terms=("conductance", "bias"))
    leak = ph.calibrate_leakage(t, v, q, terms=("conductance",))
    # tol: noise-free data: a linear solve, exact to rounding times its conditioning
    assert leak.conductance == pytest.approx(1e-9, rel=1e-6) and leak.bias == 0.0
    with pytest.raises(ph.ParameterError, match="distinct names"):
        ph.calibrate_leakage(t, v, q, terms=("ohmic",))
    # it said '0 hold(s) at 0 distinct voltage(s) (none V)'
    with pytest.raises(ph.InsufficientDataError, match=r"^no hold \(the voltage steady"):
        ph.calibrate_leakage(t, np.sin(t), q, terms=("bias",))
    leak.save(tmp_path / "leak.json")
    back = ph.Leakage.load(tmp_path / "leak.json")
    assert back == leak and back.holds == leak.holds
    (tmp_path / "bad.json").write_text('{"kind": "leakage", "conductance": "x"}')
    with pytest.raises(ph.ModelFileError, match=r"bad.json: .*'conductance' must be a number"):
        ph.Leakage.load(tmp_path / "bad.json")


def test_discharge_needs_holds_reached_from_both_sides() -> None:
    t, v = staircase([0.0, 50.0, 100.0, 25.0])
    q = 1e-8 * v + np.cumsum(1e-13 * v) / FS  # the charge almost a function of the voltage
    with pytest.raises(ph.InsufficientDataError, match="once on the way up and once on the way"):
        ph.calibrate_leakage(t, v, q, select=False)  # all four asked for, as they are
    with pytest.warns(UserWarning, match="cannot determine the discharge term .* from above"):
        chosen = ph.calibrate_leakage(t, v, q)  # chosen by evidence: discharge left out
    assert chosen.discharge == 0.0
    leak = ph.calibrate_leakage(t, v, q, terms=("conductance", "bias"))
    # tol: noise-free data: a linear solve, exact to rounding times its conditioning
    assert leak.conductance == pytest.approx(1e-13, rel=1e-6)


def test_calibration_on_the_bench_finds_its_truth() -> None:
    p = dataclasses.replace(PRESETS["T226-H4-203X"], i_bias=45e-12)
    _, v = staircase([0.0, 35.0, 70.0, 105.0, 140.0, 105.0, 70.0, 35.0, 0.0], seconds=10.0)
    rec = Bench(p, seed=1).run(v)
    leak = ph.calibrate_leakage(rec.t, rec.voltage, rec.charge)
    # tol: estimates from noisy 10 s holds: conductance 2 %, its voltage term 5 %, the bias near the
    # noise 25 %, the discharge seen through holds 15 %
    assert leak.conductance == pytest.approx(p.g_leak, rel=0.02)
    assert leak.quadratic == pytest.approx(p.g_leak * p.leak_voltage_coeff, rel=0.05)
    assert leak.bias == pytest.approx(p.i_bias, rel=0.25)
    assert leak.discharge == pytest.approx(1 / (p.r_ref * p.c_ref), rel=0.15)
    # remove_growth with it leaves the capacitor charge (plus the reading's start)
    pure = ph.ActivePI(3).fit(rec.voltage, rec.charge, t=rec.t)
    removed = pure.remove_growth(rec.voltage, rec.charge, rec.t, leakage=leak)
    truth = rec.capacitor_charge - rec.capacitor_charge[0]
    assert ph.metrics.rmse(truth, removed) < 1e-3 * np.ptp(truth)  # 1 nC rms noise on 2.6 uC
    with pytest.raises(ph.ParameterError, match="pass the measured charge"):
        leak.charge(rec.voltage, rec.t)


def test_leakage_from_a_model_and_remove_growth(model: ph.ActivePI) -> None:
    leak = ph.Leakage.from_model(model)
    assert leak.conductance == model.growth_rate_ and leak.bias == 0.0
    rec = ph.simulate(signal="fixed", duration=4.0, seed=9)
    # tol: the same growth removed two ways: rounding of outputs of ~1e-6 C
    np.testing.assert_allclose(
        model.remove_growth(rec.voltage, rec.charge, rec.t, leakage=leak),
        model.remove_growth(rec.voltage, rec.charge, rec.t),
        rtol=0,
        atol=1e-18,
    )
    gpi = ph.GeneralizedPI(8, growth_terms=("integral", "time", "abs_integral"))
    gpi.fit(rec.voltage, rec.charge, t=rec.t)
    full = ph.Leakage.from_model(gpi)
    c = gpi.growth_coefficients()
    assert (full.conductance, full.quadratic, full.bias) == (
        c["integral"][0],
        c["abs_integral"][0],
        c["time"][0],
    )


# -------------------------------------------------------------- controller
def controller(model: ph.ActivePI, **kw: object) -> ph.SelfSensingController:
    """The loop's algebra without a slew limit (the default limit is tested on its own)."""
    kw.setdefault("slew_rate", None)
    return ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=FS, **kw)  # type: ignore[arg-type]


def test_without_feedback_it_is_the_compensator(model: ph.ActivePI) -> None:
    _t, shape = make_signal("decaying", amplitude=1.0, duration=6.0)
    desired = model.hysteresis_.predict(20 + 100 * shape)
    ctl = controller(model, ki=0.0)
    comp = ph.Compensator(model, slew_rate=None, v_min=0.0, v_max=140.0)
    noise = np.random.default_rng(0).normal(0, 1e-6, desired.size)
    np.testing.assert_array_equal(ctl.process(desired, noise), comp.process(desired))


def test_process_equals_steps_in_any_chunks(model: ph.ActivePI) -> None:
    rng = np.random.default_rng(1)
    n = 3000
    desired = model.hysteresis_.predict(70 + 60 * np.sin(np.arange(n) / 150))
    measured = desired + rng.normal(0, 2e-8, n) + 1e-6
    desired[[10, 500]] = np.nan
    measured[[20, 21, 2500]] = [np.inf, np.nan, np.nan]
    kw = {"slew_rate": 5e4, "refresh_leakage": True, "hold_time": 0.1}
    a, b = controller(model, **kw), controller(model, **kw)
    whole = a.process(desired, measured)
    steps = [b.step(d, m) for d, m in zip(desired, measured, strict=True)]
    np.testing.assert_array_equal(whole, steps)
    np.testing.assert_array_equal(a.feedback, b.feedback)
    assert a.nonfinite_count == 2 and a.measurement_faults == 3
    saved = a.state
    tail = a.process(desired[:700], measured[:700])
    a.reset(saved)
    np.testing.assert_array_equal(a.process(desired[:700], measured[:700]), tail)


@settings(max_examples=examples(40), deadline=None)
@given(
    st.lists(
        st.one_of(st.floats(-1e300, 1e300), st.sampled_from([math.nan, math.inf, -math.inf])),
        min_size=1,
        max_size=40,
    ),
    st.lists(
        st.one_of(st.floats(-1e300, 1e300), st.sampled_from([math.nan, math.inf])),
        min_size=40,
        max_size=40,
    ),
)
def test_every_command_is_finite_and_inside_the_limits(
    model: ph.ActivePI, desired: list[float], measured: list[float]
) -> None:
    ctl = ph.SelfSensingController(
        model, v_min=10.0, v_max=120.0, sample_rate=FS, slew_rate=2e4, ki=1.0, kp=0.5
    )
    start = ctl.last_command
    out = ctl.process(np.array(desired), np.array(measured[: len(desired)]))
    assert np.all(np.isfinite(out)) and np.all((out >= 10.0) & (out <= 120.0))
    steps = np.abs(np.diff(np.concatenate([[start], out])))
    assert np.all(steps <= 20.0 * (1 + 1e-12))  # 2e4 V/s at 1 kHz


def test_a_constant_offset_in_the_measurement_changes_nothing(model: ph.ActivePI) -> None:
    desired = model.hysteresis_.predict(70 + 50 * np.sin(np.arange(2000) / 100))
    measured = desired * 1.02
    a = controller(model).process(desired, measured)
    b = controller(model).process(desired, measured + 3e-6)  # the frame absorbs it
    # tol: a constant offset is absorbed by the loop's frame: commands agree to its settling, micro-
    # volts
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)


def test_anti_windup_recovers_at_once(model: ph.ActivePI) -> None:
    h = model.hysteresis_
    top = float(h.predict(np.array([0.0, 140.0]))[1])
    desired = np.concatenate([np.full(500, 2 * top), h.predict(np.full(500, 70.0))])
    plant_gain = 0.9  # the real actuator gives 10 % less charge than the model
    ctl = controller(model, ki=0.5)
    m = 0.0
    out = []
    for k, d in enumerate(desired):
        v = ctl.step(d, m)
        out.append(v)
        m = plant_gain * float(h.predict(np.array([v]))[0])
        if k == 499:
            assert abs(ctl.integral) < 1e-3 * top  # 500 samples at the limit: no windup
    out_a = np.array(out)
    assert np.all(out_a[:500] == 140.0) and ctl.saturated_count >= 499
    assert np.all(out_a[501:] < 140.0)  # leaves the limit at once


def test_online_refresh_finds_an_unseen_bias(model: ph.ActivePI) -> None:
    # a plant that is the model itself plus a bias current nobody told the controller
    h = model.hysteresis_
    bias = 2e-9  # C/s
    levels = h.predict(np.array([30.0, 90.0, 60.0, 120.0]))
    desired = np.repeat(levels, 4000)
    ctl = controller(model, refresh_leakage=True, hold_time=1.0, refresh_gain=0.8)
    state = None
    m, leaked = float(h.predict(np.array([0.0]))[0]), 0.0
    for d in desired:
        v = ctl.step(d, m)
        run = h.propagate(np.array([v]), None, state)
        state = run.state
        leaked += bias / FS + model.growth_rate_ * v / FS
        m = float(run.output[0]) + leaked
    assert ctl.leakage_refreshes >= 8
    # tol: the bias refreshed online from noisy holds: within 5 %
    assert ctl.leakage_estimate.bias == pytest.approx(bias, rel=0.05)


def test_refuses_models_it_cannot_invert_analytically() -> None:
    rec = ph.simulate(duration=4.0)
    creep = ph.GeneralizedPI(6, creep=(0.5,), growth_terms=("integral",))
    creep.fit(rec.voltage, rec.charge, t=rec.t)
    with pytest.raises(ph.ParameterError, match="compiled inverse"):
        ph.SelfSensingController(creep, v_min=0.0, v_max=140.0, sample_rate=FS)
    model = ph.ActivePI(5).fit(rec.voltage, rec.charge, t=rec.t)
    with pytest.raises(ph.ParameterError, match="'ki' parameter"):
        ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=FS, ki=2.5)


@pytest.mark.heavy
def test_closed_loop_on_the_bench_beats_feedforward(model: ph.ActivePI) -> None:
    p = dataclasses.replace(PRESETS["T226-H4-203X"], i_bias=40e-12)  # a bias never identified
    _t_cal, v_cal = staircase([0.0, 35.0, 70.0, 105.0, 140.0], seconds=3.0)
    cal = Bench(p, seed=3).run(v_cal)
    leak = ph.calibrate_leakage(cal.t, cal.voltage, cal.charge)
    _, shape = make_signal("decaying", amplitude=1.0, duration=20.0)
    h = model.hysteresis_
    q_top, q_rem = (float(q) for q in h.predict(np.array([140.0, 0.0])))
    desired = q_rem + (q_top - q_rem) * (0.05 + 0.9 * shape)  # inside the major loop
    ff = ph.Compensator(model, slew_rate=None, v_min=0.0, v_max=140.0)
    w_ff = hysteresis_width(desired, Bench(p, seed=5).run(ff.process(desired)).true_displacement)
    # The loop feeds the charge amplifier's noise back: its width is a statistic of the noise
    # realisation (0.24-0.33 % over 8 seeds; a change in the last bit of the model, as another
    # BLAS gives, acts as another realisation: one of those runs reached 0.36 %). So the claim
    # is on the median of three realisations, and every run must still clearly beat the
    # feedforward (which reads no sensor: 0.77 % whatever the seed).
    widths = []
    for seed in (5, 6, 7):
        ctl = controller(model, leakage=leak)
        bench = Bench(p, seed=seed, voltage=ctl.last_command)
        actual = np.empty_like(desired)
        for k, d in enumerate(desired):
            actual[k] = bench.apply(ctl.step(d, bench.reading.charge)).true_displacement
        widths.append(hysteresis_width(desired, actual))
    assert max(widths) < 0.6 * w_ff and float(np.median(widths)) < 0.003


# ---------------------------------------------------------------------- CLI
def test_command_line_loop(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from piezohyst.cli import main

    def run(*args: object) -> tuple[int, str, str]:
        res = CliRunner().invoke(main, [str(a) for a in args])
        return res.exit_code, res.stdout, res.stderr

    p = dataclasses.replace(PRESETS["T226-H4-203X"], i_bias=45e-12)
    _, v = staircase([0.0, 35.0, 70.0, 105.0, 140.0, 105.0, 70.0, 35.0, 0.0], seconds=6.0)
    rec = Bench(p, seed=8).run(v)
    units = {"time": "s", "voltage": "V", "charge": "C"}
    ph.write_table(
        tmp_path / "holds.csv",
        {"time": rec.t, "voltage": rec.voltage, "charge": rec.charge},
        units=units,
    )
    code, out, err = run("calibrate-leakage", tmp_path / "holds.csv", "-o", tmp_path / "leak.json")
    assert code == 0, err
    assert "discharge" in out and "from 9 holds" in out
    leak = ph.Leakage.load(tmp_path / "leak.json")
    # tol: the calibration from a noisy recording, through the CLI: within 5 %
    assert leak.conductance == pytest.approx(p.g_leak, rel=0.05)
    code, _, err = run(
        "calibrate-leakage",
        tmp_path / "holds.csv",
        "--terms",
        "bias,ohmic",
        "-o",
        tmp_path / "x.json",
    )
    assert code == 1 and err.count("\n") == 1 and "distinct names" in err
    ident = ph.simulate(signal="hold", duration=10.0, seed=0)
    ph.write_table(
        tmp_path / "run.csv",
        {"time": ident.t, "voltage": ident.voltage, "charge": ident.charge},
        units=units,
    )
    assert run("fit", tmp_path / "run.csv", "-o", tmp_path / "m.json")[0] == 0
    model = ph.load_model(tmp_path / "m.json")
    t, shape = make_signal("decaying", amplitude=1.0, duration=10.0)
    h = model.hysteresis_
    q_top, q_rem = (float(q) for q in h.predict(np.array([140.0, 0.0])))
    target = q_rem + (q_top - q_rem) * (0.05 + 0.9 * shape)
    ph.write_table(tmp_path / "target.csv", {"time": t, "desired": target}, units={"time": "s"})
    common = ("--extra-bias", "4e-11", "--seed", "2")
    code, ff_out, err = run(
        "simulate-loop", tmp_path / "m.json", tmp_path / "target.csv", "--feedforward",
        *common, "-o", tmp_path / "ff.csv",
    )  # fmt: skip
    assert code == 0, err
    # the same target in uC, as its header says: read as compensate reads it, the same run
    ph.write_table(tmp_path / "target_uc.csv", {"time": t, "desired": target * 1e6},
                   units={"time": "s", "desired": "uC"})  # fmt: skip
    code, uc_out, err = run(
        "simulate-loop", tmp_path / "m.json", tmp_path / "target_uc.csv", "--feedforward",
        *common, "-o", tmp_path / "ff_uc.csv",
    )  # fmt: skip
    assert code == 0, err
    # tol: the target scaled by 1e6 and back, rounding only: the same printed width
    assert uc_out.split("width")[1] == ff_out.split("width")[1]
    code, cl_out, err = run(
        "simulate-loop", tmp_path / "m.json", tmp_path / "target.csv",
        "--leakage", tmp_path / "leak.json", *common, "-o", tmp_path / "cl.csv",
    )  # fmt: skip
    assert code == 0, err

    def width(text: str) -> float:
        return float(text.split("width desired->displacement ")[1].split(" %")[0])

    assert width(cl_out) < 0.5 * width(ff_out)
    loop = ph.read_table(tmp_path / "cl.csv")
    assert loop.columns == ["time", "desired", "command", "charge", "displacement"]
    assert 0.0 <= loop.get("command").min() and loop.get("command").max() <= 140.0
    code, out, err = run(
        "export-c", tmp_path / "m.json", "--controller", "--leakage", tmp_path / "leak.json",
        "-o", tmp_path / "loop.c",
    )  # fmt: skip
    assert code == 1 and "sample rate" in err and err.count("\n") == 1
    code, out, err = run(
        "export-c", tmp_path / "m.json", "--controller", "--leakage", tmp_path / "leak.json",
        "--sample-rate", "1000", "-o", tmp_path / "loop.c",
    )  # fmt: skip
    assert code == 0, err
    header = (tmp_path / "loop.h").read_text()
    assert "loop_real loop_step(loop_t *s, loop_real desired, loop_real measured);" in header
    wrong = ph.Leakage(1e-9, output_unit="uC")
    wrong.save(tmp_path / "uc.json")
    code, _, err = run(
        "simulate-loop", tmp_path / "m.json", tmp_path / "target.csv",
        "--leakage", tmp_path / "uc.json", "-o", tmp_path / "x.csv",
    )  # fmt: skip
    assert code == 1 and "the leakage is in uC/V, the model in C/V" in err


def _loop_reversals(model: ph.HysteresisModel, actuator: ph.PIHysteresis, *, guard: bool) -> int:
    """Command reversals of the loop on a 1 Hz sine, 2 s, plant read one sample late."""
    desired = model.hysteresis_.predict(70 + 40 * np.sin(2 * np.pi * np.arange(2000) / FS))
    ctl = ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=FS,
                                   slew_rate=None, flat_guard=guard)  # fmt: skip
    plant = ph.ActivePI.from_operator(actuator).hysteresis_
    state, reading, out = None, 0.0, []
    for d in desired:
        out.append(ctl.step(d, reading))
        run = plant.propagate(np.array([out[-1]]), None, state)
        state, reading = run.state, float(run.output[0])
    steps = np.diff(np.array(out))
    moving = steps[np.abs(steps) > 1e-9]
    return int(np.count_nonzero(np.sign(moving[1:]) != np.sign(moving[:-1])))


def test_the_flat_guard_stops_the_chatter_of_a_model_flatter_than_its_actuator() -> None:
    """A model whose branches start at 1 % of its mean slope, an actuator whose start at a
    third of it: through the inverse, ki = 0.5 becomes a loop gain of about 17 after each
    reversal, and the loop reverses the command every sample; guarded, the integral gain
    is twice the first slope over the mean (0.02), and the command turns where the sine
    does."""
    r = [0.0, 10.0, 25.0, 45.0, 70.0]
    model = ph.ActivePI.from_operator(ph.PIHysteresis(r, [2e-10, 1e-8, 6e-9, 4e-9, 2e-9]))
    plant = ph.PIHysteresis(r, [7e-9, 5e-9, 4e-9, 3e-9, 1e-9])
    chatter = _loop_reversals(model, plant, guard=False)
    guarded = _loop_reversals(model, plant, guard=True)
    assert chatter > 200
    assert guarded <= 6  # measured 4: the sine's own turns
    ctl = ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=FS,
                                   flat_guard=True)  # fmt: skip
    # the first weight over the mean slope between the limits (2e-10 against 2.42e-8 / 140 V)
    mean = float(np.ptp(model.hysteresis_.predict(np.array([0.0, 140.0, 0.0])))) / 140.0
    assert ctl.first_slope == pytest.approx(2e-10 / mean, rel=1e-9)  # tol: rounding of a difference
    assert ctl.ki_used == pytest.approx(2 * ctl.first_slope) and ctl.ki == 0.5


def test_a_bank_guards_each_channel_by_its_own_model() -> None:
    """flat_guard passes through a BankController's settings: each channel runs with the gain
    its own model's first slope allows, in the fused kernel's rows too."""
    r = [0.0, 10.0, 25.0, 45.0, 70.0]
    flat = ph.PIHysteresis(r, [2e-10, 1e-8, 6e-9, 4e-9, 2e-9])
    steep = ph.PIHysteresis(r, [7e-9, 5e-9, 4e-9, 3e-9, 1e-9])
    bank = ph.ModelBank.from_models([ph.ClassicalPI.from_operator(u) for u in (flat, steep)])
    ctl = ph.BankController(bank, v_min=0.0, v_max=140.0, sample_rate=FS, flat_guard=True)
    used = [ch.ki_used for ch in ctl._channels]
    assert used[0] < 0.05 and used[1] == 0.5  # the steep model's first slope allows ki
    from piezohyst._kernels import play as K

    np.testing.assert_array_equal(ctl.ctl[:, K.CTL_KI], used)


# ------------------------------------------------------- behind an amplifier
LAGGED = "T226-H4-203X-amp4ms"


@pytest.fixture(scope="module")
def lagged_models() -> tuple[ph.ActivePI, ph.ActivePI]:
    """ActivePI fitted with the amplifier's lag (4 ms, found), and with a lag behind a
    logged delay of 3 samples (the voltage column logged 3 ms early)."""
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=20.0)
    rec = ph.simulate(v, t, preset=LAGGED, seed=0)
    lag = ph.ActivePI(12, input_dynamics="first-order").fit(rec.voltage, rec.charge, t=rec.t)
    delayed = ph.ActivePI(12, input_dynamics="delay+first-order").fit(
        rec.voltage[3:], rec.charge[:-3], t=rec.t[3:]
    )
    return lag, delayed


def test_the_loop_inverts_the_amplifiers_lag_at_40_hz(
    lagged_models: tuple[ph.ActivePI, ph.ActivePI],
) -> None:
    """Issue 55: the self-sensing loop took no model with input dynamics; a 40 Hz scan behind
    a 4 ms amplifier (45 degrees of lag) needs one. Measured on this bench: feedforward
    0.58 %, the loop 0.43-0.46 %, with a bias current the model never saw."""
    model, _ = lagged_models
    assert model.input_dynamics_ is not None and 0.003 < model.input_dynamics_.tau < 0.005
    lo, hi = model.input_range_  # the multifreq record peaks at 138.9 V
    top, rest = (float(q) for q in model.operator_.predict(np.array([hi, lo])))
    _, shape = make_signal("fixed", amplitude=1.0, frequency=40.0, duration=6.0)
    desired = rest + (top - rest) * (0.3 + 0.4 * shape)
    keep = slice(1000, None)  # after the first second
    p = dataclasses.replace(PRESETS[LAGGED], i_bias=40e-12)  # a bias never identified
    ff = ph.Compensator(model, slew_rate=None, v_min=lo, v_max=hi, sample_rate=FS)
    bench = Bench(p, seed=5, voltage=lo)
    for x in ff.precondition(2000):
        bench.apply(x)
    moved = np.array([bench.apply(c).true_displacement for c in ff.process(desired)])
    w_ff = hysteresis_width(desired[keep], moved[keep])
    # the loop feeds the charge amplifier's noise back: its width is a statistic of the noise
    # realisation (0.43-0.46 % over four seeds), so the claim is on the median of three
    widths = []
    for seed in (5, 6, 7):
        ctl = ph.SelfSensingController(model, slew_rate=None, v_min=lo, v_max=hi, sample_rate=FS)
        bench = Bench(p, seed=seed, voltage=lo)
        for x in ctl.precondition(2000):
            bench.apply(x)
        commands = np.empty_like(desired)
        for k, d in enumerate(desired):
            commands[k] = ctl.step(d, bench.reading.charge)
            moved[k] = bench.apply(commands[k]).true_displacement
        widths.append(hysteresis_width(desired[keep], moved[keep]))
        assert np.all((commands >= lo) & (commands <= hi))
        at_limit = int(np.count_nonzero((commands == lo) | (commands == hi)))
        assert ctl.saturated_count == at_limit
    assert max(widths) < min(0.01, 0.9 * w_ff) and float(np.median(widths)) < 0.8 * w_ff


def test_through_a_delay_without_feedback_it_is_the_compensator(
    lagged_models: tuple[ph.ActivePI, ph.ActivePI],
) -> None:
    _, model = lagged_models
    assert model.input_dynamics_ is not None
    m = int(model.input_dynamics_.delay_samples)
    assert m == 3  # the 3 ms the voltage column was logged early
    _, shape = make_signal("decaying", amplitude=1.0, duration=3.0)
    desired = model.operator_.predict(20 + 100 * shape)
    noise = np.random.default_rng(0).normal(0, 1e-6, desired.size)
    lo, hi = model.input_range_
    kw = {"slew_rate": None, "v_min": lo, "v_max": hi, "sample_rate": FS}
    comp = ph.Compensator(model, **kw)  # type: ignore[arg-type]
    ff = ph.SelfSensingController(model, ki=0.0, **kw)  # type: ignore[arg-type]
    np.testing.assert_array_equal(ff.process(desired, noise), comp.process(desired))
    # with feedback: the block its own preview, as steps given the next m desired values
    a = ph.SelfSensingController(model, **kw)  # type: ignore[arg-type]
    b = ph.SelfSensingController(model, **kw)  # type: ignore[arg-type]
    whole = a.process(desired, desired + noise)
    n = desired.size - m  # the last m of the block extrapolate beyond it
    steps = [b.step(desired[k], desired[k] + noise[k], desired[k + 1 : k + 1 + m])
             for k in range(n)]  # fmt: skip
    np.testing.assert_array_equal(whole[:n], steps)


def test_a_packed_core_behind_the_amplifier_in_the_loop() -> None:
    """The loop on a Bouc-Wen core fitted with the amplifier's lag (it refused one): with the
    feedback off it is the Compensator (through a 3-sample delay too, the block its own
    preview), and with it a 40 Hz scan behind 4 ms stays under 1 % width."""
    t, v = make_signal("multifreq", amplitude=140.0, frequency=1.0, duration=8.0)
    rec = ph.simulate(v, t, preset=LAGGED, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's own notes are not under test
        lag = ph.BoucWenModel(input_dynamics="first-order").fit(rec.voltage, rec.charge, t=rec.t)
        delayed = ph.BoucWenModel(input_dynamics="delay+first-order").fit(
            rec.voltage[3:], rec.charge[:-3], t=rec.t[3:]
        )
    assert delayed.input_dynamics_.delay_samples >= 2.5
    lo, hi = lag.input_range_
    kw = {"slew_rate": None, "v_min": lo, "v_max": hi, "sample_rate": FS}
    top, rest = (float(q) for q in lag.operator_.predict(np.array([hi, lo])))
    _, shape = make_signal("fixed", amplitude=1.0, frequency=40.0, duration=3.0)
    desired = rest + (top - rest) * (0.3 + 0.4 * shape)
    for model in (lag, delayed):
        noise = np.random.default_rng(0).normal(0, 1e-9, desired.size)
        ff = ph.SelfSensingController(model, ki=0.0, **kw)  # type: ignore[arg-type]
        comp = ph.Compensator(model, **kw)  # type: ignore[arg-type]
        np.testing.assert_array_equal(ff.process(desired, noise), comp.process(desired))
    p = dataclasses.replace(PRESETS[LAGGED], i_bias=40e-12)  # a bias never identified
    ctl = ph.SelfSensingController(lag, **kw)  # type: ignore[arg-type]
    bench = Bench(p, seed=5, voltage=lo)
    for x in ctl.precondition(2000):
        bench.apply(x)
    moved = np.empty_like(desired)
    for k, d in enumerate(desired):
        moved[k] = bench.apply(ctl.step(d, bench.reading.charge)).true_displacement
    width = hysteresis_width(desired[1000:], moved[1000:])
    assert width < 0.01, width  # 0.69 % measured
