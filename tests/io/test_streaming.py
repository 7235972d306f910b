"""Fit, predict and compensate from disk block by block: same numbers as in memory."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph
import piezohyst.io as pio
import piezohyst.io._formats as formats
import piezohyst.io._text as text
import piezohyst.io.tables as tables
import piezohyst.workflows as wf
from piezohyst.errors import DataFileError
from piezohyst.io.blocks import Summary, array_blocks
from piezohyst.model.cores.play import default_thresholds, history_state
from piezohyst.workflows import model_files

from ..strategies import examples

# these tests drive targets past the voltage and slew limits on purpose (safety, exactness
# where no limit acts); that the limits then say so is tested in test_records.py
# generated signals hold one-sample jumps, which the record check names (test_records.py)
pytestmark = [
    pytest.mark.filterwarnings("ignore::piezohyst.errors.RecordWarning"),
    pytest.mark.kernels,
    pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning"),
]


@pytest.fixture(scope="module")
def record() -> ph.simulation.BenchRecord:
    return ph.simulate(duration=6.0, seed=3)


@pytest.fixture
def small_batches(monkeypatch: pytest.MonkeyPatch) -> None:
    """pyarrow parses 16 kB at a time: a few hundred rows per batch, many batches per file."""
    monkeypatch.setattr(text, "CSV_BLOCK_BYTES", 1 << 14)
    monkeypatch.setattr(formats, "BATCH_ROWS", 700)
    monkeypatch.setattr(tables, "BATCH_ROWS", 700)
    monkeypatch.setattr(model_files, "KEEP_ROWS", 1000)  # fits stream every pass (a huge file)


def split_blocks(
    x: np.ndarray, y: np.ndarray, t: np.ndarray | None, cuts: list[int]
) -> ph.io.blocks.Blocks:
    edges = [0, *sorted(set(c % x.size for c in cuts) - {0}), x.size]

    def blocks():  # type: ignore[no-untyped-def]
        for lo, hi in itertools.pairwise(edges):
            yield x[lo:hi], y[lo:hi], None if t is None else t[lo:hi]

    return blocks


def assert_same_model(a: ph.HysteresisModel, b: ph.HysteresisModel, x, t) -> None:  # type: ignore[no-untyped-def]
    out = b.predict(x, t=t)
    # tol: streamed against whole: the Gram matrix summed in another block order, amplified by the
    # play columns' conditioning (~1e6) on single weights; outputs to 1e-9 of the span
    np.testing.assert_allclose(a.predict(x, t=t), out, rtol=0, atol=1e-9 * np.ptp(out))
    np.testing.assert_allclose(np.cumsum(a.weights_), np.cumsum(b.weights_), rtol=1e-6)
    assert [t.kind for t in a.terms_] == [t.kind for t in b.terms_]
    for ca, cb in zip(a.coefs_, b.coefs_, strict=True):
        # tol: as the weights above: coefficients to 1e-6, the RMSE to 1e-6
        np.testing.assert_allclose(ca, cb, rtol=1e-6, atol=1e-9 * np.max(np.abs(cb)))
    assert a.rmse_ == pytest.approx(b.rmse_, rel=1e-6)


@pytest.mark.parametrize(
    "model",
    [
        lambda: ph.ActivePI(12),
        lambda: ph.GeneralizedPI(8, creep=(0.5,), asymmetry=2),  # selection over growth terms
    ],
)
def test_fit_blocks_equals_fit(record: ph.simulation.BenchRecord, model) -> None:  # type: ignore[no-untyped-def]
    x, y, t = record.voltage, record.charge, record.t
    whole = model().fit(x, y, t)
    cuts = [1, 999, 4097, 4098, 5000]  # blocks smaller than, straddling and equal to BLOCK
    parts = model().fit_blocks(split_blocks(x, y, t, cuts))
    # the same model to rounding: the sums are added in another order, and the
    # play columns are nearly collinear, so single weights may differ by ~1e-9
    assert_same_model(parts, whole, x, t)
    assert parts.selection_.keys() == whole.selection_.keys()
    for key, err in whole.selection_.items():
        # tol: the selection scores, as the weights above
        assert parts.selection_[key] == pytest.approx(err, rel=1e-6)
    assert parts.input_range_ == whole.input_range_
    # tol: the same maximum over the same differences
    assert parts.max_slew_rate_ == pytest.approx(whole.max_slew_rate_, rel=1e-12)


def test_fit_blocks_refuses_what_needs_memory(record: ph.simulation.BenchRecord) -> None:
    blocks = array_blocks(record.voltage, record.charge, record.t)
    with pytest.raises(ph.errors.ParameterError, match="optimize_thresholds"):
        ph.GeneralizedPI(5, optimize_thresholds=True).fit_blocks(blocks)
    untimed = array_blocks(record.voltage, record.charge, None)
    with pytest.raises(ph.errors.TimeAxisError, match="sample times"):
        ph.ActivePI(5).fit_blocks(untimed, timed=False)


@settings(max_examples=examples(40), deadline=None)
@given(
    st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=60),
    st.lists(st.integers(0, 100), max_size=6),
)
def test_summary_is_the_same_however_split(values: list[float], cuts: list[int]) -> None:
    x = np.array(values)
    y = np.cos(x)
    t = np.cumsum(np.full(x.size, 0.5))
    s = Summary.of(split_blocks(x, y, t, cuts))
    assert (s.n, s.x_first, s.y_first) == (x.size, x[0], y[0])
    assert (s.x_min, s.x_max, s.y_min, s.y_max) == (x.min(), x.max(), y.min(), y.max())
    # tol: the same maximum of |dx| / dt: rounding of one division
    assert s.max_slew_rate == pytest.approx(np.max(np.abs(np.diff(x)) / 0.5), rel=1e-12, abs=0)


def test_fit_file_streams_to_the_in_memory_fit(
    tmp_path: Path, record: ph.simulation.BenchRecord, small_batches: None
) -> None:
    path = tmp_path / "run.csv"
    ph.write_table(path, {"time": record.t, "voltage": record.voltage, "charge": record.charge})
    batches = list(pio.open_table(path).batches(["voltage"]))
    assert len(batches) > 10  # really streamed in pieces
    rows: list[int] = []
    model = wf.fit_file(path, operators=10, progress=rows.append)
    ref = ph.ActivePI(10).fit(record.voltage, record.charge, record.t)
    assert_same_model(model, ref, record.voltage, record.t)
    assert rows == sorted(rows) and rows[-1] == 3 * record.t.size  # three passes, counted on


def test_a_window_that_fits_in_memory_is_read_once(
    tmp_path: Path, record: ph.simulation.BenchRecord
) -> None:
    path = tmp_path / "run.csv"
    ph.write_table(path, {"time": record.t, "voltage": record.voltage, "charge": record.charge})
    rows: list[int] = []
    model = wf.fit_file(path, operators=10, progress=rows.append)
    assert rows[-1] == record.t.size  # one pass over the file; the others from memory
    ref = ph.ActivePI(10).fit(record.voltage, record.charge, record.t)
    assert_same_model(model, ref, record.voltage, record.t)


def test_windowed_fit_starts_from_the_history(
    tmp_path: Path, record: ph.simulation.BenchRecord, small_batches: None
) -> None:
    path = tmp_path / "run.parquet"
    ph.write_table(path, {"time": record.t, "voltage": record.voltage, "charge": record.charge})
    spec = pio.DataSpec(t_start=2.0, t_stop=5.0)
    model = wf.fit_file(path, operators=10, data_spec=spec)
    t = record.t
    w = (t >= 2.0) & (t < 5.0)
    start = int(np.argmax(w))
    thr = default_thresholds(record.voltage[w], 10)
    ref = ph.ActivePI(10, thresholds=thr).fit(
        record.voltage[w],
        record.charge[w],
        t[w],
        initial_state=history_state(record.voltage[:start], thr),
    )
    assert_same_model(model, ref, record.voltage[w], t[w])
    # tol: the history's state: the same clamps, rounding
    np.testing.assert_allclose(model.initial_state_, ref.initial_state_, rtol=1e-12)
    with pytest.raises(DataFileError, match=r"no samples in the time window \[9, inf\)"):
        wf.fit_file(path, data_spec=pio.DataSpec(t_start=9.0))


def test_predict_file_streams_with_state_carried(
    tmp_path: Path, record: ph.simulation.BenchRecord, small_batches: None
) -> None:
    data = tmp_path / "run.csv"
    ph.write_table(
        data,
        {"time": record.t, "voltage": record.voltage, "charge": record.charge},
        units={"time": "s", "voltage": "V", "charge": "C"},
    )
    model = ph.ActivePI(10).fit(record.voltage, record.charge, record.t)
    model.save(tmp_path / "m.json")
    res = wf.predict_file(
        tmp_path / "m.json", data, tmp_path / "p.csv", data_spec=pio.DataSpec(t_start=1.0)
    )
    expected = model.predict(record.voltage, t=record.t)
    w = record.t >= 1.0
    back = ph.read_table(tmp_path / "p.csv")
    # tol: written with repr and read back: exact to the last ulp
    np.testing.assert_allclose(back.get("predicted"), expected[w], rtol=1e-15, atol=0)
    np.testing.assert_array_equal(back.get("time"), record.t[w])
    assert res.samples == int(w.sum())
    # tol: the same NRMSE formula on the same numbers
    assert res.nrmse == pytest.approx(ph.metrics.nrmse(record.charge[w], expected[w]), rel=1e-9)


def test_compensate_file_streams_like_one_call(
    tmp_path: Path, record: ph.simulation.BenchRecord, small_batches: None
) -> None:
    model = ph.ActivePI(10).fit(record.voltage, record.charge, record.t)
    model.save(tmp_path / "m.json")
    t = np.arange(5000) / 1000.0
    desired = model.hysteresis_.predict(30 + 40 * (1 - np.cos(2 * np.pi * t)))
    desired[1234] = np.nan  # held and counted, in a later batch
    ph.write_table(tmp_path / "target.csv", {"time": t, "desired": desired})
    res = wf.compensate_file(tmp_path / "m.json", tmp_path / "target.csv", tmp_path / "cmd.csv")
    fs = res.sample_rate  # from the time column
    # tol: the rate from the time column's mean step: rounding of the sum
    assert fs == pytest.approx(1000.0, rel=1e-9)
    comp = ph.control.compensator.CompensatorSettings(
        slew_rate=model.max_slew_rate_, sample_rate=fs
    ).build(model)
    comp.reset(voltage=float(np.clip(0.0, comp.v_min, comp.v_max)))  # at rest by default
    back = ph.read_table(tmp_path / "cmd.csv").get("command")
    written = back[: res.preamble]  # the cycle over what the trajectory needs
    pre = comp.precondition(1000, (float(written.min()), float(written.max())))
    cmd = comp.process(desired)
    np.testing.assert_array_equal(back, np.concatenate([pre, cmd]))
    assert pre.min() <= cmd.min() and pre.max() >= cmd.max()
    assert res.compensator.nonfinite_count == comp.nonfinite_count == 1


def test_errors_in_later_batches_name_the_row(tmp_path: Path, small_batches: None) -> None:
    n = 6000
    t = np.arange(n) / 1000.0
    v = 50 - 50 * np.cos(t * 7)  # from rest at 0 V
    q = v * 1e-6
    t_bad = t.copy()
    t_bad[4321] = t_bad[4320]  # row 4322 repeats a time
    ph.write_table(tmp_path / "a.csv", {"time": t_bad, "voltage": v, "charge": q})
    with pytest.raises(DataFileError, match=r"time is not increasing at row 4322, column 'time'"):
        wf.fit_file(tmp_path / "a.csv")
    q_bad = q.copy()
    q_bad[5001] = np.inf
    ph.write_table(
        tmp_path / "b.csv", {"time": t, "voltage": v, "charge": q_bad}, units={"charge": "C"}
    )
    with pytest.raises(DataFileError, match=r"inf at row 5002, column 'charge'"):
        wf.fit_file(tmp_path / "b.csv")
    ph.write_table(tmp_path / "good.csv", {"time": t, "voltage": v, "charge": q})
    text = (tmp_path / "good.csv").read_text().splitlines()
    text[5500] = "5.499,oops,1e-6"  # line 5501, data row 5499 (a comment and the header above)
    (tmp_path / "c.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(
        DataFileError, match=r"'oops' at row 5499 \(line 5501 of the file\), column 'voltage'"
    ):
        wf.fit_file(tmp_path / "c.csv")
    # found after thousands of rows were written: still no output file, no temporary left
    wf.fit_file(tmp_path / "good.csv", tmp_path / "m.json", operators=5)
    with pytest.raises(DataFileError, match=r"inf at row 5002"):
        wf.predict_file(tmp_path / "m.json", tmp_path / "b.csv", tmp_path / "out.csv")
    assert not list(tmp_path.glob("*out.csv*"))
