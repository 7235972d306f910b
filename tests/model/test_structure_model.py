"""StructureModel: coupled linear dynamics identified in state space (an order chosen by
held-out records), each actuator's hysteresis in the loop; its kernel against a pure-Python
reference over generated structures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst.model import structure_fit as sf

from .. import reference
from ..strategies import examples, random_structure

pytestmark = pytest.mark.kernels

FS = 1000.0


def _plant(e_gain: float = 0.0, outputs: int = 3) -> sf.Structure:
    """Two actuators, two shared modes (|poles| 0.9 and 0.85), ``outputs``
    outputs read; with ``e_gain`` each actuator's play operators (its stroke's lag) act on
    the modes (a stiffness that depends on how far it moved)."""
    rot = lambda rad, th: rad * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])  # noqa: E731
    a = np.zeros((4, 4))
    a[:2, :2], a[2:, 2:] = rot(0.9, 0.5), rot(0.85, 1.1)
    b = np.array([[1.0, 0.2], [0.0, 0.3], [0.1, 1.0], [0.4, 0.0]])
    c = np.array([[1.0, 0.0, 0.3, 0.1], [0.2, 0.1, 1.0, 0.0], [0.5, 0.2, 0.5, 0.3]])[:outputs]
    d = np.zeros((outputs, 2))
    d[0, 0], d[-1, 1] = 0.05, -0.04
    t = np.linalg.pinv(d + c @ np.linalg.solve(np.eye(4) - a, b))
    r = np.array([[0.3, 1.0], [0.2, 0.8]])
    e = e_gain * np.array([[1.0, 0.5, 0.0, 0.0], [0.3, 0.0, 0.0, 0.2], [0.0, 0.0, 1.0, 0.6],
                           [0.0, 0.2, 0.4, 0.0]])  # fmt: skip
    return sf.Structure(a, b, c, d, e, t, r, np.array([0.5, -0.2, 0.1])[:outputs])


def _periodic(rng: np.random.Generator, n: int, level: float) -> np.ndarray:
    """One period of a random-phase multisine per input (every line but 0 and n/2), RMS
    ``level``."""
    spec = np.zeros((n // 2 + 1, 2), dtype=complex)
    spec[1 : n // 2] = np.exp(2j * np.pi * rng.random((n // 2 - 1, 2)))
    u = np.fft.irfft(spec, n=n, axis=0)
    return np.asarray(level * u / u.std(axis=0))


def test_the_kernel_equals_the_reference() -> None:
    @settings(max_examples=examples(25), deadline=None)
    @given(st.integers(0, 2**32 - 1), st.integers(1, 40))
    def check(seed: int, n: int) -> None:
        rng = np.random.default_rng(seed)
        a, (*mats, r, off) = random_structure(rng)
        v = rng.standard_normal((n, mats[0].shape[1]))
        want = reference.structure(a.tolist(), *[x.tolist() for x in mats], r.tolist(),
                                   off.tolist(), v.tolist())  # fmt: skip
        got = sf.Structure(a, *mats, r, off).run(v, periodic=False)
        # tol: a few roundings per sample through a contracting state (|a| < 1 on average)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)

    check()


def test_a_linear_structure_from_rest_is_found_with_its_order() -> None:
    rng = np.random.default_rng(1)
    plant = _plant(outputs=3)
    u = [rng.standard_normal((600, 2)) for _ in range(4)]
    y = [plant.run(v, periodic=False) for v in u]
    model = ph.StructureModel(operators=0).fit(u, y, sample_rate=FS)
    assert model.order_ == 4  # the smallest order that holds the held-out records
    assert model.orders_[2] > 100 * model.orders_[4]
    fresh = rng.standard_normal((800, 2))
    want = plant.run(fresh, periodic=False)
    err = np.abs(model.predict(fresh) - want).max() / np.ptp(want, axis=0).min()
    # tol: the impulse response's ridge (1e-9 of the trace) and its 150 lags' truncation
    # (the tail past them, 0.9^150 / 0.1 = 1.4e-6 of the first lag, biases the poles)
    assert err < 1e-4
    assert "order 4 (chosen from" in model.describe()
    assert "no operators in the loop" in model.describe()


def test_periodic_records_in_their_steady_state() -> None:
    rng = np.random.default_rng(2)
    plant = _plant(outputs=2)
    u = [_periodic(rng, 256, 1.0) for _ in range(4)]
    y = [plant.run(v, periodic=True) for v in u]
    model = ph.StructureModel(order=4, operators=0).fit(
        u, y, sample_rate=FS, initial_state="periodic"
    )
    fresh = _periodic(rng, 256, 1.0)
    want = plant.run(fresh, periodic=True)
    got = model.predict(fresh, state="periodic")
    # tol: 0 Hz and half the sample rate, which the multisine leaves out, held at the
    # nearest line's response (off by its change over one line: 2e-5 of the impulse
    # response at every lag, 7e-6 of the span here); a period's transient is 0.9^256
    np.testing.assert_allclose(got, want, atol=1e-4 * np.ptp(want))
    assert model.orders_ == {}
    assert "order 4 (stated)" in model.describe()


@pytest.fixture(scope="module")
def looped() -> tuple[ph.StructureModel, sf.Structure, np.random.Generator]:
    """A structure whose modes feel its actuators' hysteresis, at three drive levels."""
    rng = np.random.default_rng(3)
    plant = _plant(e_gain=0.08, outputs=2)
    u = [_periodic(rng, 512, level) for level in (0.5, 1.0, 1.5) for _ in range(4)]
    y = [plant.run(v, periodic=True) for v in u]
    model = ph.StructureModel(order=4).fit(u, y, sample_rate=FS, initial_state="periodic")
    return model, plant, rng


