"""File-to-file workflows: what each ``piezohyst`` command does, callable from Python.

Each function reads its inputs, calls the library, and writes its outputs
atomically (a failure leaves no output file). The CLI is a thin shell over
these; from Python they are one call each too::

    import piezohyst.workflows as wf
    model = wf.fit_file("run.csv", "model.json", model="active-pi", operators=20)
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ._validation import FloatArray, check_float, check_int
from ._version import __version__
from .comparison import Comparison, compare_models
from .compensator import Compensator, CompensatorSettings
from .cores.play import history_state
from .errors import DataFileError, OverwriteError, ParameterError
from .export import Precision, c_paths, write_c
from .identification import Blocks, Summary, default_thresholds
from .io import (
    MD_MARKER,
    DataSpec,
    RecordingStream,
    Table,
    atomic_write_text,
    check_finite,
    check_increasing,
    is_piezohyst_output,
    open_table,
    read_table,
    write_blocks,
    write_rows,
    write_table,
)
from .leakage import LEAKAGE_TERMS, Leakage, calibrate_leakage
from .metrics import hysteresis_width, nrmse, rmse
from .model import History, HysteresisModel, InitialState, ModelState
from .persistence import load_model, model_class, model_names
from .selfsensing import LoopSettings
from .simulation import DEFAULT_PRESET, PRESETS, Bench, BenchRecord, run_loop, simulate
from .units import to_standard

__all__ = [
    "Compensation",
    "LoopRun",
    "Prediction",
    "calibrate_leakage_file",
    "compare_file",
    "compensate_file",
    "export_c_file",
    "fit_file",
    "guard_outputs",
    "model_report",
    "predict_file",
    "simulate_file",
    "simulate_loop_file",
]

PathLike = str | os.PathLike[str]
Progress = Callable[[int], None] | None  # told the rows read so far


def guard_outputs(
    outputs: Sequence[PathLike], inputs: Sequence[PathLike], *, force: bool = False
) -> None:
    """Refuse to write where data would be lost, before any work is done.

    An output that is one of the inputs is always refused; an existing file
    (or report folder) that piezohyst did not write is refused unless
    ``force`` (see :func:`~piezohyst.io.is_piezohyst_output`).

    Parameters
    ----------
    outputs, inputs : sequence of path
    force : bool, default False
        Replace existing files piezohyst did not write.

    Raises
    ------
    OverwriteError
    """
    # inputs by resolved path and by file identity (hard links), each looked up once
    by_path: dict[Path, Path] = {}
    by_inode: dict[tuple[int, int], Path] = {}
    for src in map(Path, inputs):
        by_path.setdefault(src.resolve(), src)
        try:
            st = src.stat()
        except OSError:
            continue
        by_inode.setdefault((st.st_dev, st.st_ino), src)
    for out in map(Path, outputs):
        same = by_path.get(out.resolve())
        if same is None and out.exists():
            st = out.stat()
            same = by_inode.get((st.st_dev, st.st_ino))
        if same is not None:
            msg = (
                f"{out}: that is an input of this command ({same}); piezohyst never writes "
                "over its input: choose another output name"
            )
            raise OverwriteError(msg, replaceable=False)
        if out.exists() and not force and not is_piezohyst_output(out):
            kind = "folder" if out.is_dir() else "file"
            msg = f"{out}: an existing {kind} that piezohyst did not write; not replacing it"
            raise OverwriteError(msg, replaceable=True)


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
    force: bool = False,
) -> BenchRecord:
    """Run the simulated bench and write ``time,voltage,charge,displacement`` (s, V, C, m).

    ``force`` replaces an existing file piezohyst did not write (see :func:`guard_outputs`).
    """
    guard_outputs([out], [], force=force)
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
        units={"time": "s", "voltage": "V", "charge": "C", "displacement": "m"},
    )
    return rec


def fit_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    model: str = "active-pi",
    operators: int = 10,
    data_spec: DataSpec | None = None,
    growth_terms: str | Sequence[str] = "auto",
    creep: Sequence[float] = (),
    relaxation: float | None = None,
    input_dynamics: str = "none",
    output_dynamics: str = "none",
    initial_state: str = "rest",
    force: bool = False,
    progress: Progress = None,
) -> HysteresisModel:
    """Fit a model to a data file and save it (JSON) to ``out`` if given.

    The file streams through block by block; with ``input_dynamics`` other
    than ``"none"`` the search over the dynamics needs the window in memory.

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
    growth_terms, creep
        Settings of models that have them (``growth_terms``: every model but
        the classical and active PI; ``creep``: ``generalized-pi`` and the
        models on a differential core).
    relaxation : float, optional
        ``preisach``: time constant (s) of a relaxing part of the hysteresis
        (see :class:`~piezohyst.PreisachModel`).
    input_dynamics, output_dynamics : str
        Delay and lag between command and piezo, mode between hysteresis and
        output (see :class:`~piezohyst.models.HysteresisModel`).
    initial_state : {"rest", "periodic"}
        Where the operators start: at rest, or (a record that is one period of
        a periodic drive, starting mid-cycle) in the periodic steady state. A
        window after ``t_start`` starts from the input before it either way.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.
    progress : callable, optional
        Called with the rows read so far.

    Returns
    -------
    HysteresisModel
        The fitted model.
    """
    if out is not None:
        guard_outputs([out], [data], force=force)
    cls = model_class(model)
    accepted = cls().get_params()
    extra: dict[str, Any] = {}
    for name, value, default in (("growth_terms", growth_terms, "auto"), ("creep", creep, ())):
        if name in accepted:
            extra[name] = tuple(value) if name == "creep" else value
        elif (value if isinstance(value, str) else tuple(value)) != default:
            msg = f"the {name!r} setting does not apply to {model}"
            raise ParameterError(msg)
    if relaxation is not None:
        if "relaxation" not in accepted:
            msg = f"the 'relaxation' setting does not apply to {model} (preisach has it)"
            raise ParameterError(msg)
        extra["relaxation"] = relaxation
    stream = (data_spec or DataSpec()).open(data)
    x_unit, y_unit = stream.units
    if "n_operators" not in accepted and operators != 10:
        msg = f"the 'operators' setting does not apply to {model} (it has no play operators)"
        raise ParameterError(msg)
    settings: dict[str, Any] = {
        **({"n_operators": operators} if "n_operators" in accepted else {}),
        "input_unit": x_unit or "V",
        "output_unit": y_unit or _default_unit(stream.names[1]),
        **extra,
        "input_dynamics": input_dynamics,
        "output_dynamics": output_dynamics,
    }
    estimator = cls(**settings)
    if input_dynamics != "none" or output_dynamics != "none":  # searched over the window in memory
        rec = (data_spec or DataSpec()).read(data, progress=progress)
        w = rec.window
        assert rec.y is not None
        fitted_dyn: HysteresisModel = estimator.fit(
            rec.x[w], rec.y[w], t=rec.t[w], initial_state=initial_state
        )
        if out is not None:
            fitted_dyn.save(out)
        return fitted_dyn
    passes = _Passes(progress)
    window = _window_blocks(stream, passes)
    start: InitialState = initial_state
    if math.isfinite(stream.t_start) and "n_operators" not in accepted:
        before = _history_input(stream, passes.tick())  # a differential core runs it
        start = History(before) if before is not None else initial_state
    elif math.isfinite(stream.t_start):  # the window continues a known input history
        thresholds = default_thresholds(
            Summary.of(window).x_range, check_int(operators, "operators", "fit", 1, 1000)
        )
        estimator = cls(**{**settings, "thresholds": thresholds})
        start = _history(stream, thresholds, passes.tick())
    fitted: HysteresisModel = estimator.fit_blocks(window, initial_state=start)
    if out is not None:
        fitted.save(out)
    return fitted


def compare_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    models: Sequence[str] | None = None,
    train: float = 0.7,
    test_data: PathLike | None = None,
    data_spec: DataSpec | None = None,
    operators: int = 10,
    input_dynamics: str = "none",
    initial_state: str = "rest",
    force: bool = False,
) -> Comparison:
    """Fit several models on one record and score each on data it never saw.

    See :func:`~piezohyst.comparison.compare_models`. Without ``test_data``
    the first ``train`` fraction of the record (its window) trains and the
    rest tests; with it, the whole record trains and ``test_data`` (read with
    the same columns) tests, started at rest.

    Parameters
    ----------
    data : str or os.PathLike
        The training recording.
    out : str or os.PathLike, optional
        The table: ``.md`` (Markdown), ``.parquet``, or a text file (CSV).
    models : sequence of str, optional
        CLI names (``piezohyst fit --model``); each with its default settings.
        Default: every registered model (:func:`~piezohyst.models.model_names`).
    train : float
        Training fraction of ``data`` when there is no ``test_data``.
    test_data : str or os.PathLike, optional
        A separate test recording.
    data_spec : DataSpec, optional
        Columns and window (default: voltage, charge, time).
    operators : int
        Play operators, for the models that have them.
    input_dynamics : str
        As for :func:`fit_file`, for every model.
    initial_state : {"rest", "periodic"}
        Where the training part starts.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    Comparison
    """
    names = list(dict.fromkeys(model_names() if models is None else models))
    if not names:
        msg = "give at least one model to compare"
        raise ParameterError(msg)
    classes = [model_class(name) for name in names]
    inputs = [data] if test_data is None else [data, test_data]
    if out is not None:
        guard_outputs([out], inputs, force=force)
    spec = data_spec or DataSpec()
    rec = spec.read(data)
    assert rec.y is not None
    w = rec.window
    x_unit, y_unit = rec.units
    estimators = {}
    for name, cls in zip(names, classes, strict=True):
        accepted = cls().get_params()
        estimators[name] = cls(
            **({"n_operators": operators} if "n_operators" in accepted else {}),
            input_unit=x_unit or "V",
            output_unit=y_unit or _default_unit(rec.names[1]),
            input_dynamics=input_dynamics,
        )
    test = None
    if test_data is not None:
        trec = spec.read(test_data)
        assert trec.y is not None
        if trec.units[1] != rec.units[1]:
            msg = (
                f"{test_data}: the output column is in {trec.units[1]!r}, the training "
                f"record's in {rec.units[1]!r}"
            )
            raise DataFileError(msg)
        tw = trec.window
        test = (trec.x[tw], trec.y[tw], trec.t[tw])
    result = compare_models(
        estimators, rec.x[w], rec.y[w], rec.t[w], train=train, test=test,
        initial_state=initial_state,
    )  # fmt: skip
    if out is not None:
        if Path(out).suffix.lower() == ".md":
            atomic_write_text(out, f"{MD_MARKER} {__version__} -->\n\n{result.table()}\n")
        else:
            rows = [r.as_dict() for r in result.rows]
            text = ("model", "status", "absorbed", "notes", "error")
            write_rows(out, rows, list(rows[0]), text)
    return result


#: A window of at most this many samples is read from the file once and kept in memory
#: (24 MB per million samples) for the fit's later passes; a longer one streams every pass.
KEEP_ROWS = 2_000_000


def _window_blocks(stream: RecordingStream, passes: _Passes) -> Blocks:
    """The window of a record as a block source (each call a pass over it).

    The first pass reads the file; a window of up to :data:`KEEP_ROWS` samples
    is kept, so the later passes (normal equations, fit quality) do not parse
    the file again. Longer windows are read from the file on every pass.
    """
    kept: list[tuple[FloatArray, FloatArray, FloatArray | None]] = []
    complete = [False]

    def window() -> Iterator[tuple[FloatArray, FloatArray, FloatArray | None]]:
        if complete[0]:
            yield from kept
            return
        first = last = math.nan
        found = False
        keeping = True
        rows = 0
        for b in stream.blocks(passes.tick()):
            assert b.y is not None
            first = float(b.t[0]) if b.start == 0 else first
            last = float(b.t[-1])
            i0, i1 = np.searchsorted(b.t, [stream.t_start, stream.t_stop], "left")
            if i1 > i0:
                found = True
                block = (b.x[i0:i1], b.y[i0:i1], b.t[i0:i1])
                rows += int(i1 - i0)
                keeping = keeping and rows <= KEEP_ROWS
                if keeping:
                    kept.append(block)
                else:
                    kept.clear()
                yield block
        if not found:
            raise stream.empty_window(first, last)
        complete[0] = keeping

    return window


class _Passes:
    """Progress over several passes of one record: rows read, counted over all passes."""

    def __init__(self, progress: Progress) -> None:
        self.progress = progress
        self.done = 0  # rows of the finished passes
        self.rows = 0  # rows of the pass under way

    def tick(self) -> Callable[[int], None] | None:
        """The callback for the next pass."""
        if self.progress is None:
            return None
        self.done += self.rows
        self.rows = 0
        report = self.progress

        def tick(rows: int) -> None:
            self.rows = rows
            report(self.done + rows)

        return tick


def _history_input(
    stream: RecordingStream, progress: Callable[[int], None] | None
) -> FloatArray | None:
    """The input before the window's start (None: none), read into memory."""
    parts = []
    for b in stream.blocks(progress):
        before = int(np.searchsorted(b.t, stream.t_start, "left"))
        parts.append(b.x[:before])
        if before < b.t.size:
            break
    x = np.concatenate(parts) if parts else np.zeros(0)
    return x if x.size else None


