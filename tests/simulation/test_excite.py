"""`piezohyst excite`: the voltage a lab plays on its rig, then records, fits and compensates."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.cli import main
from piezohyst.workflows.excitation import KINDS, Excitation, excitation


def check_safe(exc: Excitation, v_min: float, v_max: float, slew: float) -> None:
    v = exc.voltage
    rest = float(np.clip(0.0, v_min, v_max))
    assert v[0] == rest and v[-1] == rest  # starts and ends at rest, exactly
    assert v.min() >= v_min and v.max() <= v_max
    # tol: a raised cosine's steepest chord is below its peak slope; 1e-9 relative for rounding
    assert np.abs(np.diff(v)).max() * exc.sample_rate <= slew * (1 + 1e-9)
    np.testing.assert_array_equal(np.diff(exc.t) > 0, True)


@given(
    kind=st.sampled_from(KINDS),
    v_min=st.floats(-200.0, 100.0),
    span=st.floats(1.0, 1000.0),
    rate=st.sampled_from([200.0, 1000.0, 2500.0]),
    slew_share=st.floats(0.05, 3.0),
)
def test_every_excitation_starts_and_ends_at_rest_inside_the_limits_and_slew(
    kind: str, v_min: float, span: float, rate: float, slew_share: float
) -> None:
    v_max = v_min + span
    slew = slew_share * np.pi * span  # from a twentieth of a 1 Hz full-range sine's to 3x
    exc = excitation(kind, v_min=v_min, v_max=v_max, sample_rate=rate, slew_rate=slew, hold=2.0)
    check_safe(exc, v_min, v_max, slew)
    for start, stop, level in exc.holds:  # every hold is flat for its whole length
        i0, i1 = round(start * rate), round(stop * rate)
        assert stop - start == pytest.approx(2.0, abs=1 / rate)  # tol: one sample
        np.testing.assert_array_equal(exc.voltage[i0:i1], level)
    if kind not in ("holds", "multisine"):
        assert exc.frequencies[0] <= 1.0 and all(f <= rate / 20 for f in exc.frequencies)


def test_the_kinds_hold_what_they_say() -> None:
    ident = excitation(v_min=0, v_max=140, sample_rate=1000)
    assert [h[2] for h in ident.holds] == [0.0, 70.0, 140.0, 70.0, 0.0]
    assert ident.frequencies == [1.0, 10.0]
    holds = excitation("holds", v_min=0, v_max=140, sample_rate=1000, hold=3.0)
    assert [h[2] for h in holds.holds] == [0, 35, 70, 105, 140, 105, 70, 35, 0]
    assert holds.frequencies == []
    multi = excitation("multifreq", v_min=0, v_max=140, sample_rate=1000)
    assert multi.frequencies == [1.0, 10.0, 40.0] and not multi.holds
    # a slew limit lowers the fast loops' frequency (pi f span under 1.1x the limit), to a
    # whole number of samples per cycle: 1000 / ceil(1000 / 4.1339) = 1000 / 242 Hz
    slow = excitation("multifreq", v_min=0, v_max=140, sample_rate=1000, slew_rate=2000.0)
    assert 2000.0 / (1.1 * np.pi * 140) == pytest.approx(4.1339, abs=1e-4)  # tol: 4 decimals
    assert slow.frequencies == [1.0, 1000.0 / 242]
    # loops of many sizes: the local extrema of the loops cover the range
    bipolar = excitation("multifreq", v_min=-30, v_max=120, sample_rate=1000)
    assert bipolar.voltage[0] == 0.0
    assert bipolar.voltage.min() == -30.0 and bipolar.voltage.max() == 120.0  # a full cycle each


def test_a_multisine_gives_each_actuator_its_own_lines() -> None:
    """Three actuators: in every steady period each column holds its own lines (every
    third, from 1 Hz to the band) and nothing else, periods repeat exactly, the peak is the
    range's half, the crest factor is flattened from a random-phase multisine's ~3."""
    exc = excitation("multisine", v_min=45, v_max=95, sample_rate=1000, band=300,
                     actuators=3, periods=3, seed=4)  # fmt: skip
    v = exc.voltage
    assert v.shape == (exc.t.size, 3) and exc.actuators == 3
    np.testing.assert_array_equal(v[0], 45.0)  # at rest (the limit nearer 0 V), exactly
    np.testing.assert_array_equal(v[-1], 45.0)
    assert v.min() >= 45 and v.max() <= 95
    a, b = exc.steady
    assert b - a == 3 * 1000
    steady = v[a:b].reshape(3, 1000, 3)
    np.testing.assert_array_equal(steady[1], steady[0])  # periodic, to the bit
    np.testing.assert_array_equal(steady[2], steady[0])
    spec = np.abs(np.fft.rfft(steady[0] - 70.0, axis=0)) ** 2
    for q in range(3):
        own = np.arange(1 + q, 301, 3)  # lines k = q + 1, q + 4, ... <= 300 Hz
        elsewhere = np.delete(spec[:, q], own)
        # tol: the lines' power against rounding's (1e-16 of the signal, squared)
        assert elsewhere.max() < 1e-20 * spec[own, q].min()
        # equal amplitudes on its lines (the crest reduction keeps them)
        np.testing.assert_allclose(spec[own, q], spec[own, q].mean(), rtol=1e-9)  # tol: rounding
        x = steady[0][:, q] - 70.0
        crest = np.max(np.abs(x)) / np.sqrt(np.mean(x**2))
        assert crest < 2.0  # a random-phase multisine's is near 3-3.5
    # the peak is the half range about the middle: 25 V (to rounding)
    assert np.max(np.abs(v[a:b] - 70.0)) == pytest.approx(25.0, rel=1e-12)  # tol: rounding
    assert exc.lines == (1.0, 300.0, 100) and exc.swing == (70.0, pytest.approx(25.0), False)
    assert "3 actuators, each on its own 100 lines (every third, interleaved)" in exc.summary()
    slow = excitation("multisine", v_min=45, v_max=95, sample_rate=1000, band=300,
                      actuators=2, slew_rate=5000.0)  # fmt: skip
    # tol: the same chord rule as every excitation's
    assert slow.peak_slew <= 5000.0 * (1 + 1e-9) and slow.swing[2]
    assert "(the slew limit lowered it)" in slow.summary()
    one = excitation("multisine", v_min=0, v_max=140, sample_rate=2000)  # the default band
    assert one.voltage.ndim == 1 and one.lines == (1.0, 800.0, 800)


def test_bad_requests_get_one_clear_error() -> None:
    for kwargs, match in [
        ({"v_min": 10, "v_max": 10}, "v_max must be above v_min"),
        ({"v_min": 0, "v_max": 140, "frequency": 100}, "fewer than 20 samples per cycle"),
        ({"v_min": 0, "v_max": 140, "slew_rate": 1.0}, "below the range over a minute"),
    ]:
        with pytest.raises(ph.ParameterError, match=match):
            excitation(sample_rate=1000, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(ph.ParameterError, match="must be one of identification, holds"):
        excitation("chirp", v_min=0, v_max=1, sample_rate=1000)
    for kwargs, match in [
        ({"kind": "holds", "actuators": 2}, "a holds excitation drives one actuator"),
        ({"kind": "multisine", "band": 500.0}, "below half the sample rate"),
        ({"kind": "multisine", "band": 3.0, "actuators": 2}, "holds 3 lines"),
        ({"kind": "multisine", "periods": 0}, "'periods' must be an integer"),
        ({"kind": "multisine", "actuators": 0}, "'actuators' must be an integer"),
    ]:
        with pytest.raises(ph.ParameterError, match=match):
            excitation(v_min=0, v_max=140, sample_rate=1000, **kwargs)  # type: ignore[arg-type]


def test_holds_are_long_enough_for_the_leakage_calibration() -> None:
    """On the bench: each hold's leakage current within 1 % of the truth."""
    exc = excitation("holds", v_min=0, v_max=140, sample_rate=1000)
    rec = ph.simulate(exc.voltage, exc.t, seed=1)
    leak = ph.calibrate_leakage(rec.t, rec.voltage, rec.charge)
    assert len(leak.holds) == 9
    p = rec.preset
    for h in leak.holds:
        s = slice(h.start, h.stop)
        # what flows on a hold: the piezo's leakage, the amplifier's bias current, and the
        # reference capacitor discharging the measured charge
        true = (
            np.polyfit(rec.t[s], rec.leak_charge[s], 1)[0]
            + p.i_bias
            - h.charge / (p.r_ref * p.c_ref)
        )
        # tol: the slope's noise is ~1e-11 A per hold (its stderr); 1 % of the smallest
        # current (2e-8 A at 35 V) is 20 stderr; at 0 V, 4 stderr
        assert abs(h.current - true) <= max(0.01 * abs(true), 4 * h.stderr)


