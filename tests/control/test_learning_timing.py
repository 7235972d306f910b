"""The loop's lag measured on the first trial learned from, where the model holds none
(issue 55, item 4: the default path learns a 40 Hz scan behind an amplifier)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.control.learning.timing import MAX_LAG, periodic_lag, trial_lag
from piezohyst.errors import LearningWarning
from piezohyst.model.dynamics import InputDynamics

RATE = 1000.0
N = 1000
H = ph.PIHysteresis([0.0, 15.0, 30.0], [1.0e-8, 4e-9, 2e-9])


def _periodic(h: ph.PIHysteresis, v: np.ndarray) -> np.ndarray:
    """The operator's output over one period of ``v`` repeated: its periodic steady state."""
    return np.asarray(h.predict(np.tile(v, 2)))[v.size :]


def _scan(f: float, level: float = 70.0, swing: float = 50.0) -> np.ndarray:
    return level + swing * np.sin(2 * np.pi * f * np.arange(N) / RATE)


@settings(max_examples=25, deadline=None)
@given(
    tau=st.floats(1e-4, 2e-2),
    amps=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    harmonics=st.lists(st.integers(1, 400), min_size=3, max_size=3),
)
def test_the_periodic_lag_is_the_held_lag_run_until_it_settles(
    tau: float, amps: list[float], harmonics: list[int]
) -> None:
    """Against the input dynamics' own recursion, run over enough periods that its start is
    forgotten: the last period is the steady state the frequency form gives at once."""
    k = np.arange(N)
    parts = zip(amps, harmonics, strict=True)
    v = 1.0 + sum(a * np.cos(2 * np.pi * h * k / N + h) for a, h in parts)
    periods = 2 + int(40 * tau * RATE / N)  # e^-40 of the start left
    x = np.tile(v, periods)
    dt = np.full(x.size, 1.0 / RATE)
    dt[0] = 0.0
    run, _ = InputDynamics("first-order", tau, 0.0, 1.0 / RATE).apply(x, dt)
    # tol: rounding of a stable one-pole recursion over a few thousand steps (gain <= 1) and of
    # an FFT of 1000 points, on values of order 1
    np.testing.assert_allclose(periodic_lag(v, tau, RATE), run[-N:], rtol=0, atol=1e-10)
    np.testing.assert_array_equal(periodic_lag(v, 0.0, RATE), v)


@settings(max_examples=8, deadline=None)
@given(tau=st.floats(5e-4, 1e-2), f=st.sampled_from([10.0, 20.0, 40.0]))
def test_a_trials_lag_is_found(tau: float, f: float) -> None:
    """Readings that are the model's response through a lag: the lag, to Brent's bracket."""
    u = _scan(f)

    def respond(v: np.ndarray) -> np.ndarray:
        return _periodic(H, v)

    measured = respond(periodic_lag(u, tau, RATE))
    found = trial_lag(respond, u, measured, np.ones(N, dtype=bool), RATE)
    assert found is not None
    # tol: the bounded search stops within xatol = 0.01 sample of the minimum, and the minimum
    # of an exact model's misfit is the lag itself; three brackets' slack
    assert abs(found.lag - tau) <= 0.03 / RATE
    # tol: what is left is the bracket's lag error, linear in it: at most 0.03 sample against a
    # lag of at least half a sample leaves (0.06)^2 of the variance
    assert found.explained > 0.99


def test_no_lag_where_the_trial_shows_none_or_one_beyond_the_search() -> None:
    u = _scan(40.0)

    def respond(v: np.ndarray) -> np.ndarray:
        return _periodic(H, v)

    every = np.ones(N, dtype=bool)
    # the model's own response: nothing to explain
    assert trial_lag(respond, u, respond(u), every, RATE) is None
    # a hysteresis the model does not hold (other weights), no lag: a lag explains little of it
    other = ph.PIHysteresis([0.0, 15.0, 30.0], [1.0e-8, 8e-9, -1e-9])
    assert trial_lag(respond, u, _periodic(other, u), every, RATE) is None
    # a lag longer than the search reaches: found at its end, so not kept
    far = respond(periodic_lag(u, 3 * MAX_LAG, RATE))
    assert trial_lag(respond, u, far, every, RATE) is None
    # too few readings
    assert trial_lag(respond, u, far, np.zeros(N, dtype=bool), RATE) is None


def _learner(law: str = "auto", measure_lag: bool = True) -> ph.LearningCompensator:
    plain = ph.ActivePI.from_operator(H)
    plain.input_range_ = (0.0, 140.0)
    return ph.LearningCompensator(plain, v_min=0.0, v_max=140.0, sample_rate=RATE,
                                  slew_rate=None, law=law,  # type: ignore[arg-type]
                                  measure_lag=measure_lag)  # fmt: skip


