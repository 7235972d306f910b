"""``piezohyst learn`` on a coupled stage (issue 57): a repeated scan learned through files,
one desired column per axis in, one command column per actuator out, the stage's sensors read
back, the state kept between calls; the same commands as Python's learner."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.simulation import XY_COUPLING, Bench, make_signal, simulate_stage

from ..helpers import assert_clean_error, one_line_error, run

LIMITS = ("--v-min", "0", "--v-max", "140", "--slew-rate", "30000")


@pytest.fixture(scope="module")
def stage(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The static stage's model file and a 4 Hz raster line (x) with y held, one period."""
    where = tmp_path_factory.mktemp("stage")
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t, seed=0)
    model = ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)
    model.save(where / "stage.json")
    comp = ph.CoupledCompensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0)
    (x0, x1), (y0, y1) = comp.reach
    k = np.arange(500)
    tri = np.abs((k / 1000 * 4) % 1 * 2 - 1)
    ph.write_table(where / "raster.csv",
                   {"time": k / 1000.0, "x": x0 + (x1 - x0) * (0.3 + 0.4 * tri),
                    "y": np.full(k.size, (y0 + y1) / 2)},
                   units={"time": "s", "x": "m", "y": "m"})  # fmt: skip
    return where / "stage.json", where / "raster.csv"


def _trial(commands: Path, benches: list[Bench], path: Path) -> Path:
    """Send a commands file to the stage and write what the DAQ recorded over it."""
    sent = ph.read_table(commands)
    u = np.column_stack([sent.get("command_0"), sent.get("command_1")])
    moved = np.column_stack([b.run(u[:, i]).displacement for i, b in enumerate(benches)])
    pos = moved @ XY_COUPLING.T
    columns = {"time": sent.get("time"), "voltage_0": u[:, 0], "voltage_1": u[:, 1],
               "x": pos[:, 0], "y": pos[:, 1]}  # fmt: skip
    units = {"time": "s", "voltage_0": "V", "voltage_1": "V", "x": "m", "y": "m"}
    ph.write_table(path, columns, units=units)
    return path


def test_learn_a_stage_from_the_shell(stage: tuple[Path, Path], tmp_path: Path) -> None:
    """Five calls: the first writes the lead-in, each later one learns from the recording of
    the trial before; the error per axis falls, the commands are Python's learner's."""
    model_file, raster = stage
    state, out = tmp_path / "learn.json", tmp_path / "next.csv"
    res = run("learn", model_file, "--desired", raster, "--column", "x,y", *LIMITS,
              "--state", state, "-o", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "trial 0's commands" in res.output
    model = ph.CoupledModel.load(model_file)
    ilc = ph.CoupledLearningCompensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0,
                                        slew_rate=30000.0)  # fmt: skip
    table = ph.read_table(raster)
    scan = np.column_stack([table.get("x"), table.get("y")])
    benches = [Bench(seed=i, voltage=v) for i, v in enumerate(ilc.last_command)]
    errors = []
    for k in range(4):
        py = ilc.command(scan)
        written = ph.read_table(out)
        shell = np.column_stack([written.get("command_0"), written.get("command_1")])
        # tol: the CSV keeps 17 significant digits (a float64 round trip): equal to the bit
        np.testing.assert_array_equal(shell, py)
        recording = _trial(out, benches, tmp_path / f"trial{k}.csv")
        rec = ph.read_table(recording)
        ilc.learn(np.column_stack([rec.get("x"), rec.get("y")]))
        res = run("learn", model_file, recording, *LIMITS, "--state", state, "-o", out,
                  "--force")  # fmt: skip
        assert res.exit_code == 0, res.output
        assert f"trial {k}: error per axis" in res.output
        errors.append(ilc.history[-1].error)
    assert "the lead-in, not learned from" not in res.output
    assert np.all(errors[-1] < 0.5 * errors[1])  # learned: both axes' error halved at least
    saved = json.loads(state.read_text())
    assert saved["run"]["columns"] == ["x", "y"] and saved["sample_rate"] == 1000.0


def test_a_stage_run_refuses_what_does_not_belong_to_it(
    stage: tuple[Path, Path], tmp_path: Path
) -> None:
    model_file, raster = stage
    state, out = tmp_path / "learn.json", tmp_path / "next.csv"
    one_line_error(run("learn", model_file, "--desired", raster, *LIMITS, "--state", state,
                       "-o", out), "give one desired column each (--column x,y)")  # fmt: skip
    assert_clean_error(run("learn", model_file, "--desired", raster, "--column", "x,y",
                           "--state", state, "-o", out), code=2)  # fmt: skip  # no limits
    assert_clean_error(run("learn", model_file, "--desired", raster, "--column", "x,y", *LIMITS,
                           "--sensor", "--state", state, "-o", out), code=2)  # fmt: skip
    assert not state.exists()
    assert run("learn", model_file, "--desired", raster, "--column", "x,y", *LIMITS,
               "--state", state, "-o", out).exit_code == 0  # fmt: skip
    benches = [Bench(seed=i) for i in range(2)]
    recording = _trial(out, benches, tmp_path / "trial0.csv")
    one_line_error(run("learn", model_file, recording, "--v-min", "0", "--v-max", "120",
                       "--slew-rate", "30000", "--state", state, "-o", out, "--force"),
                   "started with --v-max [140.0, 140.0]")  # fmt: skip
    shifted = ph.read_table(recording)
    ph.write_table(tmp_path / "other.csv",
                   {"time": shifted.get("time"), "voltage_0": shifted.get("voltage_0"),
                    "voltage_1": shifted.get("voltage_1") + 5.0 * np.sin(shifted.get("time")),
                    "x": shifted.get("x"), "y": shifted.get("y")})  # fmt: skip
    again = ("--state", state, "-o", out, "--force")
    one_line_error(run("learn", model_file, tmp_path / "other.csv", *LIMITS, *again),
                   "(actuator 1) is not the command written")  # fmt: skip
    one_line_error(run("learn", model_file, recording, *LIMITS, "--reading-column", "x,z",
                       *again), "no reading column 'z'")  # fmt: skip
