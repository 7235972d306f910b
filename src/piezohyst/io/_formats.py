"""Reading the file formats: CSV/TSV/text (delimiter sniffing, header detection,
decimal commas, streamed through pyarrow), NumPy ``.npz``, Parquet, MATLAB ``.mat``,
HDF5, NI TDMS and aixACCT tables, each into a :class:`Table` of named columns.
The public entry points are in :mod:`piezohyst.io`.
"""

from __future__ import annotations

import csv
import dataclasses
import io as _io
import logging
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validation import FloatArray
from ..errors import DataFileError
from ..units import split_unit, suffix_units
from ._cells import ISO_DATE, is_timestamp, timestamps, units_row

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

    def find(self, key: str) -> str | None:
        """The column ``key`` names (:meth:`resolve`), or None where there is none.

        Parameters
        ----------
        key : str

        Returns
        -------
        str or None
        """
        try:
            return self.resolve(key)
        except DataFileError:
            return None

    def resolve(self, key: str) -> str:
        """A column name from a name or a 0-based index given as digits; where only one
        column fits, also a nested MATLAB field as MATLAB writes it (``run.Vout`` for
        ``run/Vout``), a grouped file's column by its own name, or a name in another case.

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
        if unit is None:  # the header as the file wrote it, where its unit suffix was read
            bare, unit = suffix_units([key]).get(key, (key, None))
        if unit is not None and bare in self._getters and self.units.get(bare) == unit:
            return bare
        field = _field(key, self._getters)  # a nested field by MATLAB's name, or its own
        if field is not None:
            return field
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
    then reported as a ragged row). On a tie the comma comes last: ``1,5;2,25``
    is two numbers with decimal commas.
    """
    lines = [ln for ln in sample.splitlines() if ln.strip()][:50]
    best, best_score = None, 0.0
    for delim in ("\t", ";", "|", ","):
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
    skip_rows: int = 0,
) -> Table:
    head = _read_head(path)
    if b"\x00" in head and head[:2] not in (b"\xff\xfe", b"\xfe\xff"):
        msg = f"{path}: not a text file (binary content); expected CSV or text columns"
        raise DataFileError(msg)
    fast = _read_csv_arrow(path, head, progress, skip_rows)
    if fast is not None:
        return fast
    return _read_text_careful(path, group, channels, skip_rows)


def _read_text_careful(
    path: Path, group: str | None, channels: Sequence[str], skip_rows: int = 0
) -> Table:
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
        if n >= skip_rows and ln.strip() and not ln.lstrip().startswith(("#", "%"))
    ]
    start = _table_start(lines)
    table = _table_from_lines(path, lines[start:])
    return dataclasses.replace(table, time_step=_stated_step(ln for _, ln in lines[:start]))


# a preamble line: 'Key: value' or 'Key = value' (device, operator, date, sample rate)
_KEY_VALUE = re.compile(r"^\s*[^\W\d][^:=]{0,60}[:=]")
_STATED_RATE = re.compile(
    r"(?:sample|sampling|scan)\s*(?:rate|frequency)\s*(?:\[\s*(k?Hz)\s*\])?\s*[:=;,\t]\s*"
    r"([0-9]+(?:[.,][0-9]*)?(?:[eE][+-]?[0-9]+)?)\s*(k?Hz|S/s)?",
    re.IGNORECASE,
)


def _stated_step(preamble: Iterable[str]) -> float | None:
    """The sample interval (s) a preamble states ('Sample rate: 1000 Hz', '... [kHz]: 1,5')."""
    for line in preamble:
        found = _STATED_RATE.search(line)
        if found:
            rate = float(found.group(2).replace(",", "."))
            unit = (found.group(1) or found.group(3) or "Hz").lower()
            rate *= 1e3 if unit == "khz" else 1.0
            if rate > 0:
                return 1.0 / rate
    return None


def _cells(line: str, delim: str | None) -> list[str]:
    return line.split() if delim is None else next(csv.reader([line], delimiter=delim))


