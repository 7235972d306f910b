"""Learning a repeated scan on a coupled stage (issue 57): the coupling's inverse, then one
learner per actuator (:class:`ph.CoupledLearningCompensator`), on the simulated stages."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.errors import LearningWarning, LimitWarning
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import XY_COUPLING, XY_DYNAMIC, Bench, make_signal, simulate_stage

from . import hosts

FS = 1000.0


@pytest.fixture(scope="module")
def static_stage() -> ph.CoupledModel:
    """The static stage of ``test_coupled.py`` (x on decaying loops, y a 1.3 Hz triangle)."""
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0.0, 140.0), b]), t, seed=0)
    return ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)


def _trials(
    ilc: ph.CoupledLearningCompensator, scan: np.ndarray, presets: tuple[str, ...], n: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` trials on a bench per actuator (their state carried), coupled as the simulated
    stage is: each trial's commands and true positions."""
    benches = [Bench(p, seed=7 + i, voltage=v)
               for i, (p, v) in enumerate(zip(presets, ilc.last_command, strict=True))]  # fmt: skip
    out = []
    for _ in range(n):
        u = ilc.command(scan)
        runs = [b.run(u[:, i]) for i, b in enumerate(benches)]
        read = np.column_stack([r.displacement for r in runs]) @ XY_COUPLING.T
        ilc.learn(read)
        out.append((u, np.column_stack([r.true_displacement for r in runs]) @ XY_COUPLING.T))
    return out


# a trial whose error grew is undone and said (the learner's own safeguard), per actuator
@pytest.mark.filterwarnings(
    "ignore:actuator .. trial .*the error (grew|crept):piezohyst.errors.LearningWarning"
)
def test_a_fast_raster_is_learned_to_the_issues_bounds() -> None:
    """The 10 Hz raster line through each axis's lag and mode: the feedforward alone leaves
    the fast axis's loop 1 % wide (the PI model's own on the Preisach bench); after ten
    learned trials x tracks to 0.1 % with a 0.2 % loop and y stays within 0.05 %."""
    model, limits = hosts.dynamic_stage(16)
    ilc = ph.CoupledLearningCompensator(model, **limits, sample_rate=FS, slew_rate=None)
    (x0, x1), (y0, y1) = ilc.feedforward.reach
    k = np.arange(1000)
    tri = np.abs((k / FS * 10.0) % 1.0 * 2 - 1)
    scan = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri), np.full(k.size, 0.5 * (y0 + y1))])
    span = np.array([x1 - x0, y1 - y0])
    trials = _trials(ilc, scan, XY_DYNAMIC, 11)
    lo, hi = np.array(limits["v_min"]), np.array(limits["v_max"])
    for u, _ in trials:  # every command of every trial inside its actuator's limits
        assert np.all(np.isfinite(u)) and np.all((u >= lo) & (u <= hi))
    figures = []
    for _, moved in trials[1:]:
        error = np.sqrt(np.mean((moved - scan) ** 2, axis=0)) / span
        figures.append((error[0], hysteresis_width(scan[:, 0], moved[:, 0]),
                        np.ptp(moved[:, 1]) / span[1]))  # fmt: skip
    ff_error, ff_width, _ = figures[0]
    for error, width, held in figures[-2:]:
        # measured (trials 9 and 10): 0.08-0.09 % / 0.18-0.22 % / 0.03-0.07 % (the feedforward
        # 0.56 % / 1.03 % / 0.15 %): the issue's bounds (1 %, 1 %, 0.5 %)
        assert error < 0.01 and width < 0.01 and held < 0.005
        assert error < ff_error / 3 and width < ff_width / 2
    assert [t.index for t in ilc.history] == list(range(11)) and ilc.history[0].skipped
    assert not any(t.skipped for t in ilc.history[1:])
    assert np.all(ilc.history[-1].saturated == 0) and ilc.outside_count == 0
    assert np.isnan(ilc.history[-1].width[1])  # y held: no loop to speak of
    said = ilc.describe().splitlines()
    assert len(said) == 2 and said[0].startswith("actuator 0: the Jacobian law")
    # y's share is undoing x's coupling: a few per cent of its reach, learned without a probe
    assert said[1].startswith("actuator 1: its share of the scan moves under 10 %")


