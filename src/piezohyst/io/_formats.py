"""The readers' shared ground: a file's columns as a :class:`Table` (named, with units,
read whole or in batches), a :class:`Recording`'s columns chosen from one, and the helpers
every reader builds a table with. The readers themselves: :mod:`._text` (CSV, TSV, text,
aixACCT), :mod:`._containers` (``.npz``, Parquet, MATLAB ``.mat``, HDF5, NI TDMS). The
public entry points are in :mod:`piezohyst.io`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validation import FloatArray
from ..errors import DataFileError
from ..units import split_unit, suffix_units

__all__ = [
    "BATCH_ROWS",
    "CSV_SUFFIXES",
    "MARKER",
    "MD_MARKER",
    "Recording",
    "Table",
    "as_column",
    "choose_group",
    "constant",
    "field_named",
    "table_from_arrays",
    "timed_suffix",
    "with_suffix_units",
]


CSV_SUFFIXES = {".csv", ".tsv", ".txt", ".dat", ""}


MARKER = "# written by piezohyst"  # first line of every CSV piezohyst writes


MD_MARKER = "<!-- written by piezohyst"  # first line of every Markdown table it writes


BATCH_ROWS = 1 << 18  # rows per batch when streaming a file


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
        field = field_named(key, self._getters)  # a nested field by MATLAB's name, or its own
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


# ------------------------------------------------------------------ binary formats
def as_column(value: object) -> FloatArray | None:
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf" or arr.size < 1:
        return None
    arr = np.squeeze(arr)
    if arr.ndim != 1:
        return None
    return np.ascontiguousarray(arr, dtype=np.float64)


def table_from_arrays(path: Path, arrays: Mapping[str, object], kind: str) -> Table:
    columns: dict[str, FloatArray] = {}
    for name, value in arrays.items():
        col = as_column(value)
        if col is not None:
            columns[name] = col
    if not columns:
        msg = f"{path}: the {kind} file holds no 1-D numeric arrays"
        raise DataFileError(msg)
    return Table(path, list(columns), {k: constant(v) for k, v in columns.items()})


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


def constant(values: FloatArray) -> Callable[[], FloatArray]:
    return lambda: values


def field_named(key: str, columns: Iterable[str]) -> str | None:
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


def choose_group(
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
        if any(split_unit(k)[0].lower() == "time" or k in timed_suffix(c) for k in c)
    )
    return next(timed, next((n for n, cols in groups.items() if cols), names[0]))


def timed_suffix(columns: Iterable[str]) -> set[str]:
    """The columns named ``time_unit`` (``time_ms``) among ``columns``."""
    return {c for c, (name, _) in suffix_units(list(columns)).items() if name.lower() == "time"}