def _numeric_row(cells: list[str]) -> bool:
    filled = [c.strip() for c in cells if c.strip()]
    return bool(filled) and all(_is_number(c) or _DECIMAL_COMMA.match(c) for c in filled)


def _table_start(lines: list[tuple[int, str]], look: int = 200) -> int:
    """Index of a table's first line (its header, else its first row) after a preamble.

    DAQ exports open with ``Key: value`` lines (device, operator, date, sample rate)
    before the table. The delimiter and the field count are the ones the last lines
    agree on; the first row is the first all-numeric line with that count (within
    ``look`` lines); the line before it is the header, unless it is a ``Key: value``
    line. A numeric line above that row keeps every line (a ragged or broken row is
    then reported as such), as does a table with one column.
    """
    if len(lines) < 3:
        return 0
    tail = [ln for _, ln in lines[-50:]]
    delim = _sniff_delimiter("\n".join(tail))
    counts = [len(_cells(ln, delim)) for ln in tail]
    width = max(set(counts), key=counts.count)
    if width < 2:
        return 0
    top = [_cells(ln, delim) for _, ln in lines[:look]]
    first = next(
        (i for i, cells in enumerate(top) if len(cells) == width and _numeric_row(cells)), 0
    )
    if first == 0 or any(_numeric_row(cells) for cells in top[:first]):
        return 0
    above = top[first - 1]
    if first >= 2 and units_row(above) and len(top[first - 2]) == width:
        return first - 2  # a header, then its units (under it), then the data
    key_value = _KEY_VALUE.match(lines[first - 1][1]) is not None
    if key_value and (len(above) != width or above[0].rstrip().endswith((":", "="))):
        return first  # no header: the preamble runs up to the data
    return first - 1


def estimated_rows(path: Path) -> int | None:
    """About how many rows a file holds, without reading it: a Parquet file's own count,
    a text file's size over its head's mean line length; None for other formats.

    Parameters
    ----------
    path : Path

    Returns
    -------
    int or None
    """
    try:
        suffix = path.suffix.lower()
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            return int(pq.ParquetFile(path).metadata.num_rows)
        if suffix not in CSV_SUFFIXES:
            return None
        head = _read_head(path)
        lines = head.splitlines()[1:-1] if len(head) == 1 << 16 else head.splitlines()[1:]
        if not lines:
            return None
        return max(1, round(path.stat().st_size / (sum(map(len, lines)) / len(lines) + 1)))
    except (OSError, ValueError, ImportError):
        return None


def _read_head(path: Path, size: int = 1 << 16) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(size)


@dataclass(frozen=True)
class _CsvPlan:
    """How pyarrow reads a delimited file, decided from its head as the careful reader would."""

    skip: int  # lines before the data (comments, preamble, header)
    names: list[str]
    units: Mapping[str, str]
    delimiter: str
    decimal_comma: bool
    encoding: str
    time_step: float | None = None  # the preamble's stated sample interval


class _Fallback(Exception):
    """pyarrow cannot read this file cleanly: the careful reader must (and names the row)."""


