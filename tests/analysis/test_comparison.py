"""Model comparison: held-out scores against a naive fit-and-score, failures as rows."""

from __future__ import annotations

import csv
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

import piezohyst as ph
from piezohyst.cli import main


@pytest.fixture(scope="module")
def record() -> Any:
    return ph.simulate(signal="decaying", duration=12.0, seed=4)


def test_scores_equal_a_naive_fit_and_score(record: Any) -> None:
    v, q, t = record.voltage, record.charge, record.t
    templates = {"active": ph.ActivePI(8), "preisach": ph.PreisachModel(10)}
    cmp = ph.compare_models(templates, v, q, t=t, train=0.6)
    stop = round(0.6 * v.size)
    assert cmp.train == (0, stop) and cmp.test == (stop, v.size)
    for row, (name, template) in zip(cmp.rows, templates.items(), strict=True):
        assert row.name == name and not row.error
        assert not template.is_fitted  # the estimators passed in are not touched
        naive = type(template)(**template.get_params()).fit(v[:stop], q[:stop], t=t[:stop])
        with warnings.catch_warnings():  # the test part may leave the region: noted below
            warnings.simplefilter("ignore", ph.ExtrapolationWarning)
            pred = naive.predict(v, t=t)
        # tol: the same fit and score done twice, the same arithmetic: 1e-9 allows BLAS threads
        # summing apart
        assert row.test_nrmse == pytest.approx(ph.metrics.nrmse(q[stop:], pred[stop:]), rel=1e-9)
        # tol: the same fit and score done twice, the same arithmetic: 1e-9 allows BLAS threads
        # summing apart
        assert row.train_nrmse == pytest.approx(ph.metrics.nrmse(q[:stop], pred[:stop]), rel=1e-9)
        # tol: the same fit and score done twice, the same arithmetic: 1e-9 allows BLAS threads
        # summing apart
        assert row.test_rmse == pytest.approx(ph.metrics.rmse(q[stop:], pred[stop:]), rel=1e-9)
        assert 0 <= row.test_width < 0.5 and row.fit_seconds > 0
        assert row.absorbed == "growth integral"  # both took up the leak, nothing else
    assert cmp.best() is min(cmp.rows, key=lambda r: r.test_nrmse)
    table = cmp.table().splitlines()
    assert table[2].startswith(f"| {cmp.best().name} |")  # best first


def test_a_model_that_cannot_be_fitted_is_a_row(record: Any) -> None:
    v, q, t = record.voltage[:400], record.charge[:400], record.t[:400]
    cmp = ph.compare_models([ph.ActivePI(6), ph.PreisachModel(60)], v, q, t=t)
    ok, failed = cmp.rows
    assert ok.name == "active-pi" and not ok.error and np.isfinite(ok.test_nrmse)
    assert failed.name == "preisach" and failed.model is None
    assert "cannot identify" in failed.error and np.isnan(failed.test_nrmse)
    assert cmp.table().splitlines()[-1].startswith("| preisach | failed |")
    assert cmp.best() is ok
    with pytest.raises(ph.ParameterError, match="no model could be fitted"):
        ph.compare_models([ph.PreisachModel(60)], v, q, t=t).best()


def test_a_separate_test_record_and_leaving_the_region() -> None:
    small = ph.simulate(signal="decaying", duration=12.0, seed=4, amplitude=80.0)
    v, q, t = small.voltage, small.charge, small.t
    big = ph.simulate(duration=6.0)  # up to 140 V
    cmp = ph.compare_models(
        {"preisach": ph.PreisachModel(10)}, v, q, t=t, test=(big.voltage, big.charge, big.t)
    )
    row = cmp.rows[0]
    assert cmp.separate_test and cmp.train == (0, v.size) and cmp.test == (0, big.t.size)
    assert "left the training region" in row.notes
    assert row.model is not None
    with pytest.warns(ph.ExtrapolationWarning):
        pred = row.model.predict(big.voltage, t=big.t, state="rest")
    # tol: the same fit and score done twice, the same arithmetic: 1e-9 allows BLAS threads summing
    # apart
    assert row.test_nrmse == pytest.approx(ph.metrics.nrmse(big.charge, pred), rel=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"train": 1.0}, "between 0 and 1"),
        ({"train": 0.0001}, "fewer than 2 samples"),
        ({"models": []}, "at least one model"),
        ({"models": [object()]}, "not a piezohyst model"),
    ],
)
def test_bad_settings_are_one_line_errors(record: Any, kwargs: dict[str, Any], match: str) -> None:
    v, q, t = record.voltage, record.charge, record.t
    args: dict[str, Any] = {"models": [ph.ActivePI(4)], **kwargs}
    with pytest.raises(ph.ParameterError, match=match):
        ph.compare_models(args.pop("models"), v, q, t=t, **args)


def test_a_recommendation_the_held_out_part_disagrees_with_says_so() -> None:
    """The recommendation is chosen inside the training part; where the held-out part ranks
    another model first, the table says both, so "(recommended)" on the second row is not
    read as a mistake."""
    from piezohyst.analysis.comparison import Comparison, ComparisonRow

    rows = (ComparisonRow("active-pi", None, 0.002, 0.008), ComparisonRow("preisach", None,
            0.001, 0.010))  # fmt: skip
    table = Comparison(rows, (0, 7), (7, 10), recommended="preisach").table()
    assert table.splitlines()[2].startswith("| active-pi |")  # best held-out first
    assert table.splitlines()[-1] == (
        "Recommended: preisach, chosen inside the training part alone (forward chaining); the "
        "held-out part, which the choice never saw, ranks active-pi first (0.8 % against 1 %)."
    )
    agreed = Comparison(rows, (0, 7), (7, 10), recommended="active-pi").table()
    assert "Recommended:" not in agreed


def test_the_compare_command(tmp_path: Path) -> None:
    runner = CliRunner()
    data = tmp_path / "run.csv"
    assert runner.invoke(main, ["simulate", "--duration", "10", "-o", str(data)]).exit_code == 0
    md = tmp_path / "cmp.md"
    res = runner.invoke(main, ["compare", str(data), "--models", "active-pi,preisach",
                               "--train", "0.5", "-o", str(md)])  # fmt: skip
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[0] == "trained on run.csv samples 0-5000, held out: run.csv samples 5000-10000"
    names = {lines[k].split(" | ")[0].removesuffix(" (recommended)") for k in (3, 4)}
    assert names == {"| active-pi", "| preisach"}
    assert sum("(recommended)" in lines[k] for k in (3, 4)) == 1  # one, chosen in training
    written = md.read_text().splitlines()[2:]  # the table and what is said under it
    assert written[:4] == lines[1:5] and written == lines[1 : 1 + len(written)]
    assert ph.io.is_piezohyst_output(md)  # so a second run may replace it
    out_csv = tmp_path / "cmp.csv"
    res = runner.invoke(main, ["compare", str(data), "--models", "active-pi", "--test", str(data),
                               "-o", str(out_csv)])  # fmt: skip
    assert res.exit_code == 0, res.output
    with open(out_csv, newline="") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert rows[0]["model"] == "active-pi" and rows[0]["status"] == "ok"
    assert float(rows[0]["test_nrmse_pct"]) < 1.0 and float(rows[0]["fit_seconds"]) > 0
    bad = runner.invoke(main, ["compare", str(data), "--models", "active-pi,nonsense"])
    assert bad.exit_code != 0 and "unknown model 'nonsense'" in bad.output
    assert "Traceback" not in bad.output
