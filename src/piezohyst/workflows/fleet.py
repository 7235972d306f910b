"""Fleet calibration: fit one model per unit over many recordings, on Dask.

A production line calibrates every actuator; a mirror's actuators are recorded
channel by channel; a lab re-identifies its stages every morning. Each unit
(a recording, or an input/output column pair of one) is fitted independently
with the same settings, one model file per unit, and one summary table says
how every unit did: fit quality, identified range, hysteresis width, leakage,
and outlier flags against the rest of the fleet.

The units run as Dask tasks: by default on a local pool of processes (no
set-up: one per core), or on an existing ``dask.distributed`` cluster given
its scheduler address (workers must see the same files, e.g. a shared drive).
A unit that fails is a row of the summary with its reason; the others go on.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ParameterError, PiezohystError
from ..io import DataSpec, write_rows
from ..model.bank import model_width
from ._base import check_folder, guard_outputs
from .model_files import fit_file, model_terms

__all__ = ["FleetResult", "Unit", "fit_many", "units_of"]

PathLike = str | os.PathLike[str]

#: Robust z-score (median and MAD over the fleet) beyond which a unit is flagged.
OUTLIER_Z = 5.0
#: Fewest fitted units for outlier flags to mean anything.
OUTLIER_MIN_UNITS = 5


@dataclass(frozen=True)
class Unit:
    """One actuator to calibrate: a recording and the columns that are its input and output.

    Attributes
    ----------
    name : str
        Names its model file and its summary row.
    path : str
        The recording.
    spec : DataSpec
        Its columns, units, window and rate.
    """

    name: str
    path: str
    spec: DataSpec


def units_of(
    records: Sequence[PathLike],
    channels: Sequence[tuple[str, str]] = (),
    data_spec: DataSpec | None = None,
) -> list[Unit]:
    """The units of some recordings: one per file, or one per (input, output) column pair.

    Parameters
    ----------
    records : sequence of path
        Data files.
    channels : sequence of (str, str), optional
        Input and output column pairs, each a unit of every file (named
        ``<file stem>:<input column>``). Default: the file is one unit with
        the columns of ``data_spec``.
    data_spec : DataSpec, optional
        Columns, units, window and rate shared by all files.

    Returns
    -------
    list of Unit

    Raises
    ------
    ParameterError
        Two units would get the same name (two files with one stem).
    """
    base = data_spec or DataSpec()
    units: list[Unit] = []
    for record in records:
        p = Path(record)
        if not channels:
            units.append(Unit(p.stem, str(p), base))
        for x_col, y_col in channels:
            spec = replace(base, input_column=x_col, output_column=y_col)
            units.append(Unit(f"{p.stem}:{x_col}", str(p), spec))
    if not units:
        msg = "no recordings to fit: give at least one file"
        raise ParameterError(msg)
    seen: dict[str, str] = {}
    for u in units:
        if u.name in seen:
            msg = (
                f"two units are named {u.name!r} ({seen[u.name]} and {u.path}): model files "
                "are named after the recordings, so give the files distinct names"
            )
            raise ParameterError(msg)
        seen[u.name] = u.path
    return units


def _model_path(out_dir: Path, unit: Unit) -> Path:
    return out_dir / (unit.name.replace(":", "-").replace(os.sep, "_") + ".json")


def fit_unit(unit: Unit, out_dir: str, settings: dict[str, Any]) -> dict[str, Any]:
    """Fit and save one unit; a row of the summary (never raises for a bad recording).

    Runs in a Dask worker: everything it needs arrives as arguments, and it
    returns plain data.
    """
    if settings.get("single_threaded"):  # one process per core: no threads competing within
        _one_thread()
    settings = {k: v for k, v in settings.items() if k != "single_threaded"}
    target = _model_path(Path(out_dir), unit)
    row: dict[str, Any] = {"unit": unit.name, "file": unit.path, "model_file": str(target)}
    try:
        model = fit_file(unit.path, target, data_spec=unit.spec, force=True, **settings)
    except PiezohystError as exc:
        return {**row, "status": "failed", "error": str(exc), "model_file": ""}
    except (OSError, ValueError, MemoryError) as exc:  # an unreadable or corrupt file
        return {**row, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "model_file": ""}  # fmt: skip
    lo, hi = model.input_range_
    row.update(
        status="ok",
        error="",
        nrmse=model.nrmse_,
        rmse=model.rmse_,
        v_min=lo,
        v_max=hi,
        width=model_width(model),
    )
    for label, (value, _unit) in model.growth_coefficients().items():
        row[label] = value
    return row


def _one_thread() -> None:
    """Parse files and run BLAS on one thread in this worker (the pool has a process per core).

    Two processes each waking a thread per core would spin against each other.
    """
    import pyarrow as pa
    from threadpoolctl import threadpool_limits

    pa.set_cpu_count(1)
    global _LIMITS
    if _LIMITS is None:
        _LIMITS = threadpool_limits(1)


_LIMITS: object = None  # the worker's thread limits, set once per process


def _start_method() -> str:
    """How the local pool starts its processes: fork where the platform has it.

    A forked worker starts at once with piezohyst imported and its kernels
    loaded, and a user's script needs no ``if __name__ == "__main__":`` guard;
    the fitting code it runs takes no locks another thread could hold (Arrow
    resets its thread pools after a fork; the fit kernels are serial). Elsewhere
    (macOS, Windows) workers are spawned, and scripts need that guard.
    """
    import multiprocessing as mp
    import sys

    return "fork" if sys.platform == "linux" and "fork" in mp.get_all_start_methods() else "spawn"


def _flag_outliers(rows: list[dict[str, Any]], columns: Sequence[str]) -> None:
    """Flag units far from the fleet's median (robust z > OUTLIER_Z) in any column."""
    ok = [r for r in rows if r["status"] == "ok"]
    for r in rows:
        r["outlier"] = ""
    if len(ok) < OUTLIER_MIN_UNITS:
        return
    for col in columns:
        values = np.array([float(r.get(col, math.nan)) for r in ok])
        finite = np.isfinite(values)
        if finite.sum() < OUTLIER_MIN_UNITS:
            continue
        med = float(np.median(values[finite]))
        mad = 1.4826 * float(np.median(np.abs(values[finite] - med)))
        scale = max(mad, 1e-3 * abs(med), 1e-300)
        for r, v in zip(ok, values, strict=True):
            z = (v - med) / scale
            # a fit is bad only when worse than the fleet; the other columns both ways
            if math.isfinite(z) and (z > OUTLIER_Z if col == "nrmse" else abs(z) > OUTLIER_Z):
                r["outlier"] = ";".join(filter(None, [r["outlier"], col]))