def _csv_plan(path: Path, head: bytes, skip_rows: int = 0) -> _CsvPlan | None:
    """Delimiter, leading comment and preamble lines, header, units and decimal commas from
    the head of a file (after ``skip_rows`` lines).

    None where the careful reader must read: whitespace columns, aixACCT
    tables, UTF-16, a head that is not a clean numeric table.
    """
    if head[:2] in (b"\xff\xfe", b"\xfe\xff") or b"PiezoResult" in head[:64]:
        return None
    try:
        text = head.decode("utf-8-sig")  # Excel's 'CSV UTF-8' opens with a byte-order mark
        encoding = "utf8"
    except UnicodeDecodeError:
        text, encoding = head.decode("latin-1"), "latin1"
    lines = text.splitlines()
    if len(head) == 1 << 16:
        lines = lines[:-1]  # the last line of the head may be cut
    skip = skip_rows
    while skip < len(lines) and (
        not lines[skip].strip() or lines[skip].lstrip().startswith(("#", "%"))
    ):
        skip += 1
    body = [(n + 1, ln) for n, ln in enumerate(lines[skip:], start=skip) if ln.strip()]
    if len(body) < 2 or any(_AIXACCT_TABLE.match(ln) for _, ln in body[:50]):
        return None
    start = _table_start(body)
    preamble, body = body[:start], body[start:]
    delim = _sniff_delimiter("\n".join(ln for _, ln in body[:50]))
    if delim is None:
        return None
    try:
        sample = _table_from_lines(path, body[:50])
    except DataFileError:
        return None
    first = next(csv.reader([body[0][1]], delimiter=delim))
    has_header = any(c.strip() and not _is_number(c.strip()) for c in first)
    if has_header and len(body) > 2 and units_row(next(csv.reader([body[1][1]], delimiter=delim))):
        body = body[1:]  # the units row under the header: skipped too
    decimal_comma = delim != "," and _decimal_commas(
        [(n, next(csv.reader([ln], delimiter=delim))) for n, ln in body[:50]]
    )
    return _CsvPlan(
        body[0][0] - 1 + int(has_header),
        sample.columns,
        sample.units,
        delim,
        decimal_comma,
        encoding,
        _stated_step(ln for _, ln in preamble),
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
    path: Path, head: bytes, progress: Callable[[int], None] | None, skip_rows: int = 0
) -> Table | None:
    """Delimited numeric columns read by pyarrow in batches; None where the careful path must read.

    ``progress`` is called with the rows read so far.
    """
    plan = _csv_plan(path, head, skip_rows)
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
    getters = {k: _constant(v) for k, v in columns.items()}
    return Table(path, plan.names, getters, plan.time_step, plan.units)


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
    below = has_header and len(rows) > 2 and len(rows[1][1]) == len(first)
    if below and units_row(rows[1][1]) and not units_row(first):  # a units row: one header
        first = [f"{c} {u.strip()}" if u.strip() else c for c, u in zip(first, rows[1][1],
                                                                         strict=True)]  # fmt: skip
        rows = rows[1:]
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
    body = [(n, cells) for n, cells in body if any(cells)]  # ',,': a spreadsheet's empty row
    if not body:
        msg = f"{path}: the file has a header but no data rows"
        raise DataFileError(msg)
    width = len(names)
    for k, (line_no, cells) in enumerate(body):
        if len(cells) != width:
            msg = (
                f"{path}: row {k + 1} (line {line_no} of the file) has {len(cells)} fields, "
                f"expected {width} ({', '.join(names)})"
            )
            raise DataFileError(msg)
    line_numbers = [n for n, _ in body]

    def getter(j: int) -> Callable[[], FloatArray]:
        def convert() -> FloatArray:
            cells = [cells[j] for _, cells in body]
            try:
                return np.array(cells, dtype=np.float64)
            except ValueError:
                if _own_blanks(path, cells):  # piezohyst leaves a cell empty on purpose
                    return np.array([c or "nan" for c in cells], dtype=np.float64)
                stamps = timestamps(cells)
                if stamps is not None:  # a logger's clock: seconds from the first row
                    return stamps
                clock = bool(ISO_DATE.match(cells[0]))  # then name the first that is not
                for k, cell in enumerate(cells):
                    if not (is_timestamp(cell) if clock else _is_number(cell)):
                        shown = repr(cell) if cell else "an empty value"
                        what = "a timestamp, as the rows above are" if clock else "a number"
                        msg = (
                            f"{path}: {shown} at row {k + 1} (line {line_numbers[k]} of the "
                            f"file), column {names[j]!r} is not {what}"
                        )
                        raise DataFileError(msg) from None
                if clock:  # every cell a timestamp, some with an offset and some without
                    msg = (
                        f"{path}: column {names[j]!r} mixes timestamps with and without a UTC "
                        "offset: their differences are not defined"
                    )
                    raise DataFileError(msg) from None
                raise  # pragma: no cover

        return convert

    return Table(path, names, {name: getter(j) for j, name in enumerate(names)}, units=units)


