"""How sure a model choice is (issue 26): a paired block jackknife over the scored parts'
half-cycles, and what a record cannot test said in the selection's notes."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.analysis.selection import (
    FOLDS,
    MAJOR,
    SURE,
    TIE,
    WEIGHTS,
    Part,
    SelectionRow,
    _part,
    _turns,
    block_starts,
    chosen,
    jackknife,
    latest_of_close,
    record_notes,
    select_model,
)
from piezohyst.simulation import make_signal
from piezohyst.workflows.excitation import excitation


def naive_jackknife(
    residuals: list[np.ndarray], blocks: list[list[int]], spans: list[float], other=None
) -> float:  # type: ignore[no-untyped-def]
    """The score recomputed from the residual samples with each block deleted, plainly."""

    def score(res: list[np.ndarray], drop: tuple[int, int] | None) -> float:
        total = 0.0
        for f, (r, edges, span) in enumerate(zip(res, blocks, spans, strict=True)):
            keep = np.ones(r.size, bool)
            if drop is not None and drop[0] == f:
                a = edges[drop[1]]
                b = edges[drop[1] + 1] if drop[1] + 1 < len(edges) else r.size
                keep[a:b] = False
            total += WEIGHTS[f] * math.sqrt(float(np.mean(r[keep] ** 2))) / span
        return total

    thetas = []
    for f, edges in enumerate(blocks):
        for j in range(len(edges)):
            value = score(residuals, (f, j))
            if other is not None:
                value -= score(other, (f, j))
            thetas.append(value)
    th = np.array(thetas)
    return math.sqrt((th.size - 1) / th.size * float(np.sum((th - th.mean()) ** 2)))


@st.composite
def parts_of_two_folds(draw: st.DrawFn) -> tuple[list[np.ndarray], list[np.ndarray], list]:
    residuals, others, blocks = [], [], []
    for _ in FOLDS:
        n = draw(st.integers(8, 60))
        values = st.floats(-1.0, 1.0, allow_nan=False, width=64)
        residuals.append(np.array(draw(st.lists(values, min_size=n, max_size=n))))
        others.append(np.array(draw(st.lists(values, min_size=n, max_size=n))))
        cuts = sorted(draw(st.sets(st.integers(1, n - 1), min_size=1, max_size=6)))
        blocks.append([0, *cuts])
    return residuals, others, blocks


@settings(max_examples=60, deadline=None)
@given(parts_of_two_folds(), st.floats(0.5, 3.0))
def test_the_jackknife_is_the_score_recomputed_with_each_block_left_out(
    drawn: tuple[list[np.ndarray], list[np.ndarray], list], span: float
) -> None:
    residuals, others, blocks = drawn
    for r, o, edges in zip(residuals, others, blocks, strict=True):
        # a block holding nearly all of a part's error leaves a rest that cancels: keep the
        # rest above 1e-6 of the total, so rounding stays below 1e-9 of the score
        for res in (r, o):
            sq = np.add.reduceat(res * res, np.array(edges))
            assume(float(np.min(res @ res - sq)) > 1e-6 * float(res @ res))
    spans = [span, 1.3 * span]
    parts = [_part(r, np.array(e), s) for r, e, s in zip(residuals, blocks, spans, strict=True)]
    other = [_part(r, np.array(e), s) for r, e, s in zip(others, blocks, spans, strict=True)]
    scale = sum(p.nrmse for p in parts) + sum(p.nrmse for p in other)
    # tol: sums of <= 120 squares in two orders, and one subtraction kept above 1e-6 of its
    # total: 1e-9 of the score
    np.testing.assert_allclose(
        jackknife(parts), naive_jackknife(residuals, blocks, spans), rtol=0, atol=1e-9 * scale
    )
    np.testing.assert_allclose(
        jackknife(parts, other),
        naive_jackknife(residuals, blocks, spans, others),
        rtol=0,
        atol=1e-9 * scale,
    )
    assert jackknife(parts, parts) == 0.0  # a candidate does not differ from itself
    # a - b is exactly -(b - a) in IEEE arithmetic, and so are their sums: the same to the bit
    assert jackknife(parts, other) == jackknife(other, parts)


def test_a_part_of_one_block_gives_no_standard_error() -> None:
    one = Part(np.array([4.0]), np.array([10.0]), 1.0)
    two = Part(np.array([1.0, 3.0]), np.array([5.0, 5.0]), 1.0)
    assert math.isnan(jackknife([one, two]))


def test_blocks_are_the_half_cycles_between_the_input_s_turns() -> None:
    t = np.arange(4000) / 1000.0
    x = 70.0 + 60.0 * np.sin(2 * np.pi * 2.0 * t)  # 2 Hz: a turn every 250 samples
    turns = _turns(x)
    starts = block_starts(turns, 1000, 3000)
    lengths = np.diff(np.append(starts, 2000))
    assert starts[0] == 0 and np.all(lengths[1:-1] == 250)  # whole half-cycles inside
    # a part with fewer than two turns inside: equal blocks
    few = block_starts(turns, 1000, 1300)
    assert few.size == 8 and few[0] == 0


def test_the_choice_says_its_margins_and_what_the_record_cannot_test() -> None:
    """A constant-amplitude record (the paper's `hold` signal) shows no minor loops, and the
    selection says so; each candidate's margin over the chosen one carries its standard
    error, and the candidates within SURE of them are listed as undecided."""
    rec = ph.simulate(duration=20.0, seed=2)
    sel = select_model(rec.voltage, rec.charge, rec.t)
    win = next(r for r in sel.rows if r.name == sel.name)
    assert win.margin == 0.0 and win.margin_stderr == 0.0 and not win.decided
    for r in sel.rows:
        assert r.margin == r.score - win.score  # the same subtraction: to the bit
        assert r.stderr > 0.0 and r.margin_stderr >= 0.0
        assert (r.name in sel.undecided) == (r.name != sel.name and not r.decided)
        assert r.decided == (abs(r.margin) > SURE * r.margin_stderr)
    classical = next(r for r in sel.rows if r.name == "classical-pi")
    assert classical.decided  # no growth term on a leaking charge: far behind, and sure
    assert any("no minor loops" in n for n in sel.notes)
    table = sel.table()
    assert "vs chosen (± s.e.)" in table and "no minor loops" in table


def _row(name: str, folds: tuple[float, float], margin: float, se: float) -> SelectionRow:
    return SelectionRow(name, folds, float(np.mean(folds)), margin=margin, margin_stderr=se)


@given(
    st.lists(
        st.tuples(
            st.floats(0.001, 0.1), st.floats(0.001, 0.1), st.floats(0.0, 0.02), st.booleans()
        ),
        min_size=2,
        max_size=6,
    )
)
def test_the_latest_part_decides_among_those_the_record_does_not_tell_apart(
    drawn: list[tuple[float, float, float, bool]],
) -> None:
    """The rule written plainly: the first choice by the score, then among it and the
    candidates within SURE standard errors of it, the simplest within TIE of the best latest
    part. A candidate the record puts clearly behind is never taken, however its latest
    part went."""
    names = [f"c{k}" for k in range(len(drawn))]
    plain = [
        SelectionRow(n, (a, b), 0.5 * (a + b)) for n, (a, b, _, _) in zip(names, drawn, strict=True)
    ]
    first = chosen(plain)
    rows = []
    for row, (_, _, spread, sure) in zip(plain, drawn, strict=True):
        margin = row.score - first.score
        # a decided row: its standard error well inside the margin; else well outside
        se = abs(margin) / (4 * SURE) if sure else abs(margin) + spread + 1e-6
        se = 0.0 if row is first else se
        rows.append(replace(row, margin=margin, margin_stderr=se))
    close = [r for r in rows if r.name == first.name or not r.decided]
    best = min(r.folds[-1] for r in close)
    expected = next(r for r in close if r.folds[-1] <= best * (1 + TIE))
    got = latest_of_close(rows, first)
    assert got.name == expected.name
    assert got.name == first.name or not got.decided


def test_a_choice_the_latest_part_moved_says_so(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Where the rule takes another candidate than the score did, the selection is that
    candidate refitted, its margins are over it, and the notes say why (the figures are the
    rows' own latest parts)."""
    from piezohyst.analysis import selection

    def other(rows, first):  # type: ignore[no-untyped-def]
        return next(r for r in rows if r.name != first.name and math.isfinite(r.score))

    monkeypatch.setattr(selection, "latest_of_close", other)
    rec = ph.simulate(duration=20.0, seed=2)
    sel = select_model(rec.voltage, rec.charge, rec.t, candidates=("active-pi", "classical-pi"))
    assert sel.name == "classical-pi" and sel.model.__class__.__name__ == "ClassicalPI"
    win = next(r for r in sel.rows if r.name == "classical-pi")
    first = next(r for r in sel.rows if r.name == "active-pi")
    assert win.margin == 0.0 and first.margin == first.score - win.score < 0.0
    said = f"{100 * win.folds[-1]:.3g} % against {100 * first.folds[-1]:.3g} %"
    assert any(n.startswith("active-pi scored best") and said in n for n in sel.notes)


def test_a_rise_the_holds_show_and_the_choice_lacks_is_said() -> None:
    """On what ``piezohyst excite`` plays to the Bouc-Wen plant (its leak rises 100 % to
    140 V; the holds show it), a model without a term for the rise is chosen with a sentence
    that says so; one that takes it (the Bouc-Wen default) without. A displacement record
    has no leak: nothing said."""
    exc = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
    rec = ph.simulate(exc.voltage, exc.t, plant="bouc-wen", seed=1)
    lacking = select_model(rec.voltage, rec.charge, rec.t, candidates=("active-pi",))
    assert [term.kind for term in lacking.model.terms_] == ["integral"]
    assert any("holds show the leak rising" in n and "active-pi" in n for n in lacking.notes)
    holding = select_model(rec.voltage, rec.charge, rec.t, candidates=("bouc-wen",))
    assert "abs_integral" in [term.kind for term in holding.model.terms_]
    assert not any("holds show the leak rising" in n for n in holding.notes)
    moved = select_model(rec.voltage, rec.displacement, rec.t, candidates=("active-pi",),
                         output_unit="m")  # fmt: skip
    assert not any("holds show the leak rising" in n for n in moved.notes)


def test_a_record_with_minor_loops_has_no_such_note() -> None:
    exc = excitation(v_min=0.0, v_max=140.0, sample_rate=1000.0)
    assert record_notes(exc.voltage) == ()
    t = np.arange(6000) / 1000.0  # six cycles: 12 turns
    sine = 70.0 + 70.0 * np.sin(2 * np.pi * t)
    notes = record_notes(sine)
    assert len(notes) == 2 and f"{100 * MAJOR:.0f} %" in notes[0]
    assert "one frequency" in notes[1]  # a lag and hysteresis look alike there
    # the same sine at 1, 3 and 10 Hz: several rates, minor loops too
    chirp = np.concatenate([70.0 + a * np.sin(2 * np.pi * f * t[: int(3000 / f)])
                            for f, a in ((1.0, 70.0), (3.0, 40.0), (10.0, 20.0))])  # fmt: skip
    assert not any("one frequency" in n for n in record_notes(chirp))
    # decaying loops reach 0 V only on their first rise: that end unseen afterwards, said
    _, decaying = make_signal("decaying", amplitude=140.0, duration=40.0)
    unseen = [n for n in record_notes(decaying) if "never comes back" in n]
    assert len(unseen) == 1 and "to its lowest values" in unseen[0] and "13.89" in unseen[0]
    assert not any("never comes back" in n for n in record_notes(decaying[::-1]))  # both ends
    assert not any("never comes back" in n for n in record_notes(sine) + record_notes(chirp))
    # a slow ramp turns twice at most: too few turns to split by is said too
    assert any("fewer than" in n for n in record_notes(np.linspace(0.0, 1.0, 50)))


def test_compare_s_recommendation_says_what_its_training_part_cannot_test(  # type: ignore[no-untyped-def]
    tmp_path, monkeypatch
) -> None:
    """`compare` recommends from the training part alone, decided as select_model decides
    (the latest part among those not told apart too), and says under its table what that
    part cannot tell: the same sentences select_model would give for it."""
    import piezohyst.workflows as wf
    from piezohyst.analysis import selection
    from piezohyst.analysis.selection import decide, forward_scores, verdict, with_margins

    rec = ph.simulate(duration=20.0, seed=2)  # one amplitude: no minor loops
    ph.write_table(tmp_path / "run.csv", {"time": rec.t, "voltage": rec.voltage,
                                          "charge": rec.charge})  # fmt: skip
    got = wf.compare_file(tmp_path / "run.csv", models=["active-pi", "bouc-wen"])
    a, b = got.train
    inner = forward_scores({"active-pi": ph.ActivePI(10), "bouc-wen": ph.BoucWenModel()},
                           rec.voltage[a:b], rec.charge[a:b], rec.t[a:b])  # fmt: skip
    _, win = decide(inner)
    expected = verdict(with_margins(inner, win), win.name, record_notes(rec.voltage[a:b]))
    assert got.recommended == win.name and got.recommendation_notes == expected
    assert any("no minor loops" in n for n in got.recommendation_notes)
    assert got.table().endswith(got.recommendation_notes[-1])
    # where the latest part moves the choice, the recommendation moves with it
    monkeypatch.setattr(
        selection,
        "latest_of_close",
        lambda rows, first: next(r for r in rows if r.name != first.name),
    )
    moved = wf.compare_file(tmp_path / "run.csv", models=["active-pi", "bouc-wen"])
    assert moved.recommended != got.recommended


def test_the_creep_variant_is_taken_where_the_record_cannot_tell_them_apart() -> None:
    """Where a candidate's variant with creep operators is among those the record does not
    tell from the score's choice, the variant is taken and said (issue 55, item 5: chosen on
    development plants drawn at random, docs/selection-study.md); nowhere else."""
    from piezohyst.analysis.selection import CANDIDATES, creep_where_undecided

    names = list(CANDIDATES)
    got, said = creep_where_undecided("bouc-wen", ("bouc-wen", "bouc-wen+creep"), names)
    assert got == "bouc-wen+creep" and "within the record's noise" in said[0]
    # told apart, already with creep, or no such variant among the candidates: unchanged
    assert creep_where_undecided("bouc-wen", ("bouc-wen",), names) == ("bouc-wen", ())
    assert creep_where_undecided("bouc-wen+creep", ("bouc-wen+creep", "bouc-wen"), names) == (
        "bouc-wen+creep", ())  # fmt: skip
    assert creep_where_undecided("duhem", ("duhem", "duhem+creep"), names) == ("duhem", ())