def test_hysteresis_in_the_loop_is_kept_where_it_predicts(looped) -> None:  # type: ignore[no-untyped-def]
    model, plant, rng = looped
    assert model.operators_ == 6
    held = model.held_nrmse_
    assert held["operators"] < 0.5 * held["linear"]
    linear = ph.StructureModel(order=4, operators=0)
    u = [_periodic(rng, 512, level) for level in (0.5, 1.0, 1.5) for _ in range(4)]
    linear.fit(
        u, [plant.run(v, periodic=True) for v in u], sample_rate=FS, initial_state="periodic"
    )
    for level in (0.5, 1.5):  # fresh inputs at the ends of the levels
        fresh = _periodic(rng, 512, level)
        want = plant.run(fresh, periodic=True)
        ours = np.std(model.predict(fresh, state="periodic") - want)
        lin = np.std(linear.predict(fresh, state="periodic") - want)
        assert ours < 0.8 * lin  # the operators' widths are a grid, not the plant's own
    assert "6 play operators per actuator in the loop" in model.describe()


def test_operators_that_do_not_predict_are_not_kept() -> None:
    rng = np.random.default_rng(4)
    plant = _plant(outputs=2)  # linear: the operators can only fit the noise
    u = [_periodic(rng, 256, 1.0) for _ in range(4)]  # draws as the other seeds' tests
    u = [rng.standard_normal((300, 2)) for _ in range(2)]
    y = [plant.run(v, periodic=False) + 0.05 * rng.standard_normal((300, 2)) for v in u]
    model = ph.StructureModel(order=4).fit(u, y, sample_rate=FS)
    assert model.operators_ == 0
    assert model.held_nrmse_["operators"] > model.held_nrmse_["linear"]
    assert "did not predict the held-out records better" in model.describe()
    again = ph.StructureModel.from_dict(model.to_dict())
    assert again.describe() == model.describe()


