"""``piezohyst fit``, ``predict`` and ``compensate`` with several input and output columns: a
coupled stage identified from one file (:class:`~piezohyst.CoupledModel`), saved as a coupled
model file, run on another record, and compensated (:class:`~piezohyst.CoupledCompensator`);
or a structure's coupled dynamics (:class:`~piezohyst.StructureModel`, ``fit --model
structure``), compensated by :class:`~piezohyst.StructureCompensator`."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._validation import FloatArray
from ..control.coupled import CoupledCompensator
from ..control.export.c_code import c_paths
from ..control.export.stage_c import (
    stage_paths,
    write_stage_c,
    write_stage_fmu,
    write_stage_mex,
    write_stage_shared,
)
from ..errors import DataFileError, ParameterError
from ..io import DataSpec, read_table, write_table
from ..model.coupled import COUPLED_FORMAT, CoupledModel
from ..model.persistence import model_class
from ..model.structure import STRUCTURE_FORMAT, StructureModel

if TYPE_CHECKING:
    from ..control.structure import StructureCompensator
from ._base import PathLike, guard_outputs

__all__ = [
    "StageRun",
    "compensate_stage_file",
    "export_stage_file",
    "fit_stage_file",
    "fit_structure_file",
    "holds_format",
    "is_stage_file",
    "predict_stage_file",
    "stage_columns",
]


@dataclasses.dataclass(frozen=True)
class StageRun:
    """What a stage's ``predict`` or ``compensate`` from files did.

    Attributes
    ----------
    samples : int
        Rows written.
    nrmse : tuple of float
        ``predict``: per axis, RMS error over the axis's measured span (empty without
        measured columns).
    compensator : CoupledCompensator or None
        ``compensate``: the compensator after the run (its counts per actuator).
    preamble : int
        ``compensate``: rows of the ramp from rest to the trajectory's start.
    """

    samples: int
    nrmse: tuple[float, ...] = ()
    compensator: CoupledCompensator | StructureCompensator | None = None
    preamble: int = 0


def is_stage_file(path: PathLike) -> bool:
    """True for a coupled model file (``CoupledModel.save``) or a structure model file
    (``StructureModel.save``), read only as far as its format.

    Parameters
    ----------
    path : str or os.PathLike
        Any file: one that cannot be read, or is not JSON, is not a stage's.

    Returns
    -------
    bool
    """
    return holds_format(path, COUPLED_FORMAT, STRUCTURE_FORMAT)


def holds_format(path: PathLike, *formats: str) -> bool:
    """True where the file's start names one of ``formats`` (a file's own format comes
    first in piezohyst's JSON files); one that cannot be read names none.

    Parameters
    ----------
    path : str or os.PathLike
        Any file.
    *formats : str
        The formats looked for (``"piezohyst-coupled-model"``...).

    Returns
    -------
    bool
        Whether one of them is named there.
    """
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(4096)
    except (OSError, UnicodeDecodeError):
        return False
    return any(f'"{fmt}"' in head for fmt in formats)


def _is_structure(path: PathLike) -> bool:
    with open(path, encoding="utf-8") as fh:
        return f'"{STRUCTURE_FORMAT}"' in fh.read(4096)


def _read_stage(
    data: PathLike, inputs: Sequence[str], outputs: Sequence[str] | None, spec: DataSpec
) -> tuple[FloatArray, FloatArray, FloatArray | None, str | None]:
    """The columns on one time axis: t, U (samples x inputs), Y or None, Y's unit. Read in
    pairs, as one channel's are (an output beyond the inputs paired with the first input)."""
    outs: list[str | None] = list(outputs) if outputs is not None else []
    count = max(len(inputs), len(outs))
    outs += [None] * (count - len(outs))
    pairs = [(inputs[k] if k < len(inputs) else inputs[0], outs[k]) for k in range(count)]
    recs = [
        dataclasses.replace(spec, input_column=i, output_column=o).read(
            data, output_required=o is not None
        )
        for i, o in pairs
    ]
    w = recs[0].window
    t = recs[0].t[w]
    for rec in recs[1:]:
        if rec.t[rec.window].shape != t.shape or not np.array_equal(rec.t[rec.window], t):
            msg = f"{data}: the columns' time axes differ (rows dropped from one, not another?)"
            raise DataFileError(msg)
    u = np.column_stack([rec.x[rec.window] for rec in recs[: len(inputs)]])
    if outputs is None:
        return t, u, None, None
    y = np.column_stack([rec.y[rec.window] for rec in recs if rec.y is not None])
    return t, u, y, recs[0].units[1]


