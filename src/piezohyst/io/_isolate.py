"""Run a file parser where its crash cannot take the caller down.

SciPy's MAT reader and the HDF5 library are compiled code: a damaged file can make them read
out of bounds and kill the process (a fuzzed ``.mat`` did, one run in three). The parsers of
:mod:`piezohyst.io._parsers` run in a helper process instead: a fresh interpreter (``python -P``)
started on the first read, which loads that one file by its path, so it imports NumPy, SciPy's
MAT reader and h5py but neither piezohyst nor the caller's own script, and it needs no
``if __name__ == "__main__"`` guard anywhere. It answers one request at a time through its
pipes; a helper that dies on a file becomes one :class:`~piezohyst.errors.DataFileError` line
naming the file and the signal, and the next read starts a new helper.

A read costs a round trip and a copy of the arrays (milliseconds for 10**6 samples); the
first one also starts the helper (a few tenths of a second). A process forked after the
helper started (a Dask worker, say) starts its own.
"""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading
from pathlib import Path
from typing import IO, Any

from ..errors import DataFileError

_SOURCE = Path(__file__).with_name("_parsers.py")
_BOOT = (
    "import importlib.util as u\n"
    f"s = u.spec_from_file_location('piezohyst_parsers', {str(_SOURCE)!r})\n"
    "m = u.module_from_spec(s)\n"
    "s.loader.exec_module(m)\n"
    "m.serve()\n"
)


class _Helper:
    """The helper process of this process (one at a time, one request at a time)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.proc: subprocess.Popen[bytes] | None = None
        self.pid = 0  # the process that started it: a fork must start its own

    def running(self) -> subprocess.Popen[bytes]:
        if self.proc is None or self.pid != os.getpid() or self.proc.poll() is not None:
            self.proc = subprocess.Popen(
                [sys.executable, "-P", "-c", _BOOT],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
            )
            self.pid = os.getpid()
        return self.proc

    def stop(self) -> None:
        proc, self.proc = self.proc, None
        if proc is not None and self.pid == os.getpid():
            for stream in (proc.stdin, proc.stdout):
                if stream is not None:
                    stream.close()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


_HELPER = _Helper()
atexit.register(_HELPER.stop)


def _pipes(proc: subprocess.Popen[bytes]) -> tuple[IO[bytes], IO[bytes]]:
    assert proc.stdin is not None and proc.stdout is not None
    return proc.stdin, proc.stdout


def parse_isolated(parser: str, path: Path, kind: str) -> Any:
    """``_parsers.PARSERS[parser](str(path))`` in the helper process.

    Parameters
    ----------
    parser : str
        A name in :data:`piezohyst.io._parsers.PARSERS`.
    path : Path
    kind : str
        The format's name for the message ("MAT", "HDF5").

    Returns
    -------
    object
        What the parser returned: plain data.

    Raises
    ------
    DataFileError
        The helper died (a signal or an exit) before it answered.
    Exception
        Whatever the parser raised, raised here.
    """
    from . import _parsers  # the message format (the helper loads its own copy by path)

    with _HELPER.lock:
        proc = _HELPER.running()
        send, recv = _pipes(proc)
        try:
            _parsers.send(send, (parser, str(Path(path).absolute())))
            ok, payload = _parsers.receive(recv)
        except (EOFError, BrokenPipeError, OSError):
            code = proc.wait()
            _HELPER.stop()
            how = f"signal {-code}" if code < 0 else f"exit code {code}"
            msg = f"{path}: the {kind} reader crashed on this file ({how}): it is damaged"
            raise DataFileError(msg) from None
    if ok:
        return payload
    raise payload
