"""``piezohyst fit``, ``select``, ``compare`` and ``predict``: a model from a record, the choice
among models, and the model run on another record."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray
from .._version import __version__
from ..analysis.comparison import Comparison, compare_models
from ..analysis.selection import (
    CANDIDATES,
    CREEP,
    Selection,
    candidate_model,
    creep_where_undecided,
    decide,
    forward_scores,
    is_candidate,
    median_choice,
    median_said,
    record_notes,
    select_model,
    several_rates,
    undecided,
    verdict,
    with_margins,
)
from ..errors import (
    DataFileError,
    IdentifiabilityWarning,
    ParameterError,
    RecordWarning,
    TimeAxisError,
    warn,
)
from ..io import (
    MD_MARKER,
    DataSpec,
    Recording,
    RecordingStream,
    atomic_write_text,
    estimated_rows,
    write_blocks,
    write_rows,
)
from ..io.blocks import Blocks, Summary
from ..model.cores.base import Core
from ..model.dynamics import InputDynamics
from ..model.fit_record import undetermined
from ..model.model import History, HysteresisModel, InitialState, ModelState
from ..model.persistence import model_class, model_names
from ._base import (
    PathLike,
    Progress,
    _check_measured_unit,
    _default_unit,
    _load,
    guard_outputs,
    warn_assumed_volts,
    warn_clipped,
)


def _continuing(rec: Recording, initial_state: InitialState) -> InitialState:
    """Where a window of a record starts: after the record's first sample and "from rest",
    the state the input before it left (its History), as every windowed fit starts."""
    if rec.window.start and isinstance(initial_state, str) and initial_state == "rest":
        return History(rec.x[: rec.window.start])
    return initial_state


def select_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    data_spec: DataSpec | None = None,
    operators: int = 10,
    initial_state: str = "rest",
    candidates: Sequence[str] = CANDIDATES,
    input_dynamics: str = "none",
    growth_terms: str = "default",
    force: bool = False,
    progress: Progress = None,
    say: Callable[[str], None] | None = None,
) -> Selection:
    """Choose a model for a record (:func:`~piezohyst.analysis.selection.select_model`) and save
    the winner, fitted on the record (its window, started from the earlier input).

    Parameters
    ----------
    data : str or os.PathLike
        The recording.
    out : str or os.PathLike, optional
        Where to save the chosen model (JSON).
    data_spec : DataSpec, optional
        Columns and window.
    operators : int
        Play operators, for the candidates that have them.
    initial_state : {"rest", "periodic"}
        Where the record (or its window) starts.
    candidates : sequence of str
        Model names to choose among.
    input_dynamics : str, default "none"
        The lag every candidate identifies with its hysteresis (see
        :func:`~piezohyst.analysis.selection.select_model`).
    growth_terms : {"default", "auto"}, default "default"
        ``"auto"``: every candidate with growth terms chooses them by evidence (see
        :func:`~piezohyst.analysis.selection.select_model`).
    force : bool
        Replace an existing ``out`` piezohyst did not write.
    progress : callable, optional
        Called with the rows read so far.

    Returns
    -------
    Selection
    """
    if out is not None:
        guard_outputs([out], [data], force=force)
    rec = (data_spec or DataSpec()).read(data, progress=progress)
    assert rec.y is not None
    w = rec.window
    warn_clipped([rec.y[w]], rec.names[1], rec.units[1], data)
    warn_assumed_volts(float(np.ptp(rec.x[w])), rec.units[0], rec.names[0], data)
    start = _continuing(rec, initial_state)
    if input_dynamics == "record":
        input_dynamics, note = dynamics_by_record(rec.x[w], rec.t[w])
    else:
        note = ""

    x, y, t = rec.x[w], rec.y[w], rec.t[w]

    def choose(dynamics: str) -> Selection:
        with warnings.catch_warnings():  # the file's holes and outliers: said by its rows above
            warnings.simplefilter("ignore", RecordWarning)
            if note:  # chosen by the rates: judged below
                warnings.simplefilter("ignore", IdentifiabilityWarning)
            return select_model(
                x, y, t, candidates=candidates, operators=operators,
                initial_state=start, input_unit=rec.units[0] or "V",
                output_unit=rec.units[1] or _default_unit(rec.names[1]),
                input_dynamics=dynamics, growth_terms=growth_terms,
            )  # fmt: skip

    sel = choose(input_dynamics)
    if note and undetermined(sel.model.input_dynamics_):  # as _fit_timed: chosen again
        note = _undetermined_note(sel.model.input_dynamics_, "the chosen model")
        sel = choose("none")
    if note and say is not None:
        say(note)
    if out is not None:
        sel.model.save(out)
    return sel


def dynamics_by_record(x: FloatArray, t: FloatArray) -> tuple[str, str]:
    """``"auto"`` where a record drives several rates, so that a lag between the command and
    the piezo can be told from loop width
    (:func:`~piezohyst.analysis.selection.several_rates`), else ``"none"``; and a sentence
    that says which and why.

    Parameters
    ----------
    x, t : ndarray
        The record's input and times.

    Returns
    -------
    (str, str)
    """
    several, rates = several_rates(x, t)
    if not rates.size:
        return "none", "input dynamics: none (the input does not turn)"
    low, high = np.percentile(rates, [5.0, 95.0])
    if several:
        return "auto", (
            f"input dynamics: identified (the record drives {low:.3g}-{high:.3g} Hz: a lag "
            "of the amplifier can be told from loop width; --input-dynamics none skips it)"
        )
    return "none", (
        f"input dynamics: none (the record drives one rate, about {np.median(rates):.3g} Hz, "
        "where a lag looks like loop width; record several, piezohyst excite, to identify it)"
    )


def _fit_timed(
    estimator: HysteresisModel,
    x: FloatArray,
    y: FloatArray,
    t: FloatArray,
    start: InitialState,
    note: str,
) -> tuple[HysteresisModel, str]:
    """Fit with the input dynamics the record's rates called for; where the fit cannot tell
    them from hysteresis after all (:func:`~piezohyst.model.fit_record.undetermined`: on a
    relaxing plant's ``excite`` record, 4.6 +- 11 ms, and learning at 40 Hz through them left
    57 % width), fit again without them, and say so."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)  # judged here, said below
        model = estimator.fit(x, y, t=t, initial_state=start)
    if not undetermined(model.input_dynamics_):
        return model, note
    said = _undetermined_note(model.input_dynamics_, "this fit")
    plain = estimator.set_params(input_dynamics="none").fit(x, y, t=t, initial_state=start)
    return plain, said


