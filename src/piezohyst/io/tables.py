"""Reading a data file into a table: the format chosen by the suffix (text, NumPy, MATLAB, NI
TDMS, HDF5, Parquet), columns read when asked for, a workbook refused in one line."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

from .._validation import FloatArray
from ..errors import DataFileError
from ..units import split_unit
from ._containers import read_hdf5, read_mat, read_npz, read_parquet, read_tdms
from ._formats import BATCH_ROWS, CSV_SUFFIXES, Table, with_suffix_units
from ._text import CsvPlan, Fallback, csv_batches, csv_plan, read_head, read_text, read_text_careful


def read_table(
    path: str | os.PathLike[str],
    *,
    group: str | None = None,
    channels: Sequence[str] = (),
    progress: Callable[[int], None] | None = None,
    skip_rows: int = 0,
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
    skip_rows : int, default 0
        Text files: lines to skip before the table. A preamble of ``Key: value``
        lines is found without it (and a stated ``Sample rate: 1000 Hz`` read).

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
    _check_skip(p, skip_rows)
    _refuse_workbook(p)
    readers: dict[str, Callable[[], Table]] = {
        ".npz": lambda: read_npz(p),
        ".mat": lambda: read_mat(p, group, channels),
        ".tdms": lambda: read_tdms(p, group, channels),
        ".parquet": lambda: read_parquet(p, progress),
        ".h5": lambda: read_hdf5(p, group, channels),
        ".hdf5": lambda: read_hdf5(p, group, channels),
    }
    return _reading(
        p, readers.get(suffix, lambda: read_text(p, group, channels, progress, skip_rows))
    )


def _check_skip(p: Path, skip_rows: int) -> None:
    if skip_rows < 0:
        msg = f"the rows to skip must be 0 or more. Got {skip_rows}."
        raise DataFileError(msg)
    if skip_rows and p.suffix.lower() not in CSV_SUFFIXES:
        msg = f"{p}: rows can be skipped in text files only, not in {p.suffix} files"
        raise DataFileError(msg)


#: Spreadsheet workbooks by suffix, and the first bytes of their two containers (a zip
#: archive: .xlsx, .ods; an OLE2 compound file: .xls)
WORKBOOKS = (".xlsx", ".xlsm", ".xls", ".ods", ".numbers")
WORKBOOK_MAGIC = {b"PK\x03\x04": "a zip archive", b"\xd0\xcf\x11\xe0": "an OLE2 compound file"}


def _refuse_workbook(p: Path) -> None:
    """A spreadsheet workbook is refused in one line (it was read as text, and the error
    then spoke of a header without data rows)."""
    with p.open("rb") as f:
        head = f.read(4)
    container = WORKBOOK_MAGIC.get(head)
    if p.suffix.lower() in WORKBOOKS or (container and p.suffix.lower() != ".npz"):
        what = f"a {p.suffix} workbook" if p.suffix.lower() in WORKBOOKS else container
        advice = (
            "unzip it and give the file inside" if p.suffix.lower() == ".zip"
            else "save the sheet as CSV (in Excel: File > Save As > CSV UTF-8) and give that file"
        )  # fmt: skip
        msg = f"{p}: {what}, not a table piezohyst reads: {advice}"
        raise DataFileError(msg)


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
        return with_suffix_units(reader())
    except DataFileError:
        raise
    except Exception as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        msg = f"{p}: cannot read as {kind} ({detail})"
        raise DataFileError(msg) from None


def open_table(
    path: str | os.PathLike[str],
    *,
    group: str | None = None,
    channels: Sequence[str] = (),
    skip_rows: int = 0,
) -> Table:
    """A :class:`Table` whose columns are read from the file only when asked for.

    CSV and Parquet files are not loaded: :meth:`Table.batches` streams them
    in batches of rows, so memory does not grow with the record. Other
    formats are read as by :func:`read_table`.

    Parameters
    ----------
    path : path
        The data file (formats as :func:`read_table`).
    group, channels, skip_rows
        As for :func:`read_table`.

    Returns
    -------
    Table
    """
    p = _existing(path)
    suffix = p.suffix.lower()
    _check_skip(p, skip_rows)
    if suffix == ".parquet":
        return _reading(p, lambda: _lazy_parquet(p))
    if suffix in CSV_SUFFIXES:
        head = read_head(p)
        plan = None if b"\x00" in head else csv_plan(p, head, skip_rows)
        if plan is not None:
            return with_suffix_units(_lazy_csv(p, plan, group, channels, skip_rows))
    return read_table(p, group=group, channels=channels, skip_rows=skip_rows)


def _lazy_csv(
    path: Path, plan: CsvPlan, group: str | None, channels: Sequence[str], skip_rows: int
) -> Table:
    def stream(names: Sequence[str]) -> Iterator[dict[str, FloatArray]]:
        done = 0
        try:
            for batch in csv_batches(path, plan, names):
                done += len(batch[names[0]])
                yield batch
        except Fallback:
            # the careful reader raises naming the row, or reads what pyarrow could not
            careful = read_text_careful(path, group, channels, skip_rows)
            arrays = [careful.get(n, finite=False) for n in names]
            for lo in range(done, arrays[0].size, BATCH_ROWS):
                yield {n: a[lo : lo + BATCH_ROWS] for n, a in zip(names, arrays, strict=True)}

    def getter(name: str) -> Callable[[], FloatArray]:
        return lambda: np.concatenate([b[name] for b in stream([name])])

    getters = {n: getter(n) for n in plan.names}
    return Table(path, plan.names, getters, plan.time_step, plan.units, _stream=stream)


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