def _history(
    stream: RecordingStream, thresholds: FloatArray, progress: Callable[[int], None] | None
) -> FloatArray | None:
    """Operator states at the window's start, from the input before it (None: no history)."""
    z = None
    for b in stream.blocks(progress):
        before = int(np.searchsorted(b.t, stream.t_start, "left"))
        if before:
            z = history_state(b.x[:before], thresholds, z)
        if before < b.t.size:
            break
    return z


def _default_unit(column: str | None) -> str:
    """The unit of an output column that names none: piezohyst's own names, else arbitrary."""
    return {"charge": "C", "displacement": "m"}.get(column or "", "a.u.")


def _check_measured_unit(unit: str | None, model: HysteresisModel, data: PathLike) -> None:
    """The recorded output must be in the model's unit; a unit the file omits is assumed."""
    if unit is None:
        warnings.warn(
            f"{data}: the output column states no unit; taken to be in the model's unit "
            f"{model.output_unit!r} (give the output unit if it is not)",
            UserWarning,
            stacklevel=3,
        )
    elif unit != model.output_unit:
        msg = f"{data}: the output column is in {unit!r}, the model predicts {model.output_unit!r}"
        raise DataFileError(msg)


def _load(model_path: PathLike) -> HysteresisModel:
    model: HysteresisModel = load_model(model_path)
    return model


