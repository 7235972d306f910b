"""Run a file parser where its crash cannot take the caller down.

SciPy's MAT reader and the HDF5 library are compiled code: a damaged file can make
them read out of bounds and kill the process (a fuzzed ``.mat`` did, one run in three).
The parsers here run in a child process forked from a small server process (the
standard library's ``forkserver``, started once, on first use); the child sends the
parsed arrays back through a pipe. A child that dies becomes one
:class:`~piezohyst.errors.DataFileError` line naming the file, and the caller goes on.

Where a child cannot be had (inside a daemonic worker process, e.g. a Dask worker,
which may not start children) the parser runs in-process, as it would without this
module. Each read costs a fork and a copy of the arrays (milliseconds for a record of
10**6 samples); the first one also starts the server (about a second).
"""

from __future__ import annotations

import multiprocessing as mp
import multiprocessing.connection
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from .errors import DataFileError

T = TypeVar("T")

_PRELOAD = ["piezohyst._parsers"]


def _context() -> Any:
    """The forkserver context where the platform has it, else spawn (Windows)."""
    methods = mp.get_all_start_methods()
    if "forkserver" in methods:
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(_PRELOAD)
        return ctx
    return mp.get_context("spawn")


def _child(
    parse: Callable[[str], Any], path: str, send: multiprocessing.connection.Connection
) -> None:
    """In the child: parse, send ``(True, result)`` or ``(False, exception)``."""
    try:
        result: tuple[bool, Any] = (True, parse(path))
    except Exception as exc:  # sent back and raised in the caller
        result = (False, exc)
    try:
        send.send(result)
    except Exception as exc:  # an exception that does not pickle: its text
        send.send((False, RuntimeError(f"{type(exc).__name__}: {exc}")))
    send.close()


def parse_isolated(parse: Callable[[str], T], path: Path, kind: str) -> T:
    """``parse(str(path))`` in a child process; its crash is a one-line error.

    Parameters
    ----------
    parse : callable
        A module-level function (the child imports it by name) taking the path
        and returning picklable data.
    path : Path
    kind : str
        The format's name for the message ("MAT", "HDF5").

    Raises
    ------
    DataFileError
        The parser's process died (a signal or an exit) before it answered.
    Exception
        Whatever ``parse`` raised, raised here.
    """
    if mp.current_process().daemon:  # a daemonic worker may not start children
        return parse(str(path))
    ctx = _context()
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(parse, str(path), send), daemon=True)
    proc.start()
    send.close()
    try:
        ok, payload = recv.recv()
    except EOFError:
        proc.join()
        how = (
            f"signal {-proc.exitcode}" if proc.exitcode is not None and proc.exitcode < 0
            else f"exit code {proc.exitcode}"
        )  # fmt: skip
        msg = f"{path}: the {kind} reader crashed on this file ({how}): it is damaged"
        raise DataFileError(msg) from None
    finally:
        recv.close()
    proc.join()
    if ok:
        return payload  # type: ignore[no-any-return]
    raise payload