def test_files_round_trip(looped, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    model, _, rng = looped
    path = model.save(tmp_path / "mirror.json")
    again = ph.StructureModel.load(path)
    v = _periodic(rng, 512, 1.0)
    np.testing.assert_array_equal(again.predict(v), model.predict(v))
    assert again.describe() == model.describe()
    path.write_text(path.read_text().replace('"sample_rate": 1000.0', '"sample_rate": 999.0'))
    with pytest.raises(ph.errors.ModelFileError, match="checksum"):
        ph.StructureModel.load(path)


def test_the_estimator_contract() -> None:
    from sklearn.base import clone

    model = ph.StructureModel(order=8, operators=3, widths=(0.01, 0.2))
    twin = clone(model)
    assert twin.get_params() == model.get_params()
    assert repr(model) == "StructureModel(order=8, operators=3, widths=(0.01, 0.2))"
    assert twin.set_params(order="auto").order == "auto"
    with pytest.raises(
        ph.errors.ParameterError, match="Invalid parameter 'rank' for StructureModel"
    ):
        twin.set_params(rank=2)
    with pytest.raises(ph.errors.NotFittedError, match="not fitted"):
        model.predict(np.zeros((10, 2)))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"order": 0}, "'order' must be a positive integer or 'auto'"),
        ({"operators": -1}, "'operators' must be an integer in"),
        ({"widths": (0.5, 0.1)}, "'widths' must be (smallest, largest)"),
    ],
)
def test_bad_parameters_are_named(kwargs, message) -> None:  # type: ignore[no-untyped-def]
    u = np.zeros((100, 2))
    with pytest.raises(
        ph.errors.ParameterError, match=message.replace("(", r"\(").replace(")", r"\)")
    ):
        ph.StructureModel(**kwargs).fit(u, u, sample_rate=FS)


def test_bad_records_are_named() -> None:
    rng = np.random.default_rng(5)
    u = [rng.standard_normal((100, 2)) for _ in range(2)]
    y = [v.copy() for v in u]
    y[1][5, 1] = np.nan
    with pytest.raises(
        ph.errors.ShapeError, match="record 1: 'y' holds a non-finite value at row 5, column 1"
    ):
        ph.StructureModel().fit(u, y, sample_rate=FS)
    with pytest.raises(ph.errors.ParameterError, match="give two or more periodic records"):
        ph.StructureModel().fit(u[0], y[0], sample_rate=FS, initial_state="periodic")
    with pytest.raises(ph.errors.ParameterError, match="give the records' time stamps"):
        ph.StructureModel().fit(u[0], u[0])
    t = [np.arange(100) / FS, np.arange(100) / (2 * FS)]
    with pytest.raises(ph.errors.ShapeError, match="sampled at different rates"):
        ph.StructureModel().fit(u, [v.copy() for v in u], t=t)
    with pytest.raises(ph.errors.ShapeError, match="different numbers of inputs or outputs"):
        ph.StructureModel().fit(u, [u[0], u[1][:, :1]], sample_rate=FS)
    same = rng.standard_normal((256, 1)) @ np.ones((1, 2))  # two inputs that move together
    with pytest.raises(ph.errors.ParameterError, match="cannot separate the 2 inputs"):
        ph.StructureModel(order=2).fit([same, same], [same, same], sample_rate=FS,
                                       initial_state="periodic")  # fmt: skip


def test_predict_holds_to_the_fit_rate(looped) -> None:  # type: ignore[no-untyped-def]
    model, _, _ = looped
    v = np.zeros((64, 2))
    with pytest.raises(ph.errors.ShapeError, match="identified at 1000 Hz"):
        model.predict(v, t=np.arange(64) / 2000.0)
    with pytest.raises(ph.errors.ShapeError, match="must have 2 columns"):
        model.predict(np.zeros((64, 3)))


