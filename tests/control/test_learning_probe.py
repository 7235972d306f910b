"""The lead-in's probe: sines off the scan's harmonics, the loop's response measured from two
trials, and the timings the learning law allows for narrowed to those that agree with it
(issue 40: learning at 40 Hz where the model knows its lag only roughly)."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.control.learning.design import PROBE_SIGMAS, design_learning
from piezohyst.control.learning.probe import (
    AMPLITUDE,
    SETTLE,
    Response,
    probe_bins,
    probe_signal,
    response,
    scan_bin,
)
from piezohyst.errors import LearningWarning
from piezohyst.model.dynamics import InputDynamics, filter_response

RATE = 1000.0
N = 1000


def _scan(f: float = 40.0) -> np.ndarray:
    return 1e-6 * (1.0 + 0.4 * np.sin(2 * np.pi * f * np.arange(N) / RATE))


def _through(x: np.ndarray, delay: float, tau: float) -> np.ndarray:
    """A periodic signal through a delay and a first-order lag of held samples, exactly."""
    f = np.fft.rfftfreq(x.size, 1 / RATE)
    return np.fft.irfft(np.fft.rfft(x) * filter_response(delay, tau, 1 / RATE, f), n=x.size)


def test_the_probe_sits_between_the_scans_harmonics() -> None:
    d = _scan()
    bins = probe_bins(d)
    assert scan_bin(d) == 40
    assert bins.size == 8 and np.unique(bins).size == 8
    assert np.all(bins % 40 != 0)  # off the scan's harmonics, where its own error sits
    assert bins.min() >= 60 and bins.max() <= 0.4 * N + 1  # 1.5 f0 to 0.4 of the rate
    p = probe_signal(bins, N, float(np.ptp(d)))
    spec = np.abs(np.fft.rfft(p)) * 2 / N
    # tol: an FFT of exact harmonics: rounding of 1000 terms
    np.testing.assert_allclose(spec[bins], AMPLITUDE * np.ptp(d), rtol=1e-9)
    others = np.delete(spec, bins)
    assert others.max() <= 1e-9 * spec[bins].max()  # nothing else: periodic over the trial
    assert probe_bins(_scan()[:50]).size == 0  # too short a trial: no probe
    slow = probe_bins(_scan(1.0))  # one cycle a trial: every harmonic is the scan's
    assert slow.size == 8 and np.unique(slow).size == 8 and slow.min() >= 2


@pytest.mark.parametrize("seed", range(5))
def test_the_loops_response_is_measured_with_an_error_that_covers_it(seed: int) -> None:
    """Two trials that differ by the probe through a 1.5 ms delay and a 1 ms lag, by a slow
    drift, an arrival's decaying transient and the scan's own harmonics, with 0.25 % noise:
    the ratio at each sine is the filter's, within four of its standard errors."""
    rng = np.random.default_rng(seed)
    d = _scan()
    span = float(np.ptp(d))
    bins = probe_bins(d)
    probe = probe_signal(bins, N, span)
    base = d + 0.1 * (d - d.mean()) ** 2 / span  # a loop's shape, the same in both trials
    k = np.arange(N) / N
    noise = 2.5e-3 * span
    lead = base + _through(probe, 1.5e-3, 1e-3) + 0.01 * span * k**2
    lead = lead + 0.003 * span * np.sin(2 * np.pi * 80 * k + 0.4)  # the scan's 2nd, changed
    lead = lead + 0.05 * span * np.exp(-np.arange(N) / 40.0)  # the arrival, decaying (40 ms)
    lead = lead + noise * rng.standard_normal(N)
    after = base + noise * rng.standard_normal(N)
    usable = np.arange(N) >= 150  # the ramp-in excluded
    got = response(lead, after, usable, bins, d)
    assert got is not None
    truth = filter_response(1.5e-3, 1e-3, 1 / RATE, bins * RATE / N)
    turn = np.abs(np.angle(got.ratio / truth))
    reach = PROBE_SIGMAS * got.phase_stderr
    used = reach < 1.0  # where the design uses the phase: the response beyond the noise
    assert used.sum() >= 6
    # tol: what four standard errors of noise, in any direction of the complex plane, can
    # turn the phase (beyond: 3e-4 per sine)
    assert np.all(turn[used] <= np.arcsin(reach[used])), (turn, got.phase_stderr)
    # the error it states is the noise's: sigma sqrt(2) over the probe's amplitude, over
    # sqrt(usable / 2) samples per quadrature
    used_n = int((usable & (np.arange(N) >= SETTLE * N)).sum())  # the settled stretch
    expected = noise * math.sqrt(2) / (AMPLITUDE * span) / math.sqrt(used_n / 2)
    assert np.all(got.phase_stderr < 3 * expected / np.abs(truth))
    assert response(lead, after, np.arange(N) >= 700, bins, d) is None  # too few usable