@dataclass(frozen=True)
class Prediction:
    """What :func:`predict_file` wrote.

    Attributes
    ----------
    samples : int
        Rows written (the window's samples).
    rmse, nrmse : float
        Error against the measured output over the window (output units; a
        fraction of its span); NaN when the file has no output column.
    unit : str
        The output unit.
    """

    samples: int
    rmse: float
    nrmse: float
    unit: str


def predict_file(
    model_path: PathLike,
    data: PathLike,
    out: PathLike,
    *,
    data_spec: DataSpec | None = None,
    initial_state: str = "model",
    force: bool = False,
    progress: Progress = None,
) -> Prediction:
    """Write ``time,predicted`` (plus ``measured`` when the data has the output column).

    The record streams through block by block, the model's state carried, so
    memory does not grow with its length. The model runs from the record's
    first sample: a window's start has a history. ``initial_state`` is
    ``"model"`` (where the training record started), ``"rest"`` (at rest at
    the first sample) or ``"periodic"`` (the record is one period of a drive
    that was already running: the periodic steady state, found in extra
    passes over the file). ``force`` replaces an existing file piezohyst did
    not write (see :func:`guard_outputs`); ``progress`` is called with the
    rows read so far.
    """
    if initial_state not in ("model", "rest", "periodic"):
        msg = f"initial_state must be 'model', 'rest' or 'periodic'. Got {initial_state!r}."
        raise ParameterError(msg)
    guard_outputs([out], [model_path, data], force=force)
    model = _load(model_path)
    stream = (data_spec or DataSpec()).open(data, output_required=False)
    measured = stream.names[1] is not None
    if measured:
        _check_measured_unit(stream.units[1], model, data)
    sse, lo, hi = 0.0, math.inf, -math.inf

    start: ModelState | FloatArray | None = None
    if initial_state != "model":
        if model.input_dynamics_.active and initial_state == "periodic":
            msg = (
                "a periodic start over a file is for models without input dynamics; "
                "read the record and call model.predict(x, t, state='periodic')"
            )
            raise ParameterError(msg)
        first_x = next(iter(stream.blocks())).x[0]
        core = model.operator_
        if initial_state == "rest":
            start = core.rest_state(float(first_x))
        else:  # the periodic state needs the input in memory (one value per sample)
            start = core.periodic_state(np.concatenate([b.x for b in stream.blocks()]))

    def rows() -> Iterator[dict[str, FloatArray]]:
        nonlocal sse, lo, hi
        state: ModelState | FloatArray | None = start
        first = last = math.nan
        written = 0
        for b in stream.blocks(progress):
            run = model.propagate(b.x, b.t, state)
            state = run.state
            first = float(b.t[0]) if b.start == 0 else first
            last = float(b.t[-1])
            i0, i1 = np.searchsorted(b.t, [stream.t_start, stream.t_stop], "left")
            if i1 <= i0:
                continue
            cols = {"time": b.t[i0:i1], "predicted": run.output[i0:i1]}
            if b.y is not None:
                cols["measured"] = y = b.y[i0:i1]
                sse += float(np.sum((cols["predicted"] - y) ** 2))
                lo, hi = min(lo, float(y.min())), max(hi, float(y.max()))
            written += i1 - i0
            yield cols
        if not written:  # raised before the file is renamed into place: nothing is written
            raise stream.empty_window(first, last)

    unit = model.output_unit
    n = write_blocks(out, rows(), units={"time": "s", "predicted": unit, "measured": unit})
    err = math.sqrt(sse / n) if measured else math.nan
    return Prediction(n, err, err / (hi - lo) if hi > lo else math.nan, unit)


