"""StructureCompensator (issue 57): a structure's inverse through its shared modes, the
tracker with preview of a StructureModel; on a structure whose zeros lie outside the unit
circle (no stable plain inverse), with each actuator's operators in the loop; its kernel
against a pure-Python reference."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import given, settings
from hypothesis import strategies as st

import piezohyst as ph
from piezohyst._kernels import play as K
from piezohyst._kernels import structure as S
from piezohyst.errors import LimitWarning, ParameterError, ShapeError

from .. import reference
from ..helpers import CC
from ..strategies import examples, random_structure
from .structures import error, model_of, raster, structure

pytestmark = pytest.mark.kernels

FS = 1000.0


def test_the_kernel_equals_the_reference() -> None:
    @settings(max_examples=examples(25), deadline=None)
    @given(st.integers(0, 2**32 - 1), st.integers(1, 30))
    def check(seed: int, n: int) -> None:
        rng = np.random.default_rng(seed)
        a, (*mats, r, off) = random_structure(rng)
        order, ni = a.shape[0], mats[0].shape[1]
        k = r.shape[1]
        gain = rng.standard_normal((ni, order))
        ff = 2 * rng.standard_normal((n, ni))
        hold = rng.random(n) < 0.2
        lo, hi = -rng.random(ni) - 0.5, rng.random(ni) + 0.5
        step = np.where(rng.random(ni) < 0.5, np.inf, 0.3)
        slack = np.full(ni, 0.1)
        want_cmd, want_past = reference.structure_compensate(
            [a.tolist(), *[x.tolist() for x in mats], r.tolist()], off.tolist(), gain.tolist(),
            ff.tolist(), hold.tolist(), lo.tolist(), hi.tolist(), step.tolist(), slack.tolist(),
        )  # fmt: skip
        x = np.zeros(order)
        z = np.repeat((mats[4] @ off)[:, None], k, axis=1)
        last = np.zeros(ni)
        tally = np.zeros((ni, K.TALLY_SIZE))
        tally[:, K.TALLY_TOL], tally[:, K.TALLY_LOW], tally[:, K.TALLY_HIGH] = np.inf, lo, hi
        cmd, past = np.empty((n, ni)), np.empty(n, dtype=bool)
        S.structure_compensate(a, *mats, r, off, gain, ff, hold, lo, hi, step, slack, x, z,
                               last, tally, cmd, past)  # fmt: skip
        # tol: a few roundings per sample through a contracting state (|a| < 1 on average)
        np.testing.assert_allclose(cmd, want_cmd, rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(past, want_past)
        assert np.all((cmd >= lo) & (cmd <= hi))
        at = (cmd <= lo) | (cmd >= hi)
        counted = tally[:, K.TALLY_AT_LOW] + tally[:, K.TALLY_AT_HIGH]
        np.testing.assert_array_equal(counted, at.sum(axis=0))

    check()


def test_zeros_outside_the_circle_are_met_by_preview() -> None:
    """The structure's zeros lie outside the unit circle (a plain inverse has unstable
    poles there); with its preview the tracker follows a raster through the modes and the
    operators to rounding, without it (targets taken to hold) by about a per cent."""
    plant = structure()
    pencil = np.block([[plant.a, plant.b], [plant.c, plant.d]])
    rest = np.block([[np.eye(4), np.zeros((4, 2))], [np.zeros((2, 6))]])
    zeros = sl.eigvals(pencil, rest)
    assert np.abs(zeros[np.isfinite(zeros)]).min() > 1.05
    model = model_of(plant)
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=100.0)
    assert 50 < comp.preview < 1000  # the closed loop's slowest pole, |z| 0.9 or so
    target = raster(model)
    cmd = comp.process(target)
    # tol: the commands' weight (effort 1e-6 of the spans) against the tracking error: its
    # trade-off leaves ~1e-7 of the span (measured 3.0e-7 and 0.9e-7)
    assert np.all(error(model, cmd, target) < 2e-6)
    assert np.all((cmd >= 0.0) & (cmd <= 100.0))
    comp.reset()
    blind = np.array([comp.step(row) for row in target])
    err = error(model, blind, target)
    assert err[0] > 0.005  # the preview is what tracks: 1.8 % without it


@pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning")
def test_step_with_its_preview_equals_process() -> None:
    model = model_of(structure())
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=100.0, slew_rate=1000.0)
    target = raster(model, n=700, rate=5.0)
    block = comp.process(target)
    counts = comp.slew_limited_count.copy(), comp.saturated_count.copy()
    assert counts[0].sum() > 0  # the 5 Hz raster's corners are slew-limited
    comp.reset()
    stepped = np.array(
        [comp.step(target[k], preview=target[k + 1 : k + 1 + comp.preview])
         for k in range(target.shape[0])]
    )  # fmt: skip
    # tol: the same sums in another order (the preview's rows one at a time)
    np.testing.assert_allclose(stepped, block, rtol=0, atol=1e-9 * 100)
    np.testing.assert_array_equal(comp.slew_limited_count, counts[0])
    np.testing.assert_array_equal(comp.saturated_count, counts[1])


def test_the_limits_hold_commands_and_say_so() -> None:
    model = model_of(structure())
    target = raster(model)
    target[:, 1] += 0.6 * np.ptp(target[:, 0])  # y beyond what actuator 1 reaches
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=[100.0, 60.0], slew_rate=3000.0)
    with pytest.warns(LimitWarning) as said:
        cmd = comp.process(target)
    assert np.all(cmd >= 0.0) and np.all(cmd[:, 0] <= 100.0) and np.all(cmd[:, 1] <= 60.0)
    at = (cmd <= comp.v_min) | (cmd >= comp.v_max)
    np.testing.assert_array_equal(comp.saturated_count, at.sum(axis=0))
    moved = np.abs(np.diff(np.vstack([np.zeros(2), cmd]), axis=0))
    assert np.all(moved <= 3.0 + 1e-9)  # 3000 V/s at 1 kHz
    assert comp.saturated_count[1] > 0.01 * target.shape[0]
    text = " | ".join(str(w.message) for w in said)
    assert f"actuator 1: the voltage limits [0, 60] V held {comp.saturated_count[1]} " in text
    assert "outside what the structure reaches within the limits" in text
    slow = ph.StructureCompensator(model, v_min=0.0, v_max=100.0, slew_rate=300.0)
    with pytest.warns(LimitWarning) as said:
        slow.process(raster(model, n=700, rate=5.0))
    text = " | ".join(str(w.message) for w in said)
    assert f"actuator 0: the slew limit (300 V/s) held {slow.slew_limited_count[0]} " in text
    assert "training record" not in text  # its slew limit is the one set, nothing trained
    assert comp.outside_count > 0.5 * target.shape[0]


def test_a_nan_holds_the_last_command() -> None:
    model = model_of(structure())
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=100.0)
    target = raster(model, n=400)
    target[350:360, 0] = np.nan
    cmd = comp.process(target)
    assert np.all(np.isfinite(cmd))
    np.testing.assert_array_equal(cmd[350:360], np.repeat(cmd[349:350], 10, axis=0))
    assert comp.nonfinite_count == 10


def test_reset_at_a_voltage_settles_there() -> None:
    model = model_of(structure(e_gain=0.0))
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=100.0)
    where = np.array([30.0, 70.0])
    comp.reset(voltage=where)
    held = model.structure_.dc_gain() @ where + model.structure_.off
    cmd = comp.process(np.tile(held, (50, 1)))
    # tol: the preview's gains cut where they fall below 1e-6 of the largest (PREVIEW_TOL):
    # the commands off by that share of the sum of gains, 1e-6 of the range (measured 1.3e-4 V)
    np.testing.assert_allclose(cmd, np.tile(where, (50, 1)), atol=1e-5 * 100)
    np.testing.assert_array_equal(comp.last_command, cmd[-1])


def test_reset_at_a_position_finds_its_voltages() -> None:
    """A stated position: the voltages that settle there, the operators' lags included (the
    static inverse alone misses by their share), and the commands that hold it stay there."""
    model = model_of(structure(e_gain=0.1))
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=100.0)
    where = np.array([30.0, 70.0])
    comp.reset(voltage=where)
    there = comp.output  # where 30 V and 70 V settle, operators and all
    plain = comp.static_inverse @ (there - model.structure_.off)
    assert np.max(np.abs(plain - where)) > 0.1  # the lags' share: the static inverse misses
    comp.reset(position=there)
    # tol: SETTLE_ROUNDS corrections, each taking the lags' share off what is left
    # (measured 1e-11 V after them); 1e-6 of the range
    np.testing.assert_allclose(comp.last_command, where, atol=1e-6 * 100)
    np.testing.assert_allclose(comp.output, there, rtol=1e-9)  # tol: the same
    comp.process(np.tile(there, (400, 1)))
    # the tracker holds it from there (its commands move within the operators' play: other
    # voltages hold the same position); tol: the preview's cut (PREVIEW_TOL); measured 8e-7
    np.testing.assert_allclose(comp.output, there, rtol=1e-5)
    with pytest.raises(ParameterError, match=r"is out of reach: it needs actuator \d"):
        comp.reset(position=3 * there)
    with pytest.raises(ParameterError, match="not both"):
        comp.reset(voltage=where, position=there)
    with pytest.raises(ParameterError, match="'position' must be 2 finite numbers"):
        comp.reset(position=[1.0, np.nan])


def test_bad_input_is_named() -> None:
    model = model_of(structure())
    with pytest.raises(ParameterError, match=r"takes a fitted ph\.StructureModel"):
        ph.StructureCompensator(ph.StructureModel(), v_min=0.0, v_max=1.0)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="'v_max' must be a finite number or one per"):
        ph.StructureCompensator(model, v_min=0.0, v_max=[1.0, 2.0, 3.0])
    with pytest.raises(ParameterError, match="below its 'v_max'"):
        ph.StructureCompensator(model, v_min=5.0, v_max=1.0)
    with pytest.raises(ParameterError, match="'effort' must be a positive number"):
        ph.StructureCompensator(model, v_min=0.0, v_max=1.0, effort=0.0)
    with pytest.raises(ParameterError, match="'slew_rate' must be positive"):
        ph.StructureCompensator(model, v_min=0.0, v_max=1.0, slew_rate=-1.0)
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=100.0)
    with pytest.raises(ShapeError, match=r"'desired' must be \(samples, 2\)"):
        comp.process(np.zeros((5, 3)))
    with pytest.raises(ShapeError, match=r"'preview' must be \(samples, 2\)"):
        comp.step([0.0, 0.0], preview=np.zeros((3, 1)))
    with pytest.raises(ParameterError, match=r"a CoupledModel has ph\.CoupledCompensator"):
        ph.StructureCompensator(ph.CoupledModel(), v_min=0.0, v_max=1.0)  # type: ignore[arg-type]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert comp.process(np.empty((0, 2))).shape == (0, 2)


@pytest.mark.skipif(CC is None, reason="no C compiler on this machine")
@pytest.mark.parametrize("e_gain", [0.1, 0.0])
def test_the_c_library_equals_python(tmp_path, e_gain: float) -> None:  # type: ignore[no-untyped-def]
    """The structure's step as C, through its shared library (ctypes, as LabVIEW or MATLAB's
    loadlibrary call it): the targets pushed ``preview`` samples ahead of their commands
    equal Python's ``process`` of the same run from rest to 1e-9 V, with the same counts,
    through slew-limited corners, a stretch out of reach and NaN holds. Without operators,
    the C's one operator of width 0 per actuator acts on nothing."""
    import ctypes

    from piezohyst.control.export.structure_c import write_structure_shared

    model = model_of(structure(e_gain))
    comp = ph.StructureCompensator(model, v_min=0.0, v_max=[100.0, 80.0], slew_rate=2000.0)
    target = raster(model, n=1500, rate=5.0)
    target[900:1000, 1] += 0.3 * np.ptp(target[:, 0])  # y out of actuator 1's reach
    target[1200:1210] = np.nan
    files, lib_path = write_structure_shared(comp, tmp_path / "ph_st.c")
    assert [f.name for f in files] == ["ph_st.c", "ph_st.h"]
    lib = ctypes.CDLL(str(lib_path))
    lib.ph_st_new.restype = ctypes.c_void_p
    lib.ph_st_process.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_long]
    lib.ph_st_counts.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
    lib.ph_st_reset.argtypes = lib.ph_st_free.argtypes = [ctypes.c_void_p]
    lib.ph_st_version.restype = ctypes.c_char_p
    preview = lib.ph_st_preview()
    assert preview == comp.preview
    pushed = np.ascontiguousarray(np.vstack([target, np.repeat(target[-1:], preview, axis=0)]))
    volts = np.empty((pushed.shape[0], 2))
    handle = lib.ph_st_new()
    try:
        assert lib.ph_st_process(handle, pushed.ctypes.data, volts.ctypes.data, len(pushed)) == 0
        counts = np.zeros(6, dtype=np.uint64)
        assert lib.ph_st_counts(handle, counts.ctypes.data) == 0
        assert lib.ph_st_process(handle, None, volts.ctypes.data, 1) == -1
        assert lib.ph_st_process(handle, pushed.ctypes.data, volts.ctypes.data, -1) == -2
    finally:
        lib.ph_st_free(handle)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LimitWarning)  # the same limits, counted below
        want = comp.process(np.vstack([np.repeat(comp.output[None], preview, axis=0), target]))
    # tol: the same sums in the same order but the preview's, in C's double (1e-9 of 100 V)
    np.testing.assert_allclose(volts, want, rtol=0, atol=1e-9)
    said = [comp.outside_count, comp.nonfinite_count]
    for i in range(2):
        said += [comp.saturated_count[i], comp.slew_limited_count[i]]
    np.testing.assert_array_equal(counts, said)
    assert comp.nonfinite_count == 10 and comp.saturated_count[1] > 0
    assert comp.slew_limited_count.sum() > 0 and comp.outside_count > 0
    assert b"structure of 2 actuators and 2 outputs" in lib.ph_st_version()
