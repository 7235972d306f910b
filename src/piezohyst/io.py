"""Reading DAQ recordings and writing results.

Readers: CSV/TSV/text (delimiter sniffing, header detection), NumPy ``.npz``,
MATLAB ``.mat`` (v4-v7 through :mod:`scipy.io`, v7.3 through h5py), NI TDMS
(npTDMS; group/channel selection, time from ``wf_increment``) and HDF5.
Every problem with a file becomes one :class:`~piezohyst.errors.DataFileError`
whose message names the file and, where it applies, the row and column.
Writers (CSV, NPZ) write to a temporary file and rename it into place, so a
failure never leaves a half-written file.
"""

from __future__ import annotations

import csv
import dataclasses
import io as _io
import itertools
import logging
import math
import os
import re
import tempfile
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray
from ._version import __version__
from .errors import DataFileError
from .units import split_unit, to_standard

__all__ = [
    "BATCH_ROWS",
    "Block",
    "DataSpec",
    "Recording",
    "RecordingStream",
    "Table",
    "atomic_write",
    "atomic_write_text",
    "check_finite",
    "check_increasing",
    "collect",
    "is_piezohyst_output",
    "open_recording",
    "open_table",
    "read_recording",
    "read_table",
    "write_blocks",
    "write_table",
]

CSV_SUFFIXES = {".csv", ".tsv", ".txt", ".dat", ""}
MARKER = "# written by piezohyst"  # first line of every CSV piezohyst writes
MD_MARKER = "<!-- written by piezohyst"  # first line of every Markdown table it writes
BATCH_ROWS = 1 << 18  # rows per batch when streaming a file
CSV_BLOCK_BYTES = 1 << 22  # bytes pyarrow parses per CSV batch


@dataclass(frozen=True)
class Table:
    """Named columns read from a file, converted to numbers only when asked for.

    Attributes
    ----------
    path : Path
    columns : list of str
        Column names in file order (``col0``, ``col1``... when the file has no header).
    time_step : float or None
        Sample interval (s) stated by the file (TDMS ``wf_increment``), if any.
    units : mapping
        Unit of each column whose header named one (``time [ms]`` -> ``ms``).
    group : str or None
        The group (TDMS) or table (aixACCT) read, in files that hold several.
    groups : tuple of str
        All groups of such a file.
    """

    path: Path
    columns: list[str]
    _getters: Mapping[str, Callable[[], FloatArray]] = field(repr=False)
    time_step: float | None = None
    units: Mapping[str, str] = field(default_factory=dict)
    group: str | None = None
    groups: tuple[str, ...] = ()
    _stream: Callable[[Sequence[str]], Iterator[dict[str, FloatArray]]] | None = field(
        default=None, repr=False
    )

    def __contains__(self, name: object) -> bool:
        return name in self._getters

    def unit(self, name: str) -> str | None:
        """The unit the file gives a column (None when it gives none).

        Parameters
        ----------
        name : str
            A column name (see :meth:`resolve`).

        Returns
        -------
        str or None
        """
        return self.units.get(name)

    def resolve(self, key: str) -> str:
        """A column name from a name or a 0-based index given as digits.

        Parameters
        ----------
        key : str

        Returns
        -------
        str
        """
        if key in self._getters:
            return key
        bare, unit = split_unit(key)
        if unit is not None and bare in self._getters and self.units.get(bare) == unit:
            return bare
        if key.strip().lstrip("-").isdigit():
            i = int(key)
            if 0 <= i < len(self.columns):
                return self.columns[i]
        msg = f"{self.path}: no column {key!r}; available: " + ", ".join(
            repr(c) for c in self.columns
        )
        if self.groups:
            msg += f" (in group {self.group!r}; groups: {', '.join(map(repr, self.groups))})"
        raise DataFileError(msg)

    def get(self, key: str, *, finite: bool = True) -> FloatArray:
        """The column as float64 values (raises naming the bad row and column).

        Parameters
        ----------
        key : str
            Name or 0-based index as digits.
        finite : bool, default True
            Refuse NaN and infinity (a desired trajectory may hold them on purpose).

        Returns
        -------
        ndarray
        """
        name = self.resolve(key)
        values = self._getters[name]()
        if values.size == 0:
            msg = f"{self.path}: column {name!r} is empty"
            raise DataFileError(msg)
        bad = ~np.isfinite(values)
        if finite and bad.any():
            i = int(np.argmax(bad))
            msg = (
                f"{self.path}: {values[i]} at row {i + 1}, column {name!r} (values must be finite)"
            )
            raise DataFileError(msg)
        return values

    def batches(self, keys: Sequence[str]) -> Iterator[dict[str, FloatArray]]:
        """Columns in batches of rows, in file order, as stored (not yet checked).

        Streamed from the file where the format allows it (CSV, Parquet, see
        :func:`open_table`), so memory does not grow with the record; slices
        of the columns otherwise.

        Parameters
        ----------
        keys : sequence of str
            Names or 0-based indices as digits.

        Yields
        ------
        dict
            Column name to the batch's values.
        """
        names = [self.resolve(k) for k in keys]
        if self._stream is not None:
            yield from self._stream(names)
            return
        arrays = [self._getters[name]() for name in names]
        for name, arr in zip(names, arrays, strict=True):
            if arr.size != arrays[0].size:
                msg = (
                    f"{self.path}: column {name!r} has {arr.size} values, "
                    f"{names[0]!r} has {arrays[0].size}"
                )
                raise DataFileError(msg)
        for lo in range(0, arrays[0].size, BATCH_ROWS):
            yield {name: arr[lo : lo + BATCH_ROWS] for name, arr in zip(names, arrays, strict=True)}