def test_a_stretch_that_cannot_tell_the_sines_from_the_scan_measures_nothing() -> None:
    """The probe's sines sit at odd harmonics of a trial of two scan periods; over the
    trial's second half alone (a lead-in the slew limit ramped in: the samples until its
    extremes wiped the ramp out are not usable) they are sums of the scan's harmonics there,
    so nothing tells them apart: no response, rather than one read 175 degrees off. The
    whole trial measures it."""
    k = np.arange(500)
    d = 1e-6 * (1.0 + 0.4 * np.abs((k / RATE * 4.0) % 1.0 * 2 - 1))  # 4 Hz, two periods
    bins = probe_bins(d)
    assert scan_bin(d) == 2 and np.all(bins % 2 == 1)
    probe = probe_signal(bins, k.size, float(np.ptp(d)))
    lead, after = d + probe, d.copy()
    assert response(lead, after, k >= 250, bins, d) is None
    whole = response(lead, after, np.ones(k.size, dtype=bool), bins, d)
    assert whole is not None
    # tol: noise-free: the fit's rounding over 400 settled samples
    np.testing.assert_allclose(whole.ratio, 1.0, rtol=0, atol=1e-9)


def test_a_lead_in_the_slew_limit_ramps_in_says_nothing_false() -> None:
    """A 4 Hz scan of 500 samples from rest under a 30 kV/s slew limit: the lead-in is ramped
    in, half of it cannot measure the probe, and the learner learns without the probe's
    word instead of saying the loop lags by half a period."""
    from piezohyst.simulation import Bench, make_signal, simulate

    t, v = make_signal("decaying", duration=8.0)
    rec = simulate(np.clip(2 * v, 0.0, 140.0), t, seed=0)
    model = ph.ClassicalPI(10, output_unit="m").fit(rec.voltage, rec.displacement, t=rec.t)
    lo, hi = model.hysteresis_.predict(np.array([0.0, 140.0]))
    ilc = ph.LearningCompensator(model, v_min=0.0, v_max=140.0, sample_rate=RATE,
                                 slew_rate=30e3, domain="displacement", gain=1.0)  # fmt: skip
    zero = ilc.compensator.reference
    k = np.arange(500)
    d = lo + (hi - lo) * (0.3 + 0.4 * np.abs((k / RATE * 4.0) % 1.0 * 2 - 1)) - zero
    bench = Bench(seed=0, voltage=ilc.last_command)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the probe's misreading warned here before
        for _ in range(4):
            run = bench.run(ilc.command(d))
            ilc.learn(displacement=run.displacement - zero)
    assert ilc.history[0].saturated > 0  # the arrival: ramped in by the slew limit
    assert ilc.design is not None and not ilc.design.probed
    assert ilc.history[-1].error < 0.5 * ilc.history[1].error


def _model(covariance: tuple[float, ...]) -> ph.ActivePI:
    h = ph.PIHysteresis([0.0, 15.0, 30.0], [1.0e-8, 4e-9, 2e-9])
    model = ph.ActivePI.from_operator(h)
    model.input_range_ = (0.0, 140.0)
    model.input_dynamics_ = InputDynamics(
        "delay+first-order", tau=4e-3, delay=0.5e-3, sample_interval=1 / RATE,
        covariance=covariance,
    )  # fmt: skip
    return model


def test_a_probe_that_agrees_narrows_the_timings_and_one_that_does_not_leaves_them() -> None:
    """The identified delay and lag known to +-1.2 ms (95 %), as ActivePI knew them on the
    two-state capacitor: a probe measuring the identified timing keeps only the part of that
    region it agrees with, so the law's cutoff rises; a probe no timing of the region
    explains (90 degrees everywhere) leaves the design as it was."""
    model = _model((3.8e-7, -3.4e-8, -3.4e-8, 4.5e-7))
    first = _scan() - _scan().mean()
    plain = design_learning(model, sample_rate=RATE, samples=N, first_error=first)
    bins = probe_bins(_scan())
    agree = Response(bins, np.ones(bins.size, dtype=complex), np.full(bins.size, 0.02))
    probed = design_learning(model, sample_rate=RATE, samples=N, first_error=first,
                             measured=agree)  # fmt: skip
    assert probed.probed and not plain.probed
    assert probed.timing < plain.timing and probed.cutoff > plain.cutoff
    assert probed.contraction <= 0.9 and "as the lead-in's probe measured" in probed.describe()
    assert probed.timing >= 0.5e-3  # the reading's half sample stays allowed for
    odd = Response(bins, np.full(bins.size, 1j), np.full(bins.size, 0.02))
    same = design_learning(model, sample_rate=RATE, samples=N, first_error=first, measured=odd)
    quiet = replace(same, probe_phase=0.0, probe_frequency=0.0, probe_delay=0.0, probe_lag=0.0)
    assert quiet == plain  # and it says so:
    assert same.probe_phase == math.pi / 2 and same.probe_frequency in bins * RATE / N
    assert "90 degrees ahead of the timing the law assumes" in same.describe()
    assert not plain.beyond() and not probed.beyond()
    tight = _model(())  # dynamics given by hand: the box of their tolerance narrows alike
    boxed = design_learning(tight, sample_rate=RATE, samples=N, first_error=first)
    narrowed = design_learning(tight, sample_rate=RATE, samples=N, first_error=first,
                               measured=agree)  # fmt: skip
    assert narrowed.probed and narrowed.timing < boxed.timing
    vague = Response(bins, np.ones(bins.size, dtype=complex), np.full(bins.size, 0.5))
    assert (
        design_learning(model, sample_rate=RATE, samples=N, first_error=first, measured=vague)
        == plain
    )  # too noisy to rule anything out