def _stage(model_path: PathLike) -> CoupledModel:
    model = CoupledModel.load(model_path)
    if not isinstance(model, CoupledModel):  # pragma: no cover - load returns its class
        msg = f"{model_path}: not a coupled model file"
        raise ParameterError(msg)
    return model


def predict_stage_file(
    model_path: PathLike,
    data: PathLike,
    out: PathLike,
    *,
    inputs: Sequence[str],
    outputs: Sequence[str] | None = None,
    data_spec: DataSpec | None = None,
    force: bool = False,
    initial_state: str = "rest",
) -> StageRun:
    """Run a coupled or structure model on a record's actuator voltages; write each axis's
    prediction.

    Parameters
    ----------
    model_path : str or os.PathLike
        A coupled model file (``piezohyst fit --input vx,vy --output x,y``) or a structure
        model file (``--model structure``).
    data, out : str or os.PathLike
        The record, and the file to write: ``time``, ``predicted_<axis>`` per axis and,
        where the record has them, ``measured_<axis>``.
    inputs : sequence of str
        The actuators' voltage columns, in the model's order.
    outputs : sequence of str, optional
        The axes' measured columns: scored and written beside the prediction.
    data_spec : DataSpec, optional
        Time column, rate, window, units, as for one channel.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.
    initial_state : {"rest", "periodic", "model"}
        A structure model's start: at rest ("model" too), or the record as one period of a
        steady state; a coupled model starts as its channels do.

    Returns
    -------
    StageRun
    """
    guard_outputs([out], [model_path, data], force=force)
    model: CoupledModel | StructureModel
    if _is_structure(model_path):
        model = StructureModel.load(model_path)
        n, m = model.n_inputs_, model.n_outputs_
    else:
        model = _stage(model_path)
        n, m = len(model.channels_), model.coupling_.shape[0]
    if len(inputs) != n or (outputs is not None and len(outputs) != m):
        msg = (
            f"{model_path} is a stage of {n} actuators and {m} axes: "
            f"got {len(inputs)} input and {len(outputs or ())} output columns"
        )
        raise ParameterError(msg)
    t, u, y, unit = _read_stage(data, inputs, outputs, data_spec or DataSpec())
    if isinstance(model, StructureModel):
        pred = model.predict(u, t=t, state="periodic" if initial_state == "periodic" else "rest")
    else:
        pred = model.predict(u, t=t)
    names = list(outputs) if outputs is not None else [f"axis{i}" for i in range(pred.shape[1])]
    columns: dict[str, FloatArray] = {"time": t}
    units: dict[str, str | None] = {"time": "s"}
    for i, name in enumerate(names):
        columns[f"predicted_{name}"] = pred[:, i]
        units[f"predicted_{name}"] = unit
    nrmse: tuple[float, ...] = ()
    if y is not None:
        for i, name in enumerate(names):
            columns[f"measured_{name}"] = y[:, i]
            units[f"measured_{name}"] = unit
        err = np.sqrt(np.mean((pred - y) ** 2, axis=0)) / np.maximum(np.ptp(y, axis=0), 1e-300)
        nrmse = tuple(float(e) for e in err)
    write_table(out, columns, units)
    return StageRun(samples=int(t.size), nrmse=nrmse)