def _own_blanks(path: Path, cells: list[str]) -> bool:
    """Whether a column's only non-numbers are empty cells of a CSV piezohyst wrote (the
    precondition rows of ``compensate``, where nothing is desired), to be read as NaN."""
    if not all(_is_number(c) or not c for c in cells):
        return False
    try:
        with open(path, "rb") as fh:
            return fh.read(len(MARKER)).decode("utf-8", "replace") == MARKER
    except OSError:
        return False


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


def with_suffix_units(table: Table) -> Table:
    """``table`` with its columns named ``name_unit`` (``time_s``, ``voltage_V``, see
    :func:`~piezohyst.units.suffix_units`) as ``name`` in ``unit``, as ``name [unit]``
    headers are (a unit the file states otherwise is kept)."""
    found = suffix_units(list(table.columns))
    if not found:
        return table
    new = {c: found[c][0] if c in found else c for c in table.columns}
    old = {n: c for c, n in new.items()}
    units = {new.get(c, c): u for c, u in table.units.items()}
    for name, unit in found.values():
        units.setdefault(name, unit)
    stream = table._stream
    if stream is not None:
        inner = stream

        def stream(names: Sequence[str]) -> Iterator[dict[str, FloatArray]]:
            for batch in inner([old.get(n, n) for n in names]):
                yield {new.get(k, k): v for k, v in batch.items()}

    getters = {new[c]: table._getters[c] for c in table.columns}
    return dataclasses.replace(table, columns=[new[c] for c in table.columns],
                               _getters=getters, units=units, _stream=stream)  # fmt: skip


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


def _read_mat(path: Path, group: str | None, channels: Sequence[str]) -> Table:
    from ._isolate import parse_isolated

    return _grouped(path, parse_isolated("mat_arrays", path, "MAT"), "MAT", group, channels)


def _read_hdf5(path: Path, group: str | None, channels: Sequence[str]) -> Table:
    from ._isolate import parse_isolated

    return _grouped(path, parse_isolated("hdf5_arrays", path, "HDF5"), "HDF5", group, channels)


#: Names under which files state their sample rate (Hz) or sample interval (s)
RATE_NAMES = ("fs", "rate", "sample_rate", "sampling_rate", "samplerate", "sampling_frequency")
STEP_NAMES = ("dt", "ts", "sample_interval", "sampling_interval", "wf_increment")


def _field(key: str, columns: Iterable[str]) -> str | None:
    """The column ``key`` names without being it, or None: a nested field as MATLAB writes
    it (``run.Vout`` for ``run/Vout``); the short name of the one column that has it
    (``voltage`` for ``run 1/voltage`` when no other group has one); else the one column
    whose name, or short name, is ``key`` in another case (``Voltage`` for ``voltage``, as a
    LabVIEW channel is often named)."""
    names = list(columns)
    path = key.replace(".", "/")
    if "." in key and path in names:
        return path
    for same in (str.__eq__, lambda a, b: a.casefold() == b.casefold()):
        hits = {c for c in names if same(c, key) or same(c.rpartition("/")[2], key)}
        if len(hits) == 1:
            return hits.pop()
        if hits:
            return None  # more than one: the name does not say which
    return None