def _run(
    ilc: ph.LearningCompensator, d: np.ndarray, trials: int, tau: float, probe_said: bool = False
) -> list[float]:
    """Trials of a loop ``tau`` behind the model (its periodic steady state each trial); with
    ``probe_said`` the probe's word on a lag the law does not allow for is expected (the
    Jacobian law's, tests/control/test_learning_probe.py), else any warning fails."""
    for _ in range(trials):
        u = ilc.command(d)
        with warnings.catch_warnings():
            if probe_said:
                warnings.filterwarnings("ignore", "trial 1: the lead-in's probe", LearningWarning)
            ilc.learn(_periodic(H, periodic_lag(u, tau, RATE)))
    return [t.error for t in ilc.history if not t.skipped]


def test_the_learner_measures_the_lag_its_model_lacks_and_says_so(tmp_path: Path) -> None:
    """A model without input dynamics, the loop 4 ms behind it: the first trial after the
    lead-in measures the lag and is not learned from, the next trials' commands invert a copy
    of the model holding it (the model given is not changed), the law is chosen on the first
    of them, describe() says so and the state on file resumes it; learning from that trial
    instead (``measure_lag=False``) learns the same scan slower."""
    top, bottom = H.predict(np.array([140.0, 0.0]))
    d = bottom + (top - bottom) * (0.5 + 0.25 * np.sin(2 * np.pi * 40 * np.arange(N) / RATE))
    tau = 4e-3
    ilc = _learner()
    assert ilc.law == "auto"
    _run(ilc, d, 2, tau)  # the lead-in, then the trial that measures the lag
    assert ilc.timing is not None and ilc.timing.explained > 0.5 and ilc.timing.trial == 1
    # tol: the lead-in's probe sines and the trial's arrival from it are not in the periodic
    # response the lag is measured against: a quarter of a sample allowed
    assert abs(ilc.timing.lag - tau) <= 0.25 / RATE
    assert 0 <= ilc.timing.spread < 0.25 / RATE
    assert [t.skipped for t in ilc.history] == [True, True] and ilc.history[1].learned == 0
    assert not ilc.model.input_dynamics_.active  # the model given is not changed
    said = ilc.describe()
    assert "ms lag (+- " in said and "ms over the trial's fifths, 95 %)" in said
    assert "measured on trial 1, not learned from" in said and "chosen from the next" in said
    # the state on file resumes with the measured lag: the same commands next
    ilc.save(tmp_path / "state.json")
    again = _learner()
    again.load(tmp_path / "state.json")
    assert again.timing == ilc.timing and again.describe() == said
    u = ilc.command(d)
    np.testing.assert_array_equal(again.command(d), u)
    ilc.learn(_periodic(H, periodic_lag(u, tau, RATE)))
    assert ilc.design is not None and ilc.design.model_timed and ilc.law == "jacobian"
    assert "measured on trial 1" in ilc.describe() and "Jacobian law" in ilc.describe()
    errors = _run(ilc, d, 4, tau)
    unmeasured = _learner(measure_lag=False)
    asked = _run(unmeasured, d, 7, tau, probe_said=True)  # as many trials, one more learned
    assert unmeasured.timing is None and len(errors) == len(asked) - 1 == 5
    assert errors[-1] < 0.01 * asked[-1]  # 2.3e-6 against 0.043: measured, the lag is gone


def test_a_stated_lag_or_the_models_own_dynamics_is_not_measured_again() -> None:
    top, bottom = H.predict(np.array([140.0, 0.0]))
    d = bottom + (top - bottom) * (0.5 + 0.25 * np.sin(2 * np.pi * 40 * np.arange(N) / RATE))
    plain = ph.ActivePI.from_operator(H)
    plain.input_range_ = (0.0, 140.0)
    stated = ph.LearningCompensator(plain, v_min=0.0, v_max=140.0, sample_rate=RATE,
                                    slew_rate=None, lag=3e-3)  # fmt: skip
    _run(stated, d, 2, 4e-3)
    assert stated.design is not None and stated.design.lag == 3e-3
    assert stated.timing is None and "measured" not in stated.describe()


