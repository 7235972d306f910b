"""A recording from a data file: which columns are input, output and time, in which units, read
whole or block by block, every value and time checked (the row and column named)."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import DataFileError, RecordWarning, warn
from ..units import scaled, to_standard
from ._formats import (
    Recording,
    Table,
)
from .screening import Screen, Screener
from .tables import open_table


@dataclass(frozen=True)
class Block:
    """Consecutive samples of a recording: time in s, input and output converted.

    Attributes
    ----------
    start : int
        Index of the block's first sample in the record.
    t, x : ndarray
    y : ndarray or None
    """

    start: int
    t: FloatArray
    x: FloatArray
    y: FloatArray | None


@dataclass(frozen=True)
class RecordingStream:
    """A recording read block by block: memory does not grow with its length.

    Made by :func:`open_recording`. Each call of :meth:`blocks` reads the file
    again from its start, so several passes (statistics, then a fit) need no
    copy in memory. The checks and conversions are those of
    :func:`read_recording`, which collects this stream.

    Attributes
    ----------
    path : Path
    names : tuple
        Column names of input, output and time (None where not from a column).
    units : tuple
        Units of input and output after conversion (see :class:`Recording`).
    t_start, t_stop : float
        The window asked for (s): ``t_start <= t < t_stop`` (infinite: open).
    keep_outliers : bool
        Keep the isolated outliers :meth:`screen` finds (by default each is
        replaced by its neighbours' mean in every block).
    untimed : bool
        The file has no time column, rate or interval: its blocks carry the
        sample index as time, enough for a rate-independent model only
        (:meth:`require_time` refuses the rest).
    """

    path: Path
    names: tuple[str, str | None, str | None]
    units: tuple[str | None, str | None]
    t_start: float
    t_stop: float
    _table: Table = field(repr=False)
    _source_units: tuple[str | None, str | None, str | None] = field(repr=False)
    _rate: float | None = field(default=None, repr=False)
    _step: float | None = field(default=None, repr=False)
    _warned: set[str] = field(default_factory=set, repr=False, compare=False)  # once per stream
    keep_outliers: bool = False
    _screened: dict[str, Screen] = field(default_factory=dict, repr=False, compare=False)
    untimed: bool = False
    _scales: tuple[float, float] = field(default=(1.0, 1.0), repr=False)

    def require_time(self, why: str) -> None:
        """Raise unless the record has a time axis (a column, a rate or a stated interval).

        Parameters
        ----------
        why : str
            What needs it, for the message ("ActivePI's growth terms").

        Raises
        ------
        DataFileError
        """
        if self.untimed:
            raise DataFileError(no_time_message(self.path, self._table.columns, why))

    def in_window(self, t: FloatArray) -> FloatArray:
        """Which of the times ``t`` (s) lie in the window (a boolean array).

        Parameters
        ----------
        t : ndarray

        Returns
        -------
        ndarray of bool
        """
        return np.asarray((t >= self.t_start) & (t < self.t_stop))

    def empty_window(self, first: float, last: float) -> DataFileError:
        """The error for a window holding no sample of a record from ``first`` to ``last`` (s).

        Parameters
        ----------
        first, last : float

        Returns
        -------
        DataFileError
        """
        return DataFileError(
            f"{self.path}: no samples in the time window [{self.t_start:g}, {self.t_stop:g}) s "
            f"(the record spans {first:g} to {last:g} s)"
        )

    def screen(self) -> Screen:
        """The record's isolated outliers and holes in time (:mod:`piezohyst.io.screening`),
        found in one pass of its own the first time it is asked for, and warned of once.

        Returns
        -------
        Screen

        Warns
        -----
        RecordWarning
            Naming each outlier (row, column, value) and each hole (row, length).
        """
        found = self._screened.get("screen")
        if found is not None:
            return found
        x_name, y_name, t_name = self.names
        names = [n for n in (x_name, y_name) if n is not None]
        check = Screener(names)
        for b in self._read():
            check.add(b.start, dict(zip(names, (b.x, b.y), strict=False)),  # type: ignore[arg-type]
                      b.t if t_name is not None else None)  # fmt: skip
        found = check.finish()
        self._screened["screen"] = found
        units = dict(zip(names, self.units, strict=False))
        if found.outliers:
            message = found.outlier_message(str(self.path), units)
            if self.keep_outliers:
                message = message.split("; kept out of")[0] + "; kept, as asked (keep_outliers)"
            warn(message, RecordWarning)
        if found.holes:
            warn(found.hole_message(str(self.path)), RecordWarning)
        step = found.interval
        if t_name is not None and self._source_units[0] is None and step >= 1 and step % 1 == 0:
            warn(
                f"{self.path}: the time column {t_name!r} steps by {step:g} and states no "
                f"unit: read as seconds, the record is sampled at {1 / step:g} Hz; if it "
                "counts ms or us, say so (--time-unit ms, or a header 'time [ms]')",
                RecordWarning,
            )
        return found

    def blocks(self, progress: Callable[[int], None] | None = None) -> Iterator[Block]:
        """The record from its first sample, block by block, checked, converted and screened
        (an isolated outlier replaced by its neighbours' mean, unless ``keep_outliers``).

        Parameters
        ----------
        progress : callable, optional
            Called with the rows read so far.

        Yields
        ------
        Block

        Raises
        ------
        DataFileError
            A value that is not finite, or a time that does not increase (naming
            the row and column), or an empty record.
        """
        found = self.screen()
        x_name, y_name, _ = self.names
        for b in self._read(progress):
            if found.outliers and not self.keep_outliers:
                y = None if b.y is None or y_name is None else found.cleaned(y_name, b.y, b.start)
                b = Block(b.start, b.t, found.cleaned(x_name, b.x, b.start), y)
            yield b

    def _read(self, progress: Callable[[int], None] | None = None) -> Iterator[Block]:
        """The record's blocks as the file holds them, checked and converted."""
        x_name, y_name, t_name = self.names
        keys = [k for k in (x_name, y_name, t_name) if k is not None]
        t_unit, x_unit, y_unit = self._source_units
        where = f"{self.path}: column"
        start = 0
        t_last: float | None = None
        for batch in self._table.batches(keys):
            for name in keys:
                check_finite(batch[name], start, f"{self.path}", name)
            x = batch[x_name]
            m = x.size
            if t_name is not None:
                t = batch[t_name]
            elif self._rate is not None:
                t = (start + np.arange(m, dtype=np.float64)) / self._rate
            else:
                assert self._step is not None
                t = (start + np.arange(m, dtype=np.float64)) * self._step
            check_increasing(t, t_last, start, f"{self.path}", t_name)
            if m:
                t_last = float(t[-1])
            t_s, _ = to_standard(t, t_unit, "time", f"{where} {t_name!r}")
            if start == 0 and m > 1:
                self._check_interval(t_s)
            x_scale, y_scale = self._scales  # a DAQ's volts to the column's unit
            x = x if x_scale == 1.0 else x * x_scale
            x, _ = to_standard(x, x_unit, "input", f"{where} {x_name!r}")
            y = None
            if y_name is not None:
                y = batch[y_name] if y_scale == 1.0 else batch[y_name] * y_scale
                y, _ = to_standard(y, y_unit, "output", f"{where} {y_name!r}")
            yield Block(start, t_s, x, y)
            start += m
            if progress is not None:
                progress(start)
        if start == 0:
            msg = f"{self.path}: column {x_name!r} is empty"
            raise DataFileError(msg)

    def _check_interval(self, t: FloatArray) -> None:
        dt = float(np.median(np.diff(t)))
        if not 1e-8 <= dt <= 60.0 and "interval" not in self._warned:
            self._warned.add("interval")
            warn(
                f"{self.path}: the median sample interval is {dt:.3g} s; if the time column is "
                "not in seconds, give its unit (a header such as 'time [ms]', or the time unit)",
                UserWarning,
            )


def no_time_message(path: Path, columns: Sequence[str], why: str) -> str:
    """The one line for a record without a time axis that ``why`` needs."""
    return (
        f"{path}: no time column 'time' and no sample rate, which {why} needs; name the time "
        f"column or give the rate in Hz (columns: {', '.join(map(repr, columns))})"
    )


#: Magnitudes beyond this in a data file are logging errors, not measurements (1e100 C, V, s)
MAX_VALUE = 1e100


def check_finite(values: FloatArray, start: int, where: str, column: str) -> None:
    """Raise naming the first NaN or infinite value of a block, by its row in the file.

    Parameters
    ----------
    values : ndarray
    start : int
        Row of the block's first value (0-based).
    where : str
        The file, for the message.
    column : str

    Raises
    ------
    DataFileError
    """
    bad = ~(np.abs(values) <= MAX_VALUE)  # NaN, infinite, or beyond any measurement
    if bad.any():
        i = int(np.argmax(bad))
        why = "values must be finite" if not np.isfinite(values[i]) else (
            f"no measurement reaches {MAX_VALUE:g} in any unit: a logging error")  # fmt: skip
        msg = f"{where}: {values[i]} at row {start + i + 1}, column {column!r} ({why})"
        raise DataFileError(msg)


def check_increasing(
    t: FloatArray, t_last: float | None, start: int, where: str, column: str | None
) -> None:
    """Raise unless a block of times increases strictly, from the previous block's last time on.

    Parameters
    ----------
    t : ndarray
        The block's times (any unit).
    t_last : float or None
        The previous block's last time (None for the first block).
    start : int
        Row of the block's first sample in the file (0-based).
    where : str
        The file, for the message.
    column : str or None
        The time column's name (None when the times were made from a rate).

    Raises
    ------
    DataFileError
        Naming the row, column and the two times.
    """
    if t_last is not None and t.size:
        t = np.concatenate([[t_last], t])
        start -= 1
    steps = np.diff(t)
    if steps.size and np.any(steps <= 0):
        i = int(np.argmax(steps <= 0)) + 1
        why = (
            "the same time twice: a sample logged twice, or a clock too coarse for the rate"
            if t[i] == t[i - 1]
            else "the time goes back: two records in one file? give each its own"
        )
        msg = (
            f"{where}: time is not increasing at row {start + i + 1}"
            f"{'' if column is None else f', column {column!r}'} "
            f"({float(t[i - 1])!r} then {float(t[i])!r}: {why})"
        )
        raise DataFileError(msg)


def open_recording(
    path: str | os.PathLike[str],
    *,
    input_column: str = "voltage",
    output_column: str | None = "charge",
    time_column: str | None = "time",
    rate: float | None = None,
    group: str | None = None,
    output_required: bool = True,
    t_start: float | None = None,
    t_stop: float | None = None,
    input_unit: str | None = None,
    output_unit: str | None = None,
    time_unit: str | None = None,
    skip_rows: int = 0,
    output_file: str | os.PathLike[str] | None = None,
    keep_outliers: bool = False,
    input_scale: str | float | None = None,
    output_scale: str | float | None = None,
) -> RecordingStream:
    """A recording to read block by block (arguments as :func:`read_recording`).

    The columns, time source and units are settled here (a misnamed column
    fails at once); the values are read by :meth:`RecordingStream.blocks`.

    Parameters
    ----------
    path : str or os.PathLike
    input_column, output_column, time_column, rate, group, output_required
    t_start, t_stop, input_unit, output_unit, time_unit, skip_rows, output_file, keep_outliers
    input_scale, output_scale
        See :func:`read_recording`.

    Returns
    -------
    RecordingStream
    """
    # the default time name may be absent (TDMS states its sample interval instead)
    output = output_column
    wanted = [c for c in (input_column, None if output_file else output) if c is not None]
    if time_column is not None and time_column != "time":
        wanted.append(time_column)
    table = open_table(path, group=group, channels=wanted, skip_rows=skip_rows)
    if output_file is not None and input_column not in table and len(table.columns) == 1:
        input_column = table.columns[0]  # a file holding one signal, the output in another
    if output_file is not None:  # the output in a file of its own, row for row
        if output is None:
            msg = f"{output_file}: an output file needs the output column named"
            raise DataFileError(msg)
        other = open_table(output_file, group=group, channels=[output], skip_rows=skip_rows)
        only = other.columns[0] if len(other.columns) == 1 else None  # its one signal: no name
        name = only if only is not None and output not in other else other.resolve(output)
        table, output = _joined(table, other, name)
    x_name = _named(table, input_column, "input")
    y_name: str | None = None
    # the default output may be absent (predicting needs no output); a named one may not
    if output is not None and (output_required or output in table or output != "charge"):
        y_name = _named(table, output, "output")
    time = time_column
    if time == "time" and time not in table:  # the default name in any case ('Time', aixACCT),
        # or in the file's one group that has it, or LabVIEW's name for it (its .lvm files)
        named = {c.lower(): c for c in reversed(table.columns)}  # the first of a name
        time = named.get("time") or table.find(time) or named.get("x_value", time)
    t_name: str | None = None
    step: float | None = None
    untimed = False
    if rate is not None:
        if not rate > 0:
            msg = f"the sample rate must be positive (Hz). Got {rate}."
            raise DataFileError(msg)
        if time is not None and (time in table or time != "time"):
            msg = (
                f"{table.path}: the file has a time column {time!r} and a sample rate was "
                "given too; use one of them"
            )
            raise DataFileError(msg)
    elif time is not None and (time in table or time != "time"):  # a named one must be there
        t_name = _named(table, time, "time")  # (names the available columns where it is not)
    elif table.time_step is not None:
        step = table.time_step
    elif t_start is None and t_stop is None:  # enough for a rate-independent model
        step, untimed = 1.0, True
    else:
        raise DataFileError(no_time_message(table.path, table.columns, "a time window"))
    x_scale, x_source = scaled(
        input_scale, _unit(table, x_name, input_unit), "input", "input scale"
    )
    y_scale, y_source = 1.0, None
    if y_name is not None:
        y_source = _unit(table, y_name, output_unit)
        y_scale, y_source = scaled(output_scale, y_source, "output", "output scale")
    source = (_unit(table, t_name, time_unit), x_source, y_source)
    where = f"{table.path}: column"
    empty = np.empty(0)
    to_standard(empty, source[0], "time", f"{where} {t_name!r}")  # an unknown time unit fails now
    x_unit = to_standard(empty, source[1], "input", f"{where} {x_name!r}")[1]
    y_unit = None
    if y_name is not None:
        y_unit = to_standard(empty, source[2], "output", f"{where} {y_name!r}")[1]
    return RecordingStream(
        table.path,
        (x_name, y_name, t_name),
        (x_unit, y_unit),
        -np.inf if t_start is None else float(t_start),
        np.inf if t_stop is None else float(t_stop),
        table,
        source,
        None if rate is None else float(rate),
        step,
        keep_outliers=bool(keep_outliers),
        untimed=untimed,
        _scales=(x_scale, y_scale),
    )


def _named(table: Table, name: str, role: str) -> str:
    """The column ``name`` resolves to; where there is none, the error says which setting names
    the ``role``'s column (an oscilloscope's CH1, CH2 are no voltage and charge by name)."""
    try:
        return table.resolve(name)
    except DataFileError as exc:
        msg = f"{exc}; name the {role} column with --{role} ({role}_column=)"
        raise DataFileError(msg) from None


def _joined(table: Table, other: Table, name: str) -> tuple[Table, str]:
    """``table`` with the column ``name`` of ``other`` beside it (the two files row for row),
    and that column's name in the joined table."""
    label = name if name not in table else f"{name} ({other.path.name})"

    def stream(names: Sequence[str]) -> Iterator[dict[str, FloatArray]]:
        own = [n for n in names if n != label]
        theirs = ({label: b[name]} for b in other.batches([name]))
        if label not in names:
            yield from table.batches(own)
            return
        if not own:
            yield from theirs
            return
        sources = [table.batches(own), theirs]
        held: list[dict[str, FloatArray]] = [{}, {}]
        rows = [0, 0]
        while True:
            for i, source in enumerate(sources):
                if not held[i] or next(iter(held[i].values())).size == 0:
                    got = next(source, None)
                    held[i] = {} if got is None else got
                    rows[i] += 0 if got is None else next(iter(got.values())).size
            if not held[0] or not held[1]:
                break
            m = min(next(iter(h.values())).size for h in held)
            yield {k: v[:m] for h in held for k, v in h.items()}
            held = [{k: v[m:] for k, v in h.items()} for h in held]
        if held[0] or held[1]:  # one file ended first: count the other's rows for the message
            for i, source in enumerate(sources):
                rows[i] += sum(next(iter(b.values())).size for b in source)
            msg = (
                f"{other.path}: {rows[1]} rows, but {table.path} has {rows[0]}; the input "
                "and output files must hold the same samples, row for row"
            )
            raise DataFileError(msg)

    def getter(key: str) -> Callable[[], FloatArray]:
        return lambda: np.concatenate([b[key] for b in stream([key])])

    columns = [*table.columns, label]
    units = dict(table.units)
    if other.unit(name) is not None:
        units[label] = other.units[name]
    joined = Table(
        table.path,
        columns,
        {c: getter(c) for c in columns},
        table.time_step or other.time_step,
        units,
        table.group,
        table.groups,
        _stream=stream,
    )
    return joined, label


def read_recording(
    path: str | os.PathLike[str], *, progress: Callable[[int], None] | None = None, **options: Any
) -> Recording:
    """Input, output and time columns of a data file, in seconds and (where known) V, C or m.

    Time comes from ``time_column`` when the file has it, else from
    ``rate`` (Hz), else from the file's own sample interval (TDMS); the time
    must be strictly increasing. ``output_column=None`` reads no output.
    :func:`open_recording` reads the same block by block (the same options).

    Parameters
    ----------
    path : str or os.PathLike
        The data file (see :func:`read_table` for the formats).
    progress : callable, optional
        Called with the rows read so far (see :func:`read_table`).
    **options
        Keyword options of :func:`open_recording`:
    input_column, output_column, time_column : str or None
        Column names, or 0-based indices as digits.
    rate : float, optional
        Sample rate (Hz) when the file has no time column.
    group : str, optional
        TDMS group.
    output_required : bool, default True
        Raise if the output column is missing.
    t_start, t_stop : float, optional
        The window of samples asked for (s).
    input_unit, output_unit, time_unit : str, optional
        Units of the columns, for files whose headers name none (a header's
        ``name [unit]`` or ``name (unit)`` counts; naming both differently
        is an error). Converted by :func:`piezohyst.units.to_standard`.
    skip_rows : int, default 0
        Text files: lines to skip before the table (a ``Key: value``
        preamble is found without it).
    output_file : str or os.PathLike, optional
        The output column is in this file, row for row with ``path``
        (the Bouc-Wen benchmark's ``uval``/``yval`` files).
    keep_outliers : bool, default False
        Keep the isolated outliers (an ADC glitch) that are otherwise named in a
        :class:`~piezohyst.errors.RecordWarning` and replaced by their
        neighbours' mean (:mod:`piezohyst.io.screening`).
    input_scale, output_scale : str or float, optional
        What one unit of the column is worth, for channels a DAQ logs in volts: an
        amplifier's monitor at 1/100 (``100``), a sensor (``"10 um/V"``), a Sawyer-Tower
        circuit's reference capacitor (``"4.7 uF"``), a sensor counting the other way
        (``-1``). See :func:`piezohyst.units.scaled`.

    Returns
    -------
    Recording
        The columns in standard units (s, V, and the output's), with its window and names.

    Raises
    ------
    DataFileError
        A missing or misnamed column, a time column together with a sample
        rate, a bad or non-increasing time, or units that contradict the file.
    """
    stream = open_recording(path, **options)
    return collect(stream, progress)


def collect(stream: RecordingStream, progress: Callable[[int], None] | None = None) -> Recording:
    """A whole :class:`RecordingStream` in memory, with the window's samples marked.

    Parameters
    ----------
    stream : RecordingStream
    progress : callable, optional
        Called with the rows read so far.

    Returns
    -------
    Recording
        The stream's blocks joined in memory.

    Raises
    ------
    DataFileError
        A window that holds no sample (or any error of the stream).
    """
    stream.require_time("this command")  # only fit and predict stream an untimed record
    blocks = list(stream.blocks(progress))
    t = np.concatenate([b.t for b in blocks])
    x = np.concatenate([b.x for b in blocks])
    ys = [b.y for b in blocks if b.y is not None]
    y = np.concatenate(ys) if ys else None
    window = slice(None)
    if math.isfinite(stream.t_start) or math.isfinite(stream.t_stop):
        i0 = int(np.searchsorted(t, stream.t_start, "left"))
        i1 = int(np.searchsorted(t, stream.t_stop, "left"))
        if i1 <= i0:
            raise stream.empty_window(float(t[0]), float(t[-1]))
        window = slice(i0, i1)
    return Recording(t=t, x=x, y=y, names=stream.names, window=window, units=stream.units)


def _unit(table: Table, column: str | None, declared: str | None) -> str | None:
    """The unit of a column: the file's, or the one declared; both and different: an error."""
    found = None if column is None else table.unit(column)
    if found is not None and declared is not None and found != declared:
        msg = (
            f"{table.path}: column {column!r} is marked {found!r} in the file, but its unit "
            f"was given as {declared!r}"
        )
        raise DataFileError(msg)
    return found or declared


@dataclass(frozen=True)
class DataSpec:
    """Which columns and which samples of a data file to use (see :func:`read_recording`).

    Attributes
    ----------
    input_column, output_column, time_column : str or None
        Column names or 0-based indices as digits.
    rate : float or None
        Sample rate (Hz) when the file has no time column.
    group : str or None
        TDMS group.
    t_start, t_stop : float or None
        The window (s): ``t_start <= t < t_stop``.
    input_unit, output_unit, time_unit : str or None
        Units of the columns when the file's headers name none.
    skip_rows : int
        Text files: lines to skip before the table.
    output_file : str or None
        A second file holding the output column, row for row.
    keep_outliers : bool
        Keep the isolated outliers the record's check finds.
    input_scale, output_scale : str, float or None
        What one unit of the column is worth (``100``, ``"10 um/V"``, ``"4.7 uF"``).
    """

    input_column: str = "voltage"
    output_column: str | None = "charge"
    time_column: str | None = "time"
    rate: float | None = None
    group: str | None = None
    t_start: float | None = None
    t_stop: float | None = None
    input_unit: str | None = None
    output_unit: str | None = None
    time_unit: str | None = None
    skip_rows: int = 0
    output_file: str | None = None
    keep_outliers: bool = False
    input_scale: str | float | None = None
    output_scale: str | float | None = None

    def open(
        self, path: str | os.PathLike[str], *, output_required: bool = True
    ) -> RecordingStream:
        """:func:`open_recording` with these settings: the record block by block.

        Parameters
        ----------
        path : str or os.PathLike
            The data file.
        output_required : bool, default True
            Raise if the output column is missing (else read no output).

        Returns
        -------
        RecordingStream
        """
        return open_recording(
            path,
            input_column=self.input_column,
            output_column=self.output_column,
            time_column=self.time_column,
            rate=self.rate,
            group=self.group,
            output_required=output_required,
            t_start=self.t_start,
            t_stop=self.t_stop,
            input_unit=self.input_unit,
            output_unit=self.output_unit,
            time_unit=self.time_unit,
            skip_rows=self.skip_rows,
            output_file=self.output_file,
            keep_outliers=self.keep_outliers,
            input_scale=self.input_scale,
            output_scale=self.output_scale,
        )

    def read(
        self,
        path: str | os.PathLike[str],
        *,
        output_required: bool = True,
        progress: Callable[[int], None] | None = None,
    ) -> Recording:
        """:func:`read_recording` with these settings.

        Parameters
        ----------
        path : str or os.PathLike
            The data file, read whole.
        output_required : bool, default True
            Raise if the output column is missing (else the recording has no output).
        progress : callable, optional
            Called with the rows read so far.

        Returns
        -------
        Recording
        """
        return collect(self.open(path, output_required=output_required), progress)
