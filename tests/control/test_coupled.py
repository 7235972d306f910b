"""Coupled axes (issue 57, the static part): a stage of two actuators whose flexure couples
them, identified as one system (:class:`ph.CoupledModel`) and compensated together
(:class:`ph.CoupledCompensator`) on the simulated coupled stage."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.control.export import write_stage_c, write_stage_shared
from piezohyst.errors import IdentifiabilityWarning
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import XY_COUPLING, make_signal, simulate_stage

from ..helpers import CC
from . import hosts

FS = 1000.0


@pytest.fixture(scope="module")
def stage() -> tuple[ph.CoupledModel, np.ndarray]:
    """The model fitted on an identification record (each axis its own signal, at its own
    rate, over its whole range), and the linear voltage map fitted on the same record."""
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0.0, 140.0), b]), t, seed=0)
    model = ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)
    linear = np.linalg.lstsq(np.column_stack([rec.voltage, np.ones(t.size)]), rec.position,
                             rcond=None)[0]  # fmt: skip
    return model, linear


def test_the_coupling_is_identified(stage: tuple[ph.CoupledModel, np.ndarray]) -> None:
    model, _ = stage
    # tol: the cross terms within 0.005 of the truth (x moves y by 4 %, y x by -3 %): what
    # the per-axis models' misfit (0.2-0.35 % of the span) leaves in a least-squares coupling
    np.testing.assert_allclose(model.coupling_, XY_COUPLING, atol=5e-3)
    assert np.all(model.output_nrmse_ < 0.005)
    said = model.describe()
    assert "static coupling" in said and "ClassicalPI" in said


def _run(comp: ph.CoupledCompensator, desired: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    comp.reset()
    volts = comp.process(desired)
    t = np.arange(desired.shape[0]) / FS
    return volts, simulate_stage(volts, t, seed=5).true_position


def test_a_raster_is_compensated_and_the_held_axis_stays(
    stage: tuple[ph.CoupledModel, np.ndarray],
) -> None:
    """A 2 Hz triangle on x, y held mid-range: x tracks, y stays, where the linear voltage
    map (the same record, least squares) leaves x's hysteresis and y's cross-talk."""
    model, linear = stage
    comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS, slew_rate=None)
    (x0, x1), (y0, y1) = comp.reach
    k = np.arange(4000)
    x = x0 + (x1 - x0) * (0.2 + 0.6 * np.abs(((k / FS * 2.0) % 1.0) * 2 - 1))
    desired = np.column_stack([x, np.full(k.size, 0.5 * (y0 + y1))])
    volts, moved = _run(comp, desired)
    assert volts.min() >= 0.0 and volts.max() <= 140.0
    assert comp.saturated_count.tolist() == [0, 0] and comp.outside_count == 0
    lin_volts = np.clip((desired - linear[2]) @ np.linalg.inv(linear[:2]), 0.0, 140.0)
    lin = simulate_stage(lin_volts, k / FS, seed=5).true_position
    s = slice(1000, None)  # after the first half period from rest
    span_x = np.ptp(desired[s, 0])

    def track(p: np.ndarray) -> float:
        e = p[s, 0] - desired[s, 0]
        return float(np.sqrt(np.mean((e - e.mean()) ** 2))) / span_x

    def held(p: np.ndarray) -> float:
        return float(np.ptp(p[s, 1])) / (y1 - y0)

    # measured: x 0.78 % (linear map 7.6 %), y moves 0.09 % of its range (linear 2.0 %)
    assert track(moved) < 0.01 and track(lin) > 5 * track(moved)
    assert held(moved) < 0.005 and held(lin) > 0.015
    assert hysteresis_width(desired[s, 0], moved[s, 0]) < 0.3 * hysteresis_width(
        desired[s, 0], lin[s, 0]
    )


def test_a_lissajous_is_compensated(stage: tuple[ph.CoupledModel, np.ndarray]) -> None:
    model, linear = stage
    comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS, slew_rate=None)
    (x0, x1), (y0, y1) = comp.reach
    t = np.arange(4000) / FS
    fast, slow = np.sin(2 * np.pi * 1.5 * t), np.sin(2 * np.pi * 2 * t + 0.3)
    desired = np.column_stack(
        [x0 + (x1 - x0) * (0.5 + 0.3 * fast), y0 + (y1 - y0) * (0.5 + 0.3 * slow)]
    )
    _, moved = _run(comp, desired)
    lin_volts = np.clip((desired - linear[2]) @ np.linalg.inv(linear[:2]), 0.0, 140.0)
    lin = simulate_stage(lin_volts, t, seed=5).true_position
    s = slice(1000, None)
    for i in range(2):
        e, el = moved[s, i] - desired[s, i], lin[s, i] - desired[s, i]
        span = np.ptp(desired[s, i])
        nrmse, nrmse_lin = (float(np.sqrt(np.mean((r - r.mean()) ** 2))) / span for r in (e, el))
        # measured: 1.16 % and 0.30 % (linear map 8.8 % and 5.6 %)
        assert nrmse < 0.015 and nrmse_lin > 4 * nrmse, (i, nrmse, nrmse_lin)


def test_each_actuator_its_own_model() -> None:
    """Actuators of different physics, each with the model chosen for it: a Bouc-Wen and a
    Prandtl-Ishlinskii channel in one stage (the coupling is identified as well)."""
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t,
                         presets=("bouc-wen", "T226-H4-203X"), seed=0)  # fmt: skip
    model = ph.CoupledModel([ph.BoucWenModel(output_unit="m"), ph.ClassicalPI(10, output_unit="m")])
    model.fit(rec.voltage, rec.position, t=rec.t)
    assert [type(c).__name__ for c in model.channels_] == ["BoucWenModel", "ClassicalPI"]
    np.testing.assert_allclose(model.coupling_, XY_COUPLING, atol=5e-3)  # as on the bench
    assert model.output_nrmse_[0] < 0.002  # the Bouc-Wen actuator's own model: 0.01 %


def test_what_the_stage_cannot_reach_is_named(stage: tuple[ph.CoupledModel, np.ndarray]) -> None:
    """A corner inside each axis's own range can be outside the parallelogram the coupling
    makes of the actuators' ranges: named, counted, the commands at the limits."""
    model, _ = stage
    comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS, slew_rate=None)
    (_, x1), (y0, y1) = comp.reach
    corner = np.tile([[x1, y0]], (300, 1))  # x at its top needs y's actuator below its range
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        volts = comp.process(corner)
    messages = [str(w.message) for w in said if issubclass(w.category, ph.LimitWarning)]
    assert any("outside what the stage reaches" in m and "not a box" in m for m in messages)
    assert any(  # the actuator's own limits, the actuator named
        m.startswith("CoupledCompensator, actuator 0: the voltage limits [0, 140] V held 300")
        for m in messages
    ), messages
    assert comp.outside_count == 300
    assert volts.min() >= 0.0 and volts.max() <= 140.0
    nan = comp.step([np.nan, 0.5 * (y0 + y1)])  # NaN holds both actuators, counted
    np.testing.assert_array_equal(nan, volts[-1])
    assert comp.nonfinite_count.tolist() == [1, 1]