@dataclass
class FleetResult:
    """What :func:`fit_many` did.

    Attributes
    ----------
    rows : list of dict
        One per unit, in the order given: ``unit``, ``file``, ``status``
        (``ok``/``failed``), ``error``, ``nrmse``, ``rmse``, ``v_min``,
        ``v_max``, ``width``, growth coefficients (e.g. ``integral``),
        ``outlier`` (columns in which the unit is far from the fleet),
        ``model_file``. NRMSE and width are fractions here; the summary file
        gives them in % (``nrmse [%]``, ``width [%]``), as the CLI prints them.
    summary : Path or None
        The summary table written.
    """

    rows: list[dict[str, Any]]
    summary: Path | None

    @property
    def failed(self) -> list[dict[str, Any]]:
        """Rows of the units that could not be fitted."""
        return [r for r in self.rows if r["status"] != "ok"]

    @property
    def outliers(self) -> list[dict[str, Any]]:
        """Rows of fitted units flagged as outliers."""
        return [r for r in self.rows if r["outlier"]]


def _columns(rows: list[dict[str, Any]]) -> list[str]:
    head = ["unit", "file", "status", "nrmse", "rmse", "v_min", "v_max", "width"]
    extra = sorted({k for r in rows for k in r} - {*head, "error", "outlier", "model_file"})
    return [*head, *extra, "outlier", "model_file", "error"]


def write_summary(path: PathLike, rows: list[dict[str, Any]]) -> Path:
    """The summary table as CSV (marked as piezohyst's) or Parquet.

    Parameters
    ----------
    path : path
        ``.parquet`` or a text file (CSV).
    rows : list of dict

    Returns
    -------
    Path
    """
    text = ("unit", "file", "status", "outlier", "model_file", "error")
    shown = [_with_units(r) for r in rows]
    return write_rows(path, shown, [SUMMARY_UNITS.get(c, (c, 1.0))[0] for c in _columns(rows)],
                      text)  # fmt: skip


#: The summary file's columns with their units in the header (the reader strips them),
#: and the factor from the rows' values: NRMSE and loop width in % as the CLI prints them
SUMMARY_UNITS = {
    "nrmse": ("nrmse [%]", 100.0),
    "width": ("width [%]", 100.0),
    "v_min": ("v_min [V]", 1.0),
    "v_max": ("v_max [V]", 1.0),
}


def _with_units(row: dict[str, Any]) -> dict[str, Any]:
    out = dict(row)
    for key, (label, factor) in SUMMARY_UNITS.items():
        if key in out:
            value = out.pop(key)
            out[label] = value * factor if isinstance(value, int | float) else value
    return out


