"""A lab's record checked before it is trusted: isolated outliers (an ADC glitch) and holes in
the time axis are named, and a glitch sets no limit of the model (API and command line)."""

from __future__ import annotations

import itertools
import json
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.cli import main
from piezohyst.errors import RecordWarning
from piezohyst.io.screening import Screener, noise_level, screen

GLITCH_ROW = 1234  # 0-based: data row 1235


@pytest.fixture(scope="module")
def bench() -> ph.simulation.BenchRecord:
    return ph.simulate(signal="hold", duration=20.0, seed=0)


def _write(path: Path, rec: ph.simulation.BenchRecord, **replace: np.ndarray) -> Path:
    cols = {"time": rec.t, "voltage": rec.voltage, "charge": rec.charge, **replace}
    ph.io.write_table(path, cols)
    return path


# ------------------------------------------------------------------------- the rule itself
@settings(max_examples=40, deadline=None)
@given(
    freq=st.floats(0.2, 40.0),
    noise=st.floats(0.0, 0.02),
    lsb=st.sampled_from([0.0, 140.0 / 2**16, 140.0 / 2**12]),
    seed=st.integers(0, 2**16),
)
def test_smooth_noisy_quantised_signals_raise_no_false_alarm(
    freq: float, noise: float, lsb: float, seed: int
) -> None:
    """Sines, triangles and staircases with Gaussian noise up to 2 % of the span and a 12- or
    16-bit ADC's codes: no sample is an outlier (the rule needs 10x the noise on both sides)."""
    rng = np.random.default_rng(seed)
    t = np.arange(20000) * 1e-3
    phase = 2 * np.pi * freq * t
    signals = [
        70 - 70 * np.cos(phase),
        140 * np.abs(((freq * t) % 1.0) * 2 - 1),  # a triangle: corners are not outliers
        np.repeat(rng.uniform(0, 140, 200), 100),  # a staircase: steps are not outliers
    ]
    for x in signals:
        x = x + rng.normal(0.0, noise * 140, x.size)
        if lsb:
            x = np.round(x / lsb) * lsb
        assert screen({"v": x}, t).outliers == ()


@settings(max_examples=40, deadline=None)
@given(
    where=st.integers(1, 4998),
    cuts=st.lists(st.integers(1, 4999), max_size=4),
    size=st.floats(0.05, 1e4),
    sign=st.sampled_from([-1.0, 1.0]),
)
def test_a_planted_glitch_is_found_wherever_the_blocks_are_cut(
    where: int, cuts: list[int], size: float, sign: float
) -> None:
    """Read in blocks cut anywhere (a cut beside the glitch included), the findings are the
    whole record's: the glitch, its row and the neighbours' mean (the noise level is a median
    of the blocks' estimates, so it may differ a little)."""
    rng = np.random.default_rng(where)
    t = np.arange(5000) * 1e-3
    x = 70 - 70 * np.cos(2 * np.pi * 2.0 * t) + rng.normal(0.0, 0.01, t.size)
    x[where] += sign * 140 * size  # 5 % of the span to 10^4 spans
    bounds = [0, *sorted(set(cuts)), t.size]
    s = Screener(["v"])
    for a, b in itertools.pairwise(bounds):
        s.add(a, {"v": x[a:b]}, t[a:b])
    found = s.finish()
    whole = screen({"v": x}, t)
    assert (found.outliers, found.holes) == (whole.outliers, whole.holes)
    assert [(o.row, o.value) for o in found.outliers] == [(where + 1, x[where])]
    # tol: the mean of two doubles, as computed
    assert found.outliers[0].replacement == pytest.approx(0.5 * (x[where - 1] + x[where + 1]))
    assert found.cleaned("v", x)[where] == found.outliers[0].replacement


def test_the_first_and_last_samples_are_not_judged_and_two_in_a_row_are_not_isolated() -> None:
    """A record that starts with a step (the measured PZT creep files do) is not a glitch."""
    x = np.concatenate([[638.0], np.full(500, 1473.0)])
    x[-1] = 9e3
    assert screen({"v": x}).outliers == ()
    y = np.sin(np.linspace(0, 6, 1000))
    y[400:402] = 50.0
    assert screen({"v": y}).outliers == ()


def test_the_noise_level_is_the_noise() -> None:
    rng = np.random.default_rng(1)
    x = 70 - 70 * np.cos(2 * np.pi * np.arange(50000) * 1e-3) + rng.normal(0, 0.3, 50000)
    # tol: a MAD estimate from 5e4 samples scatters by about 1 %
    assert noise_level(x) == pytest.approx(0.3, rel=0.03)
    assert ph.selection.input_noise is noise_level  # one estimator for both uses


