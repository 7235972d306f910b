"""The simulated bench: physics checks, determinism, limits, and that it is not a PI model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import PRESETS, SIGNALS, make_signal, simulate

pytestmark = pytest.mark.kernels

T226 = PRESETS["T226-H4-203X"]


def test_deterministic_given_a_seed() -> None:
    a = simulate(duration=3.0, seed=4)
    b = simulate(duration=3.0, seed=4)
    c = simulate(duration=3.0, seed=5)
    np.testing.assert_array_equal(a.charge, b.charge)
    np.testing.assert_array_equal(a.displacement, b.displacement)
    assert not np.array_equal(a.charge, c.charge)
    np.testing.assert_array_equal(a.capacitor_charge, c.capacitor_charge)  # noise only


@pytest.mark.heavy
def test_bench_is_not_a_pi_model() -> None:
    """Even 100 operators cannot fit the noise-free, leak-free capacitor charge."""
    rec = simulate(signal="multi", duration=20.0)
    fit = ph.ClassicalPI(100).fit(rec.voltage, rec.capacitor_charge)
    assert fit.nrmse_ > 1e-3


def test_capacitor_is_rate_independent_and_leakage_is_not() -> None:
    t, v = make_signal("fixed", duration=4.0)
    fast = simulate(v, t)
    slow = simulate(v, 3.0 * t)
    # tol: the relays switch at the same voltages whatever the time axis: rounding of charges of
    # ~1e-6 C; the leak integrates time exactly 3x
    np.testing.assert_allclose(slow.capacitor_charge, fast.capacitor_charge, rtol=0, atol=1e-18)
    np.testing.assert_allclose(slow.leak_charge, 3.0 * fast.leak_charge, rtol=1e-9)


def test_leakage_at_constant_voltage_is_ohmic() -> None:
    t = np.arange(2000) / 1000.0
    v = np.full(t.size, 100.0)
    rec = simulate(v, t)
    conductance = T226.g_leak * (1 + T226.leak_voltage_coeff * 100.0 / T226.v_max)
    # tol: a constant current integrated over time: rounding of the running sum
    np.testing.assert_allclose(rec.leak_charge, conductance * 100.0 * t, rtol=1e-12)
    assert rec.true_growth_rate == pytest.approx(conductance, rel=1e-9)


def test_ideal_charge_amplifier_measures_the_capacitor_charge() -> None:
    ideal = dataclasses.replace(
        T226, g_leak=0.0, i_bias=0.0, r_ref=1e30, amp_noise=0.0, laser_noise=0.0
    )
    rec = simulate(preset=ideal, signal="fixed", duration=4.0)
    lsb = 2 * ideal.adc_range / 2**ideal.adc_bits * ideal.c_ref
    # tol: an ideal bench: the ADC's quantisation, half an LSB (plus rounding)
    np.testing.assert_allclose(
        rec.charge, rec.capacitor_charge - rec.capacitor_charge[0], rtol=0, atol=0.51 * lsb
    )
    s = ideal.gain * (rec.capacitor_charge - rec.capacitor_charge[0])
    # tol: the laser's quantisation: half its resolution (plus rounding)
    np.testing.assert_allclose(rec.displacement, s, rtol=0, atol=0.51 * ideal.laser_resolution)


def test_bias_current_integrates_on_the_reference_capacitor() -> None:
    quiet = dataclasses.replace(T226, g_leak=0.0, i_bias=1e-9, r_ref=1e30, amp_noise=0.0)
    t = np.arange(3000) / 1000.0
    rec = simulate(np.zeros_like(t), t, preset=quiet)
    lsb = 2 * quiet.adc_range / 2**quiet.adc_bits * quiet.c_ref
    # tol: the ADC's quantisation: half an LSB (plus rounding)
    np.testing.assert_allclose(rec.charge, 1e-9 * t, rtol=0, atol=0.51 * lsb)


def test_loops_are_pzt_like() -> None:
    rec = simulate(signal="fixed", duration=10.0)
    width = hysteresis_width(rec.voltage, rec.capacitor_charge)
    assert 0.10 < width < 0.18  # the measured actuator in shared/data shows 14.6 %
    grown = rec.leak_charge[-1] / np.ptp(rec.capacitor_charge)
    assert grown > 0.1  # leakage visibly "active"


def test_voltage_limits_are_enforced() -> None:
    t = np.arange(10) / 1000.0
    with pytest.raises(ph.ParameterError, match=r"limits \[-140.0, 140.0\] V. Got \[0, 150\]"):
        simulate(np.linspace(0, 150, 10), t)
    with pytest.raises(ph.ParameterError, match="preset"):
        simulate(preset="nope")
    with pytest.raises(ph.TimeAxisError):
        simulate(np.zeros(10))


def _increment_jitter(q: np.ndarray) -> float:
    """The spread of the charge's per-sample increments about their local mean, along the
    middle of each branch of a 10 Hz triangle (a smooth density would give none), over the
    branches' span."""
    parts = []
    for start in range(1000, 2950, 50):
        d = np.diff(q[start + 10 : start + 40])
        parts.append((d - np.convolve(d, np.ones(7) / 7, mode="same"))[3:-3])
    return float(np.std(np.concatenate(parts)) / np.ptp(q[1000:]))


