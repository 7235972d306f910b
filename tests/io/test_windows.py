"""A model fitted on a window of a record: predict on the same window gives the fit's number,
and on a later window the API's held-out prediction, sample for sample."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
import piezohyst.workflows as wf
from piezohyst.io import DataSpec
from piezohyst.simulation import make_signal


@pytest.fixture(scope="module")
def record(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, ph.simulation.BenchRecord]:
    t, v = make_signal("decaying", duration=12.0, rate=1000.0)
    rec = ph.simulate(v, t)
    path = tmp_path_factory.mktemp("win") / "run.csv"
    ph.write_table(path, {"time": rec.t, "voltage": rec.voltage, "charge": rec.charge},
                   units={"time": "s", "voltage": "V", "charge": "C"})  # fmt: skip
    return path, rec


@pytest.mark.parametrize("model", ["active-pi", "preisach"])
def test_windowed_numbers_agree_with_the_fit_and_the_api(
    record: tuple[Path, ph.simulation.BenchRecord], tmp_path: Path, model: str
) -> None:
    path, rec = record
    fitted = wf.fit_file(path, tmp_path / "m.json", model=model,
                         data_spec=DataSpec(t_start=1.0, t_stop=6.0))  # fmt: skip
    # tol: the first sample at or after 1 s on a 1 kHz grid built by summing steps
    assert fitted.train_window_[0] == pytest.approx(1.0) and fitted.train_window_[1] < 6.0
    assert ph.load_model(tmp_path / "m.json").train_window_ == fitted.train_window_
    same = wf.predict_file(tmp_path / "m.json", path, tmp_path / "same.csv",
                           data_spec=DataSpec(t_start=1.0, t_stop=6.0))  # fmt: skip
    # tol: the same samples, the same state at the window's start, blocks summed in another order
    assert same.nrmse == pytest.approx(fitted.nrmse_, rel=1e-6)
    # tol: as above, the first scored sample's time
    assert "training window" in same.start and same.scored[0] == pytest.approx(1.0)
    with warnings.catch_warnings():  # a held-out window may leave the identified region
        warnings.simplefilter("ignore", ph.ExtrapolationWarning)
        later = wf.predict_file(tmp_path / "m.json", path, tmp_path / "later.csv",
                                data_spec=DataSpec(t_start=6.0))  # fmt: skip
        api = model_api_prediction(tmp_path / "m.json", rec)
    cli = ph.read_table(tmp_path / "later.csv").get("predicted")
    np.testing.assert_array_equal(cli, api)
    assert later.samples == api.size


def model_api_prediction(path: Path, rec: ph.simulation.BenchRecord) -> np.ndarray:
    """The API's held-out split: the model runs its training window from its initial state,
    then the rest with the state carried."""
    x, t = rec.voltage, rec.t
    a, b = np.searchsorted(t, [1.0, 6.0])
    model = ph.load_model(path)
    state = model.propagate(x[a:b], t[a:b]).state
    return np.asarray(model.predict(x[b:], t=t[b:], state=state))


def test_the_report_on_the_training_window_repeats_the_fit(
    record: tuple[Path, ph.simulation.BenchRecord], tmp_path: Path
) -> None:
    path, _ = record
    fitted = wf.fit_file(path, tmp_path / "m.json", model="active-pi",
                         data_spec=DataSpec(t_start=1.0, t_stop=6.0))  # fmt: skip
    rep = wf.model_report(tmp_path / "m.json", path, tmp_path / "report",
                          data_spec=DataSpec(t_start=1.0, t_stop=6.0))  # fmt: skip
    nrmse = [v / 100 for k, v in rep.metrics.items() if k == "nrmse_pct"]
    # tol: the same samples from the same state; the report's sums in another order
    assert nrmse and nrmse[0] == pytest.approx(fitted.nrmse_, rel=1e-6), rep.metrics


def test_compare_on_a_window_starts_from_the_earlier_input(
    record: tuple[Path, ph.simulation.BenchRecord],
) -> None:
    """compare --t-start: the training part starts where the earlier input left the actuator
    (as fit does), the scored samples are named as rows of the record, and the numbers are
    the API's compare_models with that History."""
    path, rec = record
    spec = DataSpec(t_start=2.0, t_stop=9.0)
    got = wf.compare_file(path, models=["active-pi", "classical-pi"], data_spec=spec)
    a, b = np.searchsorted(rec.t, [2.0, 9.0])
    api = ph.compare_models(
        {"active-pi": ph.ActivePI(10), "classical-pi": ph.ClassicalPI(10)},
        rec.voltage[a:b], rec.charge[a:b], rec.t[a:b],
        initial_state=ph.History(rec.voltage[:a]),
    )  # fmt: skip
    stop = a + round(0.7 * (b - a))
    assert got.train == (a, stop) and got.test == (stop, b)
    for mine, theirs in zip(got.rows, api.rows, strict=True):
        # tol: the same fit on the same samples; the file's decimals round-trip exactly
        assert mine.test_nrmse == pytest.approx(theirs.test_nrmse, rel=1e-9)
    rest = ph.compare_models({"active-pi": ph.ActivePI(10)}, rec.voltage[a:b],
                             rec.charge[a:b], rec.t[a:b])  # fmt: skip
    # from rest the window's first loops are misread: the History start is better held out
    assert got.rows[0].test_nrmse < rest.rows[0].test_nrmse


def test_a_record_cut_from_a_running_drive_gets_a_hint(tmp_path: Path) -> None:
    """A running bipolar triangle, cut where it passes 6.5 V rising: fitted from rest the
    CLI says so and names the periodic start (on the measured PZT record of
    docs/validation.md, classical PI fits 2.11 % periodic against 9.28 % from rest); a record
    that starts at rest gets no such line."""
    from click.testing import CliRunner

    from piezohyst.cli import main

    t = np.arange(4000) / 1000.0
    phase = (t + 0.2625) % 1.0  # a 1 Hz triangle, already running, +-130 V, from 6.5 V
    v = 130.0 * np.where(phase < 0.5, 4 * phase - 1, 3 - 4 * phase)
    rec = ph.simulate(v, t, seed=2)
    ph.write_table(tmp_path / "cut.csv", {"time": t, "voltage": v, "charge": rec.charge})
    rest = CliRunner().invoke(main, ["fit", str(tmp_path / "cut.csv"), "-o",
                                     str(tmp_path / "r.json")])  # fmt: skip
    assert rest.exit_code == 0, rest.output
    # near 0 V, but moving at full slew: not a rest start
    assert "starts mid-loop (6.5 V, inside [-129.7, 129.7], moving)" in rest.stderr
    assert "--initial-state periodic" in rest.stderr
    periodic = CliRunner().invoke(main, ["fit", str(tmp_path / "cut.csv"), "--initial-state",
                                         "periodic", "-o", str(tmp_path / "p.json")])  # fmt: skip
    assert periodic.exit_code == 0 and "mid-loop" not in periodic.stderr
    calm = ph.simulate(signal="hold", duration=4.0, seed=2)  # from rest at 0 V
    ph.write_table(tmp_path / "calm.csv", {"time": calm.t, "voltage": calm.voltage,
                                           "charge": calm.charge})  # fmt: skip
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "calm.csv"), "-o",
                                    str(tmp_path / "c.json")])  # fmt: skip
    assert res.exit_code == 0 and "mid-loop" not in res.stderr
