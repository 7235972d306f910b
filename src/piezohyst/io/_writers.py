"""Writing results: atomically (a temporary file renamed into place, the umask's
permissions), CSV and NPZ tables, streamed blocks, and the marker that says piezohyst
wrote a file. The public entry points are re-exported by :mod:`piezohyst.io`.
"""

from __future__ import annotations

import contextlib
import csv
import io as _io
import itertools
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from .._version import __version__
from ..errors import DataFileError, OutputError
from ._formats import MARKER, MD_MARKER, Table


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
    with _writing(p):
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=p.suffix, dir=p.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o666 & ~_umask())
        with _writing(p):
            os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


@contextlib.contextmanager
def _writing(p: Path) -> Iterator[None]:
    """An OS error while placing ``p`` becomes one naming ``p``, not our temporary file."""
    try:
        yield
    except OSError as exc:
        if isinstance(exc, OutputError):
            raise
        reason = (exc.strerror or type(exc).__name__).lower()
        blocking = next((q for q in p.parents if q.is_file()), None)
        if blocking is not None:
            reason = f"{blocking} is a file, not a folder"
        msg = f"{p}: cannot write here ({reason})"
        raise OutputError(msg) from None


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A folder of files written as a whole: they go into a hidden folder beside ``path``,
    renamed into place when the block ends; an error or an interrupt (Ctrl-C) leaves
    nothing, and an earlier folder at ``path`` stays until the new one is complete.

    Parameters
    ----------
    path : str or os.PathLike
        The folder to write.

    Yields
    ------
    Path
        The folder to write the files into.
    """
    p = Path(path)
    with _writing(p):
        p.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{p.name}.", dir=p.parent))
    try:
        yield staging
        os.chmod(staging, 0o777 & ~_umask())
        old = None
        with _writing(p):
            if p.exists():  # the earlier folder steps aside, then goes
                old = Path(tempfile.mkdtemp(prefix=f".{p.name}.old.", dir=p.parent))
                os.replace(p, old / p.name)
            os.replace(staging, p)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def write_json(path: str | os.PathLike[str], data: object) -> Path:
    """Write ``data`` as indented JSON, atomically (a model, leakage or map file).

    Parameters
    ----------
    path : str or os.PathLike
    data : object
        JSON-ready.

    Returns
    -------
    Path
    """
    import json

    return atomic_write_text(path, json.dumps(data, indent=2) + "\n")


def read_json(path: str | os.PathLike[str], what: str) -> object:
    """The JSON in ``path``, or a one-line ModelFileError naming the file and ``what`` it
    should have been.

    Parameters
    ----------
    path : str or os.PathLike
    what : str
        "a leakage file", "an output map"...

    Returns
    -------
    object

    Raises
    ------
    ModelFileError
    """
    import json

    from ..errors import ModelFileError

    p = Path(path)
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        msg = f"{p}: cannot read {what} ({str(exc).splitlines()[0]})"
        raise ModelFileError(msg) from None


class JsonFile:
    """``save`` and ``load`` for a record kept as one JSON document: a leakage file, an
    output map. The class gives ``to_dict`` and ``from_dict(data, where)``, and names what
    its files hold in ``file_kind`` (said when a file cannot be read).
    """

    file_kind: ClassVar[str] = "a JSON file"

    def to_dict(self) -> dict[str, Any]:  # pragma: no cover - each record has its own
        """JSON-ready contents (the record's own).

        Returns
        -------
        dict
        """
        raise NotImplementedError

    @classmethod
    def from_dict(cls, data: Any, where: str = "") -> Self:  # pragma: no cover
        """Rebuild from :meth:`to_dict` output (the record's own).

        Parameters
        ----------
        data : dict
        where : str
            Named in errors.

        Returns
        -------
        object
        """
        raise NotImplementedError

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write as JSON (atomically).

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        Path
        """
        return write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Self:
        """Read a file written by :meth:`save`.

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        object
            The record.

        Raises
        ------
        ModelFileError
            The file cannot be read, or a field is missing or bad (named in one line).
        """
        return cls.from_dict(read_json(path, cls.file_kind), str(path))


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
    """Write equal-length columns as CSV (header row, full precision), Parquet, ``.npz``,
    MATLAB ``.mat`` or NI ``.tdms``.

    The file appears only when complete (temporary file, then rename).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npz``, ``.parquet``, ``.mat``, ``.tdms``, or a text file (CSV). A
        ``.tdms`` channel gets ``wf_increment`` from an evenly sampled ``time``.
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
    blank: Collection[str] = (),
) -> int:
    """Write columns that arrive block by block; CSV and Parquet never hold more than one block.

    The column names are those of the first block. The file appears only when
    complete: an exception raised while the blocks are made (a bad row found
    halfway) leaves no file. ``.npz``, ``.mat`` and ``.tdms`` are written whole,
    so their blocks are gathered in memory first.

    Parameters
    ----------
    path : str or os.PathLike
        ``.npz``, ``.parquet``, ``.mat``, ``.tdms``, or a text file (CSV). A
        ``.tdms`` channel gets ``wf_increment`` from an evenly sampled ``time``.
    blocks : iterable of mapping
        Column name to values; within a block all of one length.
    units : mapping, optional
        Column name to unit (see :func:`write_table`).
    blank : collection of str, optional
        Columns whose NaN a CSV file leaves empty (no value there, as in the
        precondition rows of ``compensate``); other formats keep NaN.

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

    def whole() -> dict[str, FloatArray]:
        parts = [arrays_of(b, names) for b in chain]
        return {
            k: np.concatenate([part[j] for part in parts]) if parts else np.empty(0)
            for j, k in enumerate(names)
        }

    def write_npz(tmp: Path) -> None:
        arrays = whole()
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
                empty = [k in blank for k in names]
                for block in chain:
                    columns = arrays_of(block, names)
                    # shortest round-trip decimal text, written in batches by pyarrow; a
                    # NaN of a blank column as a null, which pyarrow writes empty
                    cols = [pa.array(c, type=pa.float64(), from_pandas=e)
                            for c, e in zip(columns, empty, strict=True)]  # fmt: skip
                    writer.write_table(pa.Table.from_arrays(cols, schema=schema))

    def write_mat(tmp: Path) -> None:
        from scipy.io import savemat

        # the marker first: is_piezohyst_output reads the head of the file
        arrays: dict[str, object] = {"written_by": f"{MARKER[2:]} {__version__}"}
        arrays.update({f"{k}_unit": u for k, u in named.items() if u and k in names})
        arrays.update({k: v[:, None] for k, v in whole().items()})
        with open(tmp, "wb") as fh:
            savemat(fh, arrays, do_compression=False)

    def write_tdms(tmp: Path) -> None:
        from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

        arrays = whole()
        props: dict[str, object] = {}
        steps = np.diff(arrays["time"]) if "time" in arrays and arrays["time"].size > 1 else None
        if steps is not None and np.ptp(steps) <= 1e-9 * abs(float(steps.mean())):
            props = {"wf_increment": float(steps.mean()), "wf_start_offset": 0.0}
        channels = [
            ChannelObject(
                "piezohyst", k, v, properties={**props, "unit_string": named.get(k) or ""}
            )
            for k, v in arrays.items()
        ]
        with TdmsWriter(tmp) as writer:
            root = RootObject(properties={"written_by": f"{MARKER[2:]} {__version__}"})
            writer.write_segment([root, GroupObject("piezohyst"), *channels])

    writers = {
        ".npz": write_npz,
        ".parquet": write_parquet,
        ".mat": write_mat,
        ".tdms": write_tdms,
    }
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
    ``__piezohyst__`` entry, Parquet with ``written_by`` metadata, MAT and
    TDMS files whose ``written_by`` says so, model, bank and leakage JSON
    (``"format": "piezohyst-model"``...), C sources generated by piezohyst, and
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
            kinds = ("piezohyst-model", "piezohyst-bank", "piezohyst-leakage")
            return any(f'"format": "{kind}"' in head for kind in kinds)
        if suffix in (".c", ".h"):
            return "generated by piezohyst" in head.splitlines()[0] if head else False
        if suffix == ".md":
            return head.startswith(MD_MARKER)
        if suffix in (".mat", ".tdms"):
            return MARKER[2:] in head
        return head.startswith(MARKER)
    except (OSError, ValueError):
        return False