def test_a_finer_relay_grid_holds_the_same_density_in_finer_steps() -> None:
    """The bench's 120 x 60 relays switch in bunches on a fast ramp (docs/bench.md); a grid
    three times finer holds the same density, its charge's increments far smoother."""
    k = np.arange(3000)
    tri = 140.0 * (0.2 + 0.6 * np.abs((k / 1000.0 * 10.0) % 1.0 * 2 - 1))
    fine = dataclasses.replace(T226, relay_grid=360)
    coarse_q = simulate(tri, k / 1000.0).capacitor_charge
    fine_q = simulate(tri, k / 1000.0, preset=fine).capacitor_charge
    # the steps: relays on one lattice line switch together, their weight falling with the
    # grid (measured 0.16 % and 0.04 % of the scan's span per sample)
    assert _increment_jitter(fine_q) < 0.5 * _increment_jitter(coarse_q)
    assert _increment_jitter(coarse_q) > 1e-3  # the coarse grid's bunches are there to see
    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=4.0)
    a, b = simulate(v, t).capacitor_charge, simulate(v, t, preset=fine).capacitor_charge
    # the same density: two discretisations of it, each within 0.4 % of a 1440 grid's charge
    # (measured 0.41 % and 0.13 %), so within 0.6 % of each other
    assert np.max(np.abs(a - b)) < 6e-3 * np.ptp(a)
    with pytest.raises(ph.ParameterError, match=r"'relay_grid' must be an integer"):
        simulate(v, t, preset=dataclasses.replace(T226, relay_grid=4))


@given(name=st.sampled_from(sorted(SIGNALS)), amp=st.floats(1.0, 140.0), f=st.floats(0.1, 5.0))
def test_signals_stay_in_range(name: str, amp: float, f: float) -> None:
    t, v = make_signal(name, amplitude=amp, frequency=f, duration=3.0, rate=500.0)
    # tol: every signal starts at rest: rounding of its first sample's formula
    assert t.size == 1500 and v[0] == pytest.approx(0.0, abs=1e-9)
    low = -amp if name == "bipolar" else 0.0
    assert v.min() >= low - 1e-9 and v.max() <= amp + 1e-9


def test_signal_errors() -> None:
    with pytest.raises(ph.ParameterError, match="one of"):
        make_signal("square")
    with pytest.raises(ph.ParameterError, match="'amplitude'"):
        make_signal("fixed", amplitude=-1.0)


def test_hysteresis_width_of_a_line_is_zero() -> None:
    x = np.concatenate([np.linspace(0, 1, 100), np.linspace(1, 0, 100)])
    # tol: a straight line: the branches coincide to rounding
    assert hysteresis_width(x, 3 * x + 1) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.heavy  # two 300 s runs: compiled only (with the JIT off, 15 s under coverage)
def test_a_long_record_never_clips_the_charge() -> None:
    """300 s of drive leak about 1e-5 C: past the ADC's 10 V on the 1 uF reference. The
    bench picks the next E6 capacitor, as a lab would, and nothing clips; without it the
    charge is flat at full scale for the last 20 s, and the clipping check says so."""
    from piezohyst.metrics import clipped

    ranged = simulate(signal="multi", duration=300.0, seed=1)
    fixed = simulate(signal="multi", duration=300.0, seed=1, auto_range=False)
    assert fixed.preset.c_ref == 1e-6 and ranged.preset.c_ref in (1.5e-6, 2.2e-6)
    assert clipped([ranged.charge])[0] == 0
    assert np.abs(ranged.charge).max() <= 0.8 * 10.0 * ranged.preset.c_ref  # under 80 % of scale
    rows, side, level, _, _ = clipped([fixed.charge])
    assert rows > 0.03 * fixed.charge.size and side == "top"
    assert level == pytest.approx(10.0 * 1e-6, rel=1e-4)  # tol: full scale, one 16-bit LSB
    # the piezo is the same: the capacitor's charge does not depend on the reference
    # tol: the reference's discharge (r_ref c_ref = 5e4 s or more) shifts it by ~1e-3
    np.testing.assert_allclose(ranged.capacitor_charge, fixed.capacitor_charge, rtol=1e-3)
    model = ph.ActivePI(10).fit(ranged.voltage, ranged.charge, t=ranged.t)
    ((rate, _),) = model.growth_coefficients().values()
    # tol: one growth rate for a leak that grows with voltage, as on shorter records (5 %)
    assert rate == pytest.approx(ranged.true_growth_rate, rel=0.05)


def test_units_of_a_batch_differ_and_are_repeatable() -> None:
    from piezohyst.simulation import batch_unit

    base = PRESETS["T226-H4-203X"]
    assert batch_unit(base, 0) is base
    units = [batch_unit("T226-H4-203X", u) for u in range(1, 9)]
    assert units[0] == batch_unit(base, 1)  # the same unit is the same actuator
    leaks = np.array([u.g_leak for u in units])
    assert np.ptp(leaks) > 0.2 * base.g_leak and np.all(np.abs(leaks / base.g_leak - 1) <= 0.75)
    assert all(u.v_max == base.v_max and u.adc_range == base.adc_range for u in units)
    runs = [simulate(signal="hold", duration=4.0, preset=u, seed=0) for u in units[:3]]
    assert len({round(r.true_growth_rate, 14) for r in runs}) == 3
    with pytest.raises(ph.ParameterError, match="integer 0 or more"):
        batch_unit(base, -1)


def test_simulate_unit_from_the_shell(tmp_path: object) -> None:
    """`--unit` changes the actuator, `--seed` only the noise."""
    from pathlib import Path

    from click.testing import CliRunner

    from piezohyst.cli import main

    d = Path(str(tmp_path))
    said = {}
    for seed, unit in ((1, 0), (2, 0), (1, 1), (1, 2)):
        args = ["--seed", str(seed), "--unit", str(unit), "-o", str(d / f"{seed}{unit}.csv")]
        res = CliRunner().invoke(main, ["simulate", "--duration", "2", *args])
        assert res.exit_code == 0, res.output
        said[seed, unit] = res.stderr.split("true leakage")[1].split()[0]
    assert said[1, 0] == said[2, 0]  # the same actuator, other noise
    assert len({said[1, 0], said[1, 1], said[1, 2]}) == 3