# ------------------------------------------------------------------------- the fit
def test_a_glitch_is_named_and_sets_no_limit(bench: ph.simulation.BenchRecord) -> None:
    v = bench.voltage.copy()
    v[GLITCH_ROW] = 1e4
    clean = ph.ActivePI(10).fit(bench.voltage, bench.charge, t=bench.t)
    with pytest.warns(RecordWarning, match=r"x\[1234\] 10000 V"):
        model = ph.ActivePI(10).fit(v, bench.charge, t=bench.t)
    assert model.input_range_ == clean.input_range_
    assert model.max_slew_rate_ == clean.max_slew_rate_
    # tol: the replaced sample is its neighbours' mean, not the clean one: the fit moves by
    # far less than the noise (0.14 % NRMSE)
    assert model.nrmse_ == pytest.approx(clean.nrmse_, rel=1e-3)
    with pytest.warns(RecordWarning, match="kept, as asked"):
        kept = ph.ActivePI(10).fit(v, bench.charge, t=bench.t, keep_outliers=True)
    assert kept.input_range_[1] == 1e4


def test_a_hole_is_named_by_its_sample(bench: ph.simulation.BenchRecord) -> None:
    keep = np.ones(bench.t.size, bool)
    keep[8000:9000] = False
    with pytest.warns(RecordWarning, match=r"1 hole .* before t\[8000\] \(1 s missing"):
        ph.ActivePI(10).fit(bench.voltage[keep], bench.charge[keep], t=bench.t[keep])


# ------------------------------------------------------------------------- from the shell
def test_the_shell_names_the_glitch_and_no_limit_follows_it(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    v = bench.voltage.copy()
    v[GLITCH_ROW] = 1e4
    data = _write(tmp_path / "glitch.csv", bench, voltage=v)
    runner = CliRunner()
    fit = runner.invoke(main, ["fit", str(data), "-o", str(tmp_path / "m.json")])
    assert fit.exit_code == 0, fit.output
    assert "row 1235 column 'voltage' 10000" in fit.output
    model = ph.load_model(tmp_path / "m.json")
    assert model.input_range_[1] <= 140.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ph.errors.ExtrapolationWarning)
        target = model.hysteresis_.predict(np.linspace(20, 120, 500))
    ph.io.write_table(tmp_path / "target.csv", {"time": np.arange(500) * 1e-3, "charge": target})
    comp = runner.invoke(
        main, ["compensate", str(tmp_path / "m.json"), str(tmp_path / "target.csv"),
               "-o", str(tmp_path / "cmd.csv")],
    )  # fmt: skip
    assert comp.exit_code == 0, comp.output
    assert "commands in [0, 140] V" in comp.output
    c_file = tmp_path / "ph_comp.c"
    exp = runner.invoke(main, ["export-c", str(tmp_path / "m.json"), "-o", str(c_file)])
    assert exp.exit_code == 0, exp.output
    header = (tmp_path / "ph_comp.h").read_text() + c_file.read_text()
    assert "10000" not in header and "V_MAX" in header
    kept = runner.invoke(
        main, ["fit", str(data), "--keep-outliers", "-o", str(tmp_path / "k.json")]
    )
    assert kept.exit_code == 0 and "kept, as asked" in kept.output
    assert ph.load_model(tmp_path / "k.json").input_range_[1] == 1e4