def compensate_stage_file(
    model_path: PathLike,
    target: PathLike,
    out: PathLike,
    *,
    columns: Sequence[str],
    v_min: float,
    v_max: float,
    sample_rate: float | None = None,
    slew_rate: float | str | None = "trained",
    allow_extrapolation: bool = False,
    ramp: float = 0.5,
    force: bool = False,
) -> StageRun:
    """The commands that move a coupled stage along a target; write them, one per actuator.

    The file starts with a ramp (``ramp`` seconds, rows with empty desired values) from where
    the stage rests with every actuator at ``v_min`` to the trajectory's first position, so
    the first command never jumps; then one row per target row.

    Parameters
    ----------
    model_path : str or os.PathLike
        A coupled model file, or a structure model file (its inverse through the shared
        modes, :class:`~piezohyst.StructureCompensator`: the target sampled at the rate it
        was identified at; no slew limit unless ``slew_rate`` gives one).
    target : str or os.PathLike
        The desired positions: a time column (``time``, s) and one column per axis.
    out : str or os.PathLike
        Written: ``time``, ``command_<k>`` per actuator (V), ``desired_<axis>`` per axis.
    columns : sequence of str
        The target's axis columns, in the model's order.
    v_min, v_max : float
        Every actuator's voltage limits (V).
    sample_rate : float, optional
        Hz; default the target's time column's.
    slew_rate : float, "trained" or None
        As for :class:`~piezohyst.CoupledCompensator`.
    allow_extrapolation : bool
        Keep limits wider than the training range.
    ramp : float
        Seconds of the ramp-in.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    StageRun

    Raises
    ------
    ParameterError
        Columns that do not match the model, or a target mostly out of the stage's reach or
        mostly held back by the slew limit.
    """
    guard_outputs([out], [model_path, target], force=force)
    structure = _is_structure(model_path)
    model: CoupledModel | StructureModel = (
        StructureModel.load(model_path) if structure else _stage(model_path)
    )
    m = model.n_outputs_ if isinstance(model, StructureModel) else model.coupling_.shape[0]
    if len(columns) != m:
        msg = f"{model_path} moves {m} axes: got {len(columns)} target columns ({columns})"
        raise ParameterError(msg)
    table = read_table(target)
    t = table.get("time")
    desired = np.column_stack([table.get(c, finite=False) for c in columns])
    if t.size < 2 or not np.all(np.diff(t) > 0):
        msg = f"{target}: the time column must increase, one row per sample"
        raise DataFileError(msg)
    fs = float(sample_rate) if sample_rate is not None else float(1.0 / np.median(np.diff(t)))
    comp: CoupledCompensator | StructureCompensator
    if isinstance(model, StructureModel):
        from ..control.structure import StructureCompensator  # SciPy's Riccati: loaded here

        if abs(fs - model.sample_rate_) > 1e-6 * model.sample_rate_:
            msg = (
                f"{target} is sampled at {fs:.6g} Hz and {model_path} was identified at "
                f"{model.sample_rate_:.6g} Hz: a structure's dynamics hold at that rate only"
            )
            raise ParameterError(msg)
        slew = None if slew_rate in (None, "trained") else float(slew_rate)
        comp = StructureCompensator(model, v_min=v_min, v_max=v_max, slew_rate=slew)
        lo = comp.v_min
        comp.reset(voltage=lo)
        rest = comp.output
    else:
        comp = CoupledCompensator(model, v_min=v_min, v_max=v_max, sample_rate=fs,
                                  slew_rate=slew_rate, allow_extrapolation=allow_extrapolation)  # type: ignore[arg-type]  # fmt: skip
        lo = np.array([c.v_min for c in comp.compensators])
        comp.reset(voltage=lo)
        rest = model.predict(lo[None, :], t=[0.0])[0]
    first = desired[np.all(np.isfinite(desired), axis=1)][:1]
    n_ramp = max(2, round(ramp * fs)) if first.size else 0
    path = np.linspace(rest, first[0], n_ramp) if n_ramp else np.empty((0, m))
    commands = comp.process(np.vstack([path, desired]))
    rows = max(desired.shape[0], 1)
    held, slewed = comp.saturated_count / rows, comp.slew_limited_count / rows
    if np.any(held > 0.5):
        k = int(np.argmax(held))
        msg = (
            f"{target}: actuator {k} would sit at a voltage limit on {100 * held[k]:.0f} % of "
            "the target (what the stage reaches is the actuators' ranges through the "
            "coupling, not a box); bring the target within reach or widen --v-min/--v-max"
        )
        raise ParameterError(msg)
    if np.any(slewed > 0.5):  # a trajectory mostly held back by the slew limit: not followed
        k = int(np.argmax(slewed))
        msg = (
            f"{target}: the slew limit would hold back {100 * slewed[k]:.0f} % of actuator "
            f"{k}'s commands (by default the training record's fastest change); set "
            "--slew-rate to what the amplifier allows, or slow the target"
        )
        raise ParameterError(msg)
    time = np.concatenate([t[0] - np.arange(n_ramp, 0, -1) / fs, t])
    written: dict[str, FloatArray] = {"time": time}
    units: dict[str, str | None] = {"time": "s"}
    for k in range(commands.shape[1]):
        written[f"command_{k}"] = commands[:, k]
        units[f"command_{k}"] = "V"
    for i, c in enumerate(columns):
        written[f"desired_{c}"] = np.concatenate([np.full(n_ramp, np.nan), desired[:, i]])
    write_table(out, written, units)
    return StageRun(samples=int(time.size), compensator=comp, preamble=n_ramp)


def stage_columns(spec: str | None, what: str) -> list[str]:
    """Column names from ``--input vx,vy`` (several: a stage), checked.

    Parameters
    ----------
    spec : str or None
        The option's value.
    what : str
        The option, for the error.

    Returns
    -------
    list of str
        One name per channel (one: not a stage).
    """
    names = [c.strip() for c in (spec or "").split(",")]
    if any(not c for c in names):
        msg = f"{what} {spec!r}: a column name is empty (write them as vx,vy)"
        raise ParameterError(msg)
    return names


