"""Fleet calibration: one model per unit on Dask, a summary that names failures and
outliers, the local pool and a dask.distributed cluster giving the same models."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result

import piezohyst as ph
from piezohyst.cli import main
from piezohyst.workflows import fit_file
from piezohyst.workflows.fleet import fit_many, units_of

N = 3000


def _unit(seed: int, *, wide: bool = False, dead: bool = False) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 1e3
    v = 70.0 - 70.0 * np.cos(2 * np.pi * 1.0 * t) * np.exp(-t / 1.5)
    w = np.array([1e-8, 3e-9, 2e-9, 1e-9]) * (1 + 0.03 * rng.standard_normal())
    if wide:
        w[1:] *= 4  # four times the hysteresis of its siblings
    q = ph.PIHysteresis([0.0, 10.0, 25.0, 45.0], w).predict(v) + 1e-10 * np.cumsum(v) / 1e3
    q += rng.normal(0.0, 3e-11, N)
    return {"time": t, "voltage": np.full(N, 3.0) if dead else v, "charge": q}


@pytest.fixture(scope="module")
def line(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Eight units off a production line: unit 3 has a defect, unit 5 never moved."""
    folder = tmp_path_factory.mktemp("line")
    paths = []
    for i in range(8):
        path = folder / f"unit{i}.csv"
        ph.write_table(path, _unit(i, wide=i == 3, dead=i == 5))
        paths.append(path)
    return paths


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        next(fh)  # the piezohyst marker line
        return list(csv.DictReader(fh))


def test_every_unit_gets_its_own_model_and_a_row(line: list[Path], tmp_path: Path) -> None:
    seen: list[tuple[int, int]] = []
    result = fit_many(line, tmp_path / "models", operators=6, workers=2,
                      progress=lambda done, total: seen.append((done, total)))  # fmt: skip
    assert seen[-1] == (8, 8)
    assert [r["unit"] for r in result.rows] == [f"unit{i}" for i in range(8)]
    assert [r["unit"] for r in result.failed] == ["unit5"]
    assert "never moves" in result.failed[0]["error"]
    assert [r["unit"] for r in result.outliers] == ["unit3"]
    assert "width" in result.outliers[0]["outlier"]
    # each model is the one fit_file gives for that recording alone
    for i in (0, 3, 7):
        saved = ph.load_model(tmp_path / "models" / f"unit{i}.json")
        alone = fit_file(line[i], operators=6)
        np.testing.assert_array_equal(saved.weights_, alone.weights_)
    assert not (tmp_path / "models" / "unit5.json").exists()
    rows = _rows(tmp_path / "models" / "summary.csv")
    assert [r["status"] for r in rows].count("failed") == 1
    ok = [r for r in rows if r["status"] == "ok"]
    assert all(float(r["nrmse [%]"]) < 1.0 and float(r["integral"]) > 0 for r in ok)  # in %
    widths = [float(r["width [%]"]) for r in ok if r["unit"] != "unit3"]
    assert max(widths) < float(next(r["width [%]"] for r in ok if r["unit"] == "unit3")) / 2
    # a second run replaces its own outputs without --force
    again = fit_many(line[:2], tmp_path / "models", operators=6, workers=1)
    assert not again.failed


def test_channels_of_one_file_are_units(tmp_path: Path) -> None:
    a, b = _unit(1), _unit(2, wide=True)
    path = tmp_path / "mirror.parquet"
    ph.write_table(path, {"time": a["time"], "v0": a["voltage"], "q0": a["charge"],
                          "v1": b["voltage"], "q1": b["charge"]})  # fmt: skip
    result = fit_many([path], tmp_path / "m", operators=6, workers=1,
                      channels=[("v0", "q0"), ("v1", "q1")],
                      summary=tmp_path / "m" / "fleet.parquet")  # fmt: skip
    assert [r["unit"] for r in result.rows] == ["mirror:v0", "mirror:v1"]
    assert (tmp_path / "m" / "mirror-v1.json").exists()
    import pyarrow.parquet as pq

    table = pq.read_table(result.summary).to_pydict()
    assert table["unit"] == ["mirror:v0", "mirror:v1"]
    assert table["width [%]"][1] > 2 * table["width [%]"][0]
    assert ph.io.is_piezohyst_output(result.summary)


