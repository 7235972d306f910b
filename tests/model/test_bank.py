"""Model banks: each channel is the single model of its column; the bank compensator is
each channel's compensator, in any chunks; files round-trip; bad channels are named."""

from __future__ import annotations

import itertools
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import piezohyst as ph

# these tests drive targets past the voltage and slew limits on purpose (safety, exactness
# where no limit acts); that the limits then say so is tested in test_records.py
# trajectories reach past the models' training ranges on purpose
pytestmark = [
    pytest.mark.filterwarnings("ignore::piezohyst.errors.ExtrapolationWarning"),
    pytest.mark.kernels,
    pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning"),
]

FS = 1000.0


def _fleet(channels: int = 5, n: int = 3000, seed: int = 0) -> tuple[np.ndarray, ...]:
    """Simulated units: a shared decaying drive, per-unit weights, leak and noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    v = 70.0 - 70.0 * np.cos(2 * np.pi * 1.5 * t) * np.exp(-t / 3.0)
    V = np.empty((n, channels))
    Q = np.empty((n, channels))
    for c in range(channels):
        gain = 1.0 + 0.2 * rng.standard_normal()
        w = np.array([1e-8, 3e-9, 2e-9, 1e-9]) * gain
        unit = ph.PIHysteresis([0.0, 10.0, 25.0, 45.0], w)
        V[:, c] = v + rng.normal(0.0, 0.01, n)
        Q[:, c] = unit.predict(V[:, c]) + 2e-10 * rng.uniform(0.5, 1.5) * np.cumsum(V[:, c]) / FS
    return t, V, Q


@pytest.fixture(scope="module")
def fleet() -> tuple[np.ndarray, ...]:
    return _fleet()


@pytest.fixture(scope="module")
def bank(fleet: tuple[np.ndarray, ...]) -> ph.ModelBank:
    t, V, Q = fleet
    return ph.ModelBank(ph.ActivePI(n_operators=8)).fit(V, Q, t=t)


def test_each_channel_is_the_model_of_its_column(
    fleet: tuple[np.ndarray, ...], bank: ph.ModelBank
) -> None:
    t, V, Q = fleet
    assert len(bank) == V.shape[1]
    for c in range(V.shape[1]):
        alone = ph.ActivePI(n_operators=8).fit(V[:, c], Q[:, c], t=t)
        np.testing.assert_array_equal(bank[c].weights_, alone.weights_)
        assert bank[c].growth_rate_ == alone.growth_rate_
        assert bank[c].nrmse_ == alone.nrmse_
    np.testing.assert_array_equal(bank.predict(V, t)[:, 2], bank[2].predict(V[:, 2], t=t))
    table = bank.summary()
    assert table["fitted"].all()
    assert (table["nrmse"] < 0.01).all()
    assert (table["integral"] > 0).all()  # every unit leaks
    assert ((table["width"] > 0.02) & (table["width"] < 0.5)).all()
    # tol: the same minimum of the same numbers (approx's default only tolerates printing)
    assert table["v_min"][0] == pytest.approx(V[:, 0].min())
    # slicing and picking give banks of the same models
    assert bank[1:3][0] is bank[1]
    assert [m is bank[i] for i, m in zip((4, 0), bank[[4, 0]], strict=True)] == [True, True]


def test_template_is_untouched_and_shapes_are_checked(fleet: tuple[np.ndarray, ...]) -> None:
    _t, V, Q = fleet
    template = ph.ClassicalPI(n_operators=4)
    ph.ModelBank(template).fit(V, Q)
    assert not template.is_fitted
    with pytest.raises(ph.ShapeError, match="2-D array"):
        ph.ModelBank(template).fit(V[:, 0], Q[:, 0])
    with pytest.raises(ph.ShapeError, match="same shape"):
        ph.ModelBank(template).fit(V, Q[:, :2])
    bad = Q.copy()
    bad[17, 3] = np.nan
    with pytest.raises(ph.NonFiniteError, match="sample 17, channel 3"):
        ph.ModelBank(template).fit(V, bad)
    with pytest.raises(ph.ParameterError, match="template"):
        ph.ModelBank("active-pi")  # type: ignore[arg-type]
    with pytest.raises(ph.NotFittedError, match="not fitted"):
        len(ph.ModelBank(template))


def test_a_dead_channel_is_named_or_skipped(fleet: tuple[np.ndarray, ...]) -> None:
    _t, V, Q = fleet
    V2 = V.copy()
    V2[:, 1] = 3.0  # disconnected: the input never moves
    with pytest.raises(ph.InsufficientDataError, match="channel 1: the input never moves"):
        ph.ModelBank(ph.ClassicalPI(4)).fit(V2, Q)
    bank = ph.ModelBank(ph.ClassicalPI(4)).fit(V2, Q, on_error="skip")
    assert list(bank.failed_) == [1]
    assert bank.fitted_channels == [0, 2, 3, 4]
    assert not bank.summary()["fitted"][1]
    assert np.isnan(bank.summary()["nrmse"][1])
    with pytest.raises(ph.NotFittedError, match="channel 1 was not fitted"):
        bank[1]
    with pytest.raises(ph.NotFittedError, match=r"channels \[1\] have no model"):
        ph.BankCompensator(bank, v_min=1.0, v_max=130.0)
    good = bank[bank.fitted_channels]
    assert len(good) == 4 and not good.failed_
    comp = ph.BankCompensator(good, v_min=1.0, v_max=130.0)
    assert comp.step(np.zeros(4)).shape == (4,)


@pytest.mark.parametrize("suffix", [".json", ".h5", ".npz"])
def test_files_round_trip(
    tmp_path: Path, fleet: tuple[np.ndarray, ...], bank: ph.ModelBank, suffix: str
) -> None:
    t, V, _ = fleet
    path = bank.save(tmp_path / f"bank{suffix}")
    again = ph.load_bank(path)
    assert len(again) == len(bank)
    assert type(again.template) is ph.ActivePI
    np.testing.assert_array_equal(again.predict(V, t), bank.predict(V, t))
    np.testing.assert_array_equal(again.summary()["nrmse"], bank.summary()["nrmse"])
    if suffix == ".h5":  # arrays a real-time computer or MATLAB reads without piezohyst
        import h5py

        with h5py.File(path) as f:
            np.testing.assert_array_equal(f["weights"][:], [m.weights_ for m in bank])
            assert f["thresholds"].shape == (5, 8)


def test_a_tampered_channel_is_named(tmp_path: Path, bank: ph.ModelBank) -> None:
    path = bank.save(tmp_path / "bank.json")
    data = json.loads(path.read_text())
    data["channels"][3]["fitted"]["core"]["weights"][0] *= 2
    path.write_text(json.dumps(data))
    with pytest.raises(ph.ModelFileError, match=r"channel 3: .*checksum"):
        ph.load_bank(path)
    with pytest.raises(ph.ModelFileError, match="not a piezohyst model bank"):
        (tmp_path / "x.json").write_text("{}")
        ph.load_bank(tmp_path / "x.json")
    with pytest.raises(ph.ModelFileError, match="not found"):
        ph.load_bank(tmp_path / "missing.h5")
    with pytest.raises(ph.ParameterError, match=r"\.json, \.h5"):
        bank.save(tmp_path / "bank.csv")


def _singles(bank: ph.ModelBank, **kw: object) -> list[ph.Compensator]:
    lows = np.broadcast_to(kw.pop("v_min"), len(bank))  # type: ignore[arg-type]
    highs = np.broadcast_to(kw.pop("v_max"), len(bank))  # type: ignore[arg-type]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return [
            ph.Compensator(m, v_min=float(lo), v_max=float(hi), **kw)  # type: ignore[arg-type]
            for m, lo, hi in zip(bank, lows, highs, strict=True)
        ]


def _desired(bank: ph.ModelBank, t: np.ndarray) -> np.ndarray:
    """Per-channel trajectories that reach beyond the limits and hold NaN gaps."""
    d = np.empty((t.size, len(bank)))
    for c, m in enumerate(bank):
        v = 60.0 + (55.0 + 10.0 * c) * np.sin(2 * np.pi * (2.0 + c) * t)
        d[:, c] = m.hysteresis_.predict(np.clip(v, 0.0, 140.0)) * 1.05
    d[100:103, 1] = np.nan
    d[400, -1] = np.inf
    return d


def test_bank_compensator_is_each_channels_compensator(bank: ph.ModelBank) -> None:
    t = np.arange(1500) / FS
    desired = _desired(bank, t)
    lows = np.array([1.0, 5.0, 1.0, 10.0, 1.0])
    settings = {"v_min": lows, "v_max": 130.0, "slew_rate": 2e4, "sample_rate": FS}
    comp = ph.BankCompensator(bank, **settings)  # type: ignore[arg-type]
    assert isinstance(comp, ph.BankCompensator) and comp.fused
    singles = _singles(bank, **settings)
    expected = np.column_stack([s.process(desired[:, c]) for c, s in enumerate(singles)])
    out = np.empty(len(bank))
    stepped = np.array([comp.step(row, out=out).copy() for row in desired])
    # tol: the fused bank kernel and each channel's own compensator are compiled apart (FASTMATH
    # reassociation/FMA) may round apart; a play state is a clamp, so nothing accumulates: 1e-12 V
    # is thousands of ulp of 140 V
    np.testing.assert_allclose(stepped, expected, rtol=0, atol=1e-12)
    assert ((stepped >= lows - 1e-12) & (stepped <= 130.0 + 1e-12)).all()
    np.testing.assert_array_equal(comp.nonfinite_count, [0, 3, 0, 0, 1])
    np.testing.assert_array_equal(comp.saturated_count, [s.saturated_count for s in singles])
    assert comp.saturated_count.sum() > 0
    # the channel's own compensator is live: same state as the bank
    assert comp.channel(2).last_command == stepped[-1, 2]
    comp.reset()
    # tol: the fused bank kernel and each channel's own compensator are compiled apart (FASTMATH
    # reassociation/FMA) may round apart; a play state is a clamp, so nothing accumulates: 1e-12 V
    # is thousands of ulp of 140 V
    np.testing.assert_allclose(comp.process(desired), expected, rtol=0, atol=1e-12)


@given(cuts=st.lists(st.integers(0, 600), max_size=5))
def test_bank_process_in_any_chunks(bank: ph.ModelBank, cuts: list[int]) -> None:
    t = np.arange(600) / FS
    desired = _desired(bank, t)
    comp = ph.BankCompensator(bank, v_min=1.0, v_max=130.0)
    whole = comp.process(desired)
    comp.reset()
    edges = [0, *sorted(cuts), 600]
    parts = [comp.process(desired[a:b]) for a, b in itertools.pairwise(edges)]
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_unfused_channels_run_their_own_compensators(fleet: tuple[np.ndarray, ...]) -> None:
    t, V, Q = fleet
    bank = ph.ModelBank(ph.GeneralizedPI(n_operators=6, growth_terms=("integral",), asymmetry=3))
    bank.fit(V[:, :3], Q[:, :3], t=t)
    comp = ph.BankCompensator(bank, v_min=1.0, v_max=130.0)
    assert not comp.fused  # asymmetry: a Newton solve per sample
    desired = _desired(bank, t[:500])
    singles = _singles(bank, v_min=1.0, v_max=130.0)
    expected = np.column_stack([s.process(desired[:, c]) for c, s in enumerate(singles)])
    np.testing.assert_array_equal(comp.process(desired), expected)


def test_bank_compensator_limits_and_inputs(bank: ph.ModelBank) -> None:
    with pytest.warns(UserWarning, match="narrowed on 5 of 5 channels"):
        comp = ph.BankCompensator(bank, v_min=-50.0, v_max=200.0)
    assert (comp.v_min >= 0.0 - 1.0).all() and (comp.v_max <= 141.0).all()
    with pytest.raises(ph.ShapeError, match=r"shape \(5,\)"):
        comp.step(np.zeros(4))
    with pytest.raises(ph.ShapeError, match=r"\(samples, 5\)"):
        comp.process(np.zeros(5))
    with pytest.raises(ph.ShapeError, match="one value per channel"):
        ph.BankCompensator(bank, v_min=np.zeros(3), v_max=130.0)
    with pytest.raises(ph.ParameterError, match=r"channel 0: .*v_min < v_max"):
        ph.BankCompensator(bank, v_min=100.0, v_max=100.0)
    comp = ph.BankCompensator(bank, v_min=1.0, v_max=130.0)
    cycle = comp.precondition(200)
    assert cycle.shape[1] == 5 and np.allclose(cycle.max(axis=0), comp.v_max)
    comp.reset(voltage=np.linspace(10.0, 50.0, 5))
    np.testing.assert_allclose(comp.last_command, np.linspace(10.0, 50.0, 5))


def test_bank_controller_is_each_channels_controller(bank: ph.ModelBank) -> None:
    t = np.arange(800) / FS
    desired = _desired(bank, t)
    rng = np.random.default_rng(5)
    # recorded charge: each unit's model with a 3 % gain error and noise, a dropout
    measured = np.column_stack(
        [1.03 * m.hysteresis_.predict(np.clip(60 + 50 * np.sin(7 * t), 0, 130)) for m in bank]
    ) + rng.normal(0.0, 1e-10, desired.shape)
    measured[300:305, 2] = np.nan
    settings = {"v_min": 1.0, "v_max": 130.0, "sample_rate": FS, "ki": 0.4, "kp": 0.1}
    ctl = ph.BankController(bank, **settings)  # type: ignore[arg-type]
    assert isinstance(ctl, ph.BankController) and len(ctl) == 5
    singles = [ph.SelfSensingController(m, **settings) for m in bank]  # type: ignore[arg-type]
    expected = np.column_stack(
        [s.process(desired[:, c], measured[:, c]) for c, s in enumerate(singles)]
    )
    out = np.empty(5)
    stepped = np.array(
        [ctl.step(d, q, out=out).copy() for d, q in zip(desired, measured, strict=True)]
    )
    # tol: bank and single-channel controllers, compiled apart, may round apart; the integrator adds
    # an ulp per sample: 1e-12 V bounds thousands of them
    np.testing.assert_allclose(stepped, expected, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ctl.measurement_faults, [0, 0, 5, 0, 0])
    assert ctl.channel(3).integral == singles[3].integral
    ctl.reset()
    # tol: bank and single-channel controllers, compiled apart, may round apart; the integrator adds
    # an ulp per sample: 1e-12 V bounds thousands of them
    np.testing.assert_allclose(ctl.process(desired, measured), expected, rtol=0, atol=1e-12)
    with pytest.raises(ph.ShapeError, match="one value per channel"):
        ctl.step(np.zeros(5), np.zeros(4))
    with pytest.raises(ph.ShapeError, match="one Leakage or one per channel"):
        ph.BankController(bank, leakage=[ph.Leakage()], **settings)  # type: ignore[arg-type]
