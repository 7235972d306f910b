"""A fast stage on its charges alone (issue 57): the mode between an actuator's charge and
what the stage's sensor sees. The charge does not ring, the sensor does; so the mode belongs
to the output map (:func:`ph.calibrate_gain` finds it by evidence), and the self-sensing loop
inverts it from the desired trajectory before closing each actuator's loop on its charge.
On one actuator (the bench with its first bending mode) and on the XY stage with lags and
modes (``simulation.XY_DYNAMIC``), in Python and in C."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.control.export import write_stage_c, write_stage_shared
from piezohyst.errors import ModelFileError
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import (
    PRESETS,
    XY_COUPLING,
    XY_DYNAMIC,
    Bench,
    Stage,
    make_signal,
    run_loop,
    run_stage_loop,
)

from ..helpers import CC
from . import hosts

FS = 1000.0


def _bench_map(preset: str, output_dynamics: str = "auto") -> tuple[ph.ActivePI, ph.OutputMap]:
    """The paper's model (with the amplifier's lag where the bench has one) on 12 s of three
    rates, and its output map from the same record's laser."""
    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
    rec = ph.simulate(v, t, preset=preset, seed=0)
    lag = "first-order" if PRESETS[preset].amp_tau > 0 else "none"
    model = ph.ActivePI(10, input_dynamics=lag).fit(rec.voltage, rec.charge, t=rec.t)
    om = ph.calibrate_gain(model, rec.voltage, rec.charge, rec.displacement, rec.t,
                           output_dynamics=output_dynamics)  # fmt: skip
    return model, om


def test_the_mode_is_found_where_the_sensor_rings_and_nowhere_else() -> None:
    """The bench with a 150 Hz bending mode (5 % damping): the map holds it; the same bench
    without a mode, with or without the amplifier's lag, holds none (a lag is not a mode)."""
    _, om = _bench_map("T226-H4-203X-mode")
    # tol: from one noisy record, as the displacement model's own mode is identified
    # (tests/control/test_coupled_dynamics.py): the frequency to 2 %, the damping to 10 %
    assert om.mode_f0 == pytest.approx(150.0, rel=0.02)
    assert om.mode_zeta == pytest.approx(0.05, rel=0.1)
    assert om.evidence["mode"] > 5.0 and "a mode at 150 Hz" in om.summary()
    # tol: the gain to 1 %, as the stage's calibration states it
    assert om.gain == pytest.approx(125.0, rel=0.01)
    for preset in ("T226-H4-203X", "T226-H4-203X-amp4ms"):
        _, plain = _bench_map(preset)
        assert not plain.mode.active and "mode" not in plain.evidence


@pytest.mark.parametrize("cutoff", [100.0, 200.0, 300.0])
def test_a_sensors_low_pass_is_not_taken_for_a_mode(cutoff: float) -> None:
    """A laser read through a second-order Butterworth low-pass (no resonance): no mode is
    kept. At 300 Hz its delay is not a whole number of samples, and the best-fitting "mode"
    sat at the searched band's top (400 Hz at 1 kHz), kept before the band's edges were
    excluded."""
    from scipy import signal

    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
    rec = ph.simulate(v, t, preset="T226-H4-203X-amp4ms", seed=0)
    model = ph.ActivePI(10, input_dynamics="first-order").fit(rec.voltage, rec.charge, t=rec.t)
    b, a = signal.butter(2, cutoff, fs=FS)
    seen = signal.lfilter(b, a, rec.displacement - rec.displacement[0]) + rec.displacement[0]
    om = ph.calibrate_gain(model, rec.voltage, rec.charge, seen, rec.t)
    assert not om.mode.active, om.summary()


