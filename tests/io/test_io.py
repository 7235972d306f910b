"""Readers and writers: round trips, and fuzzing with garbled and truncated files."""

from __future__ import annotations

import io as stdio
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.errors import DataFileError

from ..strategies import examples

SUFFIXES = [".csv", ".txt", ".npz", ".mat", ".tdms", ".h5"]


def _valid_files(folder: Path) -> dict[str, bytes]:
    """One valid file of every format, as bytes."""
    import h5py
    from nptdms import ChannelObject, GroupObject, TdmsWriter
    from scipy.io import savemat

    v = np.linspace(0, 1, 50)
    out = {}
    ph.write_table(folder / "a.csv", {"time": v, "voltage": v})
    ph.write_table(folder / "a.npz", {"time": v, "voltage": v})
    savemat(folder / "a.mat", {"time": v, "voltage": v})
    with TdmsWriter(folder / "a.tdms") as w:
        w.write_segment([GroupObject("g"), ChannelObject("g", "voltage", v)])
    with h5py.File(folder / "a.h5", "w") as fh:
        fh["voltage"] = v
    for suffix in (".csv", ".npz", ".mat", ".tdms", ".h5"):
        out[suffix] = (folder / f"a{suffix}").read_bytes()
    out[".txt"] = out[".csv"]
    return out


def read_or_clean_error(path: Path) -> None:
    """The only outcomes allowed: data, or one DataFileError line naming the file."""
    try:
        table = ph.read_table(path)
    except DataFileError as exc:
        text = str(exc)
        assert "\n" not in text and str(path) in text
        return
    for name in table.columns:
        try:
            values = table.get(name)
        except DataFileError as exc:
            assert "\n" not in str(exc)
            continue
        assert values.dtype == np.float64 and np.all(np.isfinite(values))


@pytest.fixture(scope="module")
def valid(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    return _valid_files(tmp_path_factory.mktemp("valid"))


@settings(max_examples=examples(150), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=600), suffix=st.sampled_from(SUFFIXES))
def test_random_bytes(tmp_path: Path, data: bytes, suffix: str) -> None:
    path = tmp_path / f"f{suffix}"
    path.write_bytes(data)
    read_or_clean_error(path)


@settings(max_examples=examples(150), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    suffix=st.sampled_from(SUFFIXES),
    cut=st.floats(0.0, 1.0),
    flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)), max_size=4),
)
def test_truncated_and_corrupted_valid_files(
    tmp_path: Path, valid: dict[str, bytes], suffix: str, cut: float, flips: list
) -> None:  # fmt: skip
    raw = bytearray(valid[suffix][: max(1, int(len(valid[suffix]) * cut))])
    for where, byte in flips:
        raw[min(int(where * len(raw)), len(raw) - 1)] = byte
    path = tmp_path / f"f{suffix}"
    path.write_bytes(bytes(raw))
    read_or_clean_error(path)


@settings(max_examples=examples(150), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    rows=st.lists(
        st.lists(
            st.one_of(st.floats(allow_nan=True), st.text(max_size=4), st.just("")), max_size=5
        ),
        max_size=8,
    ),
    delim=st.sampled_from([",", ";", "\t", " "]),
    encoding=st.sampled_from(["utf-8", "utf-16", "latin-1", "cp1252"]),
)
def test_ragged_and_garbled_text(tmp_path: Path, rows: list, delim: str, encoding: str) -> None:
    text = "\n".join(delim.join(str(c) for c in row) for row in rows)
    path = tmp_path / "f.csv"
    try:
        path.write_bytes(text.encode(encoding))
    except UnicodeEncodeError:
        path.write_bytes(text.encode(encoding, errors="replace"))
    read_or_clean_error(path)


def test_csv_round_trip_and_header_detection(tmp_path: Path) -> None:
    t = np.arange(5) / 10
    ph.write_table(tmp_path / "a.csv", {"time": t, "voltage": t * 3})
    table = ph.read_table(tmp_path / "a.csv")
    assert table.columns == ["time", "voltage"]
    np.testing.assert_array_equal(table.get("voltage"), t * 3)  # full precision
    np.testing.assert_array_equal(table.get("1"), t * 3)  # by index
    (tmp_path / "b.txt").write_text("0.0 1.5\n0.1 2.5\n0.2 3.5\n")
    headless = ph.read_table(tmp_path / "b.txt")
    assert headless.columns == ["col0", "col1"]
    np.testing.assert_array_equal(headless.get("col1"), [1.5, 2.5, 3.5])
    (tmp_path / "c.csv").write_text("Zeit;Spannung\n0;1,5\n0,1;-2,25e1\n")  # decimal commas
    np.testing.assert_array_equal(ph.read_table(tmp_path / "c.csv").get("Spannung"), [1.5, -22.5])
    np.testing.assert_array_equal(ph.read_table(tmp_path / "c.csv").get("Zeit"), [0.0, 0.1])
    (tmp_path / "d.csv").write_text("Zeit;Spannung\n0;1.5\n0.1;x\n")  # a point: no commas
    with pytest.raises(
        DataFileError,
        match=r"'x' at row 2 \(line 3 of the file\), column 'Spannung' is not a number",
    ):
        ph.read_table(tmp_path / "d.csv").get("Spannung")