def test_the_trials_record_is_the_measured_error(static_stage: ph.CoupledModel) -> None:
    """A trial's error per output is the RMS of the desired minus the positions read, over
    what the stage reaches along that output; each learner's own record sits beside it."""
    ilc = ph.CoupledLearningCompensator(static_stage, v_min=0.0, v_max=140.0,
                                        sample_rate=FS, slew_rate=None)  # fmt: skip
    (x0, x1), (y0, y1) = ilc.feedforward.reach
    k = np.arange(500)
    tri = np.abs((k / FS * 4.0) % 1.0 * 2 - 1)
    scan = np.column_stack([x0 + (x1 - x0) * (0.3 + 0.4 * tri), np.full(k.size, 0.5 * (y0 + y1))])
    u = ilc.command(scan)
    read = scan + 1e-7 * np.sin(np.arange(k.size))[:, None]
    trial = ilc.learn(read)
    reach = ilc.output_reach()
    expected = np.sqrt(np.mean((scan - read) ** 2, axis=0)) / (reach[:, 1] - reach[:, 0])
    # tol: the same arithmetic in another order (a mean of squares): rounding
    np.testing.assert_allclose(trial.error, expected, rtol=1e-12)
    assert u.shape == (500, 2) and len(trial.actuators) == 2 and trial.skipped
    # the reach along each output: the parallelogram's box (corners through the coupling)
    lo, hi = ilc.feedforward.reach[:, 0], ilc.feedforward.reach[:, 1]
    corners = np.array([[a, b] for a in (lo[0], hi[0]) for b in (lo[1], hi[1])])
    through = corners @ static_stage.coupling_.T + static_stage.offset_
    # tol: two sums of the same four products: rounding of ~1e-4 m
    np.testing.assert_allclose(reach, np.column_stack([through.min(0), through.max(0)]),
                               rtol=0, atol=1e-18)  # fmt: skip


def test_an_actuator_with_nothing_to_learn_is_held(static_stage: ph.CoupledModel) -> None:
    """A scan along actuator 0 alone (actuator 1's share constant): actuator 1 is held by
    its feedforward compensator, and the stage says so."""
    ilc = ph.CoupledLearningCompensator(static_stage, v_min=0.0, v_max=140.0,
                                        sample_rate=FS, slew_rate=None)  # fmt: skip
    (x0, x1), (y0, y1) = ilc.feedforward.reach
    k = np.arange(400)
    own = np.column_stack([x0 + (x1 - x0) * (0.4 + 0.2 * np.sin(2 * np.pi * 5 * k / FS)),
                           np.full(k.size, 0.5 * (y0 + y1))])  # fmt: skip
    scan = own @ static_stage.coupling_.T + static_stage.offset_
    first = ilc.command(scan)
    assert ilc.learners[0] is not None and ilc.learners[1] is None
    assert "actuator 1: held by its compensator" in ilc.describe()
    trial = ilc.learn(scan)
    assert trial.actuators[1] is None and trial.saturated[1] == 0
    again = ilc.command()
    # the held actuator's commands: its compensator's for the same target, trial after trial
    assert np.ptp(first[:, 1]) < 1e-9 and np.ptp(again[:, 1]) < 1e-9