def test_a_map_with_a_mode_is_a_file_of_its_own_version(tmp_path: Path) -> None:
    _, om = _bench_map("T226-H4-203X-mode")
    path = tmp_path / "map.json"
    om.save(path)
    data = json.loads(path.read_text())
    assert data["schema_version"] == 2 and data["mode"]["f0"] == om.mode_f0
    back = ph.OutputMap.load(path)
    assert back == om and back.mode == om.mode
    q = np.linspace(*om.charge_range, 400)
    np.testing.assert_array_equal(back.respond(q), om.respond(q))
    _, plain = _bench_map("T226-H4-203X")
    plain.save(path)
    assert json.loads(path.read_text())["schema_version"] == 1  # as before: no mode field
    data["schema_version"] = 7
    path.write_text(json.dumps(data))
    with pytest.raises(ModelFileError, match="schema_version 7 is not 1 or 2"):
        ph.OutputMap.load(path)


def _triangle(om: ph.OutputMap, rate: float, samples: int = 3000) -> np.ndarray:
    """A triangle over 20-80 % of the map's displacements at ``rate`` Hz, ramped in from
    rest over its first half second (a jump from rest through a mode's inverse asks for
    what no amplifier gives)."""
    lo, hi = om.displacement_range()
    k = np.arange(samples)
    tri = lo + (hi - lo) * (0.2 + 0.6 * np.abs((k / FS * rate) % 1.0 * 2 - 1))
    rest = float(om.predict(np.array([0.0]))[0])
    ramp = np.minimum(k / 500.0, 1.0)
    return np.asarray(rest + ramp * (tri - rest))


@pytest.mark.filterwarnings("ignore::piezohyst.errors.ExtrapolationWarning")  # the rest's map
def test_the_loop_inverts_the_maps_mode_and_steps_as_it_processes() -> None:
    """A 10 Hz triangle on the bench with its bending mode: through the map's mode the loop
    tracks and the loop closes; without it (the same model, the map fitted without a mode)
    the mode rings at every turn. ``step`` given the next target equals ``process``."""
    model, om = _bench_map("T226-H4-203X-mode")
    _, flat = _bench_map("T226-H4-203X-mode", "none")
    d = _triangle(om, 10.0)
    got = {}
    for name, m in (("mode", om), ("none", flat)):
        ctl = ph.SelfSensingController(model, v_min=model.input_range_[0],
                                       v_max=model.input_range_[1], sample_rate=FS,
                                       output_map=m, slew_rate=None)  # fmt: skip
        assert ctl.previews == (1 if name == "mode" else 0)
        bench = Bench("T226-H4-203X-mode", seed=5, voltage=ctl.last_command)
        first = bench.reading.charge
        run = run_loop(ctl, d, bench)
        assert ctl.saturated_count == 0
        keep = slice(1000, None)
        s, dk = run.true_displacement[keep], d[keep]
        got[name] = (np.sqrt(np.mean((s - dk) ** 2)) / np.ptp(dk), hysteresis_width(dk, s))
        if name == "mode":
            ctl.reset()
            before = np.concatenate([[first], run.charge[:-1]])
            np.testing.assert_array_equal(ctl.process(d, before), run.voltage)
    # measured 0.26 % and a 0.76 % loop, against 1.49 % and 6.9 % without the mode
    assert got["mode"][0] < 0.005 and got["mode"][1] < 0.01
    assert got["none"][1] > 4 * got["mode"][1]


def _loop(stage: ph.StageMap) -> ph.CoupledSelfSensingController:
    models, _, _ = hosts.fast_stage_rig()
    return ph.CoupledSelfSensingController(
        models, stage, sample_rate=FS, slew_rate=None,
        v_min=[m.input_range_[0] for m in models], v_max=[m.input_range_[1] for m in models],
    )  # fmt: skip