def fit_stage_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    inputs: Sequence[str],
    outputs: Sequence[str],
    model: str = "classical-pi",
    operators: int = 10,
    data_spec: DataSpec | None = None,
    force: bool = False,
    input_dynamics: str = "none",
    output_dynamics: str = "none",
) -> CoupledModel:
    """Fit a coupled stage (one model per actuator and the coupling) to a file and save it.

    Each actuator's voltage column and each axis's position column are read as the single
    channel's are (units, scales, window, the record's check), pair by pair, on the same
    time axis.

    Parameters
    ----------
    data : str or os.PathLike
        The recording.
    out : str or os.PathLike, optional
        Where to save the coupled model (JSON).
    inputs, outputs : sequence of str
        The actuators' voltage columns and the axes' position columns, as many of each.
    model : str
        Each actuator's model (a name from :func:`~piezohyst.model.persistence.model_names`).
    operators : int
        Play operators, for the models that have them.
    data_spec : DataSpec, optional
        Time column, rate, group, window, units and scales (its input and output columns
        are replaced by each pair).
    force : bool
        Replace an existing ``out`` that piezohyst did not write.
    input_dynamics, output_dynamics : str
        Each actuator's amplifier lag and its axis's mode, as one model's
        (``"first-order"``, ``"second-order"``, ...): identified with its hysteresis.

    Returns
    -------
    CoupledModel

    Raises
    ------
    ParameterError
        Not as many outputs as inputs, fewer than two, or a setting the model lacks.
    DataFileError
        The pairs' time axes differ (a column read with another window).
    """
    if len(outputs) < len(inputs) or len(inputs) < 2:
        msg = (
            f"a stage pairs each actuator's voltage with one axis's position (its own, in "
            f"order; further outputs are more readings): got {len(inputs)} input and "
            f"{len(outputs)} output columns (two or more inputs, at least as many outputs)"
        )
        raise ParameterError(msg)
    if out is not None:
        guard_outputs([out], [data], force=force)
    t, u, y, unit = _read_stage(data, inputs, outputs, data_spec or DataSpec())
    assert y is not None  # outputs given: read or refused
    cls = model_class(model)
    accepted = cls().get_params()
    settings: dict[str, object] = {"output_unit": unit or "m", "input_dynamics": input_dynamics,
                                   "output_dynamics": output_dynamics}  # fmt: skip
    if "n_operators" in accepted:
        settings["n_operators"] = operators
    elif operators != 10:
        msg = f"the 'operators' setting does not apply to {model} (it has no play operators)"
        raise ParameterError(msg)
    stage = CoupledModel(cls(**settings)).fit(u, y, t=t)
    if out is not None:
        stage.save(out)
    return stage


def fit_structure_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    inputs: Sequence[str],
    outputs: Sequence[str],
    operators: int | None = None,
    initial_state: str = "rest",
    data_spec: DataSpec | None = None,
    force: bool = False,
) -> StructureModel:
    """Fit a structure's coupled dynamics (:class:`~piezohyst.StructureModel`, the order
    chosen on the record's last 30 %) to a file and save it.

    Parameters
    ----------
    data : str or os.PathLike
        The recording (uniformly sampled).
    out : str or os.PathLike, optional
        Where to save the structure model (JSON).
    inputs, outputs : sequence of str
        The actuators' voltage columns and the outputs' columns (any number of outputs).
    operators : int, optional
        Play operators per actuator in the loop (0: the linear dynamics alone); default the
        model's own.
    initial_state : {"rest", "periodic"}
        The record starts at rest, or is one period of a periodic steady state.
    data_spec : DataSpec, optional
        Time column, rate, group, window, units and scales.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    StructureModel
    """
    if len(inputs) < 2:
        msg = (
            "a structure's dynamics couple several actuators: name two or more --input "
            "columns (one actuator's mode: --output-dynamics second-order)"
        )
        raise ParameterError(msg)
    if out is not None:
        guard_outputs([out], [data], force=force)
    t, u, y, _ = _read_stage(data, inputs, outputs, data_spec or DataSpec())
    assert y is not None  # outputs given: read or refused
    model = StructureModel() if operators is None else StructureModel(operators=operators)
    model.fit(u, y, t=t, initial_state=initial_state)
    if out is not None:
        model.save(out)
    return model