@dataclass(frozen=True)
class Recording:
    """Input, output and time of one whole record, the column names they came from,
    and the window of samples asked for (``t_start <= t < t_stop``; all by default).

    The arrays hold the whole record because a hysteresis model needs the input
    history before a window to know its state at the window's start.

    Attributes
    ----------
    t, x : ndarray
        Time (s) and input.
    y : ndarray or None
        Output, if read.
    names : tuple
        Column names of input, output and time (None where not from a column).
    window : slice
        The samples asked for.
    units : tuple
        Units of input and output after conversion (V, C, m, or the file's
        own label; None when unknown). Time is always in s.
    """

    t: FloatArray
    x: FloatArray
    y: FloatArray | None
    names: tuple[str, str | None, str | None]
    window: slice = field(default_factory=lambda: slice(None))
    units: tuple[str | None, str | None] = (None, None)


# ------------------------------------------------------------------ CSV / text
def _decode(raw: bytes, path: Path) -> str:
    bom16 = raw[:2] in (b"\xff\xfe", b"\xfe\xff")
    for encoding in ("utf-16", "utf-8-sig") if bom16 else ("utf-8-sig",):
        try:
            return raw.decode(encoding)
        except UnicodeDecodeError:
            continue
    try:
        return raw.decode("latin-1")  # aixACCT and many DAQ exports
    except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes any byte
        msg = f"{path}: not a text file"
        raise DataFileError(msg) from None


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _sniff_delimiter(sample: str) -> str | None:
    """The delimiter most lines agree on with the first line; None means whitespace.

    Agreement, not unanimity: one ragged row must not hide the delimiter (it is
    then reported as a ragged row).
    """
    lines = [ln for ln in sample.splitlines() if ln.strip()][:50]
    best, best_score = None, 0.0
    for delim in (",", "\t", ";", "|"):
        first = lines[0].count(delim)
        if first == 0:
            continue
        score = sum(ln.count(delim) == first for ln in lines) / len(lines)
        if score > best_score:
            best, best_score = delim, score
    return best if best_score >= 0.5 else None


def _read_text(
    path: Path,
    group: str | None = None,
    channels: Sequence[str] = (),
    progress: Callable[[int], None] | None = None,
) -> Table:
    head = _read_head(path)
    if b"\x00" in head and head[:2] not in (b"\xff\xfe", b"\xfe\xff"):
        msg = f"{path}: not a text file (binary content); expected CSV or text columns"
        raise DataFileError(msg)
    fast = _read_csv_arrow(path, head, progress)
    if fast is not None:
        return fast
    return _read_text_careful(path, group, channels)


def _read_text_careful(path: Path, group: str | None, channels: Sequence[str]) -> Table:
    """Every text file pyarrow does not read cleanly, in memory, with exact messages."""
    raw = path.read_bytes()
    text = _decode(raw, path)
    if _AIXACCT_TABLE.match(text.split("\n", 3)[2] if text.count("\n") >= 3 else "") or (
        text.lstrip().startswith("PiezoResult")
    ):
        return _read_aixacct(path, text, group, channels)
    # '#' and '%' lines are comments (piezohyst's own first line, MATLAB and DAQ notes)
    lines = [
        (n + 1, ln)
        for n, ln in enumerate(text.splitlines())
        if ln.strip() and not ln.lstrip().startswith(("#", "%"))
    ]
    return _table_from_lines(path, lines)


def _read_head(path: Path, size: int = 1 << 16) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(size)


@dataclass(frozen=True)
class _CsvPlan:
    """How pyarrow reads a delimited file, decided from its head as the careful reader would."""

    skip: int  # lines before the data (comments, header)
    names: list[str]
    units: Mapping[str, str]
    delimiter: str
    decimal_comma: bool
    encoding: str


class _Fallback(Exception):
    """pyarrow cannot read this file cleanly: the careful reader must (and names the row)."""


def _csv_plan(path: Path, head: bytes) -> _CsvPlan | None:
    """Delimiter, leading comment lines, header, units and decimal commas from the head of a file.

    None where the careful reader must read: whitespace columns, aixACCT
    tables, UTF-16, a head that is not a clean numeric table.
    """
    if head[:2] in (b"\xff\xfe", b"\xfe\xff") or b"PiezoResult" in head[:64]:
        return None
    try:
        text = head.decode("utf-8")
        encoding = "utf8"
    except UnicodeDecodeError:
        text, encoding = head.decode("latin-1"), "latin1"
    lines = text.splitlines()
    if len(head) == 1 << 16:
        lines = lines[:-1]  # the last line of the head may be cut
    skip = 0
    while skip < len(lines) and (
        not lines[skip].strip() or lines[skip].lstrip().startswith(("#", "%"))
    ):
        skip += 1
    body = [(n + 1, ln) for n, ln in enumerate(lines[skip:], start=skip) if ln.strip()]
    if len(body) < 2 or any(_AIXACCT_TABLE.match(ln) for _, ln in body[:50]):
        return None
    delim = _sniff_delimiter("\n".join(ln for _, ln in body[:50]))
    if delim is None:
        return None
    try:
        sample = _table_from_lines(path, body[:50])
    except DataFileError:
        return None
    first = next(csv.reader([body[0][1]], delimiter=delim))
    has_header = any(c.strip() and not _is_number(c.strip()) for c in first)
    decimal_comma = delim != "," and _decimal_commas(
        [(n, next(csv.reader([ln], delimiter=delim))) for n, ln in body[:50]]
    )
    return _CsvPlan(
        skip + int(has_header), sample.columns, sample.units, delim, decimal_comma, encoding
    )