def _fast_scans(ctl: ph.CoupledSelfSensingController) -> dict[str, np.ndarray]:
    """A 10 Hz raster line (x 20-80 %, y held) and a 10 : 7.5 Hz Lissajous in the stage's
    frame, each ramped in from where the stage rests over its first half second."""
    (x0, x1), (y0, y1) = ctl.reach
    k = np.arange(2500)
    tri = np.abs((k / FS * 10.0) % 1.0 * 2 - 1)
    ph_ = 2 * np.pi * k / FS
    owns = {
        "raster": np.column_stack([x0 + (x1 - x0) * (0.2 + 0.6 * tri),
                                   np.full(k.size, 0.5 * (y0 + y1))]),
        "lissajous": np.column_stack([x0 + (x1 - x0) * (0.5 + 0.3 * np.sin(10 * ph_)),
                                      y0 + (y1 - y0) * (0.5 + 0.3 * np.sin(7.5 * ph_ + 0.5))]),
    }  # fmt: skip
    st = ctl.stage
    with warnings.catch_warnings():  # the charges at rest: a hair below the calibrated ones
        warnings.simplefilter("ignore", ph.ExtrapolationWarning)
        rest = st.predict(np.zeros((1, 2)))[0]
    ramp = np.minimum(k / 500.0, 1.0)[:, None]
    out = {}
    for case, own in owns.items():
        d = own @ st.coupling.T + st.offset
        if case == "raster":
            d[:, 1] = d[0, 1]
        out[case] = rest + ramp * (d - rest)
    return out


def test_each_actuators_mode_is_found_in_the_stage_map() -> None:
    _, stage, _ = hosts.fast_stage_rig()
    for om, name in zip(stage.maps, XY_DYNAMIC, strict=True):
        truth = PRESETS[name]
        # tol: as the single map's mode above (2 %, 10 %)
        assert om.mode_f0 == pytest.approx(truth.mech_f0, rel=0.02)
        assert om.mode_zeta == pytest.approx(truth.mech_zeta, rel=0.1)
    # tol: the cross terms within 0.006 of the truth, as on the static stage
    assert np.all(np.abs(stage.coupling - XY_COUPLING)[[0, 1], [1, 0]] < 6e-3)


def test_a_fast_raster_and_a_lissajous_on_the_charges_alone() -> None:
    """The issue's bounds on the stage with lags and modes, without its lasers: tracking and
    width 1 %, the held axis 0.5 % (scored after the ramp-in's first second). The same
    models with maps fitted without the modes ring at the raster's turns."""
    models, stage, rec = hosts.fast_stage_rig()
    flat = ph.calibrate_stage(models, rec.voltage, rec.charge, rec.position, rec.t,
                              output_dynamics="none")  # fmt: skip
    got: dict[str, dict[str, tuple]] = {}  # type: ignore[type-arg]
    for name, st in (("modes", stage), ("none", flat)):
        ctl = _loop(st)
        span = ctl.reach[:, 1] - ctl.reach[:, 0]
        got[name] = {}
        for case, d in _fast_scans(ctl).items():
            ctl.reset()
            with warnings.catch_warnings():
                warnings.simplefilter("error" if name == "modes" else "ignore")  # nothing held
                out = run_stage_loop(ctl, d, Stage(XY_DYNAMIC, seed=5, voltage=ctl.last_command))
            keep = slice(1500, None)
            p, dk = out.true_position[keep], d[keep]
            got[name][case] = (np.sqrt(np.mean((p - dk) ** 2, axis=0)) / span,
                               hysteresis_width(dk[:, 0], p[:, 0]),
                               np.ptp(p[:, 1]) / span[1])  # fmt: skip
    err, width, held = got["modes"]["raster"]
    # measured 0.50 %, 0.82 %, 0.45 % (this noise draw; over eight: 0.50-0.59 %, 0.68-0.94 %
    # and 0.38-0.53 %: the held axis sits at the bound on some draws)
    assert err[0] < 0.01 and width < 0.01 and held < 0.005
    assert np.all(got["modes"]["lissajous"][0] < 0.01)
    assert got["none"]["raster"][1] > 3 * width  # the rings, without the modes


@pytest.mark.skipif(CC is None, reason="no C compiler on this machine")
def test_the_fast_stage_loop_in_c_equals_python(tmp_path: Path) -> None:
    """Each actuator's loop with its map's mode, as C and as a shared library (ctypes): fed
    the charges a closed-loop run read, and each row's next position (the block's own in the
    library), Python's commands and counts (the FMU and MEX: test_fmu, test_mex)."""
    ctl, d, measured = hosts.stage_loop(fast=True)
    assert ctl.previews == 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # out of reach on purpose
        paths = write_stage_c(ctl, tmp_path / "ph_xy.c")
        _, lib_path = write_stage_shared(ctl, tmp_path / "ph_xy.c")
        py = ctl.process(d, measured)
    header = paths[1].read_text()
    assert "const ph_xy_real *measured" in header and "const ph_xy_real *next" in header
    hosts.check_stage_loop_library(lib_path, ctl, d, measured, py, outside=40)


