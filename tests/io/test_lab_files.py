"""Files as labs write them: DAQ preambles, decimal commas, HDF5 with a stated rate,
input and output in two files, targets in their own unit, outputs that cannot be written."""

from __future__ import annotations

import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph

from ..helpers import one_line_error, run


@pytest.fixture(scope="module")
def rec() -> ph.simulation.Recording:
    return ph.simulate(duration=3.0, seed=4)


def european(path: Path, rec: ph.simulation.Recording, *, preamble: str, time: bool) -> None:
    """A DAQ export: a preamble, ';' between fields, decimal commas, charge in µC."""
    header = ("time [s];" if time else "") + "voltage [V];charge [uC]\n"
    rows = "".join(
        (f"{t:.4f};" if time else "") + f"{v:.6f};{q * 1e6:.8f}\n"
        for t, v, q in zip(rec.t, rec.voltage, rec.charge, strict=True)
    )
    path.write_text(preamble + header + rows.replace(".", ","), encoding="utf-8")


PREAMBLE = "Device: P-885.11\nOperator: A. Lab\nDate: 2026-11-20 14:02\nSample rate: 1000 Hz\n\n"


def test_a_daq_preamble_and_decimal_commas_are_read_without_options(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    european(tmp_path / "run.csv", rec, preamble=PREAMBLE, time=True)
    european(tmp_path / "untimed.csv", rec, preamble=PREAMBLE, time=False)
    for name in ("run.csv", "untimed.csv"):
        for read in (ph.io.read_table, ph.io.open_table):  # in memory, and streamed
            table = read(tmp_path / name)
            assert table.units["charge"] == "uC"
            # tol: the file prints 6 decimals of volts and 8 of µC
            np.testing.assert_allclose(table.get("voltage"), rec.voltage, atol=5e-7)
            np.testing.assert_allclose(table.get("charge"), rec.charge * 1e6, atol=5e-9)
    # the untimed file's time comes from the preamble's 'Sample rate: 1000 Hz'
    got = ph.io.read_recording(tmp_path / "untimed.csv")
    # tol: n/1000 computed two ways, a few ulp apart
    np.testing.assert_allclose(got.t, rec.t, atol=1e-12)
    res = run("fit", tmp_path / "untimed.csv", "--operators", "8", "-o", tmp_path / "m.json")
    assert res.exit_code == 0, res.output
    assert ph.load_model(tmp_path / "m.json").train_window_ == (0.0, 2.999)


def test_skip_rows_skips_what_is_not_a_preamble(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    """A preamble line of numbers (a date as '2026 11 20') looks like data: --skip-rows says
    where the table starts."""
    rows = "".join(
        f"{t:.4f} {v:.6f} {q:.6e}\n" for t, v, q in zip(rec.t, rec.voltage, rec.charge, strict=True)
    )
    path = tmp_path / "run.txt"
    path.write_text("bench run three\n2026 11 20\ntime voltage charge\n" + rows)
    one_line_error(run("fit", path, "-o", tmp_path / "m.json"), "available: 'bench'")
    res = run("fit", path, "--skip-rows", "2", "--operators", "8", "-o", tmp_path / "m.json")
    assert res.exit_code == 0, res.output
    np.savez(tmp_path / "run.npz", voltage=rec.voltage)
    with pytest.raises(ph.DataFileError, match="rows can be skipped in text files only"):
        ph.io.read_table(tmp_path / "run.npz", skip_rows=1)


def test_an_aixacct_export_defaults_to_its_first_measurement(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    """Columns named by number: the table read is the first with a time column, not 'Summary'."""
    from ..helpers import aixacct_like

    aixacct_like(tmp_path / "loops.dat", rec)
    got = ph.io.read_recording(tmp_path / "loops.dat", input_column="1", output_column="3")
    assert got.names == ("V+", "P1", "Time")
    # tol: values printed with 7 significant digits in the file
    np.testing.assert_allclose(got.y, rec.charge[:400], rtol=1e-6)
    res = run("fit", tmp_path / "loops.dat", "--input", "1", "--output", "3", "--operators",
              "6", "-o", tmp_path / "m.json")  # fmt: skip
    assert res.exit_code == 0, res.output
    one_line_error(run("fit", tmp_path / "loops.dat", "--input", "1", "--output", "2",
                       "-o", tmp_path / "v.json"), "the output never moves")  # fmt: skip


def test_hdf5_groups_and_their_stated_rate(tmp_path: Path, rec: ph.simulation.Recording) -> None:
    """The Bouc-Wen benchmark's layout: /group/u, /group/y and a scalar /group/fs."""
    import h5py

    with h5py.File(tmp_path / "bench.h5", "w") as f:
        f["slow/u"] = rec.voltage[:, None]
        f["slow/y"] = rec.charge[:, None]
        f["slow/fs"] = np.array([[1000.0]])
        f["fast/u"] = rec.voltage[::2]
        f["fast/y"] = rec.charge[::2]
        f["fast"].attrs["sample_rate"] = 500.0
        f.attrs["fs"] = 7.0  # the file's own, below the groups': not used where a group states one
    for group, n, step in (("slow", 3000, 1e-3), ("fast", 1500, 2e-3)):
        got = ph.io.read_recording(tmp_path / "bench.h5", group=group, input_column="u",
                                   output_column="y")  # fmt: skip
        assert got.t.size == n and got.t[-1] == pytest.approx((n - 1) * step)  # tol: n*dt, ulp
    by_path = ph.io.read_recording(
        tmp_path / "bench.h5", input_column="fast/u", output_column="fast/y"
    )
    assert by_path.t[1] == pytest.approx(2e-3)  # tol: 1/500 Hz, ulp
    res = run("fit", tmp_path / "bench.h5", "--group", "slow", "--input", "u", "--output", "y",
              "--operators", "8", "-o", tmp_path / "m.json")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert ph.load_model(tmp_path / "m.json").train_window_ == (0.0, 2.999)
    one_line_error(run("fit", tmp_path / "bench.h5", "--group", "mid", "--input", "u", "--output",
                       "y", "-o", tmp_path / "x.json"),
                   "no HDF5 group 'mid'; available: 'fast', 'slow'")  # fmt: skip


def test_input_and_output_in_two_files(tmp_path: Path, rec: ph.simulation.Recording) -> None:
    """The Bouc-Wen benchmark's uval/yval .mat pair, and two CSV files streamed row for row."""
    from scipy.io import savemat

    savemat(tmp_path / "uval_test.mat", {"uval_test": rec.voltage[None, :]})
    savemat(tmp_path / "yval_test.mat", {"yval_test": rec.charge[None, :]})
    savemat(tmp_path / "yval_short.mat", {"yval_short": rec.charge[None, :-5]})
    both = ph.io.read_recording(tmp_path / "uval_test.mat", input_column="uval_test",
                                output_file=tmp_path / "yval_test.mat",
                                output_column="yval_test", rate=1000.0)  # fmt: skip
    np.testing.assert_array_equal(both.y, rec.charge)
    np.testing.assert_array_equal(both.x, rec.voltage)
    res = run("fit", tmp_path / "uval_test.mat", "--input", "uval_test", "--output-file",
              tmp_path / "yval_test.mat", "--output", "yval_test", "--rate", "1000",
              "--operators", "8", "-o", tmp_path / "m.json")  # fmt: skip
    assert res.exit_code == 0, res.output
    one_line_error(run("fit", tmp_path / "uval_test.mat", "--input", "uval_test",
                       "--output-file", tmp_path / "yval_short.mat", "--output", "yval_short",
                       "--rate", "1000", "-o", tmp_path / "x.json"),
                   "2995 rows, but", "has 3000")  # fmt: skip
    # two CSV files, read in batches of different sizes, joined row for row
    ph.write_table(tmp_path / "in.csv", {"time": rec.t, "voltage": rec.voltage})
    ph.write_table(tmp_path / "out.csv", {"time": rec.t, "charge": rec.charge})
    spec = ph.io.DataSpec(output_file=str(tmp_path / "out.csv"))
    stream = spec.open(tmp_path / "in.csv")
    blocks = list(stream.blocks())
    np.testing.assert_array_equal(np.concatenate([b.y for b in blocks]), rec.charge)
    np.testing.assert_array_equal(np.concatenate([b.t for b in blocks]), rec.t)


def test_a_target_in_its_own_unit_and_zero(tmp_path: Path, rec: ph.simulation.Recording) -> None:
    """A target in µm relative to another zero: --target-unit and --target-offset."""
    ph.write_table(tmp_path / "run.csv", {"time": rec.t, "voltage": rec.voltage,
                                          "charge": rec.charge})  # fmt: skip
    assert (
        run("fit", tmp_path / "run.csv", "--operators", "8", "-o", tmp_path / "m.json").exit_code
        == 0
    )
    model = ph.load_model(tmp_path / "m.json")
    t = np.arange(1500) / 1000.0
    desired = model.hysteresis_.predict(60 - 40 * np.cos(2 * np.pi * t))  # C
    offset_uc = -3.0
    ph.write_table(tmp_path / "abs.csv", {"time": t, "desired": desired})
    relative = (desired * 1e6 - offset_uc).tolist()
    (tmp_path / "rel.csv").write_text(
        "time,desired\n"
        + "".join(f"{a!r},{d!r}\n" for a, d in zip(t.tolist(), relative, strict=True))
    )
    assert run("compensate", tmp_path / "m.json", tmp_path / "abs.csv",
               "-o", tmp_path / "a.csv").exit_code == 0  # fmt: skip
    res = run("compensate", tmp_path / "m.json", tmp_path / "rel.csv", "--target-unit", "uC",
              "--target-offset", str(offset_uc), "-o", tmp_path / "b.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    a, b = ph.io.read_table(tmp_path / "a.csv"), ph.io.read_table(tmp_path / "b.csv")
    # tol: µC written as shortest decimals, converted and offset: a few ulp of 1e-5 C; the
    # commands then agree to the inverse's rounding
    np.testing.assert_allclose(b.get("command"), a.get("command"), atol=1e-9)
    one_line_error(run("compensate", tmp_path / "m.json", tmp_path / "a.csv", "--column",
                       "command", "--target-unit", "uC", "-o", tmp_path / "c.csv"),
                   "marked 'V' in the file")  # fmt: skip


def test_outputs_that_cannot_be_written_are_named(
    tmp_path: Path, rec: ph.simulation.Recording, monkeypatch: pytest.MonkeyPatch
) -> None:
    ph.write_table(tmp_path / "run.csv", {"time": rec.t, "voltage": rec.voltage,
                                          "charge": rec.charge})  # fmt: skip
    (tmp_path / "afile").write_text("x")
    one_line_error(run("fit", tmp_path / "run.csv", "-o", tmp_path / "afile" / "m.json"),
                   "m.json: cannot write here", "afile is a file, not a folder")  # fmt: skip

    def refused(*args: object, **kwargs: object) -> None:
        raise PermissionError(13, "Permission denied", str(tmp_path / ".m.json.abc123.json"))

    monkeypatch.setattr(tempfile, "mkstemp", refused)  # a read-only folder, even as root
    res = run("fit", tmp_path / "run.csv", "--operators", "6", "-o", tmp_path / "m.json")
    err = one_line_error(res, "m.json: cannot write here (permission denied)")
    assert ".m.json." not in err
    with pytest.raises(ph.OutputError):
        ph.io.atomic_write_text(tmp_path / "x.txt", "x")


@pytest.mark.parametrize(
    ("command", "out", "expected"),
    [
        (["predict", "M", "D"], "p.txt", "name it .csv, .npz or .parquet"),
        (["fit", "D"], "m.csv", "name it .json"),
        (["calibrate-leakage", "D"], "leak.csv", "name it .json"),
        (["export-c", "M"], "comp.h", "name it .c"),
    ],
)
def test_output_names_say_what_is_written(
    tmp_path: Path, command: list[str], out: str, expected: str
) -> None:
    (tmp_path / "d.csv").write_text("time,voltage,charge\n0,0,0\n0.001,1,1e-9\n")
    args = [{"M": "m.json", "D": str(tmp_path / "d.csv")}.get(a, a) for a in command]
    res = run(*args, "-o", tmp_path / out)
    assert res.exit_code == 2 and expected in res.output, res.output
    assert not (tmp_path / out).exists()


def test_a_units_row_under_the_header_and_a_byte_order_mark(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    """An oscilloscope's export puts the units in a row of their own under the header
    (PicoScope: ``Time,Channel A,Channel B`` then ``(ms),(V),(nC)``, then a blank line): read
    as ``Time (ms)`` (it took the units row for the header: "no column 'Channel A'; available:
    '(ms)', '(V)', '(nC)'"). Excel's 'CSV UTF-8' opens with a byte-order mark, which hid the
    time column ('\\ufefftime'). Both, in memory and streamed, in every delimiter's reader."""
    rows = "".join(f"{1e3 * t:.3f},{v:.6f},{1e9 * q:.6f}\n"
                   for t, v, q in zip(rec.t, rec.voltage, rec.charge, strict=True))  # fmt: skip
    (tmp_path / "pico.csv").write_text("Time,Channel A,Channel B\n(ms),(V),(nC)\n\n" + rows)
    (tmp_path / "pico.txt").write_text(
        "Time Channel_A Channel_B\n(ms) (V) (nC)\n" + rows.replace(",", " ")
    )
    (tmp_path / "bom.csv").write_text(
        "\ufefftime [ms],voltage [V],charge [nC]\n" + rows, encoding="utf-8"
    )
    for name, x, y in (("pico.csv", "Channel A", "Channel B"),
                       ("pico.txt", "Channel_A", "Channel_B"),
                       ("bom.csv", "voltage", "charge")):  # fmt: skip
        for read in (ph.io.read_table, ph.io.open_table):
            table = read(tmp_path / name)
            assert table.columns[0].lower() == "time" and table.units[table.columns[0]] == "ms"
        got = ph.io.read_recording(tmp_path / name, input_column=x, output_column=y)
        # tol: the file prints 3 decimals of ms, 6 of volts and of nC
        np.testing.assert_allclose(got.t, rec.t, atol=5e-7)
        np.testing.assert_allclose(got.x, rec.voltage, atol=5e-7)
        np.testing.assert_allclose(got.y, rec.charge, atol=5e-16)
        assert got.units == ("V", "C")


def test_a_time_column_of_timestamps(tmp_path: Path, rec: ph.simulation.Recording) -> None:
    """A logger writes its clock (``2026-11-27 10:00:00.125``): read as the seconds from the
    first row's, in memory and streamed (it was "'2026-11-27 10:00:00.000' at row 1 ... is
    not a number"); a cell that is not a timestamp is still named by its row."""
    from datetime import datetime, timedelta

    start = datetime(2026, 11, 27, 23, 59, 58)  # across midnight
    stamps = [(start + timedelta(seconds=float(t))).isoformat(sep=sep, timespec="milliseconds")
              for t, sep in zip(rec.t, "T " * rec.t.size, strict=False)]  # fmt: skip
    rows = [f"{s},{v:.6f},{q:.6e}"
            for s, v, q in zip(stamps, rec.voltage, rec.charge, strict=True)]  # fmt: skip
    (tmp_path / "clock.csv").write_text("time,voltage,charge\n" + "\n".join(rows) + "\n")
    for read in (ph.io.read_table, ph.io.open_table):
        # tol: the clock prints milliseconds; the times are n/1000 s
        np.testing.assert_allclose(read(tmp_path / "clock.csv").get("time"), rec.t, atol=1e-9)
    res = run("fit", tmp_path / "clock.csv", "--operators", "8", "-o", tmp_path / "m.json")
    assert res.exit_code == 0, res.output
    rows[500] = "27/11/2026 10:00:00," + rows[500].split(",", 1)[1]
    (tmp_path / "bad.csv").write_text("time,voltage,charge\n" + "\n".join(rows) + "\n")
    one_line_error(run("fit", tmp_path / "bad.csv", "-o", tmp_path / "b.json"),
                   "'27/11/2026 10:00:00' at row 501 (line 502 of the file), column 'time' "
                   "is not a timestamp, as the rows above are")  # fmt: skip
    rows[500] = "2026-11-27T10:00:00Z," + rows[500].split(",", 1)[1]  # one with an offset
    (tmp_path / "mixed.csv").write_text("time,voltage,charge\n" + "\n".join(rows) + "\n")
    one_line_error(run("fit", tmp_path / "mixed.csv", "-o", tmp_path / "x.json"),
                   "column 'time' mixes timestamps with and without a UTC offset")  # fmt: skip


LVM_HEAD = (
    "LabVIEW Measurement\t\nWriter_Version\t2\nReader_Version\t2\nSeparator\tTab\n"
    "Decimal_Separator\t.\nMulti_Headings\tNo\nX_Columns\tOne\nTime_Pref\tRelative\n"
    "Operator\tuser\nDate\t2026/11/27\nTime\t10:00:00.000\n***End_of_Header***\t\n\t\n"
    "Channels\t2\t\nSamples\t3000\t3000\t\nDate\t2026/11/27\t2026/11/27\t\n"
    "Time\t10:00:00.000\t10:00:00.000\t\nX_Dimension\tTime\tTime\t\n"
    "X0\t0.0000000000000000E+0\t0.0000000000000000E+0\t\nDelta_X\t0.001000\t0.001000\t\n"
    "***End_of_Header***\t\nX_Value\tVoltage\tCharge\tComment\n"
)


def test_a_labview_measurement_file(tmp_path: Path, rec: ph.simulation.Recording) -> None:
    """LabVIEW's 'Write To Measurement File' (.lvm): two header blocks, then ``X_Value`` for
    the time; fitted with the default names (it was "no time column 'time'")."""
    rows = "".join(f"{t:.6f}\t{v:.6f}\t{q:.6e}\t\n"
                   for t, v, q in zip(rec.t, rec.voltage, rec.charge, strict=True))  # fmt: skip
    (tmp_path / "run.lvm").write_text(LVM_HEAD + rows)
    got = ph.io.read_recording(tmp_path / "run.lvm")
    np.testing.assert_allclose(got.t, rec.t, atol=5e-7)  # tol: 6 decimals printed
    np.testing.assert_allclose(got.y, rec.charge, rtol=5e-7)  # tol: 7 significant digits
    res = run("fit", tmp_path / "run.lvm", "--operators", "8", "-o", tmp_path / "m.json")
    assert res.exit_code == 0, res.output


def test_hdf5_units_attributes(tmp_path: Path, rec: ph.simulation.Recording) -> None:
    """An HDF5 writer states each dataset's unit in its ``units`` attribute (NeXus, h5py
    scripts): time in ms and charge in nC were read as s and 'a.u.' without a word (a 1 kHz
    record taken for 1 Hz). Read and converted, as text or bytes, in a group or not."""
    import h5py

    with h5py.File(tmp_path / "u.h5", "w") as h:
        g = h.create_group("run")
        g.create_dataset("time", data=1e3 * rec.t).attrs["units"] = "ms"
        g.create_dataset("voltage", data=rec.voltage).attrs["unit"] = np.bytes_(b"V")
        g.create_dataset("charge", data=1e9 * rec.charge).attrs["units"] = "nC"
    for group in (None, "run"):
        got = ph.io.read_recording(tmp_path / "u.h5", group=group)
        assert got.units == ("V", "C")
        np.testing.assert_allclose(got.t, rec.t, rtol=1e-12)  # tol: ms -> s, one rounding
        np.testing.assert_allclose(got.y, rec.charge, rtol=1e-12)


def test_a_time_column_in_ms_without_a_unit_is_named(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    """A time column counting milliseconds with no unit anywhere was read as seconds without
    a word (a 1 kHz record fitted as 1 Hz: its leakage 1000x too small, its trained slew
    1000x too slow). Integer steps of 1 s or more with no unit stated are named; a stated
    unit says nothing."""
    pairs = zip(rec.voltage, rec.charge, strict=True)
    rows = "".join(f"{n},{v:.6f},{q:.6e}\n" for n, (v, q) in enumerate(pairs))
    (tmp_path / "ms.csv").write_text("time,voltage,charge\n" + rows)
    with pytest.warns(ph.errors.RecordWarning, match=r"steps by 1 and states no unit: read as "
                      r"seconds, the record is sampled at 1 Hz; if it counts ms"):  # fmt: skip
        ph.io.read_recording(tmp_path / "ms.csv")
    got = ph.io.read_recording(tmp_path / "ms.csv", time_unit="ms")  # said: no warning
    np.testing.assert_allclose(got.t, rec.t, atol=1e-12)  # tol: n/1000 two ways


def test_an_output_in_um_without_a_unit_is_named(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    """A column named displacement (or charge) with no unit is taken in m (or C); one in µm
    (nC) was fitted as hundreds of metres (coulombs) without a word. A span no piezo has in
    the assumed unit is named; the unit given, nothing is."""
    for column, values, unit in (("displacement", 1e6 * rec.displacement, "um"),
                                 ("charge", 1e9 * rec.charge, "nC")):  # fmt: skip
        rows = "".join(f"{t:.4f},{v:.6f},{y:.6f}\n"
                       for t, v, y in zip(rec.t, rec.voltage, values, strict=True))  # fmt: skip
        (tmp_path / "u.csv").write_text(f"time,voltage,{column}\n" + rows)
        res = run("fit", tmp_path / "u.csv", "--output", column, "--model", "classical-pi",
                  "-o", tmp_path / "m.json", "--force")  # fmt: skip
        assert res.exit_code == 0, res.output
        assert f"column '{column}' states no unit and spans" in res.output
        assert unit in res.output.split("states no unit")[1].split("give the unit")[0]
        res = run("fit", tmp_path / "u.csv", "--output", column, "--output-unit", unit,
                  "--model", "classical-pi", "-o", tmp_path / "m.json", "--force")  # fmt: skip
        assert res.exit_code == 0 and "states no unit" not in res.output, res.output
    # calibrate-gain's displacement column in um: a gain of 1.25e8 m/C, without a word
    rows = "".join(f"{t:.4f},{v:.6f},{q:.6e},{1e6 * d:.6f}\n" for t, v, q, d in
                   zip(rec.t, rec.voltage, rec.charge, rec.displacement, strict=True))  # fmt: skip
    (tmp_path / "cal.csv").write_text("time,voltage,charge,displacement\n" + rows)
    model = ph.ActivePI(8).fit(rec.voltage, rec.charge, t=rec.t)
    q = tmp_path / "q.json"
    model.save(q)
    res = run("calibrate-gain", q, tmp_path / "cal.csv", "-o", tmp_path / "g.json")
    assert res.exit_code == 0, res.output
    assert "column 'displacement' states no unit" in res.output and "--displacement-unit" in (
        res.output
    )
    # the input in mV, read as volts: 140 kV, which no piezo amplifier drives
    rows = "".join(f"{t:.4f},{1e3 * v:.3f},{q:.6e}\n"
                   for t, v, q in zip(rec.t, rec.voltage, rec.charge, strict=True))  # fmt: skip
    (tmp_path / "mv.csv").write_text("time,voltage,charge\n" + rows)
    for command, option, out in (("fit", "--model", "mv.json"), ("compare", "--models", "mv.md")):
        res = run(command, tmp_path / "mv.csv", option, "classical-pi", "-o", tmp_path / out)
        assert res.exit_code == 0, res.output
        assert "column 'voltage' states no unit and spans" in res.output
        assert "if it is in mV, give the unit (--input-unit mV" in res.output


def test_a_tdms_channel_of_timestamps(tmp_path: Path, rec: ph.simulation.Recording) -> None:
    """LabVIEW logs its clock as a TDMS channel of timestamps: it was dropped as not numeric,
    and the error then said "no time column" of a file with one. Read as seconds from its
    first sample, as a text file's timestamps are."""
    from nptdms import ChannelObject, TdmsWriter

    clock = np.datetime64("2026-11-27T23:59:58") + np.round(rec.t * 1e6).astype("timedelta64[us]")
    with TdmsWriter(tmp_path / "log.tdms") as w:
        w.write_segment([ChannelObject("Log", "Time", clock),
                         ChannelObject("Log", "Voltage", rec.voltage),
                         ChannelObject("Log", "Charge", rec.charge)])  # fmt: skip
    got = ph.io.read_recording(tmp_path / "log.tdms")
    # tol: whole microseconds (n ms exactly) back to seconds, a few ulp
    np.testing.assert_allclose(got.t, rec.t, atol=1e-12)
    np.testing.assert_array_equal(got.y, rec.charge)


def test_a_spreadsheet_workbook_is_named_not_read_as_text(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    """An Excel workbook was read as text: 'the file has a header but no data rows'. By its
    suffix or, renamed, by its first bytes (a zip archive, an OLE2 file), it is refused in a
    line that says what to do; an .npz (a zip too) is still read."""
    zipped = tmp_path / "book.xlsx"
    with zipfile.ZipFile(zipped, "w") as z:  # what an .xlsx is: a zip of XML parts
        z.writestr("xl/workbook.xml", "<workbook/>")
    (tmp_path / "renamed.csv").write_bytes(zipped.read_bytes())
    (tmp_path / "old.xls").write_bytes(b"\xd0\xcf\x11\xe0" + bytes(508))
    (tmp_path / "run.zip").write_bytes(zipped.read_bytes())
    cases = {
        "book.xlsx": "a .xlsx workbook",
        "renamed.csv": "a zip archive",
        "old.xls": "a .xls workbook",
        "run.zip": "unzip it",
    }
    for name, said in cases.items():
        one_line_error(run("fit", tmp_path / name, "-o", tmp_path / "m.json"), said)
        with pytest.raises(ph.DataFileError, match="not a table piezohyst reads"):
            ph.io.open_table(tmp_path / name)
    one_line_error(run("fit", tmp_path / "book.xlsx", "-o", tmp_path / "m.json"), "CSV UTF-8")
    np.savez(tmp_path / "run.npz", time=rec.t, voltage=rec.voltage, charge=rec.charge)
    assert ph.io.read_table(tmp_path / "run.npz").columns == ["time", "voltage", "charge"]


def test_a_spreadsheets_empty_rows_are_passed_over_and_a_time_that_repeats_is_explained(
    tmp_path: Path, rec: ph.simulation.Recording
) -> None:
    """Excel writes an emptied row as ',,' (it was 'an empty value at row N ... is not a
    number'); a row with no value carries nothing and is passed over. A time that repeats
    or goes back is still refused, saying which it is."""
    cols = zip(rec.t, rec.voltage, rec.charge, strict=True)
    lines = [f"{t:.4f},{v:.6f},{q:.9e}" for t, v, q in cols]
    body = [*lines[:1000], ",,", *lines[1000:], ",,", ",,"]
    (tmp_path / "sheet.csv").write_text("time,voltage,charge\n" + "\n".join(body) + "\n")
    for read in (ph.io.read_table, ph.io.open_table):
        table = read(tmp_path / "sheet.csv")
        # tol: the file prints 6 decimals of volts
        np.testing.assert_allclose(table.get("voltage"), rec.voltage, atol=5e-7)
    twice = [*lines[:1000], lines[999], *lines[1000:]]
    (tmp_path / "twice.csv").write_text("time,voltage,charge\n" + "\n".join(twice) + "\n")
    one_line_error(run("fit", tmp_path / "twice.csv", "-o", tmp_path / "m.json"),
                   "time is not increasing at row 1001", "a sample logged twice")  # fmt: skip
    runs = [*lines[:1500], *lines[:1500]]
    (tmp_path / "runs.csv").write_text("time,voltage,charge\n" + "\n".join(runs) + "\n")
    one_line_error(run("fit", tmp_path / "runs.csv", "-o", tmp_path / "m.json"),
                   "at row 1501", "two records in one file")  # fmt: skip
