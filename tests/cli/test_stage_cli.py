"""``piezohyst fit`` with several input and output columns: a coupled stage from one file
(issue 57)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.metrics import hysteresis_width
from piezohyst.simulation import XY_COUPLING, make_signal, simulate_stage

from ..control import hosts
from ..helpers import CC, assert_clean_error, one_line_error, run


def _stage_file(tmp_path: Path) -> Path:
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t, seed=0)
    return _written(rec, tmp_path / "stage.csv")


def _written(rec: Any, path: Path) -> Path:
    """A stage record as a lab's CSV: time, the two voltages, the two positions, with units."""
    ph.write_table(
        path,
        {"time": rec.t, "vx": rec.voltage[:, 0], "vy": rec.voltage[:, 1],
         "x": rec.position[:, 0], "y": rec.position[:, 1]},
        units={"time": "s", "vx": "V", "vy": "V", "x": "m", "y": "m"},
    )  # fmt: skip
    return path


def test_fit_a_stage_from_the_shell(tmp_path: Path) -> None:
    data = _stage_file(tmp_path)
    out = tmp_path / "stage.json"
    res = run("fit", data, "--input", "vx,vy", "--output", "x,y", "--model", "classical-pi",
              "-o", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert (
        "static coupling" in res.output and "2 actuators (ClassicalPI, ClassicalPI)" in res.output
    )
    stage = ph.CoupledModel.load(out)
    # tol: as for the model fitted in Python on the same record (tests/control/test_coupled.py)
    np.testing.assert_allclose(stage.coupling_, XY_COUPLING, atol=5e-3)


def test_a_stage_names_what_it_cannot_take(tmp_path: Path) -> None:
    data = _stage_file(tmp_path)
    out = tmp_path / "stage.json"
    one_line_error(run("fit", data, "--input", "vx,vy", "--output", "x", "-o", out),
                   "2 input and 1 output columns")  # fmt: skip
    one_line_error(run("fit", data, "--input", "vx,vz", "--output", "x,y", "-o", out), "vz")
    one_line_error(run("fit", data, "--input", "vx,", "--output", "x,y", "-o", out),
                   "a column name is empty")  # fmt: skip
    assert_clean_error(
        run("fit", data, "--input", "vx,vy", "--output", "x,y", "--model", "auto", "-o", out),
        code=2,
    )
    assert not out.exists()


def test_predict_and_compensate_a_stage_from_the_shell(tmp_path: Path) -> None:
    """The stage's model file runs from the shell as one actuator's does: ``predict`` scores
    each axis, ``compensate`` writes one command column per actuator after a ramp from rest,
    and the commands move the simulated stage along a raster with the other axis held."""
    data = _stage_file(tmp_path)
    model_file = tmp_path / "stage.json"
    assert run("fit", data, "--input", "vx,vy", "--output", "x,y", "-o", model_file).exit_code == 0
    stage = ph.CoupledModel.load(model_file)
    # another record: each actuator a sine at its own rate
    t = np.arange(4000) / 1000.0
    u = np.column_stack([70 - 60 * np.cos(2 * np.pi * 0.7 * t), 70 - 60 * np.cos(3.8 * np.pi * t)])
    rec = simulate_stage(u, t, seed=1)
    other = _written(rec, tmp_path / "other.csv")
    pred = tmp_path / "pred.csv"
    res = run("predict", model_file, other, "--input", "vx,vy", "--output", "x,y", "-o", pred)
    assert res.exit_code == 0, res.output
    assert "NRMSE per axis" in res.output
    written = ph.read_table(pred)
    expected = stage.predict(rec.voltage, t=rec.t)
    # tol: the CSV's full-precision decimal round trip (17 digits)
    np.testing.assert_allclose(written.get("predicted_x"), expected[:, 0], rtol=1e-12)
    np.testing.assert_allclose(written.get("predicted_y"), expected[:, 1], rtol=1e-12)
    e = expected - rec.position
    err = np.sqrt(np.mean(e**2, axis=0)) / np.ptp(rec.position, axis=0)
    assert f"{100 * err[0]:.4g} %, {100 * err[1]:.4g} %" in res.output
    # the shape holds (1.7 % and 0.7 % about the mean, measured); the offset (about 10 % of
    # the span here) is the bench's creep, which the default ClassicalPI per actuator lacks
    shape = np.sqrt(np.mean((e - e.mean(axis=0)) ** 2, axis=0)) / np.ptp(rec.position, axis=0)
    assert np.all(shape < 0.025), shape
    # a 2 Hz raster on x, y held mid-range
    comp = ph.CoupledCompensator(stage, v_min=0.0, v_max=140.0, sample_rate=1000.0)
    (x0, x1), (y0, y1) = comp.reach
    k = np.arange(3000)
    x = x0 + (x1 - x0) * (0.2 + 0.6 * np.abs(((k / 1000.0 * 2.0) % 1.0) * 2 - 1))
    target = tmp_path / "raster.csv"
    ph.write_table(target, {"time": k / 1000.0, "x": x, "y": np.full(k.size, 0.5 * (y0 + y1))})
    out = tmp_path / "commands.csv"
    res = run("compensate", model_file, target, "--column", "x,y", "--v-min", "0",
              "--v-max", "140", "--slew-rate", "1e6", "-o", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "500 of ramp-in first" in res.output and "outside the stage's reach" in res.output
    cmd = ph.read_table(out)
    volts = np.column_stack([cmd.get("command_0"), cmd.get("command_1")])
    assert volts.shape == (3500, 2) and volts.min() >= 0.0 and volts.max() <= 140.0
    moved = simulate_stage(volts, np.arange(3500) / 1000.0, seed=5).true_position[500:]
    s = slice(1000, None)  # after the first half period
    e = moved[s, 0] - x[s]
    assert np.sqrt(np.mean((e - e.mean()) ** 2)) / np.ptp(x[s]) < 0.01
    assert np.ptp(moved[s, 1]) / (y1 - y0) < 0.005
    # what it cannot take: the raster under the training record's slew rate (the default)
    res = run("compensate", model_file, target, "--column", "x,y", "--v-min", "0", "--v-max",
              "140", "-o", tmp_path / "c1.csv")  # fmt: skip
    one_line_error(res, "slew limit would hold")
    one_line_error(run("compensate", model_file, target, "--column", "x", "--v-min", "0",
                       "--v-max", "140", "-o", tmp_path / "c2.csv"), "moves 2 axes")  # fmt: skip
    assert_clean_error(run("compensate", model_file, target, "--column", "x,y",
                           "-o", tmp_path / "c3.csv"), code=2)  # fmt: skip


def test_export_a_stage_as_c_from_the_shell(tmp_path: Path) -> None:
    """``export-c`` on a stage's model file writes the stage's C and each actuator's, equal
    to what ``write_stage_c`` writes in Python, with --shared its library, with --mex its
    gateway, and ``export-fmu`` its FMU; the controller, not for a stage yet, says so."""
    data = _stage_file(tmp_path)
    model_file = tmp_path / "stage.json"
    assert run("fit", data, "--input", "vx,vy", "--output", "x,y", "-o", model_file).exit_code == 0
    res = run("export-c", model_file, "--v-min", "0", "--v-max", "140", "--sample-rate", "1000",
              "-o", tmp_path / "ph_xy.c")  # fmt: skip
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in tmp_path.glob("ph_xy*"))
    assert names == ["ph_xy.c", "ph_xy.h", "ph_xy_a0.c", "ph_xy_a0.h", "ph_xy_a1.c", "ph_xy_a1.h"]
    from piezohyst.control.export import export_stage_c

    comp = ph.CoupledCompensator(ph.CoupledModel.load(model_file), v_min=0.0, v_max=140.0,
                                 sample_rate=1000.0)  # fmt: skip
    for name, text in export_stage_c(comp, prefix="ph_xy").files.items():
        assert (tmp_path / name).read_text() == text, name
    if CC is not None:  # the library needs the system C compiler
        res = run("export-c", model_file, "--v-min", "0", "--v-max", "140", "--sample-rate",
                  "1000", "--shared", "--force", "-o", tmp_path / "ph_xy.c")  # fmt: skip
        assert res.exit_code == 0, res.output
        assert "libph_xy" in res.output and list(tmp_path.glob("libph_xy.*"))
        res = run("export-fmu", model_file, "--v-min", "0", "--v-max", "140", "--sample-rate",
                  "1000", "-o", tmp_path / "ph_xy.fmu")  # fmt: skip
        assert res.exit_code == 0, res.output
        from fmpy import read_model_description

        md = read_model_description(str(tmp_path / "ph_xy.fmu"))
        names = {v.name for v in md.modelVariables}
        assert {"target_0", "target_1", "voltage_0", "voltage_1", "outside"} <= names
    res = run("export-c", model_file, "--v-min", "0", "--v-max", "140", "--mex",
              "-o", tmp_path / "mex" / "ph_xy_mex.c")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "mex").iterdir()) == [
        "ph_xy.c", "ph_xy.h", "ph_xy_a0.c", "ph_xy_a0.h", "ph_xy_a1.c", "ph_xy_a1.h",
        "ph_xy_mex.c"]  # fmt: skip
    assert_clean_error(run("export-c", model_file, "--v-min", "0", "--v-max", "140",
                           "--controller", "-o", tmp_path / "other.c"), code=2)  # fmt: skip
    assert_clean_error(run("export-c", model_file, "-o", tmp_path / "other.c"), code=2)
    assert not (tmp_path / "other.c").exists()


