"""A model chosen for the user (issue 26): scored inside the record, never on what is tested."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import piezohyst as ph
import piezohyst.workflows as wf
from piezohyst.analysis.selection import CANDIDATES, FOLDS, chosen, forward_scores, select_model
from piezohyst.cli import main


@pytest.fixture(scope="module")
def boucwen_record() -> ph.simulation.BenchRecord:
    return ph.simulate(plant="bouc-wen", signal="decaying", duration=40.0, seed=1)


def test_the_plant_s_own_physics_wins_and_is_refitted_on_everything(
    boucwen_record: ph.simulation.BenchRecord,
) -> None:
    rec = boucwen_record
    sel = select_model(rec.voltage, rec.charge, rec.t)
    assert sel.name == "bouc-wen" and type(sel.model).__name__ == "BoucWenModel"
    assert sel.rows[0].name == "bouc-wen" and len(sel.rows) == len(CANDIDATES)
    scores = [r.score for r in sel.rows]
    assert scores == sorted(scores) and all(len(r.folds) == len(FOLDS) for r in sel.rows)
    # the winner is refitted on the whole record: its training window is all of it
    assert sel.model.train_window_ == (rec.t[0], rec.t[-1])
    assert "| bouc-wen (chosen) |" in sel.table()


def test_the_choice_never_sees_beyond_the_record_it_is_given(
    boucwen_record: ph.simulation.BenchRecord,
) -> None:
    """Changing what follows the record changes nothing: the scores are the record's."""
    rec = boucwen_record
    n = rec.t.size * 3 // 5
    models = {"active-pi": ph.ActivePI(10), "bouc-wen": ph.BoucWenModel()}
    first = forward_scores(models, rec.voltage[:n], rec.charge[:n], rec.t[:n])
    shuffled = rec.charge.copy()
    shuffled[n:] = shuffled[n:][::-1]
    again = forward_scores(models, rec.voltage[:n], shuffled[:n], rec.t[:n])
    assert [r.score for r in first] == [r.score for r in again]
    assert chosen(first).name == "bouc-wen"


def test_a_tie_goes_to_the_simpler_model() -> None:
    from piezohyst.analysis.selection import SelectionRow

    rows = [SelectionRow("active-pi", (0.0101,), 0.0101), SelectionRow("preisach", (0.01,), 0.01)]
    assert chosen(rows).name == "active-pi"  # within 2 % of the best, and earlier
    rows = [SelectionRow("active-pi", (0.011,), 0.011), SelectionRow("preisach", (0.01,), 0.01)]
    assert chosen(rows).name == "preisach"
    with pytest.raises(ph.ParameterError, match="candidates must be model names"):
        select_model([0.0, 1.0], [0.0, 1.0], candidates=("magic",))


def test_fit_auto_and_compare_s_recommendation_from_the_shell(
    boucwen_record: ph.simulation.BenchRecord, tmp_path: Path
) -> None:
    rec = boucwen_record
    ph.write_table(tmp_path / "run.csv", {"time": rec.t, "voltage": rec.voltage,
                                          "charge": rec.charge})  # fmt: skip
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "run.csv"), "--model", "auto",
                                    "-o", str(tmp_path / "m.json")])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "| bouc-wen (chosen) |" in res.stdout and "BoucWenModel" in res.stdout
    assert type(ph.load_model(tmp_path / "m.json")).__name__ == "BoucWenModel"
    got = wf.compare_file(tmp_path / "run.csv", models=["active-pi", "bouc-wen"])
    a, b = got.train
    inner = forward_scores({"active-pi": ph.ActivePI(10), "bouc-wen": ph.BoucWenModel()},
                           rec.voltage[a:b], rec.charge[a:b], rec.t[a:b])  # fmt: skip
    assert got.recommended == chosen(inner).name == "bouc-wen"  # the training part alone
    assert "| bouc-wen (recommended) |" in got.table()
    np.testing.assert_array_equal([r.name for r in got.rows], ["active-pi", "bouc-wen"])