def test_inputs_that_move_together_are_said() -> None:
    """Both actuators driven by one signal: which moved which output is not in the record. The
    fit says which inputs move together, and stops where the coupling it gets is singular
    (it raised numpy's LinAlgError under one BLAS, and went on with rounding under another)."""
    t, a = make_signal("triangle", duration=4.0, frequency=1.0)
    rec = simulate_stage(np.column_stack([a, a]), t, seed=0)
    with (
        pytest.warns(IdentifiabilityWarning, match=r"inputs 0 and 1 move together \(.*1\.00"),
        pytest.raises(ph.ParameterError, match="cannot separate the actuators"),
    ):
        ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)


def test_what_the_coupled_model_refuses() -> None:
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 140, (50, 2))
    with pytest.raises(ph.ShapeError, match="row 3, column 1"):
        bad = u.copy()
        bad[3, 1] = np.nan
        ph.CoupledModel().fit(bad, u)
    with pytest.raises(ph.ShapeError, match=r"2 inputs, 1 outputs \(fewer outputs than"):
        ph.CoupledModel().fit(u, u[:, :1])
    with pytest.raises(ph.ParameterError, match="'rounds'"):
        ph.CoupledModel(rounds=0).fit(u, u)
    with pytest.raises(ph.ParameterError, match="holds 1 models for 2 inputs"):
        ph.CoupledModel([ph.ClassicalPI(4)]).fit(u, u)
    with pytest.raises(ph.ParameterError, match="one per input"):
        ph.CoupledModel([ph.ClassicalPI(4), "bouc-wen"]).fit(u, u)  # type: ignore[list-item]
    with pytest.raises(ph.NotFittedError):
        ph.CoupledModel().predict(u)
    with pytest.raises(ph.ParameterError, match=r"fitted ph\.CoupledModel"):
        ph.CoupledCompensator(ph.CoupledModel(), v_min=0.0, v_max=140.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = ph.CoupledModel().fit(u, u @ XY_COUPLING.T)
    with pytest.raises(ph.ParameterError, match="one per actuator"):
        ph.CoupledCompensator(model, v_min=[0.0, 0.0, 0.0], v_max=140.0)
    with pytest.raises(ph.ShapeError, match=r"\(samples, actuators\)"):
        simulate_stage(np.zeros(10))
    with pytest.raises(ph.ShapeError, match="'coupling'"):
        simulate_stage(np.zeros((10, 2)), coupling=np.eye(3))


def test_a_coupled_model_file_loads_and_predicts_as_written(
    stage: tuple[ph.CoupledModel, np.ndarray], tmp_path: Path
) -> None:
    model, _ = stage
    path = model.save(tmp_path / "stage.json")
    again = ph.CoupledModel.load(path)
    u = np.column_stack([np.linspace(0, 60, 500), np.linspace(140, 10, 500)])
    t = np.arange(500) / FS
    np.testing.assert_array_equal(again.predict(u, t=t), model.predict(u, t=t))
    assert again.describe() == model.describe()
    # the template it can be fitted again from, the estimator contract's clone
    twin = type(again)(**again.get_params())
    assert twin.get_params()["rounds"] == model.rounds and not hasattr(twin, "coupling_")
    data = json.loads(path.read_text())
    data["coupling"][0][1] = 0.5  # an edited coupling
    path.write_text(json.dumps(data))
    with pytest.raises(ph.ModelFileError, match="checksum"):
        ph.CoupledModel.load(path)
    with pytest.raises(ph.ModelFileError, match="not a piezohyst coupled model"):
        ph.CoupledModel.from_dict({"format": "piezohyst-model"})


@pytest.mark.skipif(CC is None, reason="no C compiler on this machine")
@pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning")  # out of reach on purpose
def test_the_stage_in_c_equals_python(
    stage: tuple[ph.CoupledModel, np.ndarray], tmp_path: Path
) -> None:
    """The coupled compensator's C (each actuator's step and the coupling's inverse) gives
    Python's commands and counts: a Lissajous, a stretch beyond the reach, NaN holds."""
    model, _ = stage
    comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS, slew_rate=2e4)
    paths = write_stage_c(comp, tmp_path / "ph_xy.c")
    assert [p.name for p in paths] == ["ph_xy.c", "ph_xy.h", "ph_xy_a0.c", "ph_xy_a0.h",
                                       "ph_xy_a1.c", "ph_xy_a1.h"]  # fmt: skip
    (x0, x1), _ = comp.reach
    desired = hosts.sines_in_reach(comp, 3000, (3, 2), 0.4, FS)
    desired[1000:1100, 0] = x1 + 0.2 * (x1 - x0)  # beyond x's reach
    desired[[1500, 2000], 1] = np.nan
    py = comp.process(desired)
    c_cmds, counts = hosts.run_stage_c(paths, desired, tmp_path)
    # tol: FASTMATH kernels against the C part by an ulp per step; a feedforward step does
    # not integrate it (the single channel's C holds 1e-12 V), so 1e-9 V bounds it with room
    np.testing.assert_allclose(c_cmds, py, rtol=0, atol=1e-9)
    # (the C's slew count includes the approach to the trajectory, Python's from it on)
    assert counts == [comp.outside_count, *comp.saturated_count.tolist(),
                      *comp.nonfinite_count.tolist()]  # fmt: skip
    assert comp.outside_count == 100 and comp.saturated_count[0] > 0
    assert comp.nonfinite_count.tolist() == [2, 2]