def test_report_a_stage_from_the_shell(tmp_path: Path) -> None:
    """``report`` on a stage's model file: each axis's NRMSE (equal to the model's own on its
    training record), its figures, the coupling in the report."""
    data = _stage_file(tmp_path)
    model_file = tmp_path / "stage.json"
    assert run("fit", data, "--input", "vx,vy", "--output", "x,y", "-o", model_file).exit_code == 0
    stage = ph.CoupledModel.load(model_file)
    out = tmp_path / "report"
    res = run("report", model_file, data, "--input", "vx,vy", "--output", "x,y", "--out", out)
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())
    values = {k: v["value"] if isinstance(v, dict) else v for k, v in metrics["metrics"].items()}
    # tol: the same prediction, written to JSON and read back (17 significant digits)
    np.testing.assert_allclose([values["nrmse_x_pct"], values["nrmse_y_pct"]],
                               100 * stage.output_nrmse_, rtol=1e-9)  # fmt: skip
    assert {"fit_x.png", "fit_y.png", "loop_x.png", "loop_y.png", "report.html"} <= {
        p.name for p in out.iterdir()}  # fmt: skip
    assert "coupling" in (out / "report.md").read_text()
    assert f"x {values['nrmse_x_pct']:.4g} %" in res.output
    assert_clean_error(run("report", model_file, data, "--input", "vx,vy", "--output", "x,y",
                           "--gain", "125", "--out", tmp_path / "r2"), code=2)  # fmt: skip


