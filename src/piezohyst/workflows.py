"""File-to-file workflows: what each ``piezohyst`` command does, callable from Python.

Each function reads its inputs, calls the library, and writes its outputs
atomically (a failure leaves no output file). The CLI is a thin shell over
these; from Python they are one call each too::

    import piezohyst.workflows as wf
    model = wf.fit_file("run.csv", "model.json", model="active-pi", operators=20)
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._validation import FloatArray, check_float, check_int
from .compensator import Compensator, CompensatorSettings
from .errors import DataFileError, ParameterError
from .export import Precision, write_c
from .identification import default_thresholds, history_state
from .io import DataSpec, atomic_write_text, read_table, write_table
from .metrics import hysteresis_width, nrmse, rmse
from .models import HysteresisModel, model_class
from .persistence import load_model
from .plotting import save_panels
from .simulation import DEFAULT_PRESET, PRESETS, BenchRecord, simulate

__all__ = [
    "compensate_file",
    "export_c_file",
    "fit_file",
    "model_report",
    "predict_file",
    "simulate_file",
]

PathLike = str | os.PathLike[str]
_DEFAULT_SETTINGS = CompensatorSettings()  # frozen: safe as a shared default


def simulate_file(
    out: PathLike,
    *,
    preset: str = DEFAULT_PRESET,
    signal: str = "hold",
    amplitude: float | None = None,
    frequency: float = 0.5,
    duration: float = 20.0,
    rate: float | None = None,
    seed: int = 0,
) -> BenchRecord:
    """Run the simulated bench and write ``time,voltage,charge,displacement`` (s, V, C, m)."""
    if preset not in PRESETS:
        msg = f"unknown preset {preset!r}; available: {', '.join(PRESETS)}"
        raise ParameterError(msg)
    p = PRESETS[preset]
    if rate is not None:
        p = dataclasses.replace(
            p, rate=check_float(rate, "rate", "simulate", 0.0, 1e7, low_open=True)
        )
    rec = simulate(
        preset=p,
        signal=signal,
        amplitude=amplitude,
        frequency=frequency,
        duration=duration,
        seed=check_int(seed, "seed", "simulate", 0, 2**32 - 1),
    )
    write_table(
        out,
        {
            "time": rec.t,
            "voltage": rec.voltage,
            "charge": rec.charge,
            "displacement": rec.displacement,
        },
    )
    return rec


def fit_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    model: str = "active-pi",
    operators: int = 10,
    data_spec: DataSpec | None = None,
    output_unit: str = "C",
    growth_terms: str | Sequence[str] = "auto",
    creep: Sequence[float] = (),
) -> HysteresisModel:
    """Fit a model to a data file and save it (JSON) to ``out`` if given.

    Parameters
    ----------
    data : str or os.PathLike
        The recording.
    out : str or os.PathLike, optional
        Where to save the model.
    model : str
        A name from :func:`~piezohyst.models.model_names`.
    operators : int
        Play operators.
    data_spec : DataSpec, optional
        Columns and samples (default: voltage, charge, time).
    output_unit : str
        Unit recorded with the model.
    growth_terms, creep
        Settings of models that have them (``generalized-pi``).

    Returns
    -------
    HysteresisModel
        The fitted model.
    """
    cls = model_class(model)
    accepted = cls().get_params()
    extra: dict[str, Any] = {}
    for name, value, default in (("growth_terms", growth_terms, "auto"), ("creep", creep, ())):
        if name in accepted:
            extra[name] = tuple(value) if name == "creep" else value
        elif (value if isinstance(value, str) else tuple(value)) != default:
            msg = f"the {name!r} setting does not apply to {model}"
            raise ParameterError(msg)
    rec = (data_spec or DataSpec()).read(data)
    assert rec.y is not None
    w = rec.window
    x, y, t = rec.x[w], rec.y[w], rec.t[w]
    fitted: HysteresisModel
    settings: dict[str, Any] = {"n_operators": operators, "output_unit": output_unit, **extra}
    estimator = cls(**settings)
    start = w.start or 0
    if start > 0:  # the window continues a known input history: start from its state
        thresholds = default_thresholds(x, check_int(operators, "operators", "fit", 1, 1000))
        estimator = cls(**{**settings, "thresholds": thresholds})
        z0 = history_state(rec.x[:start], thresholds)
        fitted = estimator.fit(x, y, t=t, initial_state=z0)
    else:
        fitted = estimator.fit(x, y, t=t)
    if out is not None:
        fitted.save(out)
    return fitted


def _load(model_path: PathLike) -> HysteresisModel:
    model: HysteresisModel = load_model(model_path)
    return model


def predict_file(
    model_path: PathLike,
    data: PathLike,
    out: PathLike,
    *,
    data_spec: DataSpec | None = None,
) -> dict[str, FloatArray]:
    """Write ``time,predicted`` (plus ``measured`` when the data has the output column)."""
    model = _load(model_path)
    rec = (data_spec or DataSpec()).read(data, output_required=False)
    w = rec.window  # the model runs over the whole record: the window's start has a history
    columns: dict[str, FloatArray] = {
        "time": rec.t[w],
        "predicted": model.predict(rec.x, t=rec.t)[w],
    }
    if rec.y is not None:
        columns["measured"] = rec.y[w]
    write_table(out, columns)
    return columns


def compensate_file(
    model_path: PathLike,
    target: PathLike,
    out: PathLike,
    *,
    column: str | None = None,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
) -> Compensator:
    """Feedforward voltage for a desired trajectory; writes ``time,command,desired``.

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    target : str or os.PathLike
        The desired trajectory (a ``desired`` column, or the only one besides ``time``).
    out : str or os.PathLike
        Where to write the commands.
    column : str, optional
        The desired column's name.
    settings : CompensatorSettings
        Limits, domain, gain, slew rate.

    Returns
    -------
    Compensator
        After the run (its counters tell saturated and non-finite samples).
    """
    model = _load(model_path)
    table = read_table(target)
    if column is None:
        others = [c for c in table.columns if c != "time"]
        column = "desired" if "desired" in table else (others[0] if len(others) == 1 else None)
        if column is None:
            msg = (
                f"{target}: which column is the desired trajectory? Name it 'desired' or name "
                f"the column (columns: {', '.join(map(repr, table.columns))})"
            )
            raise DataFileError(msg)
    desired = table.get(table.resolve(column))
    comp = settings.build(model)
    if "time" in table:
        t = table.get("time")
    elif settings.sample_rate is not None:
        t = np.arange(desired.size) / float(settings.sample_rate)
    else:
        t = np.arange(desired.size, dtype=np.float64)
    write_table(out, {"time": t, "command": comp.process(desired), "desired": desired})
    return comp


def export_c_file(
    model_path: PathLike,
    out: PathLike,
    *,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precision: Precision = "double",
) -> tuple[Path, Path]:
    """Write ``NAME.c`` and ``NAME.h`` for the model's compensator (see :mod:`piezohyst.export`).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    out : str or os.PathLike
        The ``.c`` file.
    settings : CompensatorSettings
        Limits, domain, gain, slew rate.
    precision : {"double", "float"}
        The C type of every real.

    Returns
    -------
    tuple of Path
    """
    return write_c(settings.build(_load(model_path)), out, precision=precision)


@dataclass(frozen=True)
class ReportResult:
    """Metrics and files written by :func:`model_report`."""

    metrics: dict[str, Any]
    files: list[Path]


def model_report(
    model_path: PathLike,
    data: PathLike,
    out: PathLike,
    *,
    data_spec: DataSpec | None = None,
) -> ReportResult:
    """Figures (loop, fit, residual, growth removal) and metrics of a model on a data file."""
    model = _load(model_path)
    rec = (data_spec or DataSpec()).read(data)
    assert rec.y is not None
    w = rec.window  # the model runs over the whole record: the window's start has a history
    pred = model.predict(rec.x, t=rec.t)[w]
    x, y, t = rec.x[w], rec.y[w], rec.t[w]
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    in_u, out_u = model.input_unit, model.output_unit
    metrics: dict[str, Any] = {
        "model": type(model).__name__,
        "model_file": str(model_path),
        "data_file": str(data),
        "samples": int(x.size),
        "rmse": rmse(y, pred),
        "nrmse_pct": 100 * nrmse(y, pred),
        "max_abs_error": float(np.max(np.abs(y - pred))),
        "output_unit": out_u,
        "hysteresis_width_measured_pct": 100 * hysteresis_width(x, y),
    }
    lo, hi = model.input_range_
    if not math.isnan(lo):
        outside = int(np.count_nonzero((x < lo - 1e-9) | (x > hi + 1e-9)))
        metrics["samples_outside_training_range"] = outside
    files = [
        save_panels(
            out_dir / "loop.png",
            [
                {
                    "curves": [
                        (x, y, "measured", {"color": "0.6", "lw": 1.4}),
                        (x, pred, "model", {"lw": 0.9}),
                    ],
                    "xlabel": f"input ({in_u})",
                    "ylabel": f"output ({out_u})",
                    "title": "input-output loop",
                }
            ],
            suptitle=f"{type(model).__name__} on {Path(data).name}",
        ),
        save_panels(
            out_dir / "fit.png",
            [
                {
                    "curves": [
                        (t, y, "measured", {"color": "0.6", "lw": 1.4}),
                        (t, pred, "model", {"lw": 0.9}),
                    ],
                    "xlabel": "time (s)",
                    "ylabel": f"output ({out_u})",
                    "title": "output over time",
                },
                {
                    "curves": [(t, y - pred, "measured - model", {"lw": 0.7})],
                    "xlabel": "time (s)",
                    "ylabel": f"residual ({out_u})",
                    "title": f"residual (NRMSE {metrics['nrmse_pct']:.3f} %)",
                },
            ],
            suptitle="fit and residual",
        ),
    ]
    growth = model.growth_coefficients()
    if growth:
        pure = y - model.growth(rec.x, t=rec.t)[w]
        metrics["growth_terms"] = {k: {"value": v, "unit": u} for k, (v, u) in growth.items()}
        metrics["hysteresis_width_growth_removed_pct"] = 100 * hysteresis_width(x, pure)
        files.append(
            save_panels(
                out_dir / "growth_removed.png",
                [
                    {
                        "curves": [
                            (x, y, "measured", {"lw": 0.7}),
                            (x, pure, "growth removed (eq. 19)", {"lw": 1.1}),
                        ],
                        "xlabel": f"input ({in_u})",
                        "ylabel": f"output ({out_u})",
                        "title": "identified growth removed",
                    }
                ],
                suptitle="growth removal",
            )
        )
    mpath = out_dir / "metrics.json"
    atomic_write_text(mpath, json.dumps(metrics, indent=2) + "\n")
    lines = [f"# {metrics['model']} on {Path(data).name}", "", "| quantity | value |", "|---|---|"]
    lines += [
        f"| {k} | {v:.6g} |" if isinstance(v, float) else f"| {k} | {v} |"
        for k, v in metrics.items()
        if k != "growth_terms"
    ]
    lines += [f"| growth: {k} | {v:.6g} {u} |" for k, (v, u) in growth.items()]
    lines += ["", *[f"![{f.stem}]({f.name})" for f in files], ""]
    rpath = out_dir / "report.md"
    atomic_write_text(rpath, "\n".join(lines))
    return ReportResult(metrics, [*files, mpath, rpath])