def fit_many(
    records: Sequence[PathLike],
    out_dir: PathLike,
    *,
    model: str = "active-pi",
    operators: int = 10,
    data_spec: DataSpec | None = None,
    channels: Sequence[tuple[str, str]] = (),
    growth_terms: str | Sequence[str] = "default",
    creep: Sequence[float] = (),
    input_dynamics: str = "none",
    summary: PathLike | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> FleetResult:
    """Fit one model per unit, on Dask; write the models and a summary table.

    Parameters
    ----------
    records : sequence of path
        Data files (any format :func:`~piezohyst.io.read_table` reads).
    out_dir : path
        Folder for the models (``<unit>.json``) and, by default, the summary
        (``summary.csv``).
    model, operators, growth_terms, creep, input_dynamics
        As for :func:`~piezohyst.workflows.fit_file`, shared by all units.
    data_spec : DataSpec, optional
        Columns, units, window and rate shared by all files.
    channels : sequence of (str, str), optional
        Input/output column pairs: each is a unit of every file.
    summary : path, optional
        The summary table (``.csv`` or ``.parquet``).
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler
        (``tcp://host:8786``). Default: a local pool of processes.
    workers : int, optional
        Processes of the local pool (default: one per core).
    force : bool
        Replace existing outputs piezohyst did not write.
    progress : callable, optional
        Called with (units done, units in all).

    Returns
    -------
    FleetResult
    """
    out = check_folder(out_dir, "one model per unit and the summary")
    units = units_of(records, channels, data_spec)
    table = Path(summary) if summary is not None else out / "summary.csv"
    targets = [_model_path(out, u) for u in units]
    guard_outputs([*targets, table], [u.path for u in units], force=force)
    out.mkdir(parents=True, exist_ok=True)
    if workers is not None and (isinstance(workers, bool) or workers < 1):
        msg = f"'workers' must be a positive int. Got {workers!r}."
        raise ParameterError(msg)
    settings: dict[str, Any] = {
        "model": model,
        "operators": operators,
        "growth_terms": growth_terms,
        "creep": tuple(creep),
        "input_dynamics": input_dynamics,
    }
    # a bad setting is one error now, not the same error in every row
    fit_file_check(settings)
    if scheduler is None:
        rows = _run_local(units, str(out), settings, workers, progress)
    else:
        rows = _run_cluster(units, str(out), settings, scheduler, progress)
    _flag_outliers(
        rows,
        [
            c
            for c in _columns(rows)
            if c
            not in (
                "unit",
                "file",
                "status",
                "outlier",
                "model_file",
                "error",
                "rmse",
                "v_min",
                "v_max",
            )
        ],
    )
    return FleetResult(rows, write_summary(table, rows))


def fit_file_check(settings: dict[str, Any]) -> None:
    """Refuse settings no unit can be fitted with (unknown model, bad operator count)."""
    from ..model.persistence import model_class

    cls = model_class(settings["model"])
    params = cls().get_params()
    trial: dict[str, Any] = {"input_dynamics": settings["input_dynamics"]}
    if "n_operators" in params:
        trial["n_operators"] = settings["operators"]
    elif settings["operators"] != 10:
        msg = f"the 'operators' setting does not apply to {settings['model']}"
        raise ParameterError(msg)
    trial.update(model_terms(settings["model"], params, settings.get("growth_terms", "default"),
                             settings.get("creep", ())))  # fmt: skip
    cls(**trial).check_params()


def _run_local(
    units: list[Unit],
    out_dir: str,
    settings: dict[str, Any],
    workers: int | None,
    progress: Callable[[int, int], None] | None,
) -> list[dict[str, Any]]:
    import dask
    from dask.base import compute
    from dask.callbacks import Callback
    from dask.delayed import delayed

    n = workers or os.cpu_count() or 1
    settings = {**settings, "single_threaded": n > 1}
    tasks = [delayed(fit_unit, pure=False)(u, out_dir, settings) for u in units]
    done = [0]
    total = len(units)

    def posttask(key: Any, result: Any, dsk: Any, state: Any, worker_id: Any) -> None:
        if isinstance(result, dict) and "unit" in result:
            done[0] += 1
            if progress is not None:
                progress(done[0], total)

    with Callback(posttask=posttask):
        if n == 1:
            rows = compute(*tasks, scheduler="synchronous")
        else:
            with dask.config.set({"multiprocessing.context": _start_method()}):
                rows = compute(*tasks, scheduler="processes", num_workers=n, chunksize=1)
    return list(rows)


def _run_cluster(
    units: list[Unit],
    out_dir: str,
    settings: dict[str, Any],
    address: str,
    progress: Callable[[int, int], None] | None,
) -> list[dict[str, Any]]:
    from distributed import Client, as_completed

    try:
        client = Client(address, timeout="10s")
    except OSError as exc:
        msg = f"cannot reach the Dask scheduler at {address}: {exc}"
        raise ParameterError(msg) from None
    with client:
        futures = [client.submit(fit_unit, u, out_dir, settings, pure=False) for u in units]
        index = {f.key: i for i, f in enumerate(futures)}
        rows: list[dict[str, Any]] = [{} for _ in units]
        for k, fut in enumerate(as_completed(futures), 1):
            try:
                rows[index[fut.key]] = fut.result()
            except Exception as exc:  # a worker lost: that unit fails, not the fleet
                u = units[index[fut.key]]
                rows[index[fut.key]] = {
                    "unit": u.name,
                    "file": u.path,
                    "status": "failed",
                    "error": f"worker error: {exc}",
                    "model_file": "",
                }
            if progress is not None:
                progress(k, len(units))
    return rows