def export_stage_file(
    model_path: PathLike,
    out: PathLike,
    *,
    v_min: float,
    v_max: float,
    sample_rate: float | None = None,
    slew_rate: float | str | None = "trained",
    allow_extrapolation: bool = False,
    precision: str = "double",
    shared: bool = False,
    mex: bool = False,
    force: bool = False,
) -> list[os.PathLike[str]]:
    """A coupled stage's compensator as C files (:func:`~piezohyst.control.export.write_stage_c`),
    with ``shared`` its library (:func:`~piezohyst.control.export.write_stage_shared`), or
    where ``out`` ends in ``.fmu`` an FMU (:func:`~piezohyst.control.export.write_stage_fmu`).

    Parameters
    ----------
    model_path : str or os.PathLike
        A coupled model file.
    out : str or os.PathLike
        The stage's ``.c`` file; each actuator's pair goes beside it.
    v_min, v_max : float
        Every actuator's voltage limits (V).
    sample_rate : float, optional
        Hz (for a slew rate, creep or input dynamics).
    slew_rate : float, "trained" or None
    allow_extrapolation : bool
    precision : {"double", "float"}
    shared : bool
        Also build the shared library (the system C compiler).
    mex : bool
        ``out`` is a MEX gateway (``NAME_mex.c``), the stage's C beside it.
    force : bool
        Replace existing files piezohyst did not write.

    Returns
    -------
    list of Path
        The files written, the stage's ``.c`` first (the library last).
    """
    if _is_structure(model_path):
        return _export_structure(model_path, out, v_min=v_min, v_max=v_max,
                                 slew_rate=slew_rate, precision=precision, shared=shared,
                                 mex=mex, force=force)  # fmt: skip
    model = _stage(model_path)
    if str(out).endswith(".fmu"):  # an FMU: two target inputs... one voltage per actuator
        guard_outputs([out], [model_path], force=force)
        comp = CoupledCompensator(model, v_min=v_min, v_max=v_max, sample_rate=sample_rate,
                                  slew_rate=slew_rate,  # type: ignore[arg-type]
                                  allow_extrapolation=allow_extrapolation)  # fmt: skip
        return [write_stage_fmu(comp, out, precision=precision)]  # type: ignore[arg-type]
    c_path = c_paths(out)[0]
    guard_outputs(stage_paths(c_path, len(model.channels_), mex=mex), [model_path], force=force)
    comp = CoupledCompensator(model, v_min=v_min, v_max=v_max, sample_rate=sample_rate,
                              slew_rate=slew_rate,  # type: ignore[arg-type]
                              allow_extrapolation=allow_extrapolation)  # fmt: skip
    if mex:
        return list(write_stage_mex(comp, c_path, precision=precision))  # type: ignore[arg-type]
    if shared:
        files, lib = write_stage_shared(comp, c_path, precision=precision)  # type: ignore[arg-type]
        return [*files, lib]
    return list(write_stage_c(comp, c_path, precision=precision))  # type: ignore[arg-type]


def _export_structure(
    model_path: PathLike, out: PathLike, *, v_min: float, v_max: float,
    slew_rate: float | str | None, precision: str, shared: bool, mex: bool, force: bool,
) -> list[os.PathLike[str]]:  # fmt: skip
    """A structure model's compensator as C (:mod:`~piezohyst.control.export.structure_c`),
    with ``shared`` its library, with ``mex`` its MEX gateway, or an FMU (``out`` ``.fmu``)."""
    from ..control.export import structure_c as sc
    from ..control.structure import StructureCompensator

    model = StructureModel.load(model_path)
    slew = None if slew_rate in (None, "trained") else float(slew_rate)
    fmu = str(out).endswith(".fmu")
    c_path, h_path, name = c_paths(out)
    if fmu:
        written = [Path(out).with_suffix(".fmu")]
    elif mex:
        step = name[: -len("_mex")] if name.endswith("_mex") else f"{name}_step"
        written = [c_path, c_path.with_name(f"{step}.c"), c_path.with_name(f"{step}.h")]
    else:
        written = [c_path, h_path]
    guard_outputs(written, [model_path], force=force)
    comp = StructureCompensator(model, v_min=v_min, v_max=v_max, slew_rate=slew)
    prec = precision
    if fmu:
        return [sc.write_structure_fmu(comp, out, precision=prec)]  # type: ignore[arg-type]
    if mex:
        return list(sc.write_structure_mex(comp, c_path, precision=prec))  # type: ignore[arg-type]
    if shared:
        files, lib = sc.write_structure_shared(comp, c_path, precision=prec)  # type: ignore[arg-type]
        return [*files, lib]
    return list(sc.write_structure_c(comp, c_path, precision=prec))  # type: ignore[arg-type]