@dataclass(frozen=True)
class Compensation:
    """What :func:`compensate_file` did.

    Attributes
    ----------
    compensator : Compensator
        After the run: limits used, counters of saturated and non-finite samples.
    preamble : int
        Samples of ramp-in and preconditioning written before the trajectory.
    sample_rate : float
        Samples per second of the written commands (Hz).
    """

    compensator: Compensator
    preamble: int
    sample_rate: float


def compensate_file(
    model_path: PathLike,
    target: PathLike,
    out: PathLike,
    *,
    column: str | None = None,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precondition: bool = True,
    present_voltage: float | None = None,
    force: bool = False,
    progress: Progress = None,
) -> Compensation:
    """Feedforward voltage for a desired trajectory; writes ``time,command,desired``.

    Safe by default, as a lab running an amplifier needs:

    * commands stay inside the limits, which default to the voltages the model
      was identified on; limits beyond them are refused unless
      ``settings.allow_extrapolation``;
    * the slew limit defaults to the fastest change of the training record
      (``model.max_slew_rate_``);
    * the file starts with a ramp from the actuator's present voltage
      (default: where the training record started) and a full-range
      precondition cycle that wipes out the unknown history (rows with an
      empty ``desired``); ``precondition=False`` keeps only the ramp;
    * NaN or infinite desired values hold the last command and are counted;
    * a trajectory that saturates most samples (out of reach: units, or the
      sign of the gain) is an error, and nothing is written.

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    target : str or os.PathLike
        The desired trajectory with its ``time`` column (s), or give
        ``settings.sample_rate``.
    out : str or os.PathLike
        Where to write the commands.
    column : str, optional
        The desired column (default ``desired``, or the only one besides ``time``).
    settings : CompensatorSettings
        Limits, domain, gain, slew rate, sample rate, extrapolation.
    precondition : bool, default True
        Write the precondition cycle before the trajectory.
    present_voltage : float, optional
        The actuator's voltage now (V).
    force : bool, default False
        Replace an existing ``out`` that piezohyst did not write.
    progress : callable, optional
        Called with the rows of the target read so far.

    Returns
    -------
    Compensation
    """
    guard_outputs([out], [model_path, target], force=force)
    model = _load(model_path)
    table = open_table(target)
    name = _desired_column(table, column, target)
    expected = "m" if settings.domain == "displacement" else model.output_unit
    where = f"{target}: column {name!r}"
    unit = to_standard(np.empty(0), table.unit(name), "output", where)[1]
    if unit is not None and unit != expected:
        msg = f"{target}: the desired column is in {unit!r}, the compensator expects {expected!r}"
        raise DataFileError(msg)
    timed = "time" in table
    if not timed and settings.sample_rate is None:
        msg = (
            f"{target}: no time column; the commands need their sample times: add a 'time' "
            "column (s) or give the sample rate"
        )
        raise DataFileError(msg)
    keys = [name, "time"] if timed else [name]
    batches = table.batches(keys)
    head = next(batches)  # the sample rate comes from the first batch
    t_unit = table.unit("time") if timed else None
    fs = settings.sample_rate
    if fs is None:
        steps = np.diff(to_standard(head["time"], t_unit, "time", f"{target}: column 'time'")[0])
        fs = 1.0 / float(np.median(steps)) if steps.size and np.all(steps > 0) else 1.0
    slew = settings.slew_rate
    if slew is None and math.isfinite(model.max_slew_rate_) and model.max_slew_rate_ > 0:
        slew = model.max_slew_rate_
    comp = dataclasses.replace(settings, slew_rate=slew, sample_rate=fs).build(model)
    start = present_voltage
    if start is None:
        start = float(np.clip(model.initial_state_[0], comp.v_min, comp.v_max))
    comp.reset(voltage=start)
    preamble = comp.precondition(max(3, round(fs))) if precondition else np.empty(0)
    finite = 0

    def rows() -> Iterator[dict[str, FloatArray]]:
        nonlocal finite
        row = 0
        t_last: float | None = None
        for batch in itertools.chain([head], batches):
            desired = to_standard(batch[name], table.unit(name), "output", where)[0]
            if timed:
                check_finite(batch["time"], row, f"{target}", "time")
                check_increasing(batch["time"], t_last, row, f"{target}", "time")
                t_last = float(batch["time"][-1])
                t = to_standard(batch["time"], t_unit, "time", f"{target}: column 'time'")[0]
            else:
                t = (row + np.arange(desired.size, dtype=np.float64)) / fs
            if row == 0 and preamble.size:
                n = preamble.size
                yield {
                    "time": t[0] - np.arange(n, 0, -1) / fs,
                    "command": preamble,
                    "desired": np.full(n, np.nan),
                }
            finite += int(np.count_nonzero(np.isfinite(desired)))
            yield {"time": t, "command": comp.process(desired), "desired": desired}
            row += desired.size
            if progress is not None:
                progress(row)
        if finite and comp.saturated_count > 0.5 * finite:  # before the file is renamed into place
            lo, hi = _reachable(model, comp, settings)
            unit = "m" if settings.domain == "displacement" else model.output_unit
            msg = (
                f"{target}: {comp.saturated_count} of {finite} desired values "
                f"({100 * comp.saturated_count / finite:.0f} %) are out of reach of "
                f"[{comp.v_min:g}, {comp.v_max:g}] V, which reaches about [{lo:.4g}, {hi:.4g}] "
                f"{unit}; check the units and the sign of the gain"
            )
            raise ParameterError(msg)

    write_blocks(out, rows(), units={"time": "s", "command": "V", "desired": expected})
    return Compensation(comp, preamble.size, fs)