def _grouped(
    path: Path, found: Mapping[str, object], kind: str, group: str | None, channels: Sequence[str]
) -> Table:
    """A Table of a container's 1-D arrays (HDF5 paths ``group/name``; a MAT file is one
    group), with the sample interval stated beside them (:func:`_stated_interval`).

    With ``group``, its own arrays by their short names. Without, every array by its
    path, and the interval is that of the group of the columns asked for (or of the
    only group).
    """
    columns = {k: v for k, v in found.items() if "@" not in k and _as_column(v) is not None}
    groups = sorted({c.rpartition("/")[0] for c in columns})
    home: str | None
    if group is not None:
        home = group.strip("/")
        if home not in groups:
            listing = ", ".join(repr(g or "/") for g in groups)
            msg = f"{path}: no {kind} group {group!r}; available: {listing}"
            raise DataFileError(msg)
        picked = {
            k.rpartition("/")[2]: v for k, v in columns.items() if k.rpartition("/")[0] == home
        }
    else:
        picked = dict(columns)
        named = [c if c in columns else _field(c, columns) for c in channels]
        asked = [c.rpartition("/")[0] for c in named if c is not None]
        home = asked[0] if asked else (groups[0] if len(groups) == 1 else None)
    table = _table_from_arrays(path, picked, kind)
    units = {
        k[: -len("_unit")]: v
        for k, v in found.items()
        if isinstance(v, str) and k.endswith("_unit") and k[: -len("_unit")] in table
    }
    for key, value in found.items():  # an HDF5 dataset's 'units' attribute
        if not (isinstance(value, str) and key.endswith("@unit")):
            continue
        owner = key[: -len("@unit")]
        short = owner.rpartition("/")[2] if owner.rpartition("/")[0] == home else ""
        for name in (owner, short):
            if name and name in table:
                units.setdefault(name, value)
                break
    return dataclasses.replace(
        table,
        units=units,
        time_step=None if home is None else _stated_interval(found, set(columns), home),
        group=group,
        groups=tuple(g or "/" for g in groups) if len(groups) > 1 else (),
    )


def _stated_interval(found: Mapping[str, object], datasets: set[str], home: str) -> float | None:
    """The sample interval (s) a group or one of its parents states, nearest first: a
    scalar dataset or attribute named as in :data:`RATE_NAMES` (Hz) or :data:`STEP_NAMES` (s).
    Attributes come as ``owner@name``; a dataset's attributes count for its group."""
    stated: dict[str, float] = {}  # 'group/leaf' -> interval
    for key, value in found.items():
        owner, at, leaf = key.partition("@")
        if at:
            place = owner.rpartition("/")[0] if owner in datasets else owner
        else:
            place, _, leaf = key.rpartition("/")
        arr = np.asarray(value)
        if arr.size != 1 or arr.dtype.kind not in "biuf":
            continue
        v = float(arr.reshape(-1)[0])
        name = leaf.lower()
        if v > 0 and name in RATE_NAMES:
            stated.setdefault(place, 1.0 / v)
        elif v > 0 and name in STEP_NAMES:
            stated.setdefault(place, v)
    parts = home.split("/") if home else []
    for depth in range(len(parts), -1, -1):
        place = "/".join(parts[:depth])
        if place in stated:
            return stated[place]
    return None


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
    """The group to read: the one named, else the first holding every named channel, else
    the first with a time column (a measurement, not aixACCT's ``Summary``), else the first."""
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
            bare = (
                {split_unit(c)[0] for c in columns}
                | set(columns)
                | {stem for stem, _ in suffix_units(list(columns)).values()}
            )
            if columns and need and all(c in bare or split_unit(c)[0] in bare for c in need):
                return name
    timed = (
        n
        for n, c in groups.items()
        if any(split_unit(k)[0].lower() == "time" or k in _timed_suffix(c) for k in c)
    )
    return next(timed, next((n for n, cols in groups.items() if cols), names[0]))


def _timed_suffix(columns: Iterable[str]) -> set[str]:
    """The columns named ``time_unit`` (``time_ms``) among ``columns``."""
    return {c for c, (name, _) in suffix_units(list(columns)).items() if name.lower() == "time"}


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
    units: dict[str, str] = {}
    step: float | None = None
    for channel in chosen.channels():
        values = np.asarray(channel[:])
        if str(channel.properties.get("unit_string", "")).strip():
            units[channel.name] = str(channel.properties["unit_string"]).strip()
        if values.dtype.kind == "M" and values.size:  # a channel of timestamps (LabVIEW's
            # clock): seconds from its first, as a text file's ISO timestamps are read
            values = (values - values[0]) / np.timedelta64(1, "us") * 1e-6
            units[channel.name] = "s"
        arrays[channel.name] = values
        inc = channel.properties.get("wf_increment")
        if step is None and inc is not None and float(inc) > 0:
            step = float(inc)
    table = _table_from_arrays(path, arrays, "TDMS")
    units = {k: u for k, u in units.items() if k in table}
    return dataclasses.replace(
        table, time_step=step, units=units, group=chosen.name, groups=tuple(names)
    )