def test_limits_and_warnings_name_the_actuator(static_stage: ph.CoupledModel) -> None:
    """A scan beyond the stage's reach: named and counted once, and the learner whose
    commands the limits hold says so with its actuator's number."""
    ilc = ph.CoupledLearningCompensator(static_stage, v_min=0.0, v_max=140.0,
                                        sample_rate=FS, slew_rate=None)  # fmt: skip
    (x0, x1), (y0, y1) = ilc.feedforward.reach
    k = np.arange(500)
    tri = np.abs((k / FS * 4.0) % 1.0 * 2 - 1)
    scan = np.column_stack([x0 + (x1 - x0) * (0.5 + 0.7 * tri), np.full(k.size, 0.5 * (y0 + y1))])
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        u = ilc.command(scan)
        ilc.learn(scan)  # the lead-in: not learned from
        u = ilc.command()
        trial = ilc.learn(scan)
    assert ilc.outside_count > 0 and np.all((u >= 0.0) & (u <= 140.0))
    assert trial.saturated[0] > 0
    told = [(w.category, str(w.message)) for w in said]
    outside = r"CoupledLearningCompensator: \d+ desired positions lie outside what the stage"
    assert any(c is LimitWarning and re.match(outside, m) for c, m in told)
    assert any(c is LimitWarning and m.startswith("actuator 0: the voltage limits [0, 140] V held")
               for c, m in told)  # fmt: skip
    held = r"actuator 0: trial 1: the limits held \d+ of 500"
    assert any(c is LearningWarning and re.match(held, m) for c, m in told)
    assert all(m.startswith(("actuator 0", "CoupledLearningCompensator")) for _, m in told)


def test_bad_input_is_named(static_stage: ph.CoupledModel) -> None:
    kw = {"v_min": 0.0, "v_max": 140.0, "sample_rate": FS, "slew_rate": None}
    with pytest.raises(ph.ParameterError, match="does not take 'gains'"):
        ph.CoupledLearningCompensator(static_stage, gains=0.5, **kw)
    with pytest.raises(ph.ParameterError, match=r"takes a fitted ph\.CoupledModel"):
        ph.CoupledLearningCompensator(ph.CoupledModel(), **kw)
    ilc = ph.CoupledLearningCompensator(static_stage, **kw)
    with pytest.raises(ph.ParameterError, match="learn\\(\\) needs a trial"):
        ilc.learn(np.zeros((10, 2)))
    with pytest.raises(ph.ParameterError, match="the first command\\(\\) needs"):
        ilc.command()
    with pytest.raises(ph.ShapeError, match=r"'desired' must be \(samples, 2\)"):
        ilc.command(np.zeros((10, 3)))
    with pytest.raises(ph.ParameterError, match="a constant scan has nothing to learn"):
        ilc.command(np.full((10, 2), 1e-4))
    scan = np.column_stack([1.5e-4 + 5e-5 * np.sin(2 * np.pi * np.arange(10) / 10),
                            np.full(10, 1e-4)])  # fmt: skip
    scan[4, 1] = np.nan
    with pytest.raises(ph.ParameterError, match=r"must be finite.*\(row 4\)"):
        ilc.command(scan)
    scan[4, 1] = 1e-4
    ilc.command(scan)
    with pytest.raises(ph.ParameterError, match="still waits for its readings"):
        ilc.command(scan)
    with pytest.raises(ph.ShapeError, match=r"'positions' must be \(10, 2\)"):
        ilc.learn(np.zeros((9, 2)))
    ilc.learn(scan)
    with pytest.raises(ph.ParameterError, match="belongs to another scan"):
        ilc.command(scan[::-1])