def test_a_stage_with_lags_and_modes_from_the_shell(tmp_path: Path) -> None:
    """``fit`` takes each actuator's lag and mode for a stage, says what it found, and its C
    export's step takes the next position, and the FMU has the next positions as inputs."""
    rec = hosts.dynamic_record()
    data = _written(rec, tmp_path / "fast.csv")
    out = tmp_path / "stage.json"
    res = run("fit", data, "--input", "vx,vy", "--output", "x,y", "--operators", "16",
              "--input-dynamics", "first-order", "--output-dynamics", "second-order",
              "-o", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "actuator 0 a lag of 3.9" in res.output and "a mode at 149." in res.output
    assert "actuator 1 a lag of 2.9" in res.output and "a mode at 119." in res.output
    c_file = tmp_path / "ph_xy.c"
    res = run("export-c", out, "--v-min", "1", "--v-max", "139", "--sample-rate", "1000",
              "-o", c_file)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "const ph_xy_real *next" in (tmp_path / "ph_xy.h").read_text()
    fmu = tmp_path / "ph_xy.fmu"
    res = run("export-fmu", out, "--v-min", "1", "--v-max", "139", "--sample-rate", "1000",
              "-o", fmu)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert 'name="next_0"' in zipfile.ZipFile(fmu).read("modelDescription.xml").decode()


def _structure_csv(path: Path, seed: int) -> Path:
    """Two actuators, three outputs read through one structure (two shared modes), from rest."""
    from piezohyst.model import structure_fit as sf

    a = np.zeros((4, 4))
    for k, (rad, th) in enumerate([(0.9, 0.5), (0.85, 1.1)]):
        a[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = rad * np.array(
            [[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]
        )
    b = np.array([[1.0, 0.2], [0.0, 0.3], [0.1, 1.0], [0.4, 0.0]])
    c = np.array([[1.0, 0.0, 0.3, 0.1], [0.2, 0.1, 1.0, 0.0], [0.5, 0.2, 0.5, 0.3]]) * 1e-6
    plant = sf.Structure(a, b, c, np.zeros((3, 2)), np.zeros((4, 0)), np.zeros((2, 3)),
                         np.zeros((2, 0)), np.zeros(3))  # fmt: skip
    v = 10.0 * np.random.default_rng(seed).standard_normal((1500, 2))
    y = plant.run(v, periodic=False)
    ph.write_table(
        path,
        {"time": np.arange(1500) / 1e3, "vx": v[:, 0], "vy": v[:, 1],
         "x": y[:, 0], "y": y[:, 1], "z": y[:, 2]},
        units={"time": "s", "vx": "V", "vy": "V", "x": "m", "y": "m", "z": "m"},
    )  # fmt: skip
    return path


def test_a_structure_from_the_shell(tmp_path: Path) -> None:
    """fit --model structure: two actuators, three outputs; predict, compensate and export it;
    what it cannot take is said in one line."""
    data, fresh = _structure_csv(tmp_path / "s.csv", 0), _structure_csv(tmp_path / "f.csv", 1)
    out = tmp_path / "structure.json"
    res = run("fit", data, "--input", "vx,vy", "--output", "x,y,z", "--model", "structure",
              "-o", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "StructureModel: 2 inputs, 3 outputs at 1000 Hz; order 4 (chosen from" in res.output
    assert "the operators did not predict the held-out records better" in res.output  # linear
    pred = tmp_path / "pred.csv"
    res = run("predict", out, fresh, "--input", "vx,vy", "--output", "x,y,z", "-o", pred)
    assert res.exit_code == 0, res.output
    said = res.output.split("NRMSE per axis ")[1].split(" over")[0]
    figures = [float(x.strip(" %")) for x in said.split(",")]
    # tol: noise-free; the impulse response's ridge and its 375 lags' truncation (0.9^375)
    assert len(figures) == 3 and max(figures) < 1e-3
    table = ph.read_table(pred)
    model = ph.StructureModel.load(out)
    v = np.column_stack([ph.read_table(fresh).get(c) for c in ("vx", "vy")])
    # tol: the CSV's full-precision decimal round trip (17 digits)
    np.testing.assert_allclose(table.get("predicted_z"), model.predict(v)[:, 2], rtol=1e-12)
    cmds = tmp_path / "c.csv"
    res = run("compensate", out, fresh, "--column", "x,y,z", "--v-min", "-50", "--v-max", "50",
              "-o", cmds)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "2000 rows (500 of ramp-in first); actuator 0: " in res.output
    sent = ph.read_table(cmds)
    got = np.column_stack([sent.get("command_0"), sent.get("command_1")])[500:]
    # the targets are what vx, vy moved: after the ramp's state has rung out (|poles| 0.9),
    # and before the file's last rows (whose preview runs past its end: the target taken to
    # hold), the inverse sends them back; tol: the truncated preview (1e-6 of its largest
    # gain) and the fit's own error (1e-5 of the span) on a 10 V signal, 2e-5 V each
    np.testing.assert_allclose(got[300:-100], v[300:-100], atol=1e-4 * 10)  # measured 1.9e-4 V
    assert np.all(np.abs(got) <= 50.0)
    res = run("export-c", out, "-o", tmp_path / "s.c", "--v-min", "-50", "--v-max", "50")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "s.h").exists() and "#define S_PREVIEW " in (tmp_path / "s.h").read_text()
    res = run("export-c", out, "-o", tmp_path / "t_mex.c", "--v-min", "-50", "--v-max", "50",
              "--mex")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "t_mex('preview')" in (tmp_path / "t_mex.c").read_text()
    assert (tmp_path / "t.c").exists()
    one_line_error(run("fit", data, "--input", "vx", "--output", "x", "--model", "structure",
                       "-o", tmp_path / "one.json"), "two or more --input columns")  # fmt: skip


def test_report_a_structure_from_the_shell(tmp_path: Path) -> None:
    """``report`` on a structure model file: each axis scored (as ``predict`` scores it), the
    static gain, the modes and the frequency response of the structure the record came from."""
    data, fresh = _structure_csv(tmp_path / "s.csv", 0), _structure_csv(tmp_path / "f.csv", 1)
    model_file = tmp_path / "structure.json"
    res = run("fit", data, "--input", "vx,vy", "--output", "x,y,z", "--model", "structure",
              "-o", model_file)  # fmt: skip
    assert res.exit_code == 0, res.output
    out = tmp_path / "rep"
    res = run("report", model_file, fresh, "--input", "vx,vy", "--output", "x,y,z", "--out", out)
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())
    values = {k: v["value"] for k, v in metrics["metrics"].items()}
    model = ph.StructureModel.load(model_file)
    table = ph.read_table(fresh)
    v = np.column_stack([table.get(c) for c in ("vx", "vy")])
    y = np.column_stack([table.get(c) for c in "xyz"])
    pred = model.predict(v)
    for i, axis in enumerate("xyz"):
        want = 100 * np.sqrt(np.mean((pred[:, i] - y[:, i]) ** 2)) / np.ptp(y[:, i])
        # tol: the same prediction, through JSON's 17 significant digits
        assert values[f"nrmse_{axis}_pct"] == pytest.approx(want, rel=1e-9)
        assert values[f"nrmse_sd_{axis}_pct"] < 1e-3  # noise-free: the fit's own error
        assert f"{axis} {values[f'nrmse_{axis}_pct']:.4g} %" in res.output
    assert values["order"] == 4 and values["operators_per_actuator"] == 0
    # the record's structure (_structure_csv): poles 0.9 e^{+-0.5j} and 0.85 e^{+-1.1j}, its
    # static gain c (I - a)^-1 b; the report's four significant digits
    modes = metrics["tables"]["Modes"]["modes, damping ratio: operators sliding (large strokes)"]
    found = [(float(m.split(" Hz (")[0]), float(m.split("(")[1].rstrip(")")))
             for m in modes.split(", ")]  # fmt: skip
    want = sorted((abs(s) * 1e3 / (2 * np.pi), -s.real / abs(s))
                  for s in (np.log(0.9) + 0.5j, np.log(0.85) + 1.1j))  # fmt: skip
    # tol: printed to 5 and 3 significant digits (noise-free: identified to rounding)
    np.testing.assert_allclose(found, want, rtol=2e-3)
    gain = json.loads(model_file.read_text())
    said = metrics["tables"]["Structure"]
    (key,) = [k for k in said if k.startswith("the model's static gain, at 0 Hz (m/V; rows: x")]
    rows = [[float(x) for x in row.strip(" []").split(",")] for row in said[key].split(";")]
    static = ph.StructureModel.from_dict(gain).structure_.dc_gain()
    # tol: printed to 4 significant digits
    np.testing.assert_allclose(rows, static, rtol=5e-4)
    # the record's own response estimate against the model's, estimated the same way from
    # its simulated outputs: the model is the structure (noise-free), so they agree
    for axis in "xyz":
        # tol: the model's own error on its record, 5e-4 % (fit_nrmse_pct), 20 times over
        assert 0 < values[f"response_error_{axis}_pct"] < 1e-2
    # tol: as above; the cross terms of the same two estimates
    assert values["model_cross_term_pct"] == pytest.approx(values["measured_cross_term_pct"],
                                                           rel=1e-4)  # fmt: skip
    assert "Welch's H1 over 256-sample segments" in str(said)
    assert {"fit_x.png", "loop_x.png", "loop_y.png", "fit_z.png", "response.png",
            "report.html"} <= {p.name for p in out.iterdir()}  # fmt: skip
    assert "loop_z.png" not in {p.name for p in out.iterdir()}  # no actuator of its own
    one_line_error(run("report", model_file, fresh, "--input", "vx,vy", "--output", "x,y",
                       "--out", tmp_path / "r2"),
                   "a structure of 2 actuators and 3 axes")  # fmt: skip
    assert_clean_error(run("report", model_file, fresh, "--input", "vx,vy", "--output", "x,y,z",
                           "--gain", "125", "--out", tmp_path / "r3"), code=2)  # fmt: skip


def test_a_stage_with_a_third_sensor_from_the_shell(tmp_path: Path) -> None:
    """Two actuators, three position columns: the first two are the actuators' own axes, the
    third a further reading; fit, predict and compensate take them, and a target off what
    the actuators move the three outputs to is counted with the out-of-reach ones."""
    three = np.array([[1.0, -0.03], [0.04, 1.0], [0.6, 0.45]])
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t, coupling=three, seed=0)
    cols = {"time": rec.t, "vx": rec.voltage[:, 0], "vy": rec.voltage[:, 1],
            "x": rec.position[:, 0], "y": rec.position[:, 1], "z": rec.position[:, 2]}  # fmt: skip
    units = {"time": "s", "vx": "V", "vy": "V", **dict.fromkeys("xyz", "m")}
    ph.write_table(tmp_path / "three.csv", cols, units=units)
    model_file = tmp_path / "three.json"
    res = run("fit", tmp_path / "three.csv", "--input", "vx,vy", "--output", "x,y,z",
              "-o", model_file)  # fmt: skip
    assert res.exit_code == 0, res.output
    model = ph.CoupledModel.load(model_file)
    # tol: as in Python (tests/control/test_coupled.py): the per-axis misfit, 0.005
    np.testing.assert_allclose(model.coupling_, three, atol=5e-3)
    res = run("predict", model_file, tmp_path / "three.csv", "--input", "vx,vy", "--output",
              "x,y,z", "-o", tmp_path / "pred.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    k = np.arange(2000)
    own = np.column_stack([60e-6 + 30e-6 * np.sin(2 * np.pi * k / 1000), np.full(k.size, 50e-6)])
    target = own @ model.coupling_.T + model.offset_
    target[300:350, 2] += 5e-6  # off the plane
    ph.write_table(tmp_path / "target.csv", {"time": k / 1000, "x": target[:, 0],
                                              "y": target[:, 1], "z": target[:, 2]})  # fmt: skip
    limits = ("--v-min", "0", "--v-max", "140", "--slew-rate", "1e6")
    res = run("compensate", model_file, tmp_path / "target.csv", "--column", "x,y,z", *limits,
              "-o", tmp_path / "c.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "50 desired positions outside the stage's reach" in res.output
    written = ph.read_table(tmp_path / "c.csv")
    assert "command_1" in written and "command_2" not in written


def _charges_file(rec: Any, data: Path, dynamics: str) -> Path:
    """A stage record as a lab's file (each actuator's voltage and charge, each axis's
    position), and each actuator's model fitted from the shell on its own columns (``ax.json``,
    ``ay.json`` beside it, with ``--input-dynamics dynamics``)."""
    cols = {"time": rec.t, "vx": rec.voltage[:, 0], "vy": rec.voltage[:, 1],
            "qx": rec.charge[:, 0], "qy": rec.charge[:, 1],
            "x": rec.position[:, 0], "y": rec.position[:, 1]}  # fmt: skip
    ph.write_table(data, cols, units={"time": "s", "vx": "V", "vy": "V", "qx": "C", "qy": "C",
                                      "x": "m", "y": "m"})  # fmt: skip
    for axis in ("x", "y"):
        res = run("fit", data, "--input", f"v{axis}", "--output", f"q{axis}", "--model",
                  "active-pi", "--input-dynamics", dynamics, "-o",
                  data.with_name(f"a{axis}.json"))  # fmt: skip
        assert res.exit_code == 0, res.output
    return data


def test_a_stage_on_its_charges_from_the_shell(tmp_path: Path) -> None:
    """``calibrate-stage`` maps the actuators' charges to the stage's positions from a record
    (each actuator's model fitted on its own columns first), as ``ph.calibrate_stage`` does
    on the same columns; ``export-c`` of the map with ``--models`` writes the stage's
    self-sensing loop as ``export_stage_c`` does; what is missing or miscounted is named."""
    t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=8.0)
    _, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=8.0)
    rec = simulate_stage(np.column_stack([a, b]), t, seed=0)
    data = _charges_file(rec, tmp_path / "stage-q.csv", "none")
    maps = tmp_path / "stage-map.json"
    models = f"{tmp_path / 'ax.json'},{tmp_path / 'ay.json'}"
    res = run("calibrate-stage", data, "--models", models, "--input", "vx,vy", "--charge",
              "qx,qy", "--output", "x,y", "-o", maps)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "coupling [" in res.output and "actuator 1: gain" in res.output
    table = ph.read_table(data)
    fitted = [ph.load_model(tmp_path / f"a{axis}.json") for axis in ("x", "y")]
    cols_of = {k: np.asarray(table.get(k)) for k in ("vx", "vy", "qx", "qy", "x", "y")}
    mine = ph.calibrate_stage(
        fitted, np.column_stack([cols_of["vx"], cols_of["vy"]]),
        np.column_stack([cols_of["qx"], cols_of["qy"]]),
        np.column_stack([cols_of["x"], cols_of["y"]]), np.asarray(table.get("time")),
    )  # fmt: skip
    saved = ph.StageMap.load(maps)
    np.testing.assert_array_equal(saved.coupling, mine.coupling)
    res = run("export-c", maps, "--models", models, "--sample-rate", "1000", "--slew-rate",
              "2e4", "-o", tmp_path / "ph_xy.c")  # fmt: skip
    assert res.exit_code == 0, res.output
    from piezohyst.control.export import export_stage_c

    loop = ph.CoupledSelfSensingController(
        fitted, saved, sample_rate=1000.0, slew_rate=2e4,
        v_min=[m.input_range_[0] for m in fitted], v_max=[m.input_range_[1] for m in fitted],
    )  # fmt: skip
    for name, text in export_stage_c(loop, prefix="ph_xy").files.items():
        assert (tmp_path / name).read_text() == text, name
    k = np.arange(2000)
    (lo, hi), (y0, y1) = loop.reach
    x = lo + (hi - lo) * (0.2 + 0.6 * np.abs(((k / 1000 * 10.0) % 1.0) * 2 - 1))
    target = tmp_path / "raster.csv"
    ph.write_table(target, {"time": k / 1000, "x": x, "y": np.full(k.size, 0.5 * (y0 + y1))})
    res = run("simulate-loop", maps, target, "--models", models, "--column", "x,y",
              "--slew-rate", "1e6", "-o", tmp_path / "loop.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "built-in XY stage" in res.output and "(held: moved" in res.output
    got = ph.read_table(tmp_path / "loop.csv")
    assert {"command_0", "charge_1", "position_x", "desired_y"} <= set(got.columns)
    volts = np.column_stack([got.get("command_0"), got.get("command_1")])
    assert np.all(volts >= 0.0) and np.all(volts <= 140.0)
    assert_clean_error(run("simulate-loop", maps, target, "--column", "x,y", "-o",
                           tmp_path / "other.csv"), code=2)  # fmt: skip
    assert_clean_error(run("export-c", maps, "--sample-rate", "1000", "-o",
                           tmp_path / "other.c"), code=2)  # fmt: skip
    one_line_error(run("export-c", maps, "--models", str(tmp_path / "ax.json"),
                       "--sample-rate", "1000", "-o", tmp_path / "other.c"),
                   "holds 2 actuators")  # fmt: skip
    one_line_error(run("calibrate-stage", data, "--models", models, "--input", "vx,vy",
                       "--charge", "qx,qz", "--output", "x,y", "-o", tmp_path / "m2.json"),
                   "no column 'qz'", "--charge")  # fmt: skip
    assert not (tmp_path / "other.c").exists() and not (tmp_path / "m2.json").exists()
    assert not (tmp_path / "other.csv").exists()


def test_a_fast_stage_on_its_charges_from_the_shell(tmp_path: Path) -> None:
    """The stage with lags and modes: each actuator's model fitted with its lag from its own
    columns, ``calibrate-stage`` finds each actuator's mode (said in its lines), and
    ``simulate-loop`` runs the map on the built-in stage that rings (the models hold lags, the
    map modes), saying so, and tracks a 10 Hz raster line there; with ``--output-dynamics
    none`` no mode is kept, and the same raster rings."""
    data = _charges_file(hosts.dynamic_record(), tmp_path / "fast.csv", "first-order")
    models = f"{tmp_path / 'ax.json'},{tmp_path / 'ay.json'}"
    widths = {}
    for mode in ("auto", "none"):
        maps = tmp_path / f"map-{mode}.json"
        res = run("calibrate-stage", data, "--models", models, "--input", "vx,vy", "--charge",
                  "qx,qy", "--output", "x,y", "--output-dynamics", mode, "-o", maps)  # fmt: skip
        assert res.exit_code == 0, res.output
        assert ("a mode at 150 Hz" in res.output) == (mode == "auto"), res.output
        assert ("a mode at 120 Hz" in res.output) == (mode == "auto"), res.output
        stage = ph.StageMap.load(maps)
        (lo, hi) = stage.maps[0].displacement_range()
        k = np.arange(2500)
        x = lo + (hi - lo) * (0.2 + 0.6 * np.abs(((k / 1000 * 10.0) % 1.0) * 2 - 1))
        y = np.full(k.size, float(np.mean(stage.maps[1].displacement_range())))
        ramp = np.minimum(k / 500.0, 1.0)  # from where the stage rests, as a scan starts
        x, y = (float(om.predict(np.array([0.0]))[0]) * (1 - ramp) + ramp * w
                for om, w in zip(stage.maps, (x, y), strict=True))  # fmt: skip
        target = tmp_path / "raster.csv"
        own = np.column_stack([x, y]) @ stage.coupling.T + stage.offset
        own[500:, 1] = own[500, 1]  # y held still in the stage's frame once arrived
        ph.write_table(target, {"time": k / 1000, "x": own[:, 0], "y": own[:, 1]})
        res = run("simulate-loop", maps, target, "--models", models, "--column", "x,y",
                  "--slew-rate", "1e6", "-o", tmp_path / f"loop-{mode}.csv")  # fmt: skip
        assert res.exit_code == 0, res.output
        assert "built-in XY stage with lags and modes" in res.output
        got = ph.read_table(tmp_path / f"loop-{mode}.csv")
        keep = slice(1500, None)
        widths[mode] = hysteresis_width(own[keep, 0], np.asarray(got.get("position_x"))[keep])
    # measured 1.06 % against 6.9 % without the modes; the same loop's width on the Python
    # test's scan is 0.68-0.94 % over eight noise draws (tests/control/test_stage_modes.py), so
    # this draw and scan sit at the issue's 1 %: the bound here is the modes' effect
    assert widths["auto"] < 0.015 and widths["none"] > 4 * widths["auto"]
    res = run("export-c", tmp_path / "map-auto.json", "--models", models, "--sample-rate",
              "1000", "-o", tmp_path / "ph_xy.c")  # fmt: skip
    assert res.exit_code == 0, res.output
    header = (tmp_path / "ph_xy.h").read_text()
    assert "const ph_xy_real *measured" in header and "const ph_xy_real *next" in header
