"""``piezohyst report``: a model scored on a record, its figures and numbers in one folder."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import ExtrapolationWarning, ParameterError
from ..io import (
    DataSpec,
    atomic_folder,
)
from ..metrics import hysteresis_width, nrmse, rmse, run_on
from ..model.calibrations.output_map import OutputMap
from ..model.model import HysteresisModel
from ..model.state import predict_record
from ._base import (
    PathLike,
    Progress,
    _check_measured_unit,
    _load,
    check_folder,
    guard_outputs,
    warn_clipped,
)
from .calibrate_files import _sensor_spec

__all__ = ["ReportResult", "model_report"]


@dataclass(frozen=True)
class ReportResult:
    """Metrics and files written by :func:`model_report`.

    Attributes
    ----------
    metrics : dict
        Metric key to value (units in ``metrics.json``).
    files : list of Path
        Figures, ``metrics.json``, ``report.md`` and ``report.html``.
    """

    metrics: dict[str, Any]
    files: list[Path]


def model_report(
    model_path: PathLike,
    data: PathLike,
    out: PathLike,
    *,
    data_spec: DataSpec | None = None,
    command: str | None = None,
    force: bool = False,
    progress: Progress = None,
    gain: float | OutputMap | None = None,
    displacement_column: str | None = None,
    displacement_unit: str | None = None,
    displacement_scale: str | float | None = None,
) -> ReportResult:
    """A report a lab can file on a model and a data file (HTML, Markdown, JSON, figures).

    With ``gain`` (m/C, or the map :func:`calibrate_gain` identified) the report adds
    the displacement the model predicts from the voltage (its capacitor charge, growth
    removed, through the map), in metres; with ``displacement_column`` too, scored
    against that sensor (the map's delay applied).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    data : str or os.PathLike
        The recording to check it on.
    out : str or os.PathLike
        The report folder; an existing one that does not hold a piezohyst
        report is refused unless ``force`` (see :func:`guard_outputs`).
    data_spec : DataSpec, optional
        Columns, units and time window.
    command : str, optional
        The command line that made the report, recorded in it.
    force : bool, default False
        Replace an existing folder piezohyst did not write.
    progress : callable, optional
        Called with the rows read so far.
    gain : float or OutputMap, optional
        From the capacitor charge to displacement.
    displacement_column : str, optional
        A displacement sensor's column to score the displacement against (needs ``gain``).
    displacement_unit : str, optional
        Its unit if its header does not say (um, nm, m...); converted to m.
    displacement_scale : str or float, optional
        What one unit of it is worth, for a sensor logged in V (``"10 um/V"``).

    Returns
    -------
    ReportResult
    """
    from ..analysis.report import Report

    guard_outputs(
        [check_folder(out, "the figures and the report")], [model_path, data], force=force
    )
    spec = data_spec or DataSpec()
    model = _load(model_path)
    if displacement_column is not None and gain is None:
        msg = ("a displacement column is scored through the map from charge to displacement: "
               "give the gain (m/C) or the map calibrate-gain wrote")  # fmt: skip
        raise ParameterError(msg)
    rec = spec.read(data, progress=progress)
    sensor = None
    if displacement_column is not None:
        sensor = _sensor_spec(
            spec, displacement_column, displacement_unit, displacement_scale
        ).read(data)
    w = rec.window  # the model runs over the whole record: the window's start has a history
    end = rec.x.size if w.stop is None else w.stop  # nothing after the window is run
    pred = predict_record(model, rec.x[:end], rec.t[:end])[w]
    assert rec.y is not None
    _check_measured_unit(rec.units[1], model, data)
    x, y, t = rec.x[w], rec.y[w], rec.t[w]
    warn_clipped([y], rec.names[1], rec.units[1], data)
    with atomic_folder(out) as folder:  # all or nothing: Ctrl-C leaves no partial folder
        rep = _report(model, rec, pred, Report(f"{type(model).__name__} on {Path(data).name}",
                      folder), (x, y, t), (model_path, data, command))  # fmt: skip
        if gain is not None:
            charge = model.hysteresis_.predict(rec.x[:end], t=rec.t[:end])[w]
            measured = None if sensor is None or sensor.y is None else sensor.y[w]
            _in_metres(rep, x, t, charge, gain, measured)
        files = [Path(out) / f.name for f in rep.write()]
    return ReportResult({m.key: m.value for m in rep.metrics}, files)


def _report(
    model: HysteresisModel,
    rec: Any,
    pred: FloatArray,
    rep: Any,
    xyt: tuple[FloatArray, FloatArray, FloatArray],
    sources: tuple[PathLike, PathLike, str | None],
) -> Any:
    """The report's metadata, tables, metrics and figures (written by the caller)."""
    from ..analysis.report import file_facts

    x, y, t = xyt
    model_path, data, command = sources
    w = rec.window
    in_u, out_u = model.input_unit, model.output_unit
    rep.metadata = {
        "written": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": command or "(called from Python)",
        "data_file": file_facts(data),
        "model_file": file_facts(model_path),
        "columns": dict(zip(("input", "output", "time"), rec.names, strict=True)),
        "time_window_s": [float(t[0]), float(t[-1])],
        "units": {"input": in_u, "output": out_u, "time": "s"},
    }
    rep.tables["Model"] = [
        ("class", type(model).__name__),
        *[(f"setting {k}", _setting(v)) for k, v in model.params_to_json().items()],
        *model.operator_.describe(in_u, out_u),
        (
            "training input range",
            f"{model.input_range_[0]:.6g} to {model.input_range_[1]:.6g} {in_u}",
        ),
        *[(k, f"{v:.6g} {u}") for k, (v, u) in model.coefficients().items()],
        (
            "input dynamics",
            "none"
            if not model.input_dynamics_.active
            else f"{model.input_dynamics_.kind}: lag {model.input_dynamics_.tau * 1e3:.4g} ms, "
            f"delay {model.input_dynamics_.delay * 1e3:.4g} ms",
        ),
    ]
    if model.output_dynamics_.active:
        rep.add("output_mode_hz", "output mode: resonance", model.output_dynamics_.f0, "Hz")
        rep.add("output_mode_zeta", "output mode: damping ratio", model.output_dynamics_.zeta, "")
    if model.input_dynamics_.active:
        rep.add("input_lag_s", "input dynamics: lag", model.input_dynamics_.tau, "s")
        rep.add("input_delay_s", "input dynamics: delay", model.input_dynamics_.delay, "s")
    err = y - pred
    rep.add("samples", "samples", int(x.size))
    _windows(rep, model, t)
    nrmse_pct = 100 * nrmse(y, pred)
    rep.add("nrmse_pct", "NRMSE (RMSE / output span)", nrmse_pct, "%")
    zero_pct = 100 * nrmse(y, np.zeros_like(y))
    rep.add("nrmse_zero_pct", "NRMSE of predicting zero (the baseline)", zero_pct, "%")
    if nrmse_pct >= zero_pct:
        rep.add("verdict", "verdict", "worse than predicting zero: the model does not describe "
                "this record (check the columns, units and the model's class)")  # fmt: skip
    rep.add("rmse", "RMSE", rmse(y, pred), out_u)
    rep.add("max_abs_error", "largest error", float(np.max(np.abs(err))), out_u)
    rep.add("hysteresis_width_measured_pct", "hysteresis width, measured",
            100 * hysteresis_width(x, y), "%")  # fmt: skip
    lo, hi = model.input_range_
    if not math.isnan(lo):
        outside = int(np.count_nonzero((x < lo - 1e-9) | (x > hi + 1e-9)))
        rep.add("samples_outside_training_range", "samples outside the training range", outside)
    # the model a wide pale band beneath, the measured line thin on top: both stay visible
    measured = {"color": "0.2", "lw": 0.8, "zorder": 3}
    model_line = {"color": "C0", "lw": 3.0, "alpha": 0.45, "zorder": 2}
    rep.figure("loop.png", "input-output loop: data (dark line) and model (blue band)", [
        {"curves": [(x, y, "measured", measured), (x, pred, "model", model_line)],
         "xlabel": "input", "xunit": in_u, "ylabel": "output", "yunit": out_u, "title": ""},
    ])  # fmt: skip
    caption = f"output over time, and the residual (NRMSE {nrmse_pct:.3g} %)"
    rep.figure("fit.png", caption, [
        {"curves": [(t, y, "measured", measured), (t, pred, "model", model_line)],
         "xlabel": "time", "xunit": "s", "ylabel": "output", "yunit": out_u},
        {"curves": [(t, err, "measured - model", {"lw": 0.7, "color": "C3"})],
         "xlabel": "time", "xunit": "s", "ylabel": "residual", "yunit": out_u},
    ], stacked=True)  # fmt: skip
    growth = model.growth_coefficients()
    dyn = model.input_dynamics_  # the piezo's voltage, where a lag was identified
    driven = dyn.apply(rec.x, np.r_[0.0, np.diff(rec.t)])[0][w] if dyn.active else x
    pure = y - model.growth(rec.x, t=rec.t)[w] if growth else y  # eq. 19: growth removed
    share, far, turns = run_on(driven, pure)
    if turns:  # what no model whose branches rise with the input can follow
        rep.add("run_on_pct", f"output's run-on past the input's turns (median of {turns} "
                "turns; rising branches: none)", 100 * share, "%")  # fmt: skip
        rep.add("run_on_input", "the input's way back where the run-on peaks", far, in_u)
    if growth:
        for k, (v, u) in growth.items():
            rep.add(f"growth_{k}", f"growth term {k}", v, u)
        rep.add("hysteresis_width_growth_removed_pct", "hysteresis width, growth removed",
                100 * hysteresis_width(x, pure), "%")  # fmt: skip
        rep.figure("growth_removed.png", "identified growth removed (eq. 19)", [
            {"curves": [(x, y, "measured", {"lw": 0.7, "color": "0.55"}),
                        (x, pure, "growth removed", {"lw": 1.1, "color": "C1"})],
             "xlabel": "input", "xunit": in_u, "ylabel": "output", "yunit": out_u},
        ])  # fmt: skip
    chosen = "+".join(k for k in growth) or "none"
    for label, score in model.selection_.items():  # the term selection, fold by fold
        folds = ", ".join(f"{f:.4g}" for f in model.selection_folds_.get(label, []))
        mark = " (chosen)" if label == chosen else ""
        rep.add(f"selection_{label}", f"held-out RMSE, growth {label}{mark}",
                f"{score:.4g} {out_u}; per fold: {folds}")  # fmt: skip
    return rep


def _in_metres(
    rep: Any,
    x: FloatArray,
    t: FloatArray,
    charge: FloatArray,
    gain: float | OutputMap,
    measured: FloatArray | None,
) -> None:
    """The displacement predicted from the voltage through the capacitor charge and the
    map (or gain), in metres; scored against a sensor's reading when there is one."""
    if isinstance(gain, OutputMap):
        lo, hi = gain.charge_range
        outside = int(np.count_nonzero((charge < lo) | (charge > hi)))
        dt = float(np.median(np.diff(t))) if t.size > 1 else math.inf
        with warnings.catch_warnings():  # counted and reported below, not warned per call
            warnings.simplefilter("ignore", ExtrapolationWarning)
            s = gain.respond(charge, dt) if t.size > 1 else gain.predict(charge)  # its mode too
        rep.add("map", "map from charge to displacement", gain.summary())
        rep.add("map_stderr_max", "the map's standard error, largest over this record",
                float(np.max(gain.stderr(charge))), "m")  # fmt: skip
        rep.add("samples_outside_map_range", "samples whose charge lies outside the map's "
                "calibrated range (extended linearly)", outside)  # fmt: skip
        shift = min(round(gain.delay / dt), t.size // 2)
    else:
        s, shift = gain * (charge - charge[0]), 0  # a gain alone does not know the sensor's zero
        rep.add("gain", "gain from charge to displacement", gain, "m/C")
    band = {"color": "C0", "lw": 3.0, "alpha": 0.45, "zorder": 2}  # as the charge's figures
    thin = {"color": "0.2", "lw": 0.8, "zorder": 3}
    curves = [(x, s, "predicted from the charge", band)]
    panels: list[dict[str, Any]] = [
        {"curves": [(t, s, "predicted", band)], "xlabel": "time", "xunit": "s",
         "ylabel": "displacement", "yunit": "m"},
    ]  # fmt: skip
    caption = "displacement predicted from the voltage through the charge model and the map"
    if measured is not None:
        n = t.size - shift  # the sensor reads the displacement ``shift`` samples late
        got, want = s[:n], measured[shift:]
        centred = (got - got.mean()) - (want - want.mean())
        if isinstance(gain, OutputMap):
            rep.add("displacement_nrmse_pct", "displacement NRMSE (the sensor's reading)",
                    100 * nrmse(want, got), "%")  # fmt: skip
        free = 100 * float(np.sqrt(np.mean(centred**2)) / np.ptp(want))
        rep.add("displacement_nrmse_offset_free_pct", "displacement NRMSE, offsets removed",
                free, "%")  # fmt: skip
        rep.add("displacement_rmse_offset_free", "displacement RMSE, offsets removed",
                float(np.sqrt(np.mean(centred**2))), "m")  # fmt: skip
        curves.insert(0, (x[:n], want, "sensor", thin))
        panels[0]["curves"].insert(0, (t[:n], want, "sensor", thin))
        panels.append({"curves": [(t[:n], centred, "predicted - sensor, offsets removed",
                                   {"lw": 0.7, "color": "C3"})], "xlabel": "time",
                       "xunit": "s", "ylabel": "residual", "yunit": "m"})  # fmt: skip
        caption += f" and the sensor (offset-free NRMSE {free:.3g} %)"
    rep.figure("displacement_loop.png", "displacement against voltage, in metres", [
        {"curves": curves, "xlabel": "input", "xunit": "V", "ylabel": "displacement",
         "yunit": "m", "title": ""},
    ])  # fmt: skip
    rep.figure("displacement.png", caption, panels, stacked=True)


def _setting(value: object) -> str:
    """A model setting as a reader wants it: text bare, lists joined, none as 'default'."""
    if value is None:
        return "default"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return value
    if isinstance(value, list | tuple):
        return ", ".join(_setting(v) for v in value) or "none"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {_setting(v)}" for k, v in value.items()) or "none"
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _windows(rep: Any, model: HysteresisModel, t: FloatArray) -> None:
    """Which part of the record trained the model and how much of the scored part it never
    saw (by time: when the report's record is the one the model was fitted on)."""
    t0, t1 = model.train_window_
    a, b = float(t[0]), float(t[-1])
    rep.add("scored_window_s", "scored window", f"{a:.6g} to {b:.6g}", "s")
    if not (math.isfinite(t0) and math.isfinite(t1)):
        rep.add("training_window_s", "training window", "unknown (not in the model file)")
        return
    rep.add("training_window_s", "training window (of the record it was fitted on)",
            f"{t0:.6g} to {t1:.6g}", "s")  # fmt: skip
    unseen = float(np.mean((t < t0) | (t > t1)))
    rep.add("held_out_pct", "scored samples outside the training window (held out, if this "
            "is the record it was fitted on)", 100 * unseen, "%")  # fmt: skip


def _fmt(values: FloatArray) -> str:
    return ", ".join(f"{v:.6g}" for v in values)