def _undetermined_note(dyn: InputDynamics, who: str) -> str:
    """What ``--input-dynamics record`` says when the fit left the dynamics undetermined."""
    return (
        f"input dynamics: none (the record drives several rates, but {who} cannot tell a "
        f"lag from hysteresis: delay + lag {1e3 * (dyn.delay + dyn.tau):.3g} +- "
        f"{1e3 * undetermined(dyn):.2g} ms, 95 %; --input-dynamics auto keeps them)"
    )


def _dynamics_of_file(data: PathLike, spec: DataSpec | None) -> tuple[str, str]:
    """:func:`dynamics_by_record` of a file's window; none for one too long to hold."""
    rows = estimated_rows(Path(data))
    if rows is not None and rows > KEEP_ROWS:
        return "none", (
            "input dynamics: none (the record is streamed; --input-dynamics auto identifies "
            "them in memory)"
        )
    with warnings.catch_warnings():  # the fit's own read says what the file holds
        warnings.simplefilter("ignore")
        rec = (spec or DataSpec()).read(data)
    w = rec.window
    return dynamics_by_record(rec.x[w], rec.t[w])


def model_terms(
    model: str, accepted: dict[str, Any], growth_terms: str | Sequence[str], creep: Sequence[float]
) -> dict[str, Any]:
    """The growth terms and creep operators as settings of ``model`` (whose parameters are
    ``accepted``); either set away from its default where the model has no such setting is
    refused by name. ``growth_terms="default"`` leaves the model's own default (the
    presets' ``"domain"``, generalized PI's ``"auto"``)."""
    extra: dict[str, Any] = {}
    for name, value, default in (("growth_terms", growth_terms, "default"), ("creep", creep, ())):
        if name in accepted:
            if not (isinstance(value, str) and value == "default"):
                extra[name] = tuple(value) if name == "creep" else value
        elif (value if isinstance(value, str) else tuple(value)) != default:
            msg = f"the {name!r} setting does not apply to {model}"
            raise ParameterError(msg)
    return extra