def _desired_column(table: Table, column: str | None, target: PathLike) -> str:
    """The desired trajectory's column: as named, else ``desired``, else the only one but time."""
    if column is None:
        others = [c for c in table.columns if c != "time"]
        column = "desired" if "desired" in table else (others[0] if len(others) == 1 else None)
        if column is None:
            msg = (
                f"{target}: which column is the desired trajectory? Name it 'desired' or name "
                f"the column (columns: {', '.join(map(repr, table.columns))})"
            )
            raise DataFileError(msg)
    return table.resolve(column)


def _reachable(
    model: HysteresisModel, comp: Compensator, settings: CompensatorSettings
) -> tuple[float, float]:
    """Roughly the desired values the limits reach: the outputs at v_min and v_max from rest."""
    h = model.hysteresis_
    x0 = float(model.initial_state_[0])
    rest, low, high = h.predict(np.array([x0, comp.v_min, comp.v_max]))
    values = np.array([low, high])
    if settings.domain == "displacement" and settings.gain is not None:
        values = settings.gain * (values - rest)
    return float(values.min()), float(values.max())


def export_c_file(
    model_path: PathLike,
    out: PathLike,
    *,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precision: Precision = "double",
    controller: LoopSettings | None = None,
    force: bool = False,
) -> tuple[Path, Path]:
    """Write ``NAME.c`` and ``NAME.h`` for the model's compensator (see :mod:`piezohyst.export`).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    out : str or os.PathLike
        The ``.c`` file.
    settings : CompensatorSettings
        Limits, domain, gain, slew rate (and the sample rate a controller needs).
    precision : {"double", "float"}
        The C type of every real.
    controller : LoopSettings, optional
        Export the self-sensing controller instead of the feedforward compensator.
    force : bool, default False
        Replace existing files piezohyst did not write.

    Returns
    -------
    tuple of Path
    """
    c_path, h_path, _ = c_paths(out)
    inputs: list[PathLike] = [model_path]
    if controller is not None and controller.leakage is not None:
        inputs.append(controller.leakage)
    guard_outputs([c_path, h_path], inputs, force=force)
    model = _load(model_path)
    built = settings.build(model) if controller is None else controller.build(settings, model)
    return write_c(built, out, precision=precision)