def test_learn_from_the_shell_says_the_lag_it_measured(tmp_path: Path) -> None:
    """`piezohyst learn` prints what describe() says after the first trial learned from."""
    from click.testing import CliRunner

    from piezohyst.cli import main

    plain = ph.ActivePI.from_operator(H)
    plain.input_range_ = (0.0, 140.0)
    plain.save(tmp_path / "model.json")
    top, bottom = H.predict(np.array([140.0, 0.0]))
    d = bottom + (top - bottom) * (0.5 + 0.25 * np.sin(2 * np.pi * 40 * np.arange(N) / RATE))
    t = np.arange(N) / RATE
    ph.write_table(tmp_path / "scan.csv", {"time": t, "desired": d})
    runner = CliRunner()
    said: dict[str, list[str]] = {"": [], "--no-lag-measurement": []}
    for flag, out in said.items():
        base = ["learn", str(tmp_path / "model.json"), "--state", str(tmp_path / f"s{flag}.json"),
                "-o", str(tmp_path / "next.csv"), "--v-min", "0", "--v-max", "140",
                *([flag] if flag else [])]  # fmt: skip
        res = runner.invoke(main, [*base, "--desired", str(tmp_path / "scan.csv")])
        assert res.exit_code == 0, res.output
        for j in range(2):  # the lead-in, then the trial that measures the lag
            sent = ph.read_table(tmp_path / "next.csv").get("command")
            q = _periodic(H, periodic_lag(sent, 4e-3, RATE))
            ph.write_table(tmp_path / f"trial{j}.csv", {"time": t, "voltage": sent, "charge": q})
            res = runner.invoke(main, [*base[:2], str(tmp_path / f"trial{j}.csv"), *base[2:]])
            assert res.exit_code == 0, res.output
            out.append(res.output)
    lead, measuring = said[""]
    assert "measured" not in lead
    assert "trial 1: error " in measuring and "it measured the loop's lag (" in measuring
    assert "not learned from, the next trial's commands invert it" in measuring
    assert "ms over the trial's fifths, 95 %)" in measuring  # describe(), how sure
    learned = said["--no-lag-measurement"][1]  # that trial learned from, as before
    assert "trial 1: error " in learned and "learned from 1000 samples" in learned
    assert "it measured the loop's lag" not in learned
    assert "the lead-in's probe measured the loop" in learned  # the probe's word instead,
    assert "(measure_lag=False, --no-lag-measurement)" in learned  # naming what it turned off


def test_a_slew_held_trial_names_the_jacobian_law_also_where_a_lag_was_measured() -> None:
    """The harmonic law asked by name, the slew limit holding commands: the warning names the
    Jacobian law as the other way where the loop shows no lag and where the trial after the
    lead-in measured one (the model then holds it, and the Jacobian law learns through it)."""
    top, bottom = H.predict(np.array([140.0, 0.0]))
    d = bottom + (top - bottom) * (0.5 + 0.25 * np.sin(2 * np.pi * 40 * np.arange(N) / RATE))
    for tau in (0.0, 4e-3):
        plain = ph.ActivePI.from_operator(H)
        plain.input_range_ = (0.0, 140.0)
        ilc = ph.LearningCompensator(plain, v_min=0.0, v_max=140.0, sample_rate=RATE,
                                     slew_rate=6e3, law="harmonic")  # fmt: skip
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(3):
                u = ilc.command(d)
                ilc.learn(_periodic(H, periodic_lag(u, tau, RATE)))
        assert (ilc.timing is not None) == (tau > 0)
        said = [str(w.message) for w in caught if "trial 2" in str(w.message)]
        assert any("--law jacobian" in m for m in said), said


def test_the_lags_spread_covers_the_truth_as_it_says() -> None:
    """The jackknife's 95 % half-width: about nothing on exact readings; with 1 % noise it
    covers the true lag on 20 noise draws as a 95 % interval should."""
    u = _scan(40.0)

    def respond(v: np.ndarray) -> np.ndarray:
        return _periodic(H, v)

    clean = respond(periodic_lag(u, 4e-3, RATE))
    every = np.ones(N, dtype=bool)
    found = trial_lag(respond, u, clean, every, RATE)
    assert found is not None
    # tol: every fifth left out finds the same minimum, to the bracket's 0.01 sample
    assert found.spread <= 0.01 / RATE
    covered = 0
    for seed in range(20):
        noisy = clean + np.random.default_rng(seed).normal(0.0, 0.01 * np.ptp(clean), N)
        got = trial_lag(respond, u, noisy, every, RATE)
        assert got is not None and got.spread > 0
        covered += abs(got.lag - 4e-3) <= got.spread
    # at a true 95 %, 15 or fewer of 20 has probability 0.003 (binomial); 19 seen
    assert covered >= 16
    short = trial_lag(respond, u[:40], clean[:40], every[:40], RATE)  # too few to split in five
    assert short is None or np.isnan(short.spread)
