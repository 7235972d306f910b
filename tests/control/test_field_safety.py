"""Field safety: no data loss, commands inside the trusted range, a safe start."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
import piezohyst.workflows as wf

from ..helpers import aixacct_like, one_line_error, run

# these tests drive targets past the voltage and slew limits on purpose (safety, exactness
# where no limit acts); that the limits then say so is tested in test_records.py
pytestmark = pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning")


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("lab")
    assert run("simulate", "--duration", "8", "-o", d / "run.csv").exit_code == 0
    assert run("fit", d / "run.csv", "--operators", "10", "-o", d / "model.json").exit_code == 0
    model = ph.load_model(d / "model.json")
    t = np.arange(2000) / 1000.0
    v = 20 + 50 * (1 - np.cos(2 * np.pi * 0.5 * t))
    ph.write_table(d / "target.csv", {"time": t, "desired": model.hysteresis_.predict(v)})
    return d


# ------------------------------------------------------------------ no data loss
def test_an_output_that_is_an_input_is_refused(lab: Path) -> None:
    before = (lab / "run.csv").read_bytes()
    for extra in ([], ["--force"]):  # refused before anything is read: a model is .json
        res = run("fit", lab / "run.csv", "-o", lab / "run.csv", *extra)
        assert res.exit_code == 2 and "name it .json" in res.output
    assert (lab / "run.csv").read_bytes() == before
    for extra in ([], ["--force"]):  # the data read is an input, forced or not
        one_line_error(
            run("predict", lab / "model.json", lab / "run.csv", "-o", lab / "run.csv", *extra),
            "is an input",
        )
    assert (lab / "run.csv").read_bytes() == before
    model = (lab / "model.json").read_bytes()  # nor is a model written over as a table
    res = run("predict", lab / "model.json", lab / "run.csv", "-o", lab / "model.json")
    assert res.exit_code == 2 and "name it .csv, .npz or .parquet" in res.output
    assert (lab / "model.json").read_bytes() == model


def test_files_piezohyst_did_not_write_need_force(lab: Path) -> None:
    mine = lab / "measurement.csv"
    mine.write_text("time,voltage,charge\n0,0,0\n0.001,1,1e-9\n")
    err = one_line_error(
        run("predict", lab / "model.json", lab / "run.csv", "-o", mine), "did not write"
    )
    assert "--force" in err
    assert mine.read_text().startswith("time,voltage")
    assert run("predict", lab / "model.json", lab / "run.csv", "-o", mine, "--force").exit_code == 0
    assert ph.io.is_piezohyst_output(mine)
    # its own output is replaced without asking
    assert run("predict", lab / "model.json", lab / "run.csv", "-o", mine).exit_code == 0
    folder = lab / "notes"
    folder.mkdir()
    (folder / "lab-book.txt").write_text("do not lose me")
    one_line_error(run("report", lab / "model.json", lab / "run.csv", "--out", folder),
                   "did not write")  # fmt: skip
    assert (folder / "lab-book.txt").read_text() == "do not lose me"


# ----------------------------------------------------------- safe compensation
def test_limits_beyond_the_training_range_are_refused(lab: Path) -> None:
    model = ph.load_model(lab / "model.json")
    _lo, hi = model.input_range_
    args = ["compensate", lab / "model.json", lab / "target.csv", "--v-min", "-88",
            "--v-max", "233"]  # fmt: skip
    one_line_error(run(*args, "-o", lab / "wide.csv"), "beyond the voltages", f"{hi:g}")
    assert not (lab / "wide.csv").exists()
    res = run(*args, "--allow-extrapolation", "-o", lab / "wide.csv")
    assert res.exit_code == 0, res.output
    cmd = ph.io.read_table(lab / "wide.csv").get("command")
    assert cmd.min() >= -88 and cmd.max() <= 233


def test_the_cli_starts_with_a_slew_limited_ramp_and_precondition(lab: Path) -> None:
    model = ph.load_model(lab / "model.json")
    lo, hi = model.input_range_
    res = run("compensate", lab / "model.json", lab / "target.csv", "--present-voltage", "30",
              "-o", lab / "cmd.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    table = ph.io.read_table(lab / "cmd.csv")
    t, cmd = table.get("time"), table.get("command")
    desired = table.get("desired", finite=False)
    pre = ~np.isfinite(desired)
    n = int(pre.sum())
    assert n > 0 and pre[:n].all() and not pre[n:].any()  # the preamble comes first
    assert np.all(np.diff(t) > 0) and t[n] == 0.0
    # the preamble spans what the trajectory needs (with a margin), not the widest limits
    need_lo, need_hi = float(cmd[n:].min()), float(cmd[n:].max())
    assert cmd[:n].min() <= need_lo and cmd[:n].max() >= need_hi
    assert cmd[:n].max() <= need_hi + 0.15 * (need_hi - need_lo) < hi
    steps = np.abs(np.diff(np.concatenate([[30.0], cmd])))
    assert steps[0] <= model.max_slew_rate_ / 1000.0 * (1 + 1e-9)  # no jump from 30 V
    assert steps.max() <= model.max_slew_rate_ / 1000.0 * (1 + 1e-9)
    assert cmd.min() >= lo and cmd.max() <= hi


def test_compensate_starts_at_rest_unless_told(lab: Path) -> None:
    """Without --present-voltage the actuator is taken at rest: the first command is one
    slew step from 0 V (or from the nearer limit when 0 V lies outside them)."""
    model = ph.load_model(lab / "model.json")
    res = run("compensate", lab / "model.json", lab / "target.csv", "--v-min", "0",
              "--v-max", str(model.input_range_[1]), "-o", lab / "rest-cmd.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    cmd = ph.io.read_table(lab / "rest-cmd.csv").get("command")
    assert abs(cmd[0]) <= 2.0 and abs(cmd[0]) <= model.max_slew_rate_ / 1000.0 * (1 + 1e-9)


def test_python_and_the_cli_share_one_slew_default(lab: Path) -> None:
    """The Python Compensator never jumps further than the training record did: per second
    with a sample rate, per sample without one; None lifts it. The CLI's commands are the
    Python compensator's with the same settings, sample for sample."""
    model = ph.load_model(lab / "model.json")
    hi = model.input_range_[1]
    top = float(model.hysteresis_.predict([0.0, hi])[1])
    jump = np.full(50, top)  # from rest to the top in one sample
    per_sample = ph.Compensator(model, v_min=0.0, v_max=hi).process(jump)
    # tol: 1e-9 relative for the rounding of the clamp
    assert per_sample[0] <= model.max_step_ * (1 + 1e-9) < 0.05 * hi
    assert np.abs(np.diff(per_sample)).max() <= model.max_step_ * (1 + 1e-9)
    timed = ph.Compensator(model, v_min=0.0, v_max=hi, sample_rate=1000.0)
    assert timed.max_step == model.max_slew_rate_ / 1000.0
    free = ph.Compensator(model, v_min=0.0, v_max=hi, slew_rate=None).process(jump)
    assert free[0] == pytest.approx(hi, rel=1e-6)  # tol: the inverse's rounding at the top
    with pytest.raises(ph.ParameterError, match="'trained' or None"):
        ph.Compensator(model, v_min=0.0, v_max=hi, slew_rate="fast")  # type: ignore[arg-type]
    res = run("compensate", lab / "model.json", lab / "target.csv", "--v-min", "0",
              "--v-max", str(hi), "--no-precondition", "-o", lab / "same.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    written = ph.io.read_table(lab / "same.csv")
    comp = ph.Compensator(model, v_min=0.0, v_max=hi, sample_rate=1000.0)  # defaults alone
    comp.reset(voltage=0.0)  # at rest, as the CLI takes it
    expected = comp.process(ph.io.read_table(lab / "target.csv").get("desired"))
    # tol: the CLI's rate is 1/median(dt) of the file's times, an ulp off 1000 Hz, so each
    # slew-limited step may differ by ulps; 1e-9 V bounds thousands of them
    np.testing.assert_allclose(written.get("command"), expected, rtol=0, atol=1e-9)
    assert np.abs(np.diff(expected)).max() <= model.max_slew_rate_ / 1000.0 * (1 + 1e-9)


def test_nan_targets_are_held_and_counted(lab: Path) -> None:
    table = ph.io.read_table(lab / "target.csv")
    t, d = table.get("time"), table.get("desired").copy()
    d[500:510] = np.nan
    ph.write_table(lab / "gappy.csv", {"time": t, "desired": d})
    res = run("compensate", lab / "model.json", lab / "gappy.csv", "--no-precondition",
              "-o", lab / "gappy-cmd.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "10 for non-finite desired values" in res.stdout
    cmd = ph.io.read_table(lab / "gappy-cmd.csv").get("command")
    assert np.all(cmd[500:510] == cmd[499])


def test_a_trajectory_out_of_reach_is_an_error(lab: Path) -> None:
    model = ph.load_model(lab / "model.json")
    t = np.arange(2000) / 1000.0
    d = 2e-6 + 7e-6 * (1 - np.cos(2 * np.pi * 0.5 * t))  # metres: 2..16 um of a 20 um stroke
    ph.write_table(lab / "disp.csv", {"time": t, "desired": d})
    gain = 20e-6 / float(np.ptp(model.hysteresis_.predict(np.array([0.0, 140.0]))))
    ok = run("compensate", lab / "model.json", lab / "disp.csv", "--domain", "displacement",
             "--gain", f"{gain:.6g}", "--no-precondition", "-o", lab / "disp-cmd.csv")  # fmt: skip
    assert ok.exit_code == 0, ok.output
    bad = run("compensate", lab / "model.json", lab / "disp.csv", "--domain", "displacement",
              "--gain", f"{-gain:.6g}", "-o", lab / "disp-bad.csv")  # fmt: skip
    one_line_error(bad, "out of reach", "sign of the gain")
    assert not (lab / "disp-bad.csv").exists()


def test_a_target_without_times_needs_a_sample_rate(lab: Path) -> None:
    ph.write_table(
        lab / "no-time.csv", {"desired": ph.io.read_table(lab / "target.csv").get("desired")}
    )
    one_line_error(
        run("compensate", lab / "model.json", lab / "no-time.csv", "-o", lab / "nt.csv"),
        "no time column",
    )
    res = run("compensate", lab / "model.json", lab / "no-time.csv", "--sample-rate", "1000",
              "-o", lab / "nt.csv")  # fmt: skip
    assert res.exit_code == 0, res.output


def test_a_sample_rate_that_contradicts_the_targets_times_is_refused(lab: Path) -> None:
    """The target's time column at 1 kHz and --sample-rate 5000: the commands were computed
    at one rate (slew, lags) and written at the other's times, without a word. Refused,
    naming both; the rate the file has is accepted."""
    args = ("compensate", lab / "model.json", lab / "target.csv", "-o", lab / "sr.csv")
    said = "the time column steps at 1000 Hz, and the sample rate given is 5000 Hz"
    one_line_error(run(*args, "--sample-rate", "5000"), said)
    assert not (lab / "sr.csv").exists()
    res = run(*args, "--sample-rate", "1000")
    assert res.exit_code == 0, res.output
    # the simulated loop played any target at the bench's 1 kHz: one timed at 5 kHz ran 5x slow
    target = ph.io.read_table(lab / "target.csv")
    ph.write_table(
        lab / "fast.csv", {"time": target.get("time") / 5, "desired": target.get("desired")}
    )
    one_line_error(run("simulate-loop", lab / "model.json", lab / "fast.csv", "-o", lab / "l.csv"),
                   "the time column steps at 5000 Hz and the bench", "resample it")  # fmt: skip


# ------------------------------------------------------------------- Python
def test_the_compensator_narrows_wide_limits_with_one_warning(lab: Path) -> None:
    model = ph.load_model(lab / "model.json")
    lo, hi = model.input_range_
    with pytest.warns(UserWarning, match="narrowed") as record:
        comp = ph.Compensator(model, v_min=-88.0, v_max=233.0)
    assert len(record) == 1
    assert (comp.v_min, comp.v_max) == (lo, hi) and comp.requested_limits == (-88.0, 233.0)
    cmd = comp.process(np.linspace(-1e-5, 1e-5, 500))
    assert cmd.min() >= lo and cmd.max() <= hi
    wide = ph.Compensator(model, v_min=-88.0, v_max=233.0, allow_extrapolation=True)
    assert (wide.v_min, wide.v_max) == (-88.0, 233.0) and wide.requested_limits is None
    with pytest.raises(ph.ParameterError, match="do not overlap"):
        ph.Compensator(model, v_min=500.0, v_max=600.0)
    hand = ph.ClassicalPI.from_operator(ph.PIHysteresis([0.0], [1.0]))
    assert math.isnan(hand.input_range_[0])  # no training range known: limits kept as given
    assert ph.Compensator(hand, v_min=-1.0, v_max=1.0).v_min == -1.0


def test_the_training_slew_rate_is_recorded_and_saved(lab: Path) -> None:
    model = ph.load_model(lab / "model.json")
    rec = ph.io.read_table(lab / "run.csv")
    v, t = rec.get("voltage"), rec.get("time")
    # tol: the same computation on the same file's numbers
    assert model.max_slew_rate_ == pytest.approx(np.max(np.abs(np.diff(v)) / np.diff(t)))


# -------------------------------------------------------------- time and units
def bench_columns(lab: Path) -> dict[str, np.ndarray]:
    table = ph.io.read_table(lab / "run.csv")
    return {c: table.get(c) for c in ("time", "voltage", "charge")}


def test_time_in_ms_gives_the_same_leakage(lab: Path) -> None:
    cols = bench_columns(lab)
    ref = ph.load_model(lab / "model.json")
    ms = dict(cols, time=cols["time"] * 1000.0)
    ph.write_table(lab / "ms-header.csv", ms, units={"time": "ms"})  # 'time [ms]' header
    ph.write_table(lab / "ms-bare.csv", ms)  # no unit anywhere: must be declared
    ph.write_table(lab / "uc.csv", dict(cols, charge=cols["charge"] * 1e6), units={"charge": "uC"})
    for args in (
        [lab / "ms-header.csv"],
        [lab / "ms-bare.csv", "--time-unit", "ms"],
        [lab / "uc.csv"],
    ):
        out = lab / "unit-model.json"
        res = run("fit", *args, "--operators", "10", "-o", out)
        assert res.exit_code == 0, res.output
        model = ph.load_model(out)
        assert isinstance(model, ph.ActivePI) and model.output_unit == "C"
        # tol: the same data through the CLI and the API: the same arithmetic, 1e-9 allows BLAS
        # threads
        assert model.growth_rate_ == pytest.approx(ref.growth_rate_, rel=1e-9)
    # undeclared milliseconds at 1 kHz look like 1 s steps: only the unit can say; undeclared
    # microseconds (1000 "s" per sample) are called out
    ph.write_table(lab / "us-bare.csv", dict(cols, time=cols["time"] * 1e6))
    res = run("fit", lab / "us-bare.csv", "-o", lab / "unit-model.json")
    assert "warning:" in res.stderr and "not in seconds" in res.stderr
    one_line_error(
        run("fit", lab / "ms-header.csv", "--time-unit", "s", "-o", lab / "x.json"),
        "marked 'ms' in the file",
    )


def test_names_rates_and_units_that_contradict_the_file_are_errors(lab: Path) -> None:
    one_line_error(run("fit", lab / "run.csv", "--rate", "1000", "-o", lab / "x.json"),
                   "time column 'time' and a sample rate")  # fmt: skip
    one_line_error(run("predict", lab / "model.json", lab / "run.csv", "--output", "chrage",
                       "-o", lab / "p.csv"), "no column 'chrage'")  # fmt: skip
    one_line_error(run("fit", lab / "run.csv", "--time-unit", "V", "-o", lab / "x.json"),
                   "marked 's' in the file")  # fmt: skip
    ramp = np.arange(3.0)
    ph.write_table(lab / "volt-time.csv", {"time": ramp, "voltage": ramp, "charge": ramp},
                   units={"time": "V"})  # fmt: skip
    one_line_error(run("fit", lab / "volt-time.csv", "-o", lab / "x.json"), "not a unit of time")


def test_a_record_without_excitation_is_refused(lab: Path) -> None:
    t = np.arange(1000) / 1000.0
    ph.write_table(lab / "flat.csv", {"time": t, "voltage": np.full(t.size, 50.0),
                                      "charge": 1e-9 * t})  # fmt: skip
    one_line_error(run("fit", lab / "flat.csv", "-o", lab / "flat.json"), "never moves")
    assert not (lab / "flat.json").exists()


def test_displacement_data_is_not_labelled_coulomb(lab: Path) -> None:
    table = ph.io.read_table(lab / "run.csv")
    cols = {c: table.get(c) for c in ("time", "voltage", "displacement")}
    ph.write_table(lab / "disp-data.csv", {**cols, "displacement": cols["displacement"] * 1e6},
                   units={"displacement": "um"})  # fmt: skip
    res = run("fit", lab / "disp-data.csv", "--output", "displacement", "-o", lab / "d.json")
    assert res.exit_code == 0, res.output
    model = ph.load_model(lab / "d.json")
    assert model.output_unit == "m"  # converted from um
    pred = run("predict", lab / "d.json", lab / "disp-data.csv", "--output", "displacement",
               "-o", lab / "d-pred.csv")  # fmt: skip
    assert pred.exit_code == 0, pred.output
    out = ph.io.read_table(lab / "d-pred.csv")
    assert out.units["predicted"] == "m" and out.get("predicted").max() < 1e-3


def test_a_report_folder_is_replaced_by_the_next_report(lab: Path) -> None:
    args = ("report", lab / "model.json", lab / "run.csv", "--out", lab / "rep")
    assert run(*args).exit_code == 0
    assert run(*args).exit_code == 0  # its own report: replaced without --force
    assert ph.io.is_piezohyst_output(lab / "rep")


# ------------------------------------------------------------ real lab files
def test_tdms_picks_the_group_holding_the_channels(tmp_path: Path) -> None:
    from nptdms import ChannelObject, GroupObject, TdmsWriter

    rec = ph.simulate(duration=4.0, seed=1)
    props = {"wf_increment": 1e-3}
    with TdmsWriter(tmp_path / "scan.tdms") as writer:
        writer.write_segment([
            GroupObject("Meta"),
            ChannelObject("Meta", "Operator", np.array([1.0, 2.0])),
            GroupObject("Scan"),
            ChannelObject("Scan", "Ch0", rec.voltage, properties=props),
            ChannelObject("Scan", "Ch1", rec.charge, properties=props),
        ])  # fmt: skip
    res = run("fit", tmp_path / "scan.tdms", "--input", "Ch0", "--output", "Ch1",
              "-o", tmp_path / "m.json")  # fmt: skip
    assert res.exit_code == 0, res.output  # no --group needed: 'Meta' lacks the channels
    err = one_line_error(run("fit", tmp_path / "scan.tdms", "--input", "Ch9", "--output", "Ch1",
                             "-o", tmp_path / "x.json"), "no column 'Ch9'")  # fmt: skip
    assert "groups: 'Meta', 'Scan'" in err


def test_aixacct_exports_are_read_by_table(tmp_path: Path) -> None:
    rec = ph.simulate(duration=2.0, seed=3)
    aixacct_like(tmp_path / "loops.dat", rec)
    first = ph.io.read_recording(tmp_path / "loops.dat", input_column="V+", output_column="P1",
                                 time_column="Time")  # fmt: skip
    # tol: values printed with 7 significant digits in the file, scaled by the unit
    np.testing.assert_allclose(first.x, rec.voltage[:400], rtol=1e-6)
    np.testing.assert_allclose(first.y, rec.charge[:400], rtol=1e-6)  # µC -> C
    assert first.units == ("V", "C")
    second = ph.io.read_recording(tmp_path / "loops.dat", input_column="V+", output_column="P1",
                                  time_column="Time", group="2")  # fmt: skip
    # tol: the same printed precision
    np.testing.assert_allclose(second.x, rec.voltage[:400] / 2, rtol=1e-6)
    table = ph.io.read_table(tmp_path / "loops.dat", group="Summary")
    assert table.columns[:2] == ["Table No", "Vc+"] and table.groups[0] == "Summary"
    err = one_line_error(run("fit", tmp_path / "loops.dat", "--group", "7", "--input", "V+",
                             "--output", "P1", "--time", "Time", "-o", tmp_path / "m.json"),
                         "no aixACCT table '7'")  # fmt: skip
    assert "'Table 1', 'Table 2'" in err


def test_comment_lines_decimal_commas_and_parquet(tmp_path: Path) -> None:
    (tmp_path / "daq.csv").write_text(
        "% exported by a DAQ\n# operator: A. N. Other\nt (ms);U (V);Q (nC)\n"
        "0,0;0,0;0,0\n1,0;10,0;5,5\n2,0;20,0;11,0\n"
    )
    rec = ph.io.read_recording(tmp_path / "daq.csv", input_column="U", output_column="Q",
                               time_column="t")  # fmt: skip
    np.testing.assert_allclose(rec.t, [0.0, 1e-3, 2e-3])
    np.testing.assert_allclose(rec.y, [0.0, 5.5e-9, 11e-9])
    cols = {"time": rec.t, "voltage": rec.x, "charge": rec.y}
    ph.write_table(tmp_path / "r.parquet", cols, units={"time": "s", "charge": "C"})
    back = ph.io.read_table(tmp_path / "r.parquet")
    assert back.columns == ["time", "voltage", "charge"] and back.units == {
        "time": "s",
        "charge": "C",
    }
    np.testing.assert_array_equal(back.get("charge"), rec.y)
    assert ph.io.is_piezohyst_output(tmp_path / "r.parquet")


def test_large_csv_streams_with_progress(tmp_path: Path) -> None:
    n = 300_000
    t = np.arange(n) / 1000.0
    v = 70 * (1 - np.cos(2 * np.pi * 0.5 * t))
    ph.write_table(tmp_path / "big.csv", {"time": t, "voltage": v, "charge": 1e-8 * v},
                   units={"time": "s", "voltage": "V", "charge": "C"})  # fmt: skip
    seen: list[int] = []
    table = ph.io.read_table(tmp_path / "big.csv", progress=seen.append)
    assert seen and seen == sorted(seen) and seen[-1] == n and len(seen) > 1  # in batches
    np.testing.assert_array_equal(table.get("voltage"), v)  # exact round trip
    assert table.units == {"time": "s", "voltage": "V", "charge": "C"}
    ph.write_table(tmp_path / "big.parquet", {"time": t, "voltage": v}, units={"time": "s"})
    seen.clear()
    back = ph.io.read_table(tmp_path / "big.parquet", progress=seen.append)
    assert len(seen) > 1 and seen[-1] == n  # Parquet in batches too
    np.testing.assert_array_equal(back.get("voltage"), v)


def test_an_interrupted_report_leaves_nothing_and_the_rerun_works(
    lab: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C while the report is written: no folder (not even hidden staging), and the
    same command then succeeds; an earlier report stays until a new one is complete."""
    import piezohyst.analysis.report as report_module

    written = report_module.Report.write

    def interrupted(self: object) -> list[Path]:
        written(self)  # every file is on disk by now, in the staging folder
        raise KeyboardInterrupt

    args = ["report", lab / "model.json", lab / "run.csv", "--out", lab / "rep-interrupted"]
    monkeypatch.setattr(report_module.Report, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        wf.model_report(lab / "model.json", lab / "run.csv", lab / "rep-interrupted")
    assert not (lab / "rep-interrupted").exists()
    assert not [p for p in lab.iterdir() if p.name.startswith(".rep-interrupted.")]
    monkeypatch.setattr(report_module.Report, "write", written)
    assert run(*args).exit_code == 0
    first = (lab / "rep-interrupted" / "metrics.json").read_text()
    monkeypatch.setattr(report_module.Report, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        wf.model_report(lab / "model.json", lab / "run.csv", lab / "rep-interrupted")
    assert (lab / "rep-interrupted" / "metrics.json").read_text() == first  # the earlier one intact


def test_a_clipped_charge_is_reported_by_fit_predict_and_report(lab: Path) -> None:
    """A charge flat at its top on 20 % of the record (an ADC at full scale) is named,
    with its share, by every command that reads it; a clean record is not."""
    table = ph.io.read_table(lab / "run.csv")
    q = table.get("charge").copy()
    top = float(np.quantile(q, 0.8))
    ph.write_table(lab / "clipped.csv",
                   {"time": table.get("time"), "voltage": table.get("voltage"),
                    "charge": np.minimum(q, top)}, units={"time": "s", "voltage": "V",
                                                          "charge": "C"})  # fmt: skip
    for args in (
        ["fit", lab / "clipped.csv", "-o", lab / "clipped.json"],
        ["predict", lab / "model.json", lab / "clipped.csv", "-o", lab / "cp.csv"],
        ["report", lab / "model.json", lab / "clipped.csv", "--out", lab / "crep"],
    ):
        res = run(*args)
        assert res.exit_code == 0, res.output
        assert "'charge' sits at its top" in res.stderr and "(20.0 %" in res.stderr, res.stderr
    clean = run("predict", lab / "model.json", lab / "run.csv", "-o", lab / "clean.csv")
    assert clean.exit_code == 0 and "clipped" not in clean.stderr


def test_fit_names_its_output_a_json_file_and_the_report_its_version(lab: Path) -> None:
    res = run("fit", lab / "run.csv", "-o", lab / "model.txt")
    assert res.exit_code == 2 and "name it .json" in res.output
    assert not (lab / "model.txt").exists()
    assert "Output file (.json)" in run("fit", "--help").output
    assert run("report", lab / "model.json", lab / "run.csv", "--out", lab / "vrep").exit_code == 0
    md = (lab / "vrep" / "report.md").read_text()
    assert f"| piezohyst version | {ph.__version__} |" in md


def test_an_output_in_a_unit_of_another_quantity_and_an_absurd_value_are_named(
    tmp_path: Path,
) -> None:
    t = np.arange(400) / 1000.0
    v = 70 - 70 * np.cos(2 * np.pi * 5 * t)
    q = 1e-8 * v
    rows = "".join(f"{a},{b},{c * 1e3}\n" for a, b, c in zip(t, v, q, strict=True))
    (tmp_path / "ma.csv").write_text("time,voltage,charge [mA]\n" + rows)
    one_line_error(run("fit", tmp_path / "ma.csv", "-o", tmp_path / "ma.json"),
                   "'mA', a unit of [current], not a charge (C) or a displacement (m)")  # fmt: skip
    q[123] = 1e300
    rows = "".join(f"{a},{b},{c}\n" for a, b, c in zip(t, v, q, strict=True))
    (tmp_path / "big.csv").write_text("time,voltage,charge\n" + rows)
    one_line_error(run("fit", tmp_path / "big.csv", "-o", tmp_path / "big.json"),
                   "1e+300 at row 124, column 'charge'")  # fmt: skip
    assert not (tmp_path / "big.json").exists()


def test_an_aixacct_table_finds_its_time_column(tmp_path: Path) -> None:
    """aixACCT tables name their time 'Time [s]': found without --time."""
    t = np.arange(400) / 1000.0
    v = 700 * np.sin(2 * np.pi * 5 * t)
    p = 20 * np.tanh(v / 300) + 0.01 * v
    body = "".join(f"{a:e}\t{b:e}\t{c:e}\t\n" for a, b, c in zip(t, v, p, strict=True))
    (tmp_path / "trap.dat").write_text(
        "PiezoResult\n\nTable 1\nTableVersion: 4.11.0\n\nTime [s]\tV+ [V]\tP1 [uC/cm2]\t\n" + body
    )
    res = run("fit", tmp_path / "trap.dat", "--input", "V+", "--output", "P1", "--model",
              "classical-pi", "-o", tmp_path / "trap.json")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert ph.load_model(tmp_path / "trap.json").train_window_ == (0.0, 0.399)


def test_a_voltage_limit_counts_commands_sent_at_it_not_the_loops_approach(lab: Path) -> None:
    """The self-sensing loop's ramp from rest to a target mid-range: its feedback asks beyond
    140 V while the slew limit holds the commands far below it. Those were counted as held
    by the voltage limits (134 of them), and the loop warned 'the target is out of reach' of
    a target it then tracked at 0.5 % width. A command counts where it is sent at a limit (as
    the other cores count); a target beyond v_max still counts, and names its side."""
    from piezohyst.simulation import Bench
    from piezohyst.simulation.loop import run_loop

    model = ph.load_model(lab / "model.json")
    lo, hi = model.input_range_
    t = np.arange(3000) / 1000.0
    mid = model.hysteresis_.predict(70.0 + 60.0 * np.sin(2 * np.pi * t))  # from 70 V at once
    for scale, held in ((1.0, False), (1.15, True)):
        ctl = ph.SelfSensingController(model, v_min=lo, v_max=hi, sample_rate=1000.0)
        bench = Bench(ph.simulation.PRESETS["T226-H4-203X"], voltage=ctl.last_command, seed=0)
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always", ph.LimitWarning)
            rec = run_loop(ctl, scale * mid, bench)
        voltage = [str(w.message) for w in said if "voltage limits" in str(w.message)]
        at_limit = int(np.sum((rec.voltage <= lo) | (rec.voltage >= hi)))
        assert ctl.saturated_count <= at_limit  # each one sent at a limit
        assert (ctl.saturated_count > 0) == held and bool(voltage) == held, voltage
        if held:
            assert "at v_max: the target is beyond what v_max reaches" in voltage[0]
