"""File workflows around a fitted model: compensate, export C, calibrate leakage, run the
closed loop on the bench, report. Each is one call of a CLI command (see
:mod:`piezohyst.workflows`, which re-exports them).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray, check_float, check_int
from ..control.calibration import OutputMap, calibrate_gain
from ..control.compensator import CompensatorSettings
from ..control.export.c_code import Precision, c_paths, write_c
from ..control.export.fmu import write_fmu
from ..control.export.shared import write_mex, write_shared
from ..control.selfsensing import LoopSettings
from ..errors import DataFileError, ExtrapolationWarning, ParameterError
from ..io import (
    DataSpec,
    atomic_folder,
    read_table,
    write_table,
)
from ..metrics import hysteresis_width, nrmse, rmse, run_on
from ..model.leakage import LEAKAGE_TERMS, Leakage, calibrate_leakage
from ..model.model import HysteresisModel
from ..model.state import predict_record
from ..simulation import (
    DEFAULT_PRESET,
    PRESETS,
    Bench,
    BenchRecord,
    ModelPlant,
    PlantRun,
    run_loop,
    run_on_model,
)
from ..units import to_standard
from ._base import (
    _DEFAULT_SETTINGS,
    PathLike,
    Progress,
    _check_measured_unit,
    _default_unit,
    _desired_column,
    _load,
    check_folder,
    check_rate,
    desired_unit,
    guard_outputs,
    standard_column,
    time_rate,
    warn_assumed_span,
    warn_clipped,
)

__all__ = [
    "LoopRun",
    "ReportResult",
    "calibrate_gain_file",
    "calibrate_leakage_file",
    "export_file",
    "model_report",
    "simulate_loop_file",
]


def export_file(
    model_path: PathLike,
    out: PathLike,
    *,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precision: Precision = "double",
    controller: LoopSettings | None = None,
    force: bool = False,
    shared: bool = False,
    mex: bool = False,
) -> tuple[Path, ...]:
    """Export the model's compensator: C sources ``NAME.c`` and ``NAME.h``
    (:mod:`~.control.export`), or where ``out`` ends in ``.fmu`` an FMI 2.0
    Co-Simulation FMU (:mod:`~.control.export.fmu`).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    out : str or os.PathLike
        The ``.c`` file, or the ``.fmu``.
    settings : CompensatorSettings
        Limits, domain, gain, slew rate (and the sample rate a controller or an FMU needs:
        one step of the FMU).
    precision : {"double", "float"}
        The C type of every real (an FMU's step; doubles outside).
    controller : LoopSettings, optional
        Export the self-sensing controller instead of the feedforward compensator.
    force : bool, default False
        Replace existing files piezohyst did not write.
    shared : bool, default False
        Add the shared-library API and build ``libNAME.so`` beside the sources
        (:mod:`~piezohyst.control.export.shared`).
    mex : bool, default False
        ``out`` is a MEX gateway (``NAME_mex.c``), written with the step it includes.

    Returns
    -------
    tuple of Path
        Source and header (and the library), or the FMU.
    """
    fmu = Path(out).suffix.lower() == ".fmu"
    if shared + mex + fmu > 1:
        msg = "--shared, --mex and an FMU build different things: choose one"
        raise ParameterError(msg)
    inputs: list[PathLike] = [model_path]
    if controller is not None and controller.leakage is not None:
        inputs.append(controller.leakage)
    if fmu:
        if Path(out).exists() and not force and not _our_fmu(Path(out)):
            msg = f"{out} exists and piezohyst did not write it: pass --force to replace it"
            raise ParameterError(msg)
    else:
        c_path, h_path, _ = c_paths(out)
        guard_outputs([c_path, h_path], inputs, force=force)
    model = _load(model_path)
    built = settings.build(model) if controller is None else controller.build(settings, model)
    if fmu:
        return (write_fmu(built, out, precision=precision),)
    if shared:
        return write_shared(built, out, precision=precision)
    if mex:
        return write_mex(built, out, precision=precision)
    return write_c(built, out, precision=precision)


def calibrate_leakage_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    data_spec: DataSpec | None = None,
    terms: Sequence[str] = LEAKAGE_TERMS,
    min_duration: float = 1.0,
    settle: float | str = "auto",
    force: bool = False,
) -> Leakage:
    """Calibrate the leakage from the holds of a record and save it (JSON) to ``out``.

    Parameters
    ----------
    data : str or os.PathLike
        A record with constant-voltage holds (voltage, charge, time).
    out : str or os.PathLike, optional
        Where to save the leakage.
    data_spec : DataSpec, optional
        Columns, units and window.
    terms : sequence of str
        Leakage terms to fit (see :func:`~piezohyst.model.leakage.calibrate_leakage`).
    min_duration, settle
        Hold detection and trim (see :func:`~piezohyst.model.leakage.calibrate_leakage`).
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    Leakage
    """
    if out is not None:
        guard_outputs([out], [data], force=force)
    rec = (data_spec or DataSpec()).read(data)
    assert rec.y is not None
    w = rec.window
    x_unit, y_unit = rec.units
    leak = calibrate_leakage(
        rec.t[w],
        rec.x[w],
        rec.y[w],
        terms=terms,
        min_duration=min_duration,
        settle=settle,
        input_unit=x_unit or "V",
        output_unit=y_unit or _default_unit(rec.names[1]),
    )
    if out is not None:
        leak.save(out)
    return leak


def _our_fmu(path: Path) -> bool:
    """An FMU piezohyst wrote (its modelDescription names the tool): safe to replace."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            return 'generationTool="piezohyst' in z.read("modelDescription.xml").decode()
    except (OSError, KeyError, zipfile.BadZipFile, UnicodeDecodeError):
        return False


def _sensor_spec(
    spec: DataSpec, column: str, unit: str | None, scale: str | float | None
) -> DataSpec:
    """``spec`` reading the displacement sensor's column as its output: its own unit and
    scale (never the charge channel's)."""
    return dataclasses.replace(spec, output_column=column, output_unit=unit, output_scale=scale)


def calibrate_gain_file(
    model_path: PathLike,
    data: PathLike,
    out: PathLike | None = None,
    *,
    displacement_column: str = "displacement",
    displacement_unit: str | None = None,
    displacement_scale: str | float | None = None,
    data_spec: DataSpec | None = None,
    force: bool = False,
) -> OutputMap:
    """Calibrate the charge -> displacement map from a record with a displacement sensor
    (voltage, charge and displacement sampled together) and save it (JSON) to ``out``.

    Parameters
    ----------
    model_path : str or os.PathLike
        A model fitted on voltage -> charge.
    data : str or os.PathLike
        The record: its voltage, charge and time columns as ``data_spec`` names them,
        and the displacement column.
    out : str or os.PathLike, optional
        Where to save the map.
    displacement_column : str, default "displacement"
    displacement_unit : str, optional
        Its unit if its header does not say (um, nm, m...); converted to m.
    displacement_scale : str or float, optional
        What one unit of it is worth, for a sensor logged in V (``"10 um/V"``).
    data_spec : DataSpec, optional
        Columns, units, scales and window of the voltage and charge.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    OutputMap
    """
    if out is not None:
        guard_outputs([out], [data, model_path], force=force)
    model = _load(model_path)
    spec = data_spec or DataSpec()
    rec = spec.read(data)
    sensor = _sensor_spec(spec, displacement_column, displacement_unit, displacement_scale).read(
        data
    )
    if rec.t is None:
        msg = f"{data}: calibrate-gain needs the time column (or --sample-rate)"
        raise DataFileError(msg)
    assert rec.y is not None and sensor.y is not None
    w = rec.window
    unit = sensor.units[1] or "m"
    if sensor.units[1] is None:
        span = float(np.ptp(sensor.y[w]))
        warn_assumed_span(span, "m", displacement_column, data, "--displacement-unit")
    om = calibrate_gain(model, rec.x[w], rec.y[w], sensor.y[w], rec.t[w], output_unit=unit)
    if out is not None:
        om.save(out)
    return om


@dataclass(frozen=True)
class LoopRun:
    """What :func:`simulate_loop_file` did.

    Attributes
    ----------
    record : BenchRecord
        Commands, readings and the bench's hidden truth.
    desired : ndarray
        The desired trajectory.
    width : float
        Hysteresis width desired → laser displacement (fraction of the span), from the
        sample the commands reached the trajectory on (see ``arrived``).
    nrmse : float
        Tracking NRMSE desired → laser displacement (displacement domain; else NaN), the same.
    saturated : int
        Commands clipped to the limits.
    arrived : int
        Samples before the commands reached the trajectory (the ramp from rest at the slew
        limit), left out of ``width`` and ``nrmse``: the ramp's error is the limit's, not the
        controller's (on the bench's 5-35 um target, 9 % NRMSE with it, 0.8 % without).
    plant : str
        Which actuator ran: the built-in bench (another actuator than a lab's), or the
        model file standing in for the lab's.
    """

    record: BenchRecord | PlantRun
    desired: FloatArray
    width: float
    nrmse: float
    saturated: int
    arrived: int = 0
    plant: str = ""


def simulate_loop_file(
    model_path: PathLike,
    target: PathLike,
    out: PathLike,
    *,
    column: str | None = None,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    loop: LoopSettings | None = None,
    preset: str = DEFAULT_PRESET,
    extra_bias: float = 0.0,
    seed: int = 0,
    force: bool = False,
    plant: PathLike | None = None,
) -> LoopRun:
    """Run a desired trajectory through a controller against the simulated bench, or
    against a model standing in for the lab's actuator (``plant``).

    Writes ``time, desired, command, charge, displacement`` (s, desired
    units, V, C, m): what the bench read after each command. ``loop=None``
    runs the feedforward compensator alone, otherwise the self-sensing
    controller. ``extra_bias`` (A) adds to the preset's amplifier bias
    current, a change the model never saw.

    Parameters
    ----------
    model_path, target, out : path
        A saved model, the desired trajectory (``time`` and ``desired``), the output.
    column : str, optional
        The desired column.
    settings : CompensatorSettings
        Limits, domain, gain, slew; the sample rate defaults to the preset's.
    loop : LoopSettings, optional
        The controller's settings; None: feedforward alone.
    preset : str
        Bench preset.
    extra_bias : float
        A (added to the preset's bias current).
    seed : int
        Noise seed.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.
    plant : path, optional
        A saved model standing in for the actuator (:class:`~piezohyst.simulation.ModelPlant`:
        the lab's own, not the built-in bench's physics; no noise). ``preset``,
        ``extra_bias`` and ``seed`` are the bench's and not used with it; the sample rate
        is the settings' (default the model's training record's).

    Returns
    -------
    LoopRun
        ``plant_name`` says which actuator ran.
    """
    inputs: list[PathLike] = [model_path, target]
    if plant is not None:
        inputs.append(plant)
    if loop is not None and loop.leakage is not None:
        inputs.append(loop.leakage)
    guard_outputs([out], inputs, force=force)
    if preset not in PRESETS:
        msg = f"unknown preset {preset!r}; available: {', '.join(PRESETS)}"
        raise ParameterError(msg)
    p = PRESETS[preset]
    p = dataclasses.replace(
        p, i_bias=p.i_bias + check_float(extra_bias, "extra_bias", "simulate-loop", -1e-6, 1e-6)
    )
    model = _load(model_path)
    table = read_table(target)
    name = _desired_column(table, column, target)
    desired = standard_column(table, name, "desired trajectory", "output",
                              desired_unit(settings, model))  # fmt: skip
    if plant is not None:  # the lab's plant runs at the loop's rate: the settings' or the target's
        rate = settings.sample_rate
        if rate is None and "time" in table:
            times = table.get("time")
            rate = time_rate(to_standard(times, table.unit("time"), "time", f"{target}: 'time'")[0])
        if rate is None:
            msg = f"{target} has no time column: give the loop's rate (--sample-rate)"
            raise ParameterError(msg)
        p = dataclasses.replace(p, rate=float(rate))
    fs = settings.sample_rate or p.rate
    if abs(fs - p.rate) > 1e-9 * p.rate:
        msg = f"the bench {preset} samples at {p.rate:g} Hz; the loop rate must be the same"
        if plant is not None:
            msg = f"{target} is timed at {p.rate:g} Hz; the loop rate must be the same"
        raise ParameterError(msg)
    if "time" in table:  # a target timed at another rate would be played at the bench's
        t = to_standard(table.get("time"), table.unit("time"), "time", f"{target}: column 'time'")
        played = "the target would be played at the bench's rate; resample it to that rate"
        check_rate(
            target, time_rate(t[0]), fs, f" and the bench {preset} samples at {fs:g} Hz: {played}"
        )
    settings = dataclasses.replace(settings, sample_rate=fs)
    ctl = settings.build(model) if loop is None else loop.build(settings, model)
    rec: BenchRecord | PlantRun
    if plant is None:
        bench = Bench(p, voltage=ctl.last_command,
                      seed=check_int(seed, "seed", "simulate-loop", 0, 2**32 - 1))  # fmt: skip
        rec = run_loop(ctl, desired, bench)
        name = (f"the built-in bench {preset!r} (another actuator than yours: "
                "--plant MODEL runs your own model as the plant)")  # fmt: skip
    else:
        stand_in = ModelPlant(_load(plant), fs, voltage=ctl.last_command,
                              gain=settings.output_map or settings.gain)  # fmt: skip
        rec = run_on_model(ctl, desired, stand_in)
        name = f"{Path(plant).name}, {stand_in.describe()}"
    write_table(
        out,
        {
            "time": rec.t,
            "desired": desired,
            "command": rec.voltage,
            "charge": rec.charge,
            "displacement": rec.displacement,
        },
        units={
            "time": "s",
            "desired": "m" if settings.domain == "displacement" else model.output_unit,
            "command": "V",
            "charge": "C",
            "displacement": "m",
        },
    )
    arrived = ctl.sent_count - ctl.command_count  # the ramp from rest at the slew limit
    ok = np.isfinite(desired)
    ok[:arrived] = False
    shown = rec.hysteresis if isinstance(rec, PlantRun) else rec.displacement
    width = hysteresis_width(desired[ok], shown[ok])
    err = (
        nrmse(desired[ok], rec.displacement[ok]) if settings.domain == "displacement" else math.nan
    )
    return LoopRun(rec, desired, width, err, ctl.saturated_count, arrived, name)


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
        with warnings.catch_warnings():  # counted and reported below, not warned per call
            warnings.simplefilter("ignore", ExtrapolationWarning)
            s = gain.predict(charge)
        rep.add("map", "map from charge to displacement", gain.summary())
        rep.add("map_stderr_max", "the map's standard error, largest over this record",
                float(np.max(gain.stderr(charge))), "m")  # fmt: skip
        rep.add("samples_outside_map_range", "samples whose charge lies outside the map's "
                "calibrated range (extended linearly)", outside)  # fmt: skip
        dt = float(np.median(np.diff(t))) if t.size > 1 else math.inf
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