def test_a_charge_spike_is_named_and_moves_nothing(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    q = bench.charge.copy()
    span = float(np.ptp(q))
    q[5000] += 100 * span
    runner = CliRunner()
    clean = runner.invoke(main, ["fit", str(_write(tmp_path / "c.csv", bench)),
                                 "-o", str(tmp_path / "c.json")])  # fmt: skip
    spiked = runner.invoke(main, ["fit", str(_write(tmp_path / "s.csv", bench, charge=q)),
                                  "-o", str(tmp_path / "s.json")])  # fmt: skip
    assert clean.exit_code == 0 and spiked.exit_code == 0, spiked.output
    assert "row 5001 column 'charge'" in spiked.output
    a = ph.load_model(tmp_path / "c.json").predict(bench.voltage, t=bench.t)
    b = ph.load_model(tmp_path / "s.json").predict(bench.voltage, t=bench.t)
    assert np.abs(a - b).max() <= 5e-4 * span  # the bar: 0.05 % of the span


def test_the_shell_names_a_hole_by_its_row(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    keep = np.ones(bench.t.size, bool)
    keep[8000:9000] = False
    data = tmp_path / "hole.csv"
    ph.io.write_table(data, {"time": bench.t[keep], "voltage": bench.voltage[keep],
                             "charge": bench.charge[keep]})  # fmt: skip
    out = CliRunner().invoke(main, ["fit", str(data), "-o", str(tmp_path / "m.json")])
    assert out.exit_code == 0, out.output
    assert "1 hole in the time axis" in out.output and "before row 8001 (1 s missing" in out.output


# ------------------------------------------------------------------------- limits that bite
@pytest.fixture(scope="module")
def slow_model(bench: ph.simulation.BenchRecord) -> ph.ActivePI:
    """Identified on a 1 Hz-ish record: its trained slew is that record's fastest change."""
    rec = ph.simulate(signal="fixed", frequency=1.0, duration=5.0, seed=0)
    return ph.ActivePI(10).fit(rec.voltage, rec.charge, t=rec.t)


def _scan(model: ph.ActivePI, f: float, lo: float = 0.3, hi: float = 0.7) -> np.ndarray:
    q0, q1 = model.hysteresis_.predict([0.0, 140.0])
    t = np.arange(2000) * 1e-3
    return q0 + (q1 - q0) * (lo + (hi - lo) * 0.5 * (1 - np.cos(2 * np.pi * f * t)))


def test_a_scan_held_by_the_trained_slew_says_so(slow_model: ph.ActivePI) -> None:
    lo, hi = slow_model.input_range_
    comp = ph.Compensator(slow_model, v_min=lo, v_max=hi, sample_rate=1000.0)
    with pytest.warns(ph.errors.LimitWarning, match=r"slew limit \(\d.* V/s\) held \d+ of \d+"):
        comp.process(_scan(slow_model, 40.0))
    assert comp.slew_limited_count > 0.5 * comp.command_count
    stepped = ph.Compensator(slow_model, v_min=lo, v_max=hi, sample_rate=1000.0)
    with pytest.warns(ph.errors.LimitWarning, match="slew_rate"):  # step by step: the same
        for d in _scan(slow_model, 40.0):
            stepped.step(d)
    assert stepped.slew_limited_count == comp.slew_limited_count
    with warnings.catch_warnings():  # a slow scan, no limit acting: no word
        warnings.simplefilter("error")
        quiet = ph.Compensator(slow_model, v_min=lo, v_max=hi, sample_rate=1000.0)
        quiet.process(_scan(slow_model, 0.25, 0.0, 0.7))  # from rest, rising: in reach
    assert quiet.slew_limited_count == 0 and quiet.saturated_count == 0


def test_a_target_out_of_reach_says_which_limit(slow_model: ph.ActivePI) -> None:
    comp = ph.Compensator(slow_model, v_min=20.0, v_max=120.0, slew_rate=None)
    with pytest.warns(ph.errors.LimitWarning, match=r"voltage limits \[20, 120\] V held"):
        comp.process(_scan(slow_model, 0.5, 0.0, 1.0))
    # and on which side: a scan reaching only past the top, then only below the bottom (it
    # said "lower the target" for both)
    for lo, hi, side in ((0.3, 1.0, "beyond what v_max reaches"), (0.0, 0.7, "below what v_min")):
        comp = ph.Compensator(slow_model, v_min=20.0, v_max=120.0, slew_rate=None)
        with pytest.warns(ph.errors.LimitWarning) as said:
            comp.process(_scan(slow_model, 0.5, lo, hi))
        text = str(said[0].message)
        assert side in text, text
        at_low, at_high = (
            int(n) for n in re.search(r"(\d+) at v_min, (\d+) at v_max", text).groups()
        )
        assert (at_low == 0) == (side.startswith("beyond")) and at_low + at_high > 0, text


def test_a_share_held_never_exceeds_the_commands_given(slow_model: ph.ActivePI) -> None:
    """A target out of reach from the first sample, approached at the slew limit (5 s over
    the range), then held at v_max: the voltage limits' share is of every command, the
    approach too (it read 'held 800 of 164 commands (487.8 %)': the slew limit's count starts
    on the trajectory). A command counts as held by a voltage limit where it is sent at the
    limit, not where the slew limit held it first (as the other cores count). The approach
    itself is said first, at its 100th command (it went unsaid until v_max)."""
    lo, hi = slow_model.input_range_
    comp = ph.Compensator(slow_model, v_min=lo, v_max=hi, sample_rate=1000.0,
                          slew_rate=0.2 * (hi - lo))  # fmt: skip
    beyond = float(slow_model.hysteresis_.predict(np.array([hi]))[0]) * 10.0
    with pytest.warns(ph.errors.LimitWarning) as said:
        sent = np.array([comp.step(beyond) for _ in range(8000)])
    assert len(said) == 2, [str(w.message) for w in said]
    first = str(said[0].message)
    assert "has held all 100 commands since the start and they have not reached" in first
    assert f"(now at {lo + 100 * 0.2 * (hi - lo) / 1000.0:.4g} V)" in first, first
    text = str(said[1].message)
    held, given = (
        int(n) for n in re.search(r"voltage limits .* held (\d+) of (\d+)", text).groups()
    )
    assert 0 < held <= given, text
    assert comp.saturated_count == np.sum(sent == hi) > 0
    assert "at v_max: the target is beyond what v_max reaches" in text


def test_a_bank_says_when_the_voltage_limits_hold_the_approach(slow_model: ph.ActivePI) -> None:
    """The fused bank as the single compensator above: a channel's target out of reach,
    approached at the slew limit, never reaches the trajectory; the bank counted only commands
    on it, so the voltage limits held channel 0's commands at v_max without a word (and the
    approach itself went unsaid until then: now said when the first 64-step block past its
    100th command is counted)."""
    lo, hi = slow_model.input_range_
    bank = ph.ModelBank.from_models([slow_model, slow_model])
    comps = ph.BankCompensator(bank, v_min=lo, v_max=hi, sample_rate=1000.0,
                               slew_rate=0.2 * (hi - lo))  # fmt: skip
    assert comps.fused
    q_hi = float(slow_model.hysteresis_.predict(np.array([hi]))[0])
    with pytest.warns(ph.errors.LimitWarning) as said:
        # checked at every doubling of the commands: 8192 is the first after the 5 s approach
        sent = np.array([comps.step(np.array([10.0 * q_hi, 0.0]))[0] for _ in range(9000)])
    assert len(said) == 2, [str(w.message) for w in said]
    assert "held every command of 1 of 2 channels since the start (128 on channel 0)" in str(
        said[0].message
    )
    text = str(said[1].message)
    assert "voltage limits held more than 1 % of the commands on 1 of 2 channels" in text, text
    held, given = (int(n) for n in re.search(r"channel 0, (\d+) of (\d+)", text).groups())
    assert 0 < held <= given, text
    assert comps.saturated_count[0] == np.sum(sent == hi) > 0


def test_the_shell_counts_what_the_limits_held(tmp_path: Path, slow_model: ph.ActivePI) -> None:
    slow_model.save(tmp_path / "m.json")
    ph.io.write_table(tmp_path / "scan.csv", {"time": np.arange(2000) * 1e-3,
                                              "desired": _scan(slow_model, 40.0)})  # fmt: skip
    files = [str(tmp_path / "m.json"), str(tmp_path / "scan.csv")]
    # the slew limit holds most of this 40 Hz scan: an error now (issue 55: a file of
    # commands 97 % held was written, exit 0), nothing written
    res = CliRunner().invoke(main, ["compensate", *files, "-o", str(tmp_path / "c.csv")])
    assert res.exit_code == 1 and "the slew limit (439.8 V/s) held" in res.output, res.output
    assert not (tmp_path / "c.csv").exists()
    # a limit that holds a few: written, counted, said once (the dry run that sizes the
    # precondition cycle said it too, with other counts)
    res = CliRunner().invoke(main, ["compensate", *files, "--slew-rate", "9300", "-o",
                                    str(tmp_path / "c.csv")])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert res.output.count("warning: Compensator: the slew limit") == 1, res.output
    assert "by the slew limit" in res.output


def test_misused_steps_and_plots_are_piezohyst_errors(
    slow_model: ph.ActivePI, bench: ph.simulation.BenchRecord
) -> None:
    comp = ph.Compensator(slow_model, v_min=0.0, v_max=139.0, allow_extrapolation=True)
    with pytest.raises(ph.errors.ParameterError, match=r"one desired value .* Got 'x'"):
        comp.step("x")
    with pytest.raises(ph.errors.ShapeError, match="same length"):
        slow_model.plot(bench.voltage, bench.charge[:100], t=bench.t)


def test_predicting_beyond_the_identified_range_warns_for_every_kind(
    slow_model: ph.ActivePI,
) -> None:
    inverse = slow_model.hysteresis_.inverse()
    with pytest.warns(ph.errors.ExtrapolationWarning, match=r"sample 0, 1 C\) lie outside"):
        inverse.predict(np.array([1.0]))  # 1 C: 10^5 times the record's charge
    with pytest.warns(ph.errors.ExtrapolationWarning, match="300 V"):
        slow_model.predict(np.array([0.0, 300.0]), t=np.array([0.0, 1e-3]))
    with warnings.catch_warnings():  # inside the range: no word
        warnings.simplefilter("error")
        slow_model.predict(np.linspace(0.0, 130.0, 50), t=np.arange(50) * 1e-3)


# ------------------------------------------------------------------------- a lab's files
def test_a_mat_struct_of_signals_and_a_matrix_of_columns(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    """MATLAB's usual saves: a struct of signals (--group names it) and one [t v q] matrix
    (columns by index, whether the signals lie in columns or rows)."""
    from scipy.io import savemat

    t, v, q = bench.t[:3000], bench.voltage[:3000], bench.charge[:3000]
    savemat(tmp_path / "s.mat", {"meas": {"t": t, "v": v, "q": q}})
    savemat(tmp_path / "m.mat", {"data": np.column_stack([t, v, q])})
    savemat(tmp_path / "r.mat", {"data": np.vstack([t, v, q])})
    runner = CliRunner()
    wrong = runner.invoke(main, ["fit", str(tmp_path / "s.mat"), "--group", "nope",
                                 "-o", str(tmp_path / "x.json")])  # fmt: skip
    assert wrong.exit_code == 1 and "available: 'meas'" in wrong.output
    fits = []
    for name, cols in (("s.mat", ["--group", "meas", "--input", "v", "--output", "q",
                                  "--time", "t"]),
                       ("m.mat", ["--input", "1", "--output", "2", "--time", "0"]),
                       ("r.mat", ["--input", "1", "--output", "2", "--time", "0"])):  # fmt: skip
        res = runner.invoke(main, ["fit", str(tmp_path / name), *cols, "--model", "classical-pi",
                                   "-o", str(tmp_path / f"{name}.json")])  # fmt: skip
        assert res.exit_code == 0, res.output
        fits.append(ph.load_model(tmp_path / f"{name}.json").nrmse_)
    direct = ph.ClassicalPI(10).fit(v, q).nrmse_
    # tol: the same samples through three readers: the same fit to rounding
    assert fits == pytest.approx([direct] * 3, rel=1e-9)


def test_a_nested_struct_s_fields_are_named_as_matlab_writes_them(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    """A struct holding another struct is read as paths (run/Vout); a MATLAB user writes the
    field run.Vout, and both name the same column (the time too); a field that is not there
    is refused by name, listing the ones that are."""
    from scipy.io import savemat

    t, v, q = bench.t[:3000], bench.voltage[:3000], bench.charge[:3000]
    savemat(tmp_path / "n.mat", {"run": {"time": t, "Vout": v, "Q": q, "meta": {"rate": 1e3}}})
    runner = CliRunner()
    fits = []
    for k, sep in enumerate((".", "/")):
        cols = [f"run{sep}Vout", f"run{sep}Q", f"run{sep}time"]
        args = ["--input", cols[0], "--output", cols[1], "--time", cols[2]]
        out = str(tmp_path / f"m{k}.json")
        res = runner.invoke(main, ["fit", str(tmp_path / "n.mat"), *args, "--model",
                                   "classical-pi", "-o", out])  # fmt: skip
        assert res.exit_code == 0, res.output
        fits.append(ph.load_model(out).nrmse_)
    assert fits[0] == fits[1]  # the same column, read the same way
    args = ["--input", "run.Vx", "--output", "run.Q", "--time", "run.time"]
    wrong = runner.invoke(main, ["fit", str(tmp_path / "n.mat"), *args, "-o",
                                 str(tmp_path / "x.json")])  # fmt: skip
    assert wrong.exit_code == 1
    assert "no column 'run.Vx'; available: 'run/time', 'run/Vout', 'run/Q'" in wrong.output


def test_a_column_in_one_group_is_found_by_its_own_name(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    """An HDF5 file whose one group holds time, voltage and charge fits with no names (and the
    charge in C, its default unit); where two groups each hold a voltage, the name is
    ambiguous and refused, listing the paths; a TDMS file's 'Voltage' and 'Charge' are found
    by the default names."""
    import h5py

    t, v, q = bench.t[:3000], bench.voltage[:3000], bench.charge[:3000]
    with h5py.File(tmp_path / "one.h5", "w") as h:
        g = h.create_group("run 1")
        g["time"], g["voltage"], g["charge"] = t, v, q
    with h5py.File(tmp_path / "two.h5", "w") as h:
        for name in ("run 1", "run 2"):
            g = h.create_group(name)
            g["time"], g["voltage"], g["charge"] = t, v, q
    runner = CliRunner()
    res = runner.invoke(main, ["fit", str(tmp_path / "one.h5"), "-o", str(tmp_path / "a.json")])
    assert res.exit_code == 0, res.output
    assert ph.load_model(tmp_path / "a.json").output_unit == "C"
    res = runner.invoke(main, ["fit", str(tmp_path / "two.h5"), "-o", str(tmp_path / "b.json")])
    assert res.exit_code == 1
    assert "no column 'voltage'; available: 'run 1/charge'" in res.output
    # a LabVIEW file's channels named in capitals: the default names find them
    from nptdms import ChannelObject, TdmsWriter

    wave = {"wf_increment": 1e-3}
    with TdmsWriter(tmp_path / "lv.tdms") as w:
        w.write_segment([ChannelObject("Measure", "Voltage", v, properties=wave),
                         ChannelObject("Measure", "Charge", q, properties=wave)])  # fmt: skip
    res = runner.invoke(main, ["fit", str(tmp_path / "lv.tdms"), "-o", str(tmp_path / "c.json")])
    assert res.exit_code == 0, res.output
    assert ph.load_model(tmp_path / "c.json").output_unit == "C"


def test_a_time_column_named_with_its_unit(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    """'--time "t [s]"' names the column t whose header gives it in s, as '--input "v [V]"'
    names v (it ended in an internal error when the time was the one named so)."""
    data = tmp_path / "u.csv"
    n = 3000
    rows = np.column_stack([bench.t[:n], bench.voltage[:n], bench.charge[:n]])
    data.write_text(
        "t [s],v [V],q [C]\n" + "\n".join(",".join(f"{x!r}" for x in r.tolist()) for r in rows)
    )
    res = CliRunner().invoke(main, ["fit", str(data), "--input", "v [V]", "--output", "q",
                                    "--time", "t [s]", "-o", str(tmp_path / "m.json")])  # fmt: skip
    assert res.exit_code == 0, res.output


def test_columns_named_with_a_unit_suffix(tmp_path: Path, bench: ph.simulation.BenchRecord) -> None:
    """A script's export names its columns ``time_s, voltage_V, charge_nC`` (the PZT set's
    CSVs do): the default names find them, in their units, as ``time [s]`` headers are (it
    was "no column 'voltage'"); the header as written still names its column; a channel
    letter, an inch or an ampere is not read as a unit."""
    n = 3000
    rows = np.column_stack([1e3 * bench.t[:n], bench.voltage[:n], 1e9 * bench.charge[:n],
                            np.zeros(n)])  # fmt: skip
    data = tmp_path / "s.csv"
    data.write_text("time_ms,voltage_V,charge_nC,current_A\n"
                    + "\n".join(",".join(f"{x!r}" for x in r.tolist()) for r in rows))  # fmt: skip
    rec = ph.read_recording(data)
    np.testing.assert_allclose(rec.t, bench.t[:n], rtol=1e-12)  # ms -> s
    np.testing.assert_allclose(rec.y, bench.charge[:n], rtol=1e-12)  # nC -> C
    assert rec.units == ("V", "C")
    same = ph.read_recording(data, input_column="voltage_V", output_column="charge_nC",
                             time_column="time_ms")  # fmt: skip
    np.testing.assert_array_equal(same.y, rec.y)
    res = CliRunner().invoke(main, ["fit", str(data), "-o", str(tmp_path / "m.json")])
    assert res.exit_code == 0, res.output
    assert ph.load_model(tmp_path / "m.json").output_unit == "C"
    table = ph.io.read_table(data)
    assert table.columns == ["time", "voltage", "charge", "current_A"]  # amperes: no role
    odd = tmp_path / "odd.csv"
    odd.write_text(
        "v_in,channel_A,channel_B,channel_C,voltage,voltage_V\n1,2,3,4,5,6\n2,3,4,5,6,7\n"
    )
    assert ph.io.read_table(odd).columns == ["v_in", "channel_A", "channel_B", "channel_C",
                                            "voltage", "voltage_V"]  # fmt: skip
    assert ph.io.read_table(odd).units == {}


def test_the_unit_registry_is_built_once() -> None:
    """pint's registry takes 0.2-2 s to build: one per process, whatever converts (a
    decorator moved onto the wrong function once rebuilt it for every column, 2.5 s a read)."""
    from piezohyst import units

    assert units._registry() is units._registry()


def test_a_second_file_holding_one_signal_needs_no_name(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    """The Bouc-Wen benchmark's uval/yval pairs: one signal in each file, no time column."""
    from scipy.io import savemat

    savemat(tmp_path / "u.mat", {"uval_multisine": bench.voltage[:3000]})
    savemat(tmp_path / "y.mat", {"yval_multisine": bench.charge[:3000]})
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "u.mat"), "--output-file",
                                    str(tmp_path / "y.mat"), "--rate", "1000", "--model",
                                    "classical-pi", "-o", str(tmp_path / "m.json")])  # fmt: skip
    assert res.exit_code == 0, res.output


def test_a_rate_independent_model_needs_no_time(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    data = tmp_path / "untimed.csv"
    ph.io.write_table(data, {"voltage": bench.voltage, "charge": bench.charge})
    runner = CliRunner()
    res = runner.invoke(main, ["fit", str(data), "--model", "classical-pi",
                               "-o", str(tmp_path / "m.json")])  # fmt: skip
    assert res.exit_code == 0, res.output
    pred = runner.invoke(main, ["predict", str(tmp_path / "m.json"), str(data),
                                "-o", str(tmp_path / "p.csv")])  # fmt: skip
    assert pred.exit_code == 0, pred.output
    assert ph.io.read_table(tmp_path / "p.csv").columns[0] == "sample"  # not a fake time
    growth = runner.invoke(main, ["fit", str(data), "-o", str(tmp_path / "a.json")])
    assert growth.exit_code == 1
    assert "no time column 'time' and no sample rate, which ActivePI's" in growth.output


@pytest.mark.parametrize("cell", ["nan", "", "abc"])
def test_one_row_number_for_a_bad_cell_whatever_it_holds(
    tmp_path: Path, bench: ph.simulation.BenchRecord, cell: str
) -> None:
    ph.io.write_table(tmp_path / "ok.csv", {"time": bench.t[:2000], "voltage":
                      bench.voltage[:2000], "charge": bench.charge[:2000]})  # fmt: skip
    lines = (tmp_path / "ok.csv").read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("time"))
    parts = lines[header + 1 + GLITCH_ROW].split(",")
    parts[1] = cell
    lines[header + 1 + GLITCH_ROW] = ",".join(parts)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "bad.csv"), "-o",
                                    str(tmp_path / "m.json")])  # fmt: skip
    assert res.exit_code == 1
    assert "at row 1235" in res.output and "column 'voltage'" in res.output


def test_compensate_writes_empty_precondition_cells_and_clean_times(
    tmp_path: Path, slow_model: ph.ActivePI
) -> None:
    slow_model.save(tmp_path / "m.json")
    t = np.arange(1500) * 1e-3  # times as a DAQ writes them: 0.001 steps, not exact
    ph.io.write_table(tmp_path / "scan.csv", {"time": t, "desired": _scan(slow_model, 1.0)[:1500]})
    files = [str(tmp_path / "m.json"), str(tmp_path / "scan.csv")]
    res = CliRunner().invoke(main, ["compensate", *files, "-o", str(tmp_path / "c.csv")])
    assert res.exit_code == 0, res.output
    text = (tmp_path / "c.csv").read_text()
    assert "nan" not in text
    rows = [line.split(",") for line in text.splitlines()[2:]]
    pre = [r for r in rows if r[2] == ""]
    assert pre and all(len(r[0]) <= 6 for r in pre)  # -1.001, not -1.001000000000001
    back = ph.io.read_table(tmp_path / "c.csv").get("desired", finite=False)
    assert np.isnan(back[: len(pre)]).all() and np.isfinite(back[len(pre) :]).all()


def test_the_report_names_its_windows_and_the_zero_baseline(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    data = _write(tmp_path / "r.csv", bench)
    runner = CliRunner()
    fit = runner.invoke(main, ["fit", str(data), "--t-stop", "10", "-o", str(tmp_path / "m.json")])
    assert fit.exit_code == 0, fit.output
    rep = runner.invoke(main, ["report", str(tmp_path / "m.json"), str(data), "--t-start", "10",
                               "--out", str(tmp_path / "rep")])  # fmt: skip
    assert rep.exit_code == 0, rep.output
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text())["metrics"]
    assert metrics["training_window_s"]["value"] == "0 to 9.999"
    assert metrics["held_out_pct"]["value"] == 100.0
    assert metrics["nrmse_zero_pct"]["value"] > metrics["nrmse_pct"]["value"]
    assert "verdict" not in metrics
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "&quot;" not in page and 'setting thresholds</th><td class="v">default' in page
    # a record the model does not describe: worse than predicting zero, and said so
    flipped = _write(tmp_path / "f.csv", bench, charge=-bench.charge)
    bad = runner.invoke(main, ["report", str(tmp_path / "m.json"), str(flipped),
                               "--out", str(tmp_path / "bad")])  # fmt: skip
    assert bad.exit_code == 0, bad.output
    verdict = json.loads((tmp_path / "bad" / "metrics.json").read_text())["metrics"]["verdict"]
    assert verdict["value"].startswith("worse than predicting zero")


def test_an_approach_that_never_arrives_says_so(slow_model: ph.ActivePI) -> None:
    """A target inside the range but far from rest, approached at a slow slew limit (0.1 V a
    sample) over a run too short to arrive: every command was held by the slew limit and
    none by a voltage limit, and nothing was said (the approach is not counted, so that a
    ramp from rest is not a fault). An approach still under way after 100 commands is said,
    once, by the compensator, the bank and the controller; one that arrives is not."""
    lo, hi = slow_model.input_range_
    q_lo, q_hi = (float(q) for q in slow_model.hysteresis_.predict(np.array([lo, hi])))
    target = np.full(500, q_lo + 0.8 * (q_hi - q_lo))  # about 110 V: 1100 samples away
    kept = {"v_min": lo, "v_max": hi, "sample_rate": 1000.0, "slew_rate": 100.0}
    comp = ph.Compensator(slow_model, **kept)
    with pytest.warns(ph.errors.LimitWarning) as said:
        sent = comp.process(target)
    assert len(said) == 1 and "has held all 500 commands since the start" in str(said[0].message)
    assert f"(now at {sent[-1]:.4g} V)" in str(said[0].message)
    np.testing.assert_allclose(np.diff(sent), 0.1, rtol=1e-9)  # every one held
    assert comp.approach_count == 500 and comp.slew_limited_count == comp.saturated_count == 0
    bank = ph.BankCompensator(ph.ModelBank.from_models([slow_model, slow_model]), **kept)
    with pytest.warns(
        ph.errors.LimitWarning, match=r"1 of 2 channels since the start \(500 on channel 0\)"
    ):
        bank.process(np.column_stack([target, np.full(500, q_lo)]))  # channel 1 sits there
    ctl = ph.SelfSensingController(slow_model, **kept)
    with pytest.warns(ph.errors.LimitWarning, match="SelfSensingController: the slew limit "
                      r"\(100 V/s\) has held all 500"):  # fmt: skip
        ctl.process(target, np.full(500, q_lo))
    near = ph.Compensator(slow_model, **kept)  # a ramp of 50 commands arrives: not said
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        near.process(np.full(500, float(slow_model.hysteresis_.predict(np.array([5.0]))[0])))
    assert 0 < near.approach_count < 100


def test_the_controller_and_the_bank_say_when_a_limit_bites(slow_model: ph.ActivePI) -> None:
    lo, hi = slow_model.input_range_
    ctl = ph.SelfSensingController(slow_model, v_min=lo, v_max=hi, sample_rate=1000.0)
    scan = _scan(slow_model, 40.0)
    with pytest.warns(ph.errors.LimitWarning, match="SelfSensingController: the slew limit"):
        ctl.process(scan, scan)
    assert ctl.slew_limited_count > 0.1 * scan.size  # 633 of 2000 measured
    bank = ph.ModelBank(ph.ActivePI(10))
    rec = ph.simulate(signal="fixed", frequency=1.0, duration=5.0, seed=0)
    bank.fit(np.column_stack([rec.voltage] * 3), np.column_stack([rec.charge] * 3), t=rec.t)
    comps = ph.BankCompensator(bank, v_min=lo, v_max=hi, sample_rate=1000.0)
    assert comps.fused
    with pytest.warns(ph.errors.LimitWarning, match=r"slew limit held .* on 3 of 3 channels"):
        comps.process(np.column_stack([scan] * 3))
    stepped = ph.BankCompensator(bank, v_min=lo, v_max=hi, sample_rate=1000.0)
    with pytest.warns(ph.errors.LimitWarning, match="BankCompensator"):
        for row in np.column_stack([scan] * 3):
            stepped.step(row)
    np.testing.assert_array_equal(stepped.slew_limited_count, comps.slew_limited_count)


@pytest.mark.skipif(shutil.which("script") is None, reason="no 'script' to give a terminal")
def test_model_choice_shows_progress_on_a_terminal(
    tmp_path: Path, bench: ph.simulation.BenchRecord
) -> None:
    """compare and fit --model auto run for seconds: on a terminal a spinner says what runs
    (piped, nothing: the output stays clean)."""
    data = _write(tmp_path / "r.csv", bench)
    exe = Path(sys.executable).parent / "piezohyst"
    cmd = f"{exe} compare {data} --models active-pi,classical-pi"
    shown = subprocess.run(["script", "-qc", cmd, "/dev/null"], capture_output=True, text=True)
    assert "fitting 2 models on r.csv" in shown.stdout
    piped = subprocess.run(cmd.split(), capture_output=True, text=True)
    assert piped.returncode == 0 and "fitting 2 models" not in piped.stdout + piped.stderr


def test_a_warning_points_at_the_callers_line(tmp_path: Path) -> None:
    """Warnings from deep inside the readers pointed at ``io/__init__.py`` (a fixed
    stacklevel); now at the line of the caller outside the library."""
    t = np.delete(np.arange(1000) / 1000.0, np.s_[400:440])  # 40 ms the DAQ lost
    ph.write_table(tmp_path / "gap.csv", {"time": t, "voltage": np.sin(t), "charge": t})
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        ph.read_recording(tmp_path / "gap.csv")
    assert said and all(w.filename == __file__ for w in said), [w.filename for w in said]