def _csv_batches(
    path: Path, plan: _CsvPlan, columns: Sequence[str]
) -> Iterator[dict[str, FloatArray]]:
    """The named columns in batches of rows, parsed by pyarrow (raises :class:`_Fallback`)."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    read = pacsv.ReadOptions(column_names=plan.names, encoding=plan.encoding)
    parse = pacsv.ParseOptions(delimiter=plan.delimiter)
    convert = pacsv.ConvertOptions(
        column_types=dict.fromkeys(plan.names, pa.float64()),
        include_columns=list(columns),
        decimal_point="," if plan.decimal_comma else ".",
        strings_can_be_null=False,
    )
    # pieces cut at line ends, each parsed on its own: pyarrow's own streaming
    # reader buffers ahead and its memory grew with the file (measured)
    with open(path, "rb") as fh:
        for _ in range(plan.skip):
            fh.readline()
        rest = b""
        while True:
            piece = fh.read(CSV_BLOCK_BYTES)
            text = rest + piece
            if piece:
                cut = text.rfind(b"\n") + 1
                if cut == 0:
                    rest = text
                    continue
                text, rest = text[:cut], text[cut:]
            if text.strip():
                try:
                    batch = pacsv.read_csv(
                        _io.BytesIO(text),
                        read_options=read,
                        parse_options=parse,
                        convert_options=convert,
                    )
                except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
                    raise _Fallback from None
                if any(col.null_count for col in batch.columns):
                    raise _Fallback  # empty cells: the careful reader names their rows
                yield {
                    name: np.ascontiguousarray(col.to_numpy(zero_copy_only=False), np.float64)
                    for name, col in zip(columns, batch.columns, strict=True)
                }
            if not piece:
                return


def _read_csv_arrow(
    path: Path, head: bytes, progress: Callable[[int], None] | None
) -> Table | None:
    """Delimited numeric columns read by pyarrow in batches; None where the careful path must read.

    ``progress`` is called with the rows read so far.
    """
    plan = _csv_plan(path, head)
    if plan is None:
        return None
    parts: dict[str, list[FloatArray]] = {name: [] for name in plan.names}
    rows = 0
    try:
        for batch in _csv_batches(path, plan, plan.names):
            for name, values in batch.items():
                parts[name].append(values)
            rows += len(batch[plan.names[0]])
            if progress is not None:
                progress(rows)
    except _Fallback:
        return None
    if rows == 0:
        return None
    columns = {name: np.concatenate(v) for name, v in parts.items()}
    return Table(path, plan.names, {k: _constant(v) for k, v in columns.items()}, units=plan.units)


_DECIMAL_COMMA = re.compile(r"^[+-]?\d*,\d+(?:[eE][+-]?\d+)?$")


def _decimal_commas(rows: list[tuple[int, list[str]]]) -> bool:
    """True when numbers are written with a decimal comma (1,5): European DAQ exports."""
    cells = [c for _, row in rows[1:50] for c in row if c]
    commas = sum(bool(_DECIMAL_COMMA.match(c)) for c in cells)
    points = sum("." in c and _is_number(c) for c in cells)
    return commas > 0 and points == 0


def _table_from_lines(path: Path, lines: list[tuple[int, str]]) -> Table:
    """A table from numbered text lines: delimiter, header and decimal commas detected."""
    if not lines:
        msg = f"{path}: the file is empty"
        raise DataFileError(msg)
    delim = _sniff_delimiter("\n".join(ln for _, ln in lines[:50]))
    if delim is None:
        rows = [(n, ln.split()) for n, ln in lines]
    else:
        parsed = csv.reader((ln for _, ln in lines), delimiter=delim)
        rows = [
            (n, [c.strip() for c in cells]) for (n, _), cells in zip(lines, parsed, strict=True)
        ]
    if delim != "," and _decimal_commas(rows):
        rows = [(n, [c.replace(",", ".") for c in cells]) for n, cells in rows]
    first = rows[0][1]
    has_header = any(c and not _is_number(c) for c in first)
    units: dict[str, str] = {}
    if has_header:
        split = [split_unit(c) if c else (f"col{i}", None) for i, c in enumerate(first)]
        bare = [name for name, _ in split]
        # 'time [ms]' is the column 'time' in ms, unless that would make two columns one name
        names = [
            name if bare.count(name) == 1 else (first[i] or f"col{i}")
            for i, name in enumerate(bare)
        ]
        units = {n: u for n, (_, u) in zip(names, split, strict=True) if u is not None}
        body = rows[1:]
    else:
        names = [f"col{i}" for i in range(len(first))]
        body = rows
    if len(set(names)) != len(names):
        names = [f"{c}_{i}" if names.count(c) > 1 else c for i, c in enumerate(names)]
    if not body:
        msg = f"{path}: the file has a header but no data rows"
        raise DataFileError(msg)
    width = len(names)
    for line_no, cells in body:
        if len(cells) != width:
            msg = (
                f"{path}: row {line_no} has {len(cells)} fields, expected {width} "
                f"({', '.join(names)})"
            )
            raise DataFileError(msg)
    line_numbers = [n for n, _ in body]

    def getter(j: int) -> Callable[[], FloatArray]:
        def convert() -> FloatArray:
            cells = [cells[j] for _, cells in body]
            try:
                return np.array(cells, dtype=np.float64)
            except ValueError:
                for k, cell in enumerate(cells):
                    if not _is_number(cell):
                        shown = repr(cell) if cell else "an empty value"
                        msg = (
                            f"{path}: {shown} at row {line_numbers[k]}, column {names[j]!r} "
                            "is not a number"
                        )
                        raise DataFileError(msg) from None
                raise  # pragma: no cover

        return convert

    return Table(path, names, {name: getter(j) for j, name in enumerate(names)}, units=units)


# ------------------------------------------------------------------ binary formats
def _as_column(value: object) -> FloatArray | None:
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf" or arr.size < 1:
        return None
    arr = np.squeeze(arr)
    if arr.ndim != 1:
        return None
    return np.ascontiguousarray(arr, dtype=np.float64)


def _table_from_arrays(path: Path, arrays: Mapping[str, object], kind: str) -> Table:
    columns: dict[str, FloatArray] = {}
    for name, value in arrays.items():
        col = _as_column(value)
        if col is not None:
            columns[name] = col
    if not columns:
        msg = f"{path}: the {kind} file holds no 1-D numeric arrays"
        raise DataFileError(msg)
    return Table(path, list(columns), {k: _constant(v) for k, v in columns.items()})


def _constant(values: FloatArray) -> Callable[[], FloatArray]:
    return lambda: values


def _read_npz(path: Path) -> Table:
    # open the file ourselves: np.load(path) leaks its handle when the zip is damaged
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    return _table_from_arrays(path, arrays, "NPZ")


def _read_parquet(path: Path, progress: Callable[[int], None] | None = None) -> Table:
    """Numeric columns of a Parquet file, read batch by batch (``progress``: rows so far)."""
    import pyarrow.parquet as pq

    source = pq.ParquetFile(path)
    names = source.schema_arrow.names
    parts: dict[str, list[np.ndarray]] = {name: [] for name in names}
    rows = 0
    for batch in source.iter_batches(batch_size=1 << 18):
        for name, column in zip(names, batch.columns, strict=True):
            parts[name].append(column.to_numpy(zero_copy_only=False))
        rows += batch.num_rows
        if progress is not None:
            progress(rows)
    arrays: dict[str, object] = {}
    units: dict[str, str] = {}
    for name in names:
        bare, unit = split_unit(name)
        arrays[bare] = np.concatenate(parts[name]) if parts[name] else np.empty(0)
        if unit is not None:
            units[bare] = unit
    return dataclasses.replace(_table_from_arrays(path, arrays, "Parquet"), units=units)


def _read_mat(path: Path) -> Table:
    from ._isolate import parse_isolated

    return _table_from_arrays(path, parse_isolated("mat_arrays", path, "MAT"), "MAT")


def _read_hdf5(path: Path) -> Table:
    from ._isolate import parse_isolated

    return _table_from_arrays(path, parse_isolated("hdf5_arrays", path, "HDF5"), "HDF5")


class _Collect(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


_AIXACCT_TABLE = re.compile(r"^\s*Table\s+\d+\s*$")


def _read_aixacct(path: Path, text: str, group: str | None, channels: Sequence[str]) -> Table:
    """aixACCT TF Analyzer ``.dat``: ``Table N`` blocks of ``Key: value`` lines, then a
    tab-separated table whose header cells carry units (``Time [s]``, ``P1 [uC/cm2]``).

    The leading results table (header ``Table No ...``) is the group ``Summary``.
    """
    all_lines = text.splitlines()
    starts = [i for i, ln in enumerate(all_lines) if _AIXACCT_TABLE.match(ln)]
    blocks: dict[str, list[tuple[int, str]]] = {}
    for k, start in enumerate(starts):
        stop = starts[k + 1] if k + 1 < len(starts) else len(all_lines)
        rows = [
            (i + 1, ln)
            for i, ln in enumerate(all_lines[start + 1 : stop], start=start + 1)
            if "\t" in ln and ln.strip()
        ]
        if not rows:
            continue
        name = all_lines[start].strip()
        if rows[0][1].lstrip().startswith("Table No"):
            name = "Summary"
        while name in blocks:
            name += "'"
        blocks[name] = [(n, ln.rstrip("\t ")) for n, ln in rows]
    if not blocks:
        msg = f"{path}: an aixACCT file without data tables"
        raise DataFileError(msg)
    headers = {name: rows[0][1].split("\t") for name, rows in blocks.items()}
    chosen = _choose_group(path, headers, group, channels, "aixACCT table")
    table = _table_from_lines(path, blocks[chosen])
    return dataclasses.replace(table, group=chosen, groups=tuple(blocks))


def _choose_group(
    path: Path,
    groups: Mapping[str, Sequence[str]],
    group: str | None,
    channels: Sequence[str],
    kind: str,
) -> str:
    """The group to read: the one named, else the first holding every named channel."""
    names = list(groups)
    listing = ", ".join(map(repr, names))
    if group is not None:
        if group in groups:
            return group
        numbered = f"Table {group.strip()}"
        if group.strip().isdigit() and numbered in groups:
            return numbered
        msg = f"{path}: no {kind} {group!r}; available: {listing}"
        raise DataFileError(msg)
    wanted = [c for c in channels if not c.strip().isdigit()]
    for need in (wanted, wanted[:1]):  # every named channel, else at least the first
        for name, columns in groups.items():
            bare = {split_unit(c)[0] for c in columns} | set(columns)
            if columns and need and all(c in bare or split_unit(c)[0] in bare for c in need):
                return name
    return next((n for n, cols in groups.items() if cols), names[0])


def _read_tdms(path: Path, group: str | None, channels: Sequence[str] = ()) -> Table:
    from nptdms import TdmsFile

    # npTDMS reads what it can of a damaged file and logs a warning: for us that is
    # a damaged file, said once, not partial data behind a few lines of log
    logger = logging.getLogger("nptdms")
    collect = _Collect()
    propagate = logger.propagate
    logger.addHandler(collect)
    logger.propagate = False
    try:
        tdms = TdmsFile.read(path)
    finally:
        logger.removeHandler(collect)
        logger.propagate = propagate
    if collect.messages:
        msg = f"{path}: the TDMS file is truncated or damaged ({collect.messages[0]})"
        raise DataFileError(msg)
    groups = tdms.groups()
    if not groups:
        msg = f"{path}: the TDMS file has no groups"
        raise DataFileError(msg)
    names = [g.name for g in groups]
    chosen = tdms[
        _choose_group(
            path,
            {g.name: [c.name for c in g.channels()] for g in groups},
            group,
            channels,
            "TDMS group",
        )
    ]
    arrays: dict[str, object] = {}
    step: float | None = None
    for channel in chosen.channels():
        arrays[channel.name] = channel[:]
        inc = channel.properties.get("wf_increment")
        if step is None and inc is not None and float(inc) > 0:
            step = float(inc)
    table = _table_from_arrays(path, arrays, "TDMS")
    return dataclasses.replace(table, time_step=step, group=chosen.name, groups=tuple(names))


def read_table(
    path: str | os.PathLike[str],
    *,
    group: str | None = None,
    channels: Sequence[str] = (),
    progress: Callable[[int], None] | None = None,
) -> Table:
    """Read a data file into a :class:`Table` (format chosen by the file's suffix).

    Parameters
    ----------
    path : path
        ``.csv``, ``.tsv``, ``.txt``, ``.dat`` (text), ``.npz``, ``.mat``,
        ``.tdms``, ``.h5``/``.hdf5``, ``.parquet``; aixACCT ``.dat`` exports.
    group : str, optional
        In files with several groups or tables (TDMS, aixACCT ``.dat``): the
        one to read, by name (or by number for aixACCT's ``Table N``).
    channels : sequence of str, optional
        Columns the caller needs: without ``group``, the first group holding
        all of them is read (else the first with data).
    progress : callable, optional
        Called with the number of rows read so far, as a large CSV streams in.

    Returns
    -------
    Table

    Raises
    ------
    DataFileError
        Missing, empty or unreadable file, in one line.
    """
    p = _existing(path)
    suffix = p.suffix.lower()
    readers: dict[str, Callable[[], Table]] = {
        ".npz": lambda: _read_npz(p),
        ".mat": lambda: _read_mat(p),
        ".tdms": lambda: _read_tdms(p, group, channels),
        ".parquet": lambda: _read_parquet(p, progress),
        ".h5": lambda: _read_hdf5(p),
        ".hdf5": lambda: _read_hdf5(p),
    }
    return _reading(p, readers.get(suffix, lambda: _read_text(p, group, channels, progress)))


def _existing(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        msg = f"{p}: no such file"
        raise DataFileError(msg)
    if p.is_dir():
        msg = f"{p}: is a folder, not a data file"
        raise DataFileError(msg)
    if p.stat().st_size == 0:
        msg = f"{p}: the file is empty"
        raise DataFileError(msg)
    return p


def _reading(p: Path, reader: Callable[[], Table]) -> Table:
    """Run a reader; anything but a DataFileError becomes one naming the file and format."""
    kind = p.suffix.lstrip(".").upper() or "text"
    try:
        return reader()
    except DataFileError:
        raise
    except Exception as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        msg = f"{p}: cannot read as {kind} ({detail})"
        raise DataFileError(msg) from None


def open_table(
    path: str | os.PathLike[str], *, group: str | None = None, channels: Sequence[str] = ()
) -> Table:
    """A :class:`Table` whose columns are read from the file only when asked for.

    CSV and Parquet files are not loaded: :meth:`Table.batches` streams them
    in batches of rows, so memory does not grow with the record. Other
    formats are read as by :func:`read_table`.

    Parameters
    ----------
    path : path
        The data file (formats as :func:`read_table`).
    group, channels
        As for :func:`read_table`.

    Returns
    -------
    Table
    """
    p = _existing(path)
    suffix = p.suffix.lower()
    if suffix == ".parquet":
        return _reading(p, lambda: _lazy_parquet(p))
    if suffix in CSV_SUFFIXES:
        head = _read_head(p)
        plan = None if b"\x00" in head else _csv_plan(p, head)
        if plan is not None:
            return _lazy_csv(p, plan, group, channels)
    return read_table(p, group=group, channels=channels)


def _lazy_csv(path: Path, plan: _CsvPlan, group: str | None, channels: Sequence[str]) -> Table:
    def stream(names: Sequence[str]) -> Iterator[dict[str, FloatArray]]:
        done = 0
        try:
            for batch in _csv_batches(path, plan, names):
                done += len(batch[names[0]])
                yield batch
        except _Fallback:
            # the careful reader raises naming the row, or reads what pyarrow could not
            careful = _read_text_careful(path, group, channels)
            arrays = [careful.get(n, finite=False) for n in names]
            for lo in range(done, arrays[0].size, BATCH_ROWS):
                yield {n: a[lo : lo + BATCH_ROWS] for n, a in zip(names, arrays, strict=True)}

    def getter(name: str) -> Callable[[], FloatArray]:
        return lambda: np.concatenate([b[name] for b in stream([name])])

    return Table(
        path, plan.names, {n: getter(n) for n in plan.names}, units=plan.units, _stream=stream
    )


def _lazy_parquet(path: Path) -> Table:
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = pq.ParquetFile(path).schema_arrow
    raw: dict[str, str] = {}
    units: dict[str, str] = {}
    for fld in schema:
        if not (pa.types.is_integer(fld.type) or pa.types.is_floating(fld.type)):
            continue
        bare, unit = split_unit(fld.name)
        raw[bare] = fld.name
        if unit is not None:
            units[bare] = unit
    if not raw:
        msg = f"{path}: the Parquet file holds no numeric columns"
        raise DataFileError(msg)

    def stream(names: Sequence[str]) -> Iterator[dict[str, FloatArray]]:
        source = pq.ParquetFile(path)
        for batch in source.iter_batches(batch_size=BATCH_ROWS, columns=[raw[n] for n in names]):
            yield {
                n: np.asarray(col.to_numpy(zero_copy_only=False), dtype=np.float64)
                for n, col in zip(names, batch.columns, strict=True)
            }

    def getter(name: str) -> Callable[[], FloatArray]:
        return lambda: np.concatenate([b[name] for b in stream([name])] or [np.empty(0)])

    return Table(path, list(raw), {n: getter(n) for n in raw}, units=units, _stream=stream)


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

    def blocks(self, progress: Callable[[int], None] | None = None) -> Iterator[Block]:
        """The record from its first sample, block by block, checked and converted.

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
            x, _ = to_standard(x, x_unit, "input", f"{where} {x_name!r}")
            y = None
            if y_name is not None:
                y, _ = to_standard(batch[y_name], y_unit, "output", f"{where} {y_name!r}")
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
            warnings.warn(
                f"{self.path}: the median sample interval is {dt:.3g} s; if the time column is "
                "not in seconds, give its unit (a header such as 'time [ms]', or the time unit)",
                UserWarning,
                stacklevel=3,
            )


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
    bad = ~np.isfinite(values)
    if bad.any():
        i = int(np.argmax(bad))
        msg = (
            f"{where}: {values[i]} at row {start + i + 1}, column {column!r} "
            "(values must be finite)"
        )
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
        msg = (
            f"{where}: time is not increasing at row {start + i + 1}"
            f"{'' if column is None else f', column {column!r}'} "
            f"({float(t[i - 1])!r} then {float(t[i])!r})"
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
) -> RecordingStream:
    """A recording to read block by block (arguments as :func:`read_recording`).

    The columns, time source and units are settled here (a misnamed column
    fails at once); the values are read by :meth:`RecordingStream.blocks`.

    Parameters
    ----------
    path : str or os.PathLike
    input_column, output_column, time_column, rate, group, output_required
    t_start, t_stop, input_unit, output_unit, time_unit
        See :func:`read_recording`.

    Returns
    -------
    RecordingStream
    """
    # the default time name may be absent (TDMS states its sample interval instead)
    wanted = [c for c in (input_column, output_column) if c is not None]
    if time_column is not None and time_column != "time":
        wanted.append(time_column)
    table = open_table(path, group=group, channels=wanted)
    x_name = table.resolve(input_column)
    y_name: str | None = None
    output = output_column
    # the default output may be absent (predicting needs no output); a named one may not
    if output is not None and (output_required or output in table or output != "charge"):
        y_name = table.resolve(output)
    time = time_column
    t_name: str | None = None
    step: float | None = None
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
    elif time is not None and (time in table or (time != "time" and time.isdigit())):
        t_name = table.resolve(time)
    elif time is not None and time != "time":
        table.resolve(time)  # raises: names the available columns
        raise AssertionError  # pragma: no cover
    elif table.time_step is not None:
        step = table.time_step
    else:
        msg = (
            f"{table.path}: no time column 'time' and no sample rate; name the time column "
            f"or give the rate in Hz (columns: {', '.join(map(repr, table.columns))})"
        )
        raise DataFileError(msg)
    source = (
        _unit(table, t_name, time_unit),
        _unit(table, x_name, input_unit),
        None if y_name is None else _unit(table, y_name, output_unit),
    )
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
    )


def read_recording(
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
    progress: Callable[[int], None] | None = None,
) -> Recording:
    """Input, output and time columns of a data file, in seconds and (where known) V, C or m.

    Time comes from ``time_column`` when the file has it, else from
    ``rate`` (Hz), else from the file's own sample interval (TDMS); the time
    must be strictly increasing. ``output_column=None`` reads no output.
    :func:`open_recording` reads the same block by block.

    Parameters
    ----------
    path : str or os.PathLike
        The data file (see :func:`read_table` for the formats).
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
    progress : callable, optional
        Called with the rows read so far (see :func:`read_table`).

    Returns
    -------
    Recording

    Raises
    ------
    DataFileError
        A missing or misnamed column, a time column together with a sample
        rate, a bad or non-increasing time, or units that contradict the file.
    """
    stream = open_recording(
        path,
        input_column=input_column,
        output_column=output_column,
        time_column=time_column,
        rate=rate,
        group=group,
        output_required=output_required,
        t_start=t_start,
        t_stop=t_stop,
        input_unit=input_unit,
        output_unit=output_unit,
        time_unit=time_unit,
    )
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

    Raises
    ------
    DataFileError
        A window that holds no sample (or any error of the stream).
    """
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
            The data file.
        output_required : bool, default True
            Raise if the output column is missing (else read no output).
        progress : callable, optional
            Called with the rows read so far.

        Returns
        -------
        Recording
        """
        return collect(self.open(path, output_required=output_required), progress)


# ------------------------------------------------------------------ writers
def _umask() -> int:
    """The process umask (read without changing it where the OS tells it)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)  # elsewhere: read it by setting it, and put it back at once
    os.umask(mask)
    return mask


def atomic_write(path: str | os.PathLike[str], write: Callable[[Path], None]) -> Path:
    """Write a file through ``write(tmp)`` on a temporary beside it, then rename it into place.

    A failure leaves no partial file. The file gets the permissions any new
    file would get (0666 less the umask), not the temporary file's 0600, so
    colleagues on a shared drive can read it.

    Parameters
    ----------
    path : str or os.PathLike
        The destination.
    write : callable
        Writes the content to the temporary path it is given.

    Returns
    -------
    Path
        ``path``.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=p.suffix, dir=p.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) atomically; see :func:`atomic_write`.

    Parameters
    ----------
    path : str or os.PathLike
    text : str

    Returns
    -------
    Path
    """

    def write(tmp: Path) -> None:
        tmp.write_text(text, encoding="utf-8")

    return atomic_write(path, write)


def write_rows(
    path: str | os.PathLike[str],
    rows: Sequence[Mapping[str, object]],
    columns: Sequence[str],
    text_columns: Iterable[str],
) -> Path:
    """Write records (one dict per row) as CSV (marked as piezohyst's) or Parquet.

    Numeric columns are written at full precision (a missing value as NaN);
    text columns as given (a missing value as "").

    Parameters
    ----------
    path : str or os.PathLike
        ``.parquet``, or a text file (CSV).
    rows : sequence of mapping
        Column name to value, per row.
    columns : sequence of str
        The columns, in order.
    text_columns : iterable of str
        Those of ``columns`` that hold text; the others are numbers.

    Returns
    -------
    Path
    """
    text = set(text_columns)

    def cell(row: Mapping[str, object], c: str) -> object:
        value = row.get(c, "" if c in text else math.nan)
        return str(value) if c in text else float(value)  # type: ignore[arg-type]

    p = Path(path)
    if p.suffix.lower() == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        data = {c: [cell(r, c) for r in rows] for c in columns}
        table = pa.table(data).replace_schema_metadata({"written_by": f"piezohyst {__version__}"})

        def write(tmp: Path) -> None:
            pq.write_table(table, tmp)

        return atomic_write(p, write)
    buf = _io.StringIO()
    buf.write(f"{MARKER} {__version__}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([repr(v) if isinstance(v, float) else v for v in (cell(r, c) for c in columns)])
    return atomic_write_text(p, buf.getvalue())


def write_table(
    path: str | os.PathLike[str],
    columns: Mapping[str, ArrayLike],
    units: Mapping[str, str | None] | None = None,
) -> Path:
    """Write equal-length columns as CSV (header row, full precision), Parquet or ``.npz``.

    The file appears only when complete (temporary file, then rename).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npz``, ``.parquet``, or a text file (CSV).
    columns : mapping
        Column name to values, all of one length.
    units : mapping, optional
        Column name to unit: a CSV header then reads ``name [unit]``, which
        :func:`read_table` reads back.

    Returns
    -------
    Path
    """
    write_blocks(path, [columns], units)
    return Path(path)


def write_blocks(
    path: str | os.PathLike[str],
    blocks: Iterable[Mapping[str, ArrayLike]],
    units: Mapping[str, str | None] | None = None,
) -> int:
    """Write columns that arrive block by block; CSV and Parquet never hold more than one block.

    The column names are those of the first block. The file appears only when
    complete: an exception raised while the blocks are made (a bad row found
    halfway) leaves no file. ``.npz`` cannot be appended to, so its blocks are
    gathered in memory first.

    Parameters
    ----------
    path : str or os.PathLike
        ``.npz``, ``.parquet``, or a text file (CSV).
    blocks : iterable of mapping
        Column name to values; within a block all of one length.
    units : mapping, optional
        Column name to unit (see :func:`write_table`).

    Returns
    -------
    int
        Rows written.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    named = units or {}
    rows = [0]

    def arrays_of(block: Mapping[str, ArrayLike], names: list[str]) -> list[FloatArray]:
        if list(block) != names:
            msg = f"a block to write has columns {list(block)}, the first had {names}"
            raise DataFileError(msg)
        arrays = [np.asarray(v, dtype=np.float64).reshape(-1) for v in block.values()]
        sizes = {a.size for a in arrays}
        if len(sizes) > 1:
            msg = f"columns to write have different lengths: {sorted(sizes)}"
            raise DataFileError(msg)
        rows[0] += arrays[0].size if arrays else 0
        return arrays

    it = iter(blocks)
    first = next(it, None)
    names = [] if first is None else list(first)
    labels = [f"{k} [{named[k]}]" if named.get(k) else k for k in names]
    chain = itertools.chain([] if first is None else [first], it)

    def write_npz(tmp: Path) -> None:
        parts = [arrays_of(b, names) for b in chain]
        arrays = {
            k: np.concatenate([part[j] for part in parts]) if parts else np.empty(0)
            for j, k in enumerate(names)
        }
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays, __piezohyst__=np.array(__version__))  # type: ignore[arg-type]

    def write_parquet(tmp: Path) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        schema = pa.schema([(label, pa.float64()) for label in labels])
        schema = schema.with_metadata({"written_by": f"piezohyst {__version__}"})
        with pq.ParquetWriter(tmp, schema) as writer:
            for block in chain:
                columns = arrays_of(block, names)
                writer.write_table(pa.Table.from_arrays(columns, schema=schema))

    def write_csv(tmp: Path) -> None:
        import pyarrow as pa
        import pyarrow.csv as pacsv

        with open(tmp, "wb") as fh:
            fh.write(f"{MARKER} {__version__}\n{io_csv_line(labels)}".encode())
            schema = pa.schema([(f"c{i}", pa.float64()) for i in range(len(names))])
            options = pacsv.WriteOptions(include_header=False, batch_size=1 << 16)
            with pacsv.CSVWriter(fh, schema, write_options=options) as writer:
                for block in chain:
                    columns = arrays_of(block, names)
                    # shortest round-trip decimal text, written in batches by pyarrow
                    writer.write_table(pa.Table.from_arrays(columns, schema=schema))

    writers = {".npz": write_npz, ".parquet": write_parquet}
    atomic_write(p, writers.get(suffix, write_csv))
    return rows[0]