def test_the_adjoint_gradient_equals_finite_differences() -> None:
    """The output-error refinement's gradient (reverse mode through the play operators)
    against central differences of the same loss: every matrix and the stroke map, and the
    dynamics a drive's level schedules, from a given start (the operators' states 0,
    whatever the stroke map)."""
    from piezohyst._kernels import structure as S

    rng = np.random.default_rng(6)
    n, ni, m, na, nk, length = 4, 2, 2, 2, 3, 300
    a = 0.3 * rng.standard_normal((n, n))
    mats = [rng.standard_normal(s) for s in [(n, ni), (m, n), (m, ni)]]
    e = 0.3 * rng.standard_normal((n, na * nk))
    t, r = rng.standard_normal((na, m)), np.abs(rng.standard_normal((na, nk)))
    off, v, y = (
        rng.standard_normal(m),
        rng.standard_normal((length, ni)),
        rng.standard_normal((length, m)),
    )
    a1, b1 = 0.2 * rng.standard_normal((n, n)), rng.standard_normal((n, ni))
    e1, rho = 0.2 * rng.standard_normal((n, na * nk)), 0.5 * rng.standard_normal(length)

    def run(p: list[np.ndarray]) -> tuple[float, list[np.ndarray]]:
        aa, b, c, d, ee, tt, aa1, bb1, ee1 = (np.ascontiguousarray(x) for x in p)
        x, z = np.zeros(n), np.zeros((na, nk))
        out, xs, ps = np.empty((length, m)), np.empty((length, n)), np.empty((length, na * nk))
        moved = np.zeros((length, na * nk), dtype=np.bool_)
        sched = (rho, aa1, bb1, ee1)
        S.structure_trace(aa, b, c, d, ee, tt, r, off, *sched, x, z, v, out, xs, ps, moved)
        grads = [np.zeros_like(q) for q in (aa, b, c, d, ee, tt, aa1, bb1, ee1)]
        ga, gb, gc, gd, ge, gt, ga1, gb1, ge1 = grads
        gy = np.ascontiguousarray(out - y)
        S.structure_adjoint(aa, c, ee, tt, nk, rho, aa1, ee1, xs, ps, moved, v, out, gy, ga, gb,
                            gc, gd, ge, np.zeros(m), gt, ga1, gb1, ge1)  # fmt: skip
        return 0.5 * float(np.sum((out - y) ** 2)), grads

    params = [a, *mats, e, t, a1, b1, e1]
    _, grads = run(params)
    for k, p in enumerate(params):
        for idx in [tuple(rng.integers(0, s) for s in p.shape) for _ in range(3)]:
            up, down = [q.copy() for q in params], [q.copy() for q in params]
            up[k][idx] += 1e-6
            down[k][idx] -= 1e-6
            fd = (run(up)[0] - run(down)[0]) / 2e-6
            # tol: central differences, step 1e-6: truncation ~1e-12 of the loss's curvature,
            # rounding ~1e-10 / 1e-6 of a loss near 1e3; no operator switches within the step
            assert abs(grads[k][idx] - fd) <= 1e-5 * max(1.0, abs(fd))


def test_the_output_error_refinement_lowers_the_error(looped) -> None:  # type: ignore[no-untyped-def]
    model, plant, rng = looped
    ref = model.refinement_
    assert ref is not None and ref.kept and ref.after < ref.before and ref.iterations > 0
    assert "refined by output error" in model.describe()
    raw = ph.StructureModel(order=4, refine=False)
    u = [_periodic(rng, 512, level) for level in (0.5, 1.0, 1.5) for _ in range(4)]
    y = [plant.run(v, periodic=True) for v in u]
    raw.fit(u, y, sample_rate=FS, initial_state="periodic")
    assert raw.refinement_ is None
    fresh = [_periodic(rng, 512, level) for level in (0.5, 1.0, 1.5)]
    want = [plant.run(v, periodic=True) for v in fresh]
    err = [
        sum(
            float(np.std(m.predict(v, state="periodic") - w))
            for v, w in zip(fresh, want, strict=True)
        )
        for m in (model, raw)
    ]
    assert err[0] < err[1]  # on inputs neither saw