@pytest.mark.parametrize("suffix", [".csv", ".mat", ".tdms"])
def test_the_lab_round_trip(tmp_path: Path, suffix: str) -> None:
    """excite (as typed in a shell) -> the rig records -> fit -> compensate from rest."""
    exe = Path(sys.executable).with_name("piezohyst")
    out = tmp_path / f"excite{suffix}"
    proc = subprocess.run(
        [str(exe), "excite", "--v-min", "0", "--v-max", "140", "--sample-rate", "1000",
         "--slew-rate", "5000", "--hold", "3", "-o", str(out)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "5 holds of 3 s at 0, 70, 140 V; loops at 1, 10 Hz" in proc.stdout
    assert ph.io.is_piezohyst_output(out)
    played = ph.io.read_recording(out, output_column=None)
    assert played.units[0] == "V" and played.t[1] == pytest.approx(1e-3)  # tol: ulp
    check_safe(
        excitation(v_min=0, v_max=140, sample_rate=1000, slew_rate=5000, hold=3), 0, 140, 5000
    )
    rec = ph.simulate(played.x, played.t, seed=2)  # the rig
    ph.write_table(tmp_path / "rec.csv", {"time": rec.t, "voltage": rec.voltage,
                                          "charge": rec.charge})  # fmt: skip
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "rec.csv"), "-o",
                                    str(tmp_path / "m.json")])  # fmt: skip
    assert res.exit_code == 0, res.output
    model = ph.load_model(tmp_path / "m.json")
    assert model.nrmse_ < 0.005  # a half-percent model from one recording
    # tol: the bench's leakage conductance (5e-10 S, 50 % more at 140 V) seen as one growth rate
    ((rate, unit),) = model.growth_coefficients().values()
    assert 4e-10 < rate < 9e-10 and unit == "C/(V*s)"


