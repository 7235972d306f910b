"""A model chosen for the user (issue 26): scored inside the record, never on what is tested."""

from __future__ import annotations

import warnings
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


def test_the_choice_with_the_amplifiers_lag_identified_by_every_candidate(
    tmp_path: Path,
) -> None:
    """`fit --model auto --input-dynamics auto` dropped the dynamics without a word: on the
    bench's 4 ms amplifier (a multi-frequency record) the candidates were scored with the lag
    absorbed as hysteresis (8-9 % inside the record) and the chosen ActivePI saved without
    it (2.5 %). Each candidate now identifies the lag; a model's own terms are refused with
    auto, by name, rather than ignored."""
    from piezohyst.simulation import make_signal

    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=8.0)
    rec = ph.simulate(v, t, preset="T226-H4-203X-amp4ms", seed=4)
    names = ("classical-pi", "active-pi")  # the cheap ones: the dynamics search is per fit
    lagged = select_model(rec.voltage, rec.charge, rec.t, candidates=names, input_dynamics="auto")
    blind = select_model(rec.voltage, rec.charge, rec.t, candidates=names)
    dyn = lagged.model.input_dynamics_
    assert dyn.active and not blind.model.input_dynamics_.active
    # tol: the preset's 4 ms; 30 s of this record find 4.00 ± 0.09 ms (95 %), 8 s less
    assert dyn.tau + dyn.delay == pytest.approx(4e-3, abs=5e-4)
    # measured 1.2 % against 8.5 % with the lag absorbed (on 30 s, every candidate: 0.39 %
    # against 8.4 %)
    assert lagged.rows[0].score < blind.rows[0].score / 3
    # play operators beside a kept asymmetry, with the lag: once given way to the next (no
    # compensator inverted it), now the winner is kept and compensated by the Newton step
    # behind the lag's inverse
    pair = ("classical-pi", "generalized-pi")
    with warnings.catch_warnings():  # classical PI cannot tell the lag here: said, not tested
        warnings.simplefilter("ignore", ph.errors.IdentifiabilityWarning)
        sel = select_model(rec.voltage, rec.charge, rec.t, candidates=pair, input_dynamics="auto")
    assert sel.rows[0].name == "generalized-pi" == sel.name
    assert not any(note.startswith("Left out") for note in sel.notes)
    lo, hi = sel.model.input_range_
    comp = ph.Compensator(sel.model, v_min=lo, v_max=hi, sample_rate=1000.0)
    assert comp.dynamic and not comp.analytic
    ph.write_table(tmp_path / "run.csv", {"time": rec.t, "voltage": rec.voltage,
                                          "charge": rec.charge})  # fmt: skip
    for option in (["--creep", "0.1,1"], ["--growth", "integral"], ["--relaxation", "0.1"]):
        res = CliRunner().invoke(main, ["fit", str(tmp_path / "run.csv"), "--model", "auto",
                                        *option, "-o", str(tmp_path / "m.json")])  # fmt: skip
        assert res.exit_code == 2 and f"{option[0]} set one model's terms" in res.output
        assert not (tmp_path / "m.json").exists()


def test_a_record_that_never_comes_back_low_is_chosen_for_by_the_candidates_median() -> None:
    """Decaying loops reach 0 V on their first rise only: the scores cannot rank how the
    candidates predict loops from there. select_model then takes, among the candidates
    scoring within 1.5x of the best, the one whose loops from the bottom lie nearest the
    candidates' median (chosen on plants drawn at random, docs/selection-study.md), and says
    so. Recomputed here from the candidates' own fits; a record whose loops reach both ends
    is left to the scores."""
    from piezohyst.analysis.selection import MEDIAN_WITHIN, candidate_model, probe_loops

    rec = ph.simulate(plant="two-state", signal="decaying", duration=40.0, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sel = select_model(rec.voltage, rec.charge, rec.t)
        best = min(r.score for r in sel.rows)
        close = [r.name for r in sel.rows if r.score <= MEDIAN_WITHIN * best]
        loops = probe_loops(rec.voltage, "lowest", 1e-3)
        tl = np.arange(loops.size) * 1e-3
        preds = {
            n: candidate_model(n, 10, ("V", "C"), rec.t)
            .fit(rec.voltage, rec.charge, t=rec.t)
            .predict(loops, t=tl)
            for n in close
        }
    assert len(close) >= 3 and loops.min() == rec.voltage.min()
    median = np.median(np.array(list(preds.values())), axis=0)
    nearest = min(preds, key=lambda n: float(np.sqrt(np.mean((preds[n] - median) ** 2))))
    assert sel.name == nearest == "bouc-wen"
    assert sel.rows[0].name != sel.name  # the scores alone took another
    said = [n for n in sel.notes if "nearest the candidates' median" in n]
    assert len(said) == 1 and "bouc-wen chosen (rather than" in said[0]
    assert type(sel.model).__name__ == "BoucWenModel"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ph.ExtrapolationWarning)  # the loops leave the record
        again = sel.model.predict(loops, t=tl)
    np.testing.assert_array_equal(again, preds["bouc-wen"])
    # loops to both ends: the scores decide, nothing said of a median
    both = ph.simulate(plant="two-state", signal="multi", duration=20.0, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = select_model(both.voltage, both.charge, both.t)
    assert not any("candidates' median" in n for n in plain.notes)