@pytest.mark.skipif(CC is None, reason="no C compiler on this machine")
@pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning")  # out of reach on purpose
def test_the_stage_as_a_shared_library_equals_python(
    stage: tuple[ph.CoupledModel, np.ndarray], tmp_path: Path
) -> None:
    """The stage's library through ctypes (as LabVIEW or MATLAB's loadlibrary call it): the
    commands of a raster equal Python's to 1e-9 V, the counts equal, a reset starts again."""

    model, _ = stage
    comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS, slew_rate=2e4)
    _, lib_path = write_stage_shared(comp, tmp_path / "ph_xy.c")
    (x0, x1), (y0, y1) = comp.reach
    k = np.arange(2000)
    tri = np.abs(((k / FS * 2.0) % 1.0) * 2 - 1)
    desired = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri), np.full(k.size, (y0 + y1) / 2)])
    desired[700:760, 1] = y1 + 0.3 * (y1 - y0)  # beyond y's reach
    desired[900, 0] = np.nan
    py = comp.process(desired)
    lib = hosts.stage_library(lib_path)
    handle = lib.ph_xy_new()
    target = np.ascontiguousarray(desired)
    volts = np.empty((k.size, 2))
    for _ in range(2):  # the second time after a reset: the same
        assert lib.ph_xy_process(handle, target.ctypes.data, volts.ctypes.data, k.size) == 0
        # tol: an ulp per step of a feedforward step (not integrated), as the C test above
        np.testing.assert_allclose(volts, py, rtol=0, atol=1e-9)
        counts = np.zeros(7, dtype=np.uint64)
        assert lib.ph_xy_counts(handle, counts.ctypes.data) == 0
        assert counts[0] == comp.outside_count == 60
        assert counts[[1, 4]].tolist() == comp.nonfinite_count.tolist() == [1, 1]
        assert counts[[2, 5]].tolist() == comp.saturated_count.tolist()
        lib.ph_xy_reset(handle)
    assert lib.ph_xy_process(handle, None, volts.ctypes.data, 1) == -1
    lib.ph_xy_free(handle)