def iter_columns(table: Table) -> Iterator[tuple[str, FloatArray]]:
    """Every column that converts to finite numbers (others are skipped)."""
    for name in table.columns:
        try:
            yield name, table.get(name)
        except DataFileError:
            continue


def io_csv_line(cells: Sequence[str]) -> str:
    """One CSV line (quoted where needed), newline included."""
    buf = _io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(cells)
    return buf.getvalue()


def is_piezohyst_output(path: str | os.PathLike[str]) -> bool:
    """True for a file (or report folder) piezohyst wrote, which it may overwrite.

    Recognised: CSV whose first line is :data:`MARKER`, Markdown whose first
    line is :data:`MD_MARKER`, ``.npz`` with a
    ``__piezohyst__`` entry, Parquet with ``written_by`` metadata, model JSON
    (``"format": "piezohyst-model"``), C sources generated by piezohyst, and
    report folders holding a
    ``metrics.json`` that names a piezohyst version.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    bool
        False for anything else, unreadable files included.
    """
    p = Path(path)
    try:
        if p.is_dir():
            metrics = p / "metrics.json"
            return metrics.is_file() and '"piezohyst_version"' in metrics.read_text("utf-8")
        suffix = p.suffix.lower()
        if suffix == ".npz":
            with np.load(p, allow_pickle=False) as data:
                return "__piezohyst__" in data.files
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            meta = pq.read_schema(p).metadata or {}
            return bool(meta.get(b"written_by", b"").startswith(b"piezohyst"))
        with open(p, "rb") as fh:
            head = fh.read(4096).decode("utf-8", errors="replace")
        if suffix == ".json":
            return '"format": "piezohyst-model"' in head or '"format": "piezohyst-bank"' in head
        if suffix in (".c", ".h"):
            return "generated by piezohyst" in head.splitlines()[0] if head else False
        if suffix == ".md":
            return head.startswith(MD_MARKER)
        return head.startswith(MARKER)
    except (OSError, ValueError):
        return False