def fit_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    model: str = "active-pi",
    operators: int = 10,
    data_spec: DataSpec | None = None,
    growth_terms: str | Sequence[str] = "default",
    creep: Sequence[float] = (),
    relaxation: float | None = None,
    input_dynamics: str = "none",
    output_dynamics: str = "none",
    initial_state: str = "rest",
    force: bool = False,
    progress: Progress = None,
    say: Callable[[str], None] | None = None,
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
        A name from :func:`~piezohyst.model.presets.model_names`.
    operators : int
        Play operators.
    data_spec : DataSpec, optional
        Columns and samples (default: voltage, charge, time).
    growth_terms, creep
        Settings of models that have them (``growth_terms``: every model but
        the classical and active PI, ``"default"`` its own default; ``creep``:
        ``generalized-pi`` and the models on a packed core: Preisach, Duhem, Bouc-Wen).
    relaxation : float, optional
        ``preisach``: time constant (s) of a relaxing part of the hysteresis
        (see :class:`~piezohyst.PreisachModel`).
    input_dynamics, output_dynamics : str
        Delay and lag between command and piezo, mode between hysteresis and
        output (see :class:`~piezohyst.model.presets.HysteresisModel`);
        ``input_dynamics="record"``: ``"auto"`` where the record drives several rates
        (:func:`dynamics_by_record`), else none, said through ``say``.
    initial_state : {"rest", "periodic"}
        Where the operators start: at rest, or (a record that is one period of
        a periodic drive, starting mid-cycle) in the periodic steady state. A
        window after ``t_start`` starts from the input before it either way.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.
    progress : callable, optional
        Called with the rows read so far.
    say : callable, optional
        Told, in a sentence, what ``input_dynamics="record"`` decided and why.

    Returns
    -------
    HysteresisModel
        The fitted model.
    """
    if out is not None:
        guard_outputs([out], [data], force=force)
    cls = model_class(model)
    accepted = cls().get_params()
    extra = model_terms(model, accepted, growth_terms, creep)
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
    note = ""
    if input_dynamics == "record" and stream.untimed:  # no times: no dynamics to identify
        input_dynamics = settings["input_dynamics"] = "none"
    if input_dynamics == "record":  # by the record's rates; read once more to judge them
        cls(**{**settings, "input_dynamics": "none"}).check_params()  # bad settings first
        input_dynamics, note = _dynamics_of_file(data, data_spec)
        settings["input_dynamics"] = input_dynamics
    estimator = cls(**settings)
    if note and input_dynamics == "none" and say is not None:
        say(note)
    if input_dynamics != "none" or output_dynamics != "none":  # searched over the window in memory
        stream.require_time(f"{model}'s input and output dynamics")
        rec = (data_spec or DataSpec()).read(data, progress=progress)
        w = rec.window
        assert rec.y is not None
        y_win = rec.y[w]
        warn_clipped([y_win], rec.names[1], rec.units[1], data)
        start_dyn = _continuing(rec, initial_state)
        warn_assumed_volts(float(np.ptp(rec.x[w])), x_unit, stream.names[0], data)
        if note:  # chosen by the record's rates: kept only where the record determines them
            fitted_dyn, note = _fit_timed(estimator, rec.x[w], rec.y[w], rec.t[w], start_dyn,
                                          note)  # fmt: skip
        else:
            fitted_dyn = estimator.fit(rec.x[w], rec.y[w], t=rec.t[w], initial_state=start_dyn)
        if note and say is not None:
            say(note)
        if start_dyn == "rest":
            _mid_loop_hint(rec.x[w][:2], rec.t[w][:2], fitted_dyn)
        if out is not None:
            fitted_dyn.save(out)
        return fitted_dyn
    passes = _Passes(progress)
    window = _window_blocks(stream, passes)
    warn_clipped(_window_output(stream), stream.names[1], stream.units[1], data)
    start: InitialState = initial_state
    if math.isfinite(stream.t_start):  # the window continues a known input history
        plan = estimator.core_class.states_before_fit(estimator.get_params(), Summary.of(window))
        if plan is None:  # the fit runs the history itself
            before = _history_input(stream, passes.tick())
            start = History(before) if before is not None else initial_state
        else:  # the core's states run through the history first, streamed
            fixed, probe = plan
            estimator.set_params(**fixed)
            start = _history(stream, probe, passes.tick())
    try:
        fitted: HysteresisModel = estimator.fit_blocks(
            window, timed=not stream.untimed, initial_state=start
        )
    except TimeAxisError:  # a rate-dependent term, and the file gives no time
        stream.require_time(f"{type(estimator).__name__}'s rate-dependent terms")
        raise
    lo, hi = fitted.input_range_
    warn_assumed_volts(hi - lo, x_unit, stream.names[0], data)
    if isinstance(start, str) and start == "rest":
        x_head, _, t_head = next(iter(window()))
        _mid_loop_hint(x_head[:2], None if t_head is None else t_head[:2], fitted)
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

    See :func:`~piezohyst.analysis.comparison.compare_models`. Without ``test_data``
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
        CLI names (``piezohyst fit --model``); each with its default settings, and with
        ``+creep`` creep operators timed by the record
        (:func:`~piezohyst.analysis.selection.candidate_model`). Default: every registered
        model (:func:`~piezohyst.model.presets.model_names`) and the creep candidates of
        :data:`~piezohyst.analysis.selection.CANDIDATES`.
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
    every = [*model_names(), *(n for n in CANDIDATES if n.endswith(CREEP))]  # creep: timed
    names = list(dict.fromkeys(every if models is None else models))
    if not names:
        msg = "give at least one model to compare"
        raise ParameterError(msg)
    for name in names:
        if not is_candidate(name):
            model_class(name.removesuffix(CREEP))  # names the unknown model
            msg = f"{name!r}: the {name.removesuffix(CREEP)} model takes no creep operators"
            raise ParameterError(msg)
    inputs = [data] if test_data is None else [data, test_data]
    if out is not None:
        guard_outputs([out], inputs, force=force)
    spec = data_spec or DataSpec()
    rec = spec.read(data)
    assert rec.y is not None
    w = rec.window
    x_unit, y_unit = rec.units
    warn_assumed_volts(float(np.ptp(rec.x[w])), x_unit, rec.names[0], data)
    units = (x_unit or "V", y_unit or _default_unit(rec.names[1]))
    times = None if rec.t is None else rec.t[w]
    estimators = {
        name: candidate_model(name, operators, units, times, input_dynamics=input_dynamics)
        for name in names
    }
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
    start = _continuing(rec, initial_state)
    result = compare_models(
        estimators, rec.x[w], rec.y[w], rec.t[w], train=train, test=test,
        initial_state=start,
    )  # fmt: skip
    a, b = result.train
    inner = forward_scores(estimators, rec.x[w][a:b], rec.y[w][a:b], rec.t[w][a:b], start)
    if any(math.isfinite(r.score) for r in inner):  # chosen inside the training part alone
        first, winner = decide(inner)  # as select_model decides
        part = (rec.x[w][a:b], rec.y[w][a:b], rec.t[w][a:b])
        notes = record_notes(part[0])

        def fitted(name: str) -> Any:
            with warnings.catch_warnings():  # the candidates' own fits: said by compare above
                warnings.simplefilter("ignore")
                fresh = candidate_model(
                    name, operators, units, times, input_dynamics=input_dynamics
                )
                return fresh.fit(*part[:2], t=part[2], initial_state=start)

        near = median_choice(inner, part[0], part[2], fitted)
        if near is not None and near[0].name != winner.name:
            notes = (median_said(near[0].name, winner.name, part[0]), *notes)
            winner = near[0]
        close = (first.name, *undecided(with_margins(inner, first), first.name))
        creep, creep_said = creep_where_undecided(winner.name, close, [r.name for r in inner])
        if creep_said:
            notes, winner = (*creep_said, *notes), next(r for r in inner if r.name == creep)
        said = verdict(with_margins(inner, winner), winner.name, notes)
        result = dataclasses.replace(result, recommended=winner.name, recommendation_notes=said)
    if w.start:  # the samples scored, as rows of the record
        (a, b), (c, d) = result.train, result.test
        shift = 0 if result.separate_test else w.start
        result = dataclasses.replace(
            result, train=(a + w.start, b + w.start), test=(c + shift, d + shift)
        )
    if out is not None:
        if Path(out).suffix.lower() == ".md":
            atomic_write_text(out, f"{MD_MARKER} {__version__} -->\n\n{result.table()}\n")
        else:
            rows = [r.as_dict() for r in result.rows]
            text = ("model", "status", "absorbed", "notes", "error")
            write_rows(out, rows, list(rows[0]), text)
    return result


def _mid_loop_hint(x: FloatArray, t: FloatArray | None, model: HysteresisModel) -> None:
    """Warn when a record fitted from rest looks cut from a running drive: it starts inside
    its input range and either away from 0 V or already moving at half its fastest slew.
    A rest start then misreads the first loops (the PZT ceramic's 1000 V period of
    docs/validation.md, cut at 77 V: classical PI 9.28 % NRMSE from rest, 2.11 % periodic)."""
    lo, hi = model.input_range_
    span, x0 = hi - lo, float(x[0])
    if not span > 0 or not min(x0 - lo, hi - x0) > 0.1 * span:
        return
    moving = False
    if t is not None and x.size > 1 and t[1] > t[0] and math.isfinite(model.max_slew_rate_):
        moving = x0 != 0.0 and abs(x[1] - x0) / (t[1] - t[0]) > 0.5 * model.max_slew_rate_
    if abs(x0) > 0.05 * span or moving:
        warn(
            f"the record starts mid-loop ({x0:.4g} {model.input_unit}, inside "
            f"[{lo:.4g}, {hi:.4g}]{', moving' if moving else ''}) and was fitted from rest "
            "there; if the actuator was cycling before it, initial_state='periodic' "
            "(--initial-state periodic) starts it on its loop",
            UserWarning,
        )


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
                block = (b.x[i0:i1], b.y[i0:i1], None if stream.untimed else b.t[i0:i1])
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


def _window_output(stream: RecordingStream) -> Iterator[FloatArray]:
    """The measured output inside the record's window, block by block."""
    for b in stream.blocks():
        i0, i1 = np.searchsorted(b.t, [stream.t_start, stream.t_stop], "left")
        if i1 > i0 and b.y is not None:
            yield b.y[i0:i1]