def test_long_records_are_solved_a_few_rows_at_a_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows built in chunks (each mode's filter state carried across them) give the least
    squares of all the rows at once: any length fits in memory."""
    rng = np.random.default_rng(7)
    plant = _plant(e_gain=0.05, outputs=2)
    given = [(rng.standard_normal((3000, 2)), False), (_periodic(rng, 2048, 1.0), True)]
    recs = [sf.Record(v, plant.run(v, periodic=p), p) for v, p in given]
    r = np.array([[0.1, 0.5], [0.2, 0.6]])
    whole = sf.least_squares(recs[:1], plant.a, plant.c, plant.t, r)
    whole_p = sf.least_squares(recs[1:], plant.a, plant.c, plant.t, r)
    monkeypatch.setattr(sf, "CHUNK", 700)
    parts = sf.least_squares(recs[:1], plant.a, plant.c, plant.t, r)
    parts_p = sf.least_squares(recs[1:], plant.a, plant.c, plant.t, r)
    for one, other in ((whole, parts), (whole_p, parts_p)):
        for name in ("b", "d", "e", "off"):
            # tol: the normal equations summed in another order (rounding), then solved with a
            # condition number near 1e6
            np.testing.assert_allclose(
                getattr(other, name), getattr(one, name), rtol=1e-8, atol=1e-9
            )


def test_scikit_learn_sees_a_fitted_model_of_several_channels(looped) -> None:  # type: ignore[no-untyped-def]
    from sklearn.exceptions import NotFittedError
    from sklearn.utils.validation import check_is_fitted

    model, _, _ = looped
    check_is_fitted(model)
    for fresh in (ph.StructureModel(), ph.CoupledModel()):
        with pytest.raises(NotFittedError):
            check_is_fitted(fresh)
        tags = fresh.__sklearn_tags__()
        assert tags.input_tags.two_d_array and tags.target_tags.multi_output


def _steady_sine(structure: sf.Structure, f: float, amp: float) -> np.ndarray:
    """The outputs' complex amplitude (outputs,) in the steady state of a sine of ``amp`` V
    at ``f`` Hz on the first input (the last 1000 samples, whole periods)."""
    k = np.arange(3000)
    v = np.zeros((k.size, 2))
    v[:, 0] = amp * np.sin(2 * np.pi * f * k / FS)
    y = structure.run(v, periodic=False)[-1000:]
    y = y - y.mean(axis=0)
    basis = np.exp(2j * np.pi * f * k[-1000:] / FS)
    return np.asarray(2j * (basis.conj() @ y) / 1000 / amp)  # sin = Im(e^{jwt}): G e^{jwt}


def test_the_frequency_response_is_what_a_sine_drives() -> None:
    """``frequency_response`` against a simulated sine's steady state: small strokes (all
    operators stuck: their lag feeds each stroke back) and large ones (all sliding: a
    constant lag, the loop open); ``modes`` are the poles' own."""
    plant = _plant(e_gain=0.08, outputs=2)
    model = ph.StructureModel(order=4)
    model.structure_, model.sample_rate_ = plant, FS
    for f in (20.0, 50.0, 125.0):  # whole periods in 1000 samples
        # 0.01 V: each stroke moves about 0.01, inside the narrowest operator (0.2 each side)
        small = model.frequency_response([f], strokes="small")[0][:, 0]
        # tol: the transient left after 2000 samples (|poles| < 0.95: < 1e-40) and rounding
        np.testing.assert_allclose(_steady_sine(plant, f, 0.01), small, rtol=1e-9)
        sliding = sf.Structure(plant.a, plant.b, plant.c, plant.d, plant.e, plant.t,
                               1e-9 * plant.r, plant.off)  # fmt: skip
        large = model.frequency_response([f], strokes="large")[0][:, 0]
        # tol: the sliding operators' lag is +-1e-9 (their width), through E (0.08): a
        # few 1e-10 of the 1 V sine's response
        np.testing.assert_allclose(_steady_sine(sliding, f, 1.0), large, rtol=1e-7)
        assert np.max(np.abs(small - large)) > 0.01 * np.max(np.abs(large))  # they differ
    # the plant's poles: 0.9 e^{+-0.5j}, 0.85 e^{+-1.1j}
    want = sorted(
        (abs(s) * FS / (2 * np.pi), -s.real / abs(s))
        for s in (np.log(0.9) + 0.5j, np.log(0.85) + 1.1j)
    )
    # tol: the eigenvalues of a 4 x 4 matrix, to rounding
    np.testing.assert_allclose(model.modes(), want, rtol=1e-10)
    assert model.modes(strokes="small") != model.modes()
    with pytest.raises(ph.errors.ParameterError, match="'strokes' must be"):
        model.modes(strokes="medium")
    with pytest.raises(ph.errors.ParameterError, match="half the sample rate"):
        model.frequency_response([600.0])
    with pytest.raises(ph.errors.NotFittedError):
        ph.StructureModel().frequency_response([1.0])