def test_cli_refuses_what_it_cannot_write(tmp_path: Path) -> None:
    excite = ["excite", "--sample-rate", "1000", "-o"]
    res = CliRunner().invoke(main, [*excite, str(tmp_path / "e.txt"), "--v-min", "0",
                                    "--v-max", "140"])  # fmt: skip
    assert res.exit_code == 2 and "name it .csv, .mat, .tdms, .npz or .parquet" in res.output
    res = CliRunner().invoke(main, [*excite, str(tmp_path / "e.csv"), "--v-min", "140",
                                    "--v-max", "0"])  # fmt: skip
    assert res.exit_code == 1 and "v_max must be above v_min" in res.stderr
    assert not (tmp_path / "e.csv").exists()


def test_a_leakage_file_is_piezohyst_s_own(tmp_path: Path) -> None:
    """Rerunning calibrate-leakage replaces its own file (it was refused as a stranger's)."""
    exc = excitation("holds", v_min=0, v_max=140, sample_rate=1000, hold=2.0)
    rec = ph.simulate(exc.voltage, exc.t, seed=3)
    ph.write_table(tmp_path / "holds.csv", {"time": rec.t, "voltage": rec.voltage,
                                            "charge": rec.charge})  # fmt: skip
    for _ in range(2):
        res = CliRunner().invoke(main, ["calibrate-leakage", str(tmp_path / "holds.csv"), "-o",
                                        str(tmp_path / "leak.json")])  # fmt: skip
        assert res.exit_code == 0, res.output
    assert ph.io.is_piezohyst_output(tmp_path / "leak.json")
    assert ph.Leakage.load(tmp_path / "leak.json").holds


def test_a_multisine_for_a_stage_from_the_shell(tmp_path: Path) -> None:
    """excite --kind multisine --actuators 2: a column per actuator, the same samples as
    Python's, in the DAQ's volts with --command-scale."""
    out = tmp_path / "ms.csv"
    res = CliRunner().invoke(main, ["excite", "--kind", "multisine", "--actuators", "2",
                                    "--v-min", "45", "--v-max", "95", "--sample-rate", "1000",
                                    "--band", "300", "--periods", "2", "--command-scale", "10",
                                    "-o", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "2 actuators, each on its own 150 lines (every second, interleaved)" in res.output
    table = ph.read_table(out)
    assert list(table.columns) == ["time", "voltage_0", "voltage_1"]
    want = excitation("multisine", v_min=45, v_max=95, sample_rate=1000, band=300,
                      actuators=2, periods=2)  # fmt: skip
    # tol: the CSV's full-precision decimal round trip (17 digits)
    np.testing.assert_allclose(table.get("voltage_1"), want.voltage[:, 1] / 10, rtol=1e-15)
    res = CliRunner().invoke(main, ["excite", "--actuators", "2", "--v-min", "0", "--v-max",
                                    "140", "--sample-rate", "1000", "-o",
                                    str(tmp_path / "x.csv")])  # fmt: skip
    assert res.exit_code == 1 and "several take --kind multisine" in res.stderr