def _history(
    stream: RecordingStream, core: Core, progress: Callable[[int], None] | None
) -> FloatArray | None:
    """The core's state at the window's start, from the input before it, block by block
    (None: no history)."""
    z = None
    for b in stream.blocks(progress):
        before = int(np.searchsorted(b.t, stream.t_start, "left"))
        if before:
            x = b.x[:before]
            z = core.propagate(x, core.rest_state(float(x[0])) if z is None else z).state
        if before < b.t.size:
            break
    return z


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
    scored : (float, float)
        Times (s) of the first and last scored sample.
    start : str
        From which state the model ran, in words.
    """

    samples: int
    rmse: float
    nrmse: float
    unit: str
    scored: tuple[float, float] = (math.nan, math.nan)
    start: str = ""


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

    Parameters
    ----------
    model_path, data, out : str or path
        The model file, the record to run it on, the file to write.
    data_spec : DataSpec, optional
        Which columns and samples of ``data`` (default: the usual names, every sample).
    initial_state : {"model", "rest", "periodic"}
    force : bool, default False
    progress : callable, optional

    Returns
    -------
    Prediction
        The scores where the record has the output, and what was written.
    """
    if initial_state not in ("model", "rest", "periodic"):
        msg = f"initial_state must be 'model', 'rest' or 'periodic'. Got {initial_state!r}."
        raise ParameterError(msg)
    guard_outputs([out], [model_path, data], force=force)
    model = _load(model_path)
    stream = (data_spec or DataSpec()).open(data, output_required=False)
    if model.rate_dependent_:
        stream.require_time(f"{type(model).__name__}'s rate-dependent terms")
    clock = "sample" if stream.untimed else "time"  # no time axis: the sample's index
    measured = stream.names[1] is not None
    if measured:
        _check_measured_unit(stream.units[1], model, data)
        warn_clipped(_window_output(stream), stream.names[1], stream.units[1], data)
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

    # a model identified on a window of this record runs from its own initial state at the
    # window's start (where its fit started: the history's state, the growth at rest); a
    # sample before the window, if asked for, runs from rest at the record's start
    t_w = model.train_window_[0]
    warm = initial_state == "model" and math.isfinite(t_w)
    first_block = next(iter(stream.blocks())) if warm else None  # read only when needed
    warm = first_block is not None and float(first_block.t[0]) < t_w
    said = "the model's initial state at the record's start"
    if initial_state != "model":
        said = f"{initial_state} at the record's start"
    elif warm:
        said = (
            f"the model's own state at its training window's start ({t_w:.6g} s; before it, "
            "from rest at the record's start)"
        )
    scored = [math.inf, -math.inf]

    def rows() -> Iterator[dict[str, FloatArray]]:
        nonlocal sse, lo, hi
        state: ModelState | FloatArray | None = start
        if warm:
            assert first_block is not None
            state = model.rest_state(float(first_block.x[0]))
        first = last = math.nan
        written = 0
        for b in stream.blocks(progress):
            first = float(b.t[0]) if b.start == 0 else first
            last = float(b.t[-1])
            end = int(np.searchsorted(b.t, stream.t_stop, "left"))  # later: nothing to score
            if end == 0:
                break
            xb, tb = b.x[:end], b.t[:end]
            if warm and tb[0] < t_w:  # samples before the training window
                k = int(np.searchsorted(tb, t_w, "left"))
                output = np.full(k, np.nan)
                if tb[k - 1] >= stream.t_start:  # some are asked for
                    run = model.propagate(xb[:k], tb[:k], state)
                    output, state = run.output, run.state
                if k < tb.size:  # the training window starts in this block
                    run = model.propagate(xb[k:], tb[k:])
                    output, state = np.concatenate([output, run.output]), run.state
            else:
                run = model.propagate(xb, tb, state)
                output, state = run.output, run.state
            i0 = int(np.searchsorted(tb, stream.t_start, "left"))
            if end <= i0:
                continue
            cols = {clock: tb[i0:], "predicted": output[i0:]}
            scored[0], scored[1] = min(scored[0], float(tb[i0])), float(tb[-1])
            if b.y is not None:
                cols["measured"] = y = b.y[i0:end]
                sse += float(np.sum((cols["predicted"] - y) ** 2))
                lo, hi = min(lo, float(y.min())), max(hi, float(y.max()))
            written += end - i0
            yield cols
        if not written:  # raised before the file is renamed into place: nothing is written
            raise stream.empty_window(first, last)

    unit = model.output_unit
    n = write_blocks(out, rows(), units={"time": "s", "sample": None, "predicted": unit,
                                         "measured": unit})  # fmt: skip
    err = math.sqrt(sse / n) if measured else math.nan
    nrmse = err / (hi - lo) if hi > lo else math.nan
    return Prediction(n, err, nrmse, unit, (scored[0], scored[1]), said)