def test_a_loop_unstable_where_its_operators_stick_is_not_kept() -> None:
    """A passive structure at rest is stable: a model whose loop, with every operator stuck
    (a small drive's linear end), has a pole outside the unit circle rings by itself. Here
    the plant itself is such a loop (E's sign flipped). The refinement keeps the model's
    stuck poles within STUCK_RADIUS (a penalty) and still predicts better than the linear
    dynamics; without the refinement, the least squares' loop is unstable stuck, and the
    linear dynamics are kept instead, said in ``describe``."""
    rng = np.random.default_rng(3)
    plant = _plant(e_gain=-0.3, outputs=2)
    assert plant.radius() > 1.1 and np.max(np.abs(np.linalg.eigvals(plant.a))) < 1
    u = [_periodic(rng, 512, level) for level in (0.5, 1.0, 1.5) for _ in range(4)]
    y = [plant.run(v, periodic=True) for v in u]
    model = ph.StructureModel(order=4).fit(u, y, sample_rate=FS, initial_state="periodic")
    assert model.operators_ == 6 and model.unstable_stuck_ is None
    # tol: the penalty is soft: its excess squared times 100 against the error's decrease
    assert model.structure_.radius() < sf.STUCK_RADIUS + 1e-3
    assert model.output_nrmse_ < 0.5 * model.held_nrmse_["linear"]
    plain = ph.StructureModel(order=4, refine=False)
    plain.fit(u, y, sample_rate=FS, initial_state="periodic")
    assert plain.held_nrmse_["operators"] < 0.8 * plain.held_nrmse_["linear"]
    assert plain.operators_ == 0 and plain.unstable_stuck_ is not None
    assert plain.unstable_stuck_ > 1.0 and plain.structure_.radius() < 1.0
    assert "unstable where every operator sticks (small strokes; a pole of modulus" in (
        plain.describe()
    )
    again = ph.StructureModel.from_dict(plain.to_dict())
    assert again.describe() == plain.describe()
    # a refinement kept for its stable loop though its error is above the unstable start's
    model.refinement_ = sf.Refinement(1.0, 1.68, 10, True)
    said = model.describe()
    assert "68 % more squared error than the least squares' loop, which was unstable" in said
    first = model.modes()[0]  # the modes said beside it, their own words
    assert f"modes (damping) {first[0]:.4g} Hz ({first[1]:.2g})" in said


def test_the_stuck_penalty_s_gradient_equals_finite_differences() -> None:
    """The refinement's penalty on the stuck loop's poles: its gradient (the eigenvalues'
    first-order perturbation, through ``a - E' t c``) against central differences."""
    st = _plant(e_gain=-0.3, outputs=2)
    nk = st.r.shape[1]
    blocks = {"a": st.a, "c": st.c, "e": st.e, "t": st.t}

    def value(**given: np.ndarray) -> tuple[float, list[np.ndarray]]:
        grads = [np.zeros(x.shape) for x in (st.a, st.b, st.c, st.d, st.e, st.off, st.t)]
        args = {**blocks, **given}
        return sf.stuck_penalty(args["a"], args["c"], args["e"], args["t"], nk, grads), grads

    total, grads = value()
    assert total > 0  # the plant's stuck loop is past the radius
    rng = np.random.default_rng(0)
    for name, k in (("a", 0), ("c", 2), ("e", 4), ("t", 6)):
        step = rng.standard_normal(blocks[name].shape)
        h = 1e-6
        up = value(**{name: blocks[name] + h * step})[0]
        down = value(**{name: blocks[name] - h * step})[0]
        # tol: central differences' truncation (h^2 times the third derivative) and the
        # penalty's rounding over 2h (1e-16 * 4.5 / 1e-6): 1e-6 relative
        assert (up - down) / (2 * h) == pytest.approx(np.sum(grads[k] * step), rel=1e-6)