def test_the_lead_in_carries_the_probe_and_the_law_uses_what_it_measured() -> None:
    """On a plant that is the model behind its own identified dynamics, known roughly: the
    lead-in's commands carry the sines (not the trials after it), and the first law learned
    allows only for the timings the probe agrees with."""
    model = _model((3.8e-7, -3.4e-8, -3.4e-8, 4.5e-7))
    d = _scan()
    kw = {"v_min": 0.0, "v_max": 140.0, "sample_rate": RATE, "slew_rate": None}
    runs = {}
    for probe in (True, False):
        ilc = ph.LearningCompensator(model, probe=probe, **kw)  # type: ignore[arg-type]
        sent = []
        for _ in range(3):
            u = ilc.command(d)
            sent.append(u)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ph.ExtrapolationWarning)
                y = model.predict(u, t=np.arange(u.size) / RATE)
            ilc.learn(y)
        runs[probe] = (ilc, sent)
    (on, sent_on), (off, sent_off) = runs[True], runs[False]
    assert not np.array_equal(sent_on[0], sent_off[0])  # the lead-in carries the sines
    spec = np.abs(np.fft.rfft(sent_on[0] - sent_off[0]))
    bins = probe_bins(d)
    # at the probe's bins (the inverse's curvature spreads a little of it to others)
    assert spec[bins].min() > 2 * np.delete(spec, bins)[1:].max()
    assert on.design is not None and off.design is not None
    assert on.design.probed and not off.design.probed
    assert on.design.timing < off.design.timing


def test_a_loop_lagging_a_model_without_dynamics_is_told_by_the_probe() -> None:
    """A model that knows no lag, the loop 4 ms behind it (an amplifier), the lag not measured
    on the trial after the lead-in (``measure_lag=False``; tests/control/
    test_learning_timing.py): the lead-in's probe measures the phase, the law allows for half
    a sample only, and the learner says so once, naming what to do; the same loop with the
    lag in the model is quiet, and so is the model without it where that trial measured it."""
    h = ph.PIHysteresis([0.0, 15.0, 30.0], [1.0e-8, 4e-9, 2e-9])
    plain = ph.ActivePI.from_operator(h)
    plain.input_range_ = (0.0, 140.0)
    d = _scan()
    kw = {"v_min": 0.0, "v_max": 140.0, "sample_rate": RATE, "slew_rate": None, "law": "jacobian"}
    said = {}
    for name, model in (("plain", plain), ("lagged", _model(())), ("measured", plain)):
        ilc = ph.LearningCompensator(model, **kw, measure_lag=name != "plain")  # type: ignore[arg-type]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(3):
                u = ilc.command(d)
                ilc.learn(plain.hysteresis_.predict(_through(u, 0.5e-3, 4e-3)))
        said[name] = [str(w.message) for w in caught if w.category is LearningWarning]
        assert ilc.design is not None
        assert (ilc.design.probe_phase < 0) == (name == "plain")  # the loop lags
        if name == "plain":  # sized roughly (a hysteresis' response to small sines is not a
            # linear system's): the delay to its grid's quarter sample, the lag to a factor 2
            assert abs(ilc.design.probe_delay - 0.5e-3) <= 0.25e-3 + 1e-12
            assert 2e-3 <= ilc.design.probe_lag <= 8e-3
    told = [m for m in said["plain"] if "the lead-in's probe measured the loop" in m]
    assert len(told) == 1 and "behind" in told[0] and "input_dynamics='auto'" in told[0]
    assert "by default the trial after the lead-in measures the loop's lag" in told[0]
    assert "this run was told not to (measure_lag=False, --no-lag-measurement)" in told[0]
    assert not any("probe measured" in m for m in said["lagged"] + said["measured"])
