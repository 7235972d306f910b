"""Reading text tables: CSV/TSV/text (delimiter sniffing, header detection, decimal commas,
streamed through pyarrow) and aixACCT exports, each into a :class:`~._formats.Table`."""

from __future__ import annotations

import csv
import dataclasses
import io as _io
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._validation import FloatArray
from ..errors import DataFileError
from ..units import split_unit
from ._cells import ISO_DATE, is_timestamp, timestamps, units_row
from ._formats import CSV_SUFFIXES, MARKER, Table, choose_group, constant

__all__ = [
    "CSV_BLOCK_BYTES",
    "CsvPlan",
    "Fallback",
    "csv_batches",
    "csv_plan",
    "estimated_rows",
    "read_aixacct",
    "read_head",
    "read_text",
    "read_text_careful",
    "table_from_lines",
]


CSV_BLOCK_BYTES = 1 << 22  # bytes pyarrow parses per CSV batch


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


def is_number(cell: str) -> bool:
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


def read_text(
    path: Path,
    group: str | None = None,
    channels: Sequence[str] = (),
    progress: Callable[[int], None] | None = None,
    skip_rows: int = 0,
) -> Table:
    head = read_head(path)
    if b"\x00" in head and head[:2] not in (b"\xff\xfe", b"\xfe\xff"):
        msg = f"{path}: not a text file (binary content); expected CSV or text columns"
        raise DataFileError(msg)
    fast = _read_csv_arrow(path, head, progress, skip_rows)
    if fast is not None:
        return fast
    return read_text_careful(path, group, channels, skip_rows)


def read_text_careful(
    path: Path, group: str | None, channels: Sequence[str], skip_rows: int = 0
) -> Table:
    """Every text file pyarrow does not read cleanly, in memory, with exact messages."""
    raw = path.read_bytes()
    text = _decode(raw, path)
    if _AIXACCT_TABLE.match(text.split("\n", 3)[2] if text.count("\n") >= 3 else "") or (
        text.lstrip().startswith("PiezoResult")
    ):
        return read_aixacct(path, text, group, channels)
    # '#' and '%' lines are comments (piezohyst's own first line, MATLAB and DAQ notes)
    lines = [
        (n + 1, ln)
        for n, ln in enumerate(text.splitlines())
        if n >= skip_rows and ln.strip() and not ln.lstrip().startswith(("#", "%"))
    ]
    start = _table_start(lines)
    table = table_from_lines(path, lines[start:])
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
    return bool(filled) and all(is_number(c) or _DECIMAL_COMMA.match(c) for c in filled)


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
        head = read_head(path)
        lines = head.splitlines()[1:-1] if len(head) == 1 << 16 else head.splitlines()[1:]
        if not lines:
            return None
        return max(1, round(path.stat().st_size / (sum(map(len, lines)) / len(lines) + 1)))
    except (OSError, ValueError, ImportError):
        return None


def read_head(path: Path, size: int = 1 << 16) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(size)


@dataclass(frozen=True)
class CsvPlan:
    """How pyarrow reads a delimited file, decided from its head as the careful reader would."""

    skip: int  # lines before the data (comments, preamble, header)
    names: list[str]
    units: Mapping[str, str]
    delimiter: str
    decimal_comma: bool
    encoding: str
    time_step: float | None = None  # the preamble's stated sample interval


class Fallback(Exception):
    """pyarrow cannot read this file cleanly: the careful reader must (and names the row)."""


def csv_plan(path: Path, head: bytes, skip_rows: int = 0) -> CsvPlan | None:
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
        sample = table_from_lines(path, body[:50])
    except DataFileError:
        return None
    first = next(csv.reader([body[0][1]], delimiter=delim))
    has_header = any(c.strip() and not is_number(c.strip()) for c in first)
    if has_header and len(body) > 2 and units_row(next(csv.reader([body[1][1]], delimiter=delim))):
        body = body[1:]  # the units row under the header: skipped too
    decimal_comma = delim != "," and _decimal_commas(
        [(n, next(csv.reader([ln], delimiter=delim))) for n, ln in body[:50]]
    )
    return CsvPlan(
        body[0][0] - 1 + int(has_header),
        sample.columns,
        sample.units,
        delim,
        decimal_comma,
        encoding,
        _stated_step(ln for _, ln in preamble),
    )


def csv_batches(
    path: Path, plan: CsvPlan, columns: Sequence[str]
) -> Iterator[dict[str, FloatArray]]:
    """The named columns in batches of rows, parsed by pyarrow (raises :class:`Fallback`)."""
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
                    raise Fallback from None
                if any(col.null_count for col in batch.columns):
                    raise Fallback  # empty cells: the careful reader names their rows
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
    plan = csv_plan(path, head, skip_rows)
    if plan is None:
        return None
    parts: dict[str, list[FloatArray]] = {name: [] for name in plan.names}
    rows = 0
    try:
        for batch in csv_batches(path, plan, plan.names):
            for name, values in batch.items():
                parts[name].append(values)
            rows += len(batch[plan.names[0]])
            if progress is not None:
                progress(rows)
    except Fallback:
        return None
    if rows == 0:
        return None
    columns = {name: np.concatenate(v) for name, v in parts.items()}
    getters = {k: constant(v) for k, v in columns.items()}
    return Table(path, plan.names, getters, plan.time_step, plan.units)


_DECIMAL_COMMA = re.compile(r"^[+-]?\d*,\d+(?:[eE][+-]?\d+)?$")


def _decimal_commas(rows: list[tuple[int, list[str]]]) -> bool:
    """True when numbers are written with a decimal comma (1,5): European DAQ exports."""
    cells = [c for _, row in rows[1:50] for c in row if c]
    commas = sum(bool(_DECIMAL_COMMA.match(c)) for c in cells)
    points = sum("." in c and is_number(c) for c in cells)
    return commas > 0 and points == 0


def table_from_lines(path: Path, lines: list[tuple[int, str]]) -> Table:
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
    has_header = any(c and not is_number(c) for c in first)
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
                    if not (is_timestamp(cell) if clock else is_number(cell)):
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
    if not all(is_number(c) or not c for c in cells):
        return False
    try:
        with open(path, "rb") as fh:
            return fh.read(len(MARKER)).decode("utf-8", "replace") == MARKER
    except OSError:
        return False


_AIXACCT_TABLE = re.compile(r"^\s*Table\s+\d+\s*$")


def read_aixacct(path: Path, text: str, group: str | None, channels: Sequence[str]) -> Table:
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
    chosen = choose_group(path, headers, group, channels, "aixACCT table")
    table = table_from_lines(path, blocks[chosen])
    return dataclasses.replace(table, group=chosen, groups=tuple(blocks))