def test_the_scheduled_kernel_equals_a_plain_loop() -> None:
    """``x+ = a x + b v + e p + rho (a1 x + b1 v + e1 p)`` sample by sample, written out with
    NumPy, against the kernel over generated structures and levels."""

    @settings(max_examples=examples(15), deadline=None)
    @given(st.integers(0, 2**32 - 1), st.integers(1, 40))
    def check(seed: int, n: int) -> None:
        rng = np.random.default_rng(seed)
        a, (b, c, d, e, t, r, off) = random_structure(rng)
        a1 = 0.3 * rng.standard_normal(a.shape)
        b1, e1 = rng.standard_normal(b.shape), rng.standard_normal(e.shape)
        v, rho = rng.standard_normal((n, b.shape[1])), 0.5 * rng.standard_normal(n)
        x, z = np.zeros(a.shape[0]), np.repeat((t @ off)[:, None], r.shape[1], axis=1)
        want = []
        for k in range(n):
            y = c @ x + d @ v[k] + off
            s = t @ y
            z = np.clip(z, s[:, None] - r, s[:, None] + r)
            p = (z - s[:, None]).ravel()
            x = a @ x + b @ v[k] + e @ p + rho[k] * (a1 @ x + b1 @ v[k] + e1 @ p)
            want.append(y)
        from piezohyst._kernels import structure as S

        got = np.empty((n, c.shape[0]))
        S.structure_run(a, b, c, d, e, t, r, off, rho, a1, b1, e1, np.zeros(a.shape[0]),
                        np.repeat((t @ off)[:, None], r.shape[1], axis=1), v, got)  # fmt: skip
        # tol: a few roundings per sample through a contracting state (|a| < 1 on average,
        # the schedule adding at most half of a1's)
        np.testing.assert_allclose(got, np.array(want), rtol=1e-9, atol=1e-9)

    check()


def _levelled() -> sf.Structure:
    """:func:`_plant` whose poles grow 8 % per unit of the drive's level over 1.4 (its
    stiffness falls the harder it is driven)."""
    p = _plant(outputs=2)
    sched = sf.Schedule(0.08 * p.a, np.zeros_like(p.b), np.zeros_like(p.e), 1.4, 50.0, -1.0,
                        np.inf)  # fmt: skip
    return sf.Structure(p.a, p.b, p.c, p.d, p.e, p.t, p.r, p.off, sched)


def test_dynamics_that_follow_the_drive_level_are_scheduled() -> None:
    """Records at three levels of a structure whose modes move with the level: one linear
    model for all of them leaves 9-11 % at levels between and beside them; scheduled by the
    level (the inputs' running RMS), 0.5-0.8 % (measured), said in ``describe``. Records at
    one level are not scheduled."""
    rng = np.random.default_rng(4)
    plant = _levelled()
    u = [_periodic(rng, 512, level) for level in (0.5, 1.0, 1.5) for _ in range(4)]
    y = [plant.run(v, periodic=True) for v in u]
    kw = {"sample_rate": FS, "initial_state": "periodic"}
    fitted = {s: ph.StructureModel(order=4, operators=0, scheduled=s).fit(u, y, **kw)
              for s in (True, False)}  # fmt: skip
    for level in (0.75, 1.25):
        v = _periodic(rng, 512, level)
        want = plant.run(v, periodic=True)
        err = {s: float(np.mean(np.sqrt(np.mean((m.predict(v, state="periodic") - want) ** 2,
                                                axis=0)) / np.std(want, axis=0)))
               for s, m in fitted.items()}  # fmt: skip
        # measured: 0.54 / 0.82 % scheduled against 9.4 / 11.4 % (the level's reach)
        assert err[True] < 0.015 and err[False] > 0.05
    said = fitted[True].describe()
    assert "scheduled by the drive's level (the inputs' RMS over 0.1 s" in said
    assert fitted[True].structure_.schedule is not None
    assert fitted[False].structure_.schedule is None and "scheduled" not in fitted[False].describe()
    one = [_periodic(rng, 512, 1.0) for _ in range(4)]
    m1 = ph.StructureModel(order=4, operators=0).fit(
        one, [plant.run(v, periodic=True) for v in one], **kw
    )
    assert m1.schedule_refinement_ is None and m1.structure_.schedule is None
    # the compensator inverts the structure at a level (default the records' mean), said bad
    comp = ph.StructureCompensator(fitted[True], v_min=-10.0, v_max=10.0, level=1.0)
    assert comp.preview > 0
    with pytest.raises(ph.errors.ParameterError, match="'level' must be a positive RMS"):
        ph.StructureCompensator(fitted[True], v_min=-10.0, v_max=10.0, level=-1.0)