def test_latin1_headers_are_read(tmp_path: Path) -> None:
    (tmp_path / "a.dat").write_bytes("Time [s]\tP1 [µC/cm2]\n0\t1\n1\t2\n".encode("latin-1"))
    table = ph.read_table(tmp_path / "a.dat")
    assert table.columns == ["Time", "P1"]  # units read from the headers
    assert table.units == {"Time": "s", "P1": "µC/cm2"}
    assert table.resolve("P1 [µC/cm2]") == "P1"  # the full header names the column too


def test_writes_are_atomic(tmp_path: Path) -> None:
    target = tmp_path / "out.csv"
    target.write_text("old")
    with pytest.raises(DataFileError):
        ph.write_table(target, {"a": [1, 2], "b": [1]})
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]


def test_npz_round_trip(tmp_path: Path) -> None:
    ph.write_table(tmp_path / "a.npz", {"x": [1.0, 2.0]})
    np.testing.assert_array_equal(ph.read_table(tmp_path / "a.npz").get("x"), [1.0, 2.0])


def test_unused_bad_columns_do_not_block_reading(tmp_path: Path) -> None:
    """Like the measured actuator file: an empty leftover index column before the data."""
    (tmp_path / "d.csv").write_text(",0.0,1.5,2\n,0.1,2.5,3\n")
    table = ph.read_table(tmp_path / "d.csv")
    np.testing.assert_array_equal(table.get("col2"), [1.5, 2.5])
    with pytest.raises(
        DataFileError, match=r"an empty value at row 1 \(line 1 of the file\), column 'col0'"
    ):
        table.get("col0")


def test_stdlib_io_not_shadowed() -> None:
    assert stdio.StringIO("x").read() == "x" and shutil.which("sh")


def _real_part_tag(raw: bytes) -> int:
    """Offset of the first real part's data-type tag in a MAT v5 file of doubles."""
    import struct

    return raw.index(struct.pack("<II", 9, 400))  # miDOUBLE, 50 values


@pytest.mark.parametrize("dtype", [20, 140, 255])
def test_a_mat_file_that_crashed_scipy_is_one_line(
    tmp_path: Path, valid: dict[str, bytes], dtype: int
) -> None:
    """An unknown data type in an array's tag made SciPy's MAT reader read out of bounds
    and kill the process (SciPy 1.17, found by the fuzz test above)."""
    raw = bytearray(valid[".mat"])
    raw[_real_part_tag(raw)] = dtype
    path = tmp_path / "damaged.mat"
    path.write_bytes(bytes(raw))
    with pytest.raises(DataFileError, match=r"damaged\.mat") as err:
        ph.read_table(path)
    assert "\n" not in str(err.value)


def test_a_parser_crash_is_an_error_naming_the_file(tmp_path: Path) -> None:
    from piezohyst.io._isolate import parse_isolated

    path = tmp_path / "x.h5"
    with pytest.raises(DataFileError, match=r"x\.h5: the HDF5 reader crashed .*signal 11"):
        parse_isolated("crash", path, "HDF5")
    with pytest.raises(FileNotFoundError):  # the parser's own errors come back as they are
        parse_isolated("hdf5_arrays", tmp_path / "missing.h5", "HDF5")
    # and the next read starts a new helper
    ph.write_table(tmp_path / "ok.npz", {"v": np.arange(3.0)})
    import h5py

    with h5py.File(tmp_path / "ok.h5", "w") as fh:
        fh["v"] = np.arange(3.0)
    np.testing.assert_array_equal(ph.read_table(tmp_path / "ok.h5").get("v"), [0.0, 1.0, 2.0])


def test_the_parser_helper_runs_none_of_the_callers_code(tmp_path: Path) -> None:
    """A script without a main guard that reads a MAT file runs once: the helper is a fresh
    interpreter that loads the parsers by path, not the caller's script, not piezohyst."""
    from scipy.io import savemat

    savemat(tmp_path / "a.mat", {"voltage": np.linspace(0.0, 1.0, 5)})
    script = tmp_path / "lab.py"
    script.write_text(
        "import sys\n"
        "import piezohyst as ph\n"
        "print('ran', flush=True)\n"
        "print(ph.read_table(sys.argv[1]).get('voltage').tolist(), flush=True)\n"
    )
    res = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "a.mat")],
        capture_output=True, text=True, check=True, cwd=tmp_path,
    )  # fmt: skip
    assert res.stdout.splitlines() == ["ran", "[0.0, 0.25, 0.5, 0.75, 1.0]"]