THREE = hosts.THREE


@pytest.fixture(scope="module")
def three_sensors() -> ph.CoupledModel:
    return hosts.three_sensor_stage()


def test_more_sensors_than_actuators_is_a_least_squares(three_sensors: ph.CoupledModel) -> None:
    """Output i is actuator i's own axis, the third a further reading: the coupling is
    identified (3 x 2), a raster on x with y held tracks as the square stage's does, and a
    target off what the two actuators move the three outputs to is followed in least
    squares, counted and said."""
    model = three_sensors
    # tol: as the square stage's (the per-axis models' misfit in the least squares): 0.005
    np.testing.assert_allclose(model.coupling_, THREE, atol=5e-3)
    assert model.coupling_.shape == (3, 2) and np.all(model.output_nrmse_ < 0.005)
    comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=FS, slew_rate=None)
    (x0, x1), (y0, y1) = comp.reach
    k = np.arange(3000)
    tri = np.abs(((k / FS * 2.0) % 1.0) * 2 - 1)
    own = np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri), np.full(k.size, (y0 + y1) / 2)])
    desired = own @ model.coupling_.T + model.offset_  # every output's: on the plane
    volts = comp.process(desired)
    assert comp.outside_count == comp.off_plane_count == 0
    moved = simulate_stage(volts, np.arange(k.size) / FS, coupling=THREE, seed=5).true_position
    span = np.ptp(desired, axis=0)
    e = moved[1000:] - desired[1000:]  # offset-free, as the square stage's (the simulated
    error = np.std(e, axis=0) / span  # stage rests where its first command leaves it)
    # measured 0.76 / 1.45 / 0.75 % of each output's span (y's span is x's coupling alone,
    # 4 % of x's: its error is 0.06 % of x's span); the square stage's x: 0.78 %
    assert error[0] < 0.01 and error[2] < 0.01 and error[1] * span[1] < 0.002 * span[0]
    off = desired.copy()
    off[500:600, 2] += 0.02 * span[2]  # the third reading asked 2 % of its span off the plane
    comp.reset()
    said = r"100 desired positions lie off what the 2 actuators move the stage's 3 outputs"
    with pytest.warns(ph.LimitWarning, match=said + r" to \(first at sample 500\)"):
        nearest = comp.process(off)
    assert comp.off_plane_count == comp.outside_count == 100
    ls = np.linalg.lstsq(model.coupling_, (off - model.offset_).T, rcond=None)[0].T
    projected = ls @ model.coupling_.T + model.offset_  # the nearest position they give
    comp.reset()
    # tol: pinv against lstsq, the same least squares: rounding of ~1e-4 m through the
    # inverses (the lag-free PI inverse: no amplification), 1e-9 V
    np.testing.assert_allclose(nearest, comp.process(projected), rtol=0, atol=1e-9)


@pytest.mark.skipif(CC is None, reason="no C compiler on this machine")
@pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning")  # off the plane on purpose
def test_more_sensors_than_actuators_in_c_equals_python(
    three_sensors: ph.CoupledModel, tmp_path: Path
) -> None:
    """The stage's library with three outputs and two actuators: the least squares' commands
    equal Python's to 1e-9 V, and a target off the plane counts as out of reach in C too."""

    comp = ph.CoupledCompensator(three_sensors, v_min=0.0, v_max=140.0, sample_rate=FS,
                                 slew_rate=2e4)  # fmt: skip
    _, lib_path = write_stage_shared(comp, tmp_path / "ph_xy.c")
    own = hosts.sines_in_reach(comp, 2000, (3, 2), 0.35, FS)
    desired = own @ three_sensors.coupling_.T + three_sensors.offset_
    desired[400:450, 2] -= 0.05 * np.ptp(desired[:, 2])  # off the plane
    py = comp.process(desired)
    lib = hosts.stage_library(lib_path)
    handle = lib.ph_xy_new()
    volts = np.empty((2000, 2))
    target = np.ascontiguousarray(desired)
    assert lib.ph_xy_process(handle, target.ctypes.data, volts.ctypes.data, 2000) == 0
    # tol: an ulp per step of a feedforward step (not integrated), as the square stage's C
    np.testing.assert_allclose(volts, py, rtol=0, atol=1e-9)
    counts = np.zeros(7, dtype=np.uint64)
    assert lib.ph_xy_counts(handle, counts.ctypes.data) == 0
    assert counts[0] == comp.outside_count == comp.off_plane_count == 50
    lib.ph_xy_free(handle)
