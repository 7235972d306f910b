"""The controllers' one contract (issue 56, item 4): ``step(desired, measured=None)``,
``process(desired, measured=None)`` and ``reads``, so that one loop runs every controller."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.control import Controller
from piezohyst.simulation import Bench, run_loop

pytestmark = [
    pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning"),
    pytest.mark.filterwarnings("ignore::piezohyst.errors.RecordWarning"),
    # a lag fitted from one rate, to make a compensator that takes a preview (not to use)
    pytest.mark.filterwarnings("ignore::piezohyst.errors.IdentifiabilityWarning"),
]
KW = {"v_min": 0.0, "v_max": 140.0}


@pytest.fixture(scope="module")
def model() -> ph.ActivePI:
    rec = ph.simulate(duration=10.0, seed=2)
    return ph.ActivePI(n_operators=8).fit(rec.voltage, rec.charge, t=rec.t)


def scan(model: ph.ActivePI, n: int = 200) -> np.ndarray:
    """A 20 Hz scan inside the major loop, four periods in a 200-sample trial."""
    top, bottom = model.hysteresis_.predict(np.array([140.0, 0.0]))
    k = np.arange(n)
    return bottom + (top - bottom) * (0.4 + 0.1 * np.sin(2 * np.pi * 4 * k / n))


def test_every_controller_answers_the_contract(model: ph.ActivePI) -> None:
    bank = ph.ModelBank.from_models([model, model])
    made = {
        ph.Compensator(model, **KW): False,
        ph.BankCompensator(bank, **KW): False,
        ph.SelfSensingController(model, sample_rate=1000.0, **KW): True,
        ph.BankController(bank, sample_rate=1000.0, **KW): True,
        ph.LearningCompensator(model, sample_rate=1000.0, **KW): True,
    }
    for ctl, reads in made.items():
        assert isinstance(ctl, Controller), type(ctl).__name__
        assert ctl.reads is reads, type(ctl).__name__


def test_one_loop_runs_each_controller(model: ph.ActivePI) -> None:
    """run_loop asks ``reads``, never the class: the compensator's block, the self-sensing
    loop's samples and the learner's trials all run through it."""
    d = scan(model)
    comp = ph.Compensator(model, slew_rate=None, **KW)
    fed = run_loop(comp, d, Bench(seed=1, voltage=comp.last_command))
    # the feedforward compensator was sent the block: its commands are process()'s
    np.testing.assert_array_equal(
        fed.voltage, ph.Compensator(model, slew_rate=None, **KW).process(d)
    )
    ctl = ph.SelfSensingController(model, sample_rate=1000.0, **KW)
    looped = run_loop(ctl, d, Bench(seed=1, voltage=ctl.last_command))
    assert looped.voltage.size == d.size and ctl.measurement_faults == 0


def test_the_learner_stepped_learns_as_in_whole_trials(model: ph.ActivePI) -> None:
    """Sample by sample in a loop (the reading after each command arriving with the next
    step) the learning compensator sends exactly the commands it sends trial by trial."""
    d, trials = scan(model), 6
    by_trial = ph.LearningCompensator(model, sample_rate=1000.0, slew_rate=30e3, **KW)
    bench = Bench(seed=1, voltage=by_trial.last_command)
    sent = []
    for _ in range(trials):
        u = by_trial.command(d)
        sent.append(u)
        by_trial.learn(bench.run(u).charge)
    stepped = ph.LearningCompensator(model, sample_rate=1000.0, slew_rate=30e3, **KW)
    start = stepped.last_command
    first = stepped.command(d)  # the trajectory, once; step() sends this trial's commands
    np.testing.assert_array_equal(first, sent[0])
    record = run_loop(stepped, np.tile(d, trials), Bench(seed=1, voltage=start))
    assert stepped.trials == trials - 1  # the last trial waits for its last reading
    np.testing.assert_array_equal(record.voltage, np.concatenate(sent))
    assert [t.error for t in stepped.history] == [t.error for t in by_trial.history[:-1]]
    assert by_trial.history[-1].error < 0.6 * by_trial.history[1].error  # it did learn


def test_what_the_contract_refuses(model: ph.ActivePI) -> None:
    rec = ph.simulate(duration=10.0, seed=2)
    lagged = ph.ActivePI(8, input_dynamics="delay+first-order").fit(
        rec.voltage, rec.charge, t=rec.t
    )
    timed = ph.Compensator(lagged, sample_rate=1000.0, **KW)
    with pytest.raises(ph.ParameterError, match=r"second argument is a reading.*preview="):
        timed.step(1e-7, [1e-7, 1e-7])  # the preview where it once was: where it counts
    comp = ph.Compensator(model, **KW)
    assert comp.step(1e-7, 3.0) == ph.Compensator(model, **KW).step(1e-7)  # read, ignored
    with pytest.raises(ph.ShapeError, match="'measured' must match"):
        comp.process(np.zeros(3), np.zeros(4))
    ctl = ph.SelfSensingController(model, sample_rate=1000.0, **KW)
    with pytest.raises(ph.ParameterError, match="takes one reading"):
        ctl.step(1e-7, [0.0, 1.0])
    ilc = ph.LearningCompensator(model, sample_rate=1000.0, **KW)
    with pytest.raises(ph.ParameterError, match="give it once with command"):
        ilc.step(1e-7)
    d = scan(model)
    ilc.command(d)
    with pytest.raises(ph.ParameterError, match="at sample 0 of the trial"):
        ilc.step(float(d[0]) + 0.01 * float(np.ptp(d)))


def test_none_is_no_reading(model: ph.ActivePI) -> None:
    """Without a reading the self-sensing controller runs on its feedforward for that sample
    and counts it, exactly as for a NaN reading."""
    d = scan(model)
    none, nan = (ph.SelfSensingController(model, sample_rate=1000.0, **KW) for _ in range(2))
    a = [none.step(float(x)) for x in d[:50]]
    b = [nan.step(float(x), math.nan) for x in d[:50]]
    assert a == b and none.measurement_faults == nan.measurement_faults == 50
    np.testing.assert_array_equal(
        ph.SelfSensingController(model, sample_rate=1000.0, **KW).process(d[:50]), np.array(a)
    )


def test_a_stepping_learner_saved_mid_trial_resumes_exactly(
    model: ph.ActivePI, tmp_path: Path
) -> None:
    """Saved in the middle of a trial that a loop is stepping, the learner resumes at the same
    sample with the readings it had: the rest of the run is the run without the stop."""
    d = scan(model)
    kw = {"sample_rate": 1000.0, "slew_rate": 30e3, **KW}
    whole = ph.LearningCompensator(model, **kw)
    start = whole.last_command
    whole.command(d)
    desired = np.tile(d, 3)
    full = run_loop(whole, desired, Bench(seed=1, voltage=start))
    first = ph.LearningCompensator(model, **kw)
    first.command(d)
    bench = Bench(seed=1, voltage=start)
    head = run_loop(first, desired[:330], bench)  # into the second trial
    first.save(tmp_path / "learner.json")
    again = ph.LearningCompensator(model, **kw)
    again.load(tmp_path / "learner.json")
    tail = run_loop(again, desired[330:], bench)
    np.testing.assert_array_equal(np.concatenate([head.voltage, tail.voltage]), full.voltage)
    assert [t.error for t in again.history] == [t.error for t in whole.history]
