"""``piezohyst fit`` with several input and output columns: a coupled stage from one file
(issue 57)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import piezohyst as ph
from piezohyst.simulation import XY_COUPLING, make_signal, simulate_stage

from ..helpers import assert_clean_error, one_line_error, run


def _stage_file(tmp_path: Path) -> Path:
    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t, seed=0)
    path = tmp_path / "stage.csv"
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