@pytest.mark.filterwarnings(
    "ignore:actuator .. trial .*the error (grew|crept):piezohyst.errors.LearningWarning"
)
def test_a_saved_learner_resumes_exactly(static_stage: ph.CoupledModel, tmp_path) -> None:
    """Saved between trials (or with a trial waiting for its readings), a learner made again
    with the same model and settings gives the same next commands, to the bit, and the same
    record; a file of another kind is refused."""
    kw = {"v_min": 0.0, "v_max": 140.0, "sample_rate": FS, "slew_rate": None}
    ilc = ph.CoupledLearningCompensator(static_stage, **kw)
    (x0, x1), (y0, y1) = ilc.feedforward.reach
    k = np.arange(400)
    own = np.column_stack([x0 + (x1 - x0) * (0.4 + 0.2 * np.sin(2 * np.pi * 5 * k / FS)),
                           np.full(k.size, 0.5 * (y0 + y1))])  # fmt: skip
    scan = own @ static_stage.coupling_.T + static_stage.offset_  # actuator 1 held
    rng = np.random.default_rng(3)
    for _ in range(3):
        ilc.command(scan)
        ilc.learn(scan + 2e-7 * rng.standard_normal(scan.shape))
    ilc.save(tmp_path / "between.json")
    nxt = ilc.command()
    ilc.save(tmp_path / "waiting.json")
    readings = scan + 2e-7 * rng.standard_normal(scan.shape)
    trial = ilc.learn(readings)
    after = ilc.command()

    again = ph.CoupledLearningCompensator(static_stage, **kw)
    again.load(tmp_path / "between.json")
    assert again.trials == 3 and again.learners[1] is None
    np.testing.assert_array_equal(again.command(), nxt)
    waiting = ph.CoupledLearningCompensator(static_stage, **kw)
    waiting.load(tmp_path / "waiting.json")
    resumed = waiting.learn(readings)
    np.testing.assert_array_equal(resumed.error, trial.error)
    np.testing.assert_array_equal(waiting.command(), after)
    assert [t.skipped for t in waiting.history] == [t.skipped for t in ilc.history]

    (tmp_path / "other.json").write_text(json.dumps({"format": "piezohyst-learning"}))
    with pytest.raises(ph.errors.ModelFileError, match="not a piezohyst coupled learning state"):
        again.load(tmp_path / "other.json")
    data = json.loads((tmp_path / "between.json").read_text())
    data["learners"][0]["fingerprint"] = "0" * 16
    (tmp_path / "other.json").write_text(json.dumps(data))
    with pytest.raises(
        ph.errors.ModelFileError, match=r"^\S+other.json, actuator 0: made with another model"
    ):
        again.load(tmp_path / "other.json")


def test_a_loop_that_steps_the_stage_learns_as_whole_trials_do(
    static_stage: ph.CoupledModel, tmp_path
) -> None:
    """``step`` per sample, the positions read after each command passed with the next call:
    the same commands, to the bit, as ``command`` and ``learn`` on whole trials (the
    controllers' one contract); saved mid-trial, the loop resumes where it stood."""
    kw = {"v_min": 0.0, "v_max": 140.0, "sample_rate": FS, "slew_rate": None}
    whole = ph.CoupledLearningCompensator(static_stage, **kw)
    (x0, x1), (y0, y1) = whole.feedforward.reach
    k = np.arange(200)
    scan = np.column_stack([x0 + (x1 - x0) * (0.5 + 0.2 * np.sin(2 * np.pi * 10 * k / FS)),
                            np.full(k.size, 0.5 * (y0 + y1))])  # fmt: skip
    rng = np.random.default_rng(4)
    readings = [scan + 3e-7 * rng.standard_normal(scan.shape) for _ in range(3)]
    sent = []
    for r in readings:
        sent.append(whole.command(scan))
        whole.learn(r)
    sent.append(whole.command())

    loop = ph.CoupledLearningCompensator(static_stage, **kw)
    loop.command(scan)  # the scan, once: its commands are the first trial's
    assert loop.reads
    got, before = [], None
    for trial in range(4):
        rows = []
        for j in range(k.size):
            if trial == 1 and j == 50:  # saved mid-trial and resumed by another learner
                loop.save(tmp_path / "mid.json")
                loop = ph.CoupledLearningCompensator(static_stage, **kw)
                loop.load(tmp_path / "mid.json")
            rows.append(loop.step(scan[j], before))
            before = readings[trial][j] if trial < 3 else None
        got.append(np.array(rows))
    for a, b in zip(got, sent, strict=True):
        np.testing.assert_array_equal(a, b)
    assert loop.trials == 3
    fresh = ph.CoupledLearningCompensator(static_stage, **kw)
    with pytest.raises(ph.ParameterError, match=r"give it once with command\(desired\)"):
        fresh.step(scan[0])
    fresh.command(scan)
    fresh.step(scan[0])
    with pytest.raises(ph.ParameterError, match="the learner repeats one scan"):
        fresh.step(scan[1] + 1e-6)