def test_bad_fleets_are_refused_before_any_work(line: list[Path], tmp_path: Path) -> None:
    twin = tmp_path / "other"
    twin.mkdir()
    (twin / "unit0.csv").write_bytes(line[0].read_bytes())
    with pytest.raises(ph.ParameterError, match="two units are named 'unit0'"):
        units_of([line[0], twin / "unit0.csv"])
    with pytest.raises(ph.ParameterError, match="n_operators"):
        fit_many(line, tmp_path / "x", operators=0)
    with pytest.raises(ph.ParameterError, match="'growth_terms' setting does not apply"):
        fit_many(line, tmp_path / "x", model="classical-pi", growth_terms=("time",))
    with pytest.raises(ph.ParameterError, match="'creep' setting does not apply"):
        fit_many(line, tmp_path / "x", model="active-pi", creep=(0.1,))
    (tmp_path / "y").mkdir()
    (tmp_path / "y" / "summary.csv").write_text("my notes\n")
    with pytest.raises(ph.errors.OverwriteError, match="piezohyst did not write"):
        fit_many(line, tmp_path / "y", operators=6)


def run(*args: str | Path) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args])


def test_cli_fit_many_reports_failures_and_outliers(line: list[Path], tmp_path: Path) -> None:
    res = run("fit-many", *line, "-o", tmp_path / "out", "--operators", "6", "--workers", "2")
    assert res.exit_code == 1, res.output  # one unit failed: the status says so
    assert "fitted 7 of 8 units; 1 failed, 1 flagged as outliers" in res.output
    assert "failed  unit5: the input never moves" in res.output
    assert "outlier unit3: " in res.output
    assert len(list((tmp_path / "out").glob("unit*.json"))) == 7
    res = run("fit-many", line[0], "-o", tmp_path / "o2", "--channel", "voltage")
    assert res.exit_code == 2 and "expected IN:OUT" in res.output


def test_cli_fit_many_expands_a_pattern_the_shell_did_not(line: list[Path], tmp_path: Path) -> None:
    """``fit-many line/*.csv`` from a Windows prompt arrives as the pattern itself ("no such
    file"): it is expanded, in order of the names; a pattern that matches nothing is named."""
    folder = line[0].parent
    res = run("fit-many", folder / "unit[01].csv", "-o", tmp_path / "p", "--operators", "6",
              "--workers", "1")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "fitted 2 of 2 units" in res.output
    assert sorted(p.name for p in (tmp_path / "p").glob("*.json")) == ["unit0.json", "unit1.json"]
    res = run("fit-many", folder / "nothing*.csv", "-o", tmp_path / "q")
    assert res.exit_code == 2 and "no file matches" in res.output


def test_cli_fit_many_takes_the_terms_fit_takes(line: list[Path], tmp_path: Path) -> None:
    """Every unit with the same growth terms and creep operators as `fit` would give one (the
    field's standard, PI with creep, for a line of actuators); they were fit's alone."""
    res = run("fit-many", *line[:2], "-o", tmp_path / "g", "--model", "generalized-pi",
              "--operators", "6", "--growth", "integral", "--creep", "0.1,1",
              "--workers", "1")  # fmt: skip
    assert res.exit_code == 0, res.output
    for unit in ("unit0", "unit1"):
        model = ph.load_model(tmp_path / "g" / f"{unit}.json")
        assert model.growth_terms_ == ("integral",)
        np.testing.assert_array_equal(model.creep_taus_, [0.1, 1.0])
        alone = ph.GeneralizedPI(6, growth_terms=("integral",), creep=(0.1, 1.0))
        rec = ph.read_table(line[int(unit[-1])])
        alone.fit(rec.get("voltage"), rec.get("charge"), t=rec.get("time"))
        # tol: the same fit from the same file (a CSV's decimal digits, read the same way)
        assert model.nrmse_ == pytest.approx(alone.nrmse_, rel=1e-9)
    res = run("fit-many", line[0], "-o", tmp_path / "a", "--creep", "0.1")
    assert res.exit_code == 1 and "'creep' setting does not apply to active-pi" in res.output


def test_the_same_command_runs_on_a_dask_cluster(line: list[Path], tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://")
        res = run("fit-many", *line[:4], "-o", tmp_path / "cluster", "--operators", "6",
                  "--scheduler", address)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "fitted 4 of 4 units" in res.output
    local = fit_many(line[:4], tmp_path / "local", operators=6, workers=1)
    on_cluster = _rows(tmp_path / "cluster" / "summary.csv")
    assert [r["nrmse [%]"] for r in on_cluster] == [repr(100 * r["nrmse"]) for r in local.rows]
    for i in range(4):
        a = json.loads((tmp_path / "cluster" / f"unit{i}.json").read_text())
        b = json.loads((tmp_path / "local" / f"unit{i}.json").read_text())
        assert a["fitted"] == b["fitted"]
    res = run("fit-many", line[0], "-o", tmp_path / "nowhere", "--scheduler",
              "tcp://127.0.0.1:9")  # fmt: skip
    assert res.exit_code == 1 and "cannot reach the Dask scheduler" in res.output