def calibrate_leakage_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    data_spec: DataSpec | None = None,
    terms: Sequence[str] = LEAKAGE_TERMS,
    min_duration: float = 1.0,
    settle: float = 0.25,
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
        Leakage terms to fit (see :func:`~piezohyst.leakage.calibrate_leakage`).
    min_duration, settle
        Hold detection (see :func:`~piezohyst.leakage.find_holds`).
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
        Hysteresis width desired → laser displacement (fraction of the span).
    nrmse : float
        Tracking NRMSE desired → laser displacement (displacement domain; else NaN).
    saturated : int
        Commands clipped to the limits.
    """

    record: BenchRecord
    desired: FloatArray
    width: float
    nrmse: float
    saturated: int


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
) -> LoopRun:
    """Run a desired trajectory through a controller against the simulated bench.

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

    Returns
    -------
    LoopRun
    """
    inputs: list[PathLike] = [model_path, target]
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
    desired = table.get(name, finite=False)
    fs = settings.sample_rate or p.rate
    if abs(fs - p.rate) > 1e-9 * p.rate:
        msg = f"the bench {preset} samples at {p.rate:g} Hz; the loop rate must be the same"
        raise ParameterError(msg)
    settings = dataclasses.replace(settings, sample_rate=fs)
    ctl = settings.build(model) if loop is None else loop.build(settings, model)
    bench = Bench(
        p, voltage=ctl.last_command, seed=check_int(seed, "seed", "simulate-loop", 0, 2**32 - 1)
    )
    rec = run_loop(ctl, desired, bench)
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
    ok = np.isfinite(desired)
    width = hysteresis_width(desired[ok], rec.displacement[ok])
    err = (
        nrmse(desired[ok], rec.displacement[ok]) if settings.domain == "displacement" else math.nan
    )
    return LoopRun(rec, desired, width, err, ctl.saturated_count)


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
) -> ReportResult:
    """A report a lab can file on a model and a data file (HTML, Markdown, JSON, figures).

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

    Returns
    -------
    ReportResult
    """
    from .report import Report, file_facts

    guard_outputs([out], [model_path, data], force=force)
    spec = data_spec or DataSpec()
    model = _load(model_path)
    rec = spec.read(data, progress=progress)
    w = rec.window  # the model runs over the whole record: the window's start has a history
    pred = model.predict(rec.x, t=rec.t)[w]
    assert rec.y is not None
    _check_measured_unit(rec.units[1], model, data)
    x, y, t = rec.x[w], rec.y[w], rec.t[w]
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    in_u, out_u = model.input_unit, model.output_unit
    rep = Report(f"{type(model).__name__} on {Path(data).name}", out_dir)
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
        *[(f"setting {k}", json.dumps(v)) for k, v in model.params_to_json().items()],
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
    nrmse_pct = 100 * nrmse(y, pred)
    rep.add("nrmse_pct", "NRMSE (RMSE / output span)", nrmse_pct, "%")
    rep.add("rmse", "RMSE", rmse(y, pred), out_u)
    rep.add("max_abs_error", "largest error", float(np.max(np.abs(err))), out_u)
    rep.add("hysteresis_width_measured_pct", "hysteresis width, measured",
            100 * hysteresis_width(x, y), "%")  # fmt: skip
    lo, hi = model.input_range_
    if not math.isnan(lo):
        outside = int(np.count_nonzero((x < lo - 1e-9) | (x > hi + 1e-9)))
        rep.add("samples_outside_training_range", "samples outside the training range", outside)
    measured = {"color": "0.55", "lw": 1.6}
    model_line = {"color": "C0", "lw": 1.0, "ls": "--"}
    rep.figure("loop.png", "input-output loop: data (grey) and model (dashed)", [
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
    if growth:
        pure = y - model.growth(rec.x, t=rec.t)[w]
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
    files = rep.write()
    return ReportResult({m.key: m.value for m in rep.metrics}, files)


def _fmt(values: FloatArray) -> str:
    return ", ".join(f"{v:.6g}" for v in values)