@pytest.mark.filterwarnings("ignore::piezohyst.errors.ExtrapolationWarning")  # the rest's map
def test_learning_through_a_maps_mode_learns_from_the_sensor_and_refuses_the_charge() -> None:
    """A learner in metres through a map with a mode: its feedforward inverts the mode; from
    the laser it learns; from the charge it would read the displacement through the map's
    static part (the charge does not show the mode), so it refuses, saying why."""
    ctl, d, _ = hosts.mode_loop()
    model, om = ctl.model, ctl.compensator.output_map
    ilc = ph.LearningCompensator(model, v_min=model.input_range_[0],
                                 v_max=model.input_range_[1], sample_rate=FS, output_map=om,
                                 slew_rate=None)  # fmt: skip
    assert ilc.compensator.mode.active
    scan = np.asarray(d[300:800])  # half a second of the 10 Hz triangle
    volts = ilc.command(scan)
    run = ph.simulate(volts, np.arange(volts.size) / FS, preset="T226-H4-203X-mode", seed=2)
    with pytest.raises(ph.ParameterError, match=r"holds a mode .* learn from the sensor"):
        ilc.learn(charge=run.charge)
    ilc.learn(displacement=run.displacement)
    assert ilc.trials == 1


def test_a_report_in_metres_rings_as_the_map_says(tmp_path: Path) -> None:
    """``report`` with a map that holds a mode predicts the displacement through it: on a
    record neither saw (a 10 Hz triangle on the bench with its bending mode) the sensor is
    met closer than through the same map's static part."""
    from piezohyst.workflows import model_report

    model, om = _bench_map("T226-H4-203X-mode")
    _, flat = _bench_map("T226-H4-203X-mode", "none")
    t, v = make_signal("triangle", amplitude=140.0, frequency=10.0, duration=2.0)
    rec = ph.simulate(v, t, preset="T226-H4-203X-mode", seed=7)
    data = tmp_path / "held.csv"
    cols = {"time": rec.t, "voltage": rec.voltage, "charge": rec.charge,
            "displacement": rec.displacement}  # fmt: skip
    ph.write_table(data, cols, units={"time": "s", "voltage": "V", "charge": "C",
                                      "displacement": "m"})  # fmt: skip
    model.save(tmp_path / "model.json")
    got = {}
    for name, m in (("mode", om), ("flat", flat)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the report's own notes are not under test
            out = model_report(tmp_path / "model.json", data, tmp_path / name, gain=m,
                               displacement_column="displacement")  # fmt: skip
        got[name] = out.metrics["displacement_nrmse_offset_free_pct"]
    assert got["mode"] < 0.5 * got["flat"], got  # measured 0.33 % against 1.24 %


def test_a_loop_refuses_a_model_with_a_mode_whatever_its_map() -> None:
    """The charge has no mode: a model fitted with one (on a displacement) is refused by the
    loop with or without a map, and beside a map with its own mode too."""
    import dataclasses

    model = hosts.mode_model()
    assert model.output_dynamics_.active
    ctl, _, _ = hosts.mode_loop()
    om = ctl.compensator.output_map
    assert om is not None
    flat = dataclasses.replace(om, mode_f0=0.0, mode_zeta=0.0, mode_dt=0.0)
    lo, hi = model.input_range_
    for m, said in ((None, "the mode into the output map"), (flat, "the mode into the output map"),
                    (om, "so does the output map")):  # fmt: skip
        with pytest.raises(ph.ParameterError, match=said), warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the map was calibrated through another
            ph.SelfSensingController(model, v_min=lo, v_max=hi, sample_rate=FS, output_map=m)
