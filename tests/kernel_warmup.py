"""Compile the numba kernels the tests call, before they run, split between the cores.

On a fresh clone numba's cache is empty, and ``make test``'s two workers each compile nearly
every kernel specialization the suite calls (about 1.6 s each): the same work twice, once per
core. ``make test`` first runs ``python tests/kernel_warmup.py warm``: two processes compile
disjoint halves of the specializations listed in tests/kernel_signatures.txt into numba's
cache, and the workers then load them. A specialization missing from the list is compiled by
the test that calls it, as before (slower, never wrong); a listed kernel that no longer
exists is named by ``tests/test_testing.py``.

``python tests/kernel_warmup.py record`` (from the repository's root, after kernels or their
callers change) runs the compiled suite with every worker writing the specializations it
holds at its end, and writes the list.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
LIST = ROOT / "tests" / "kernel_signatures.txt"
#: The modules whose numba dispatchers the list covers.
MODULES = (
    "piezohyst._kernels.signal",
    "piezohyst._kernels.play",
    "piezohyst._kernels.packed",
    "piezohyst._kernels.structure",
    "piezohyst.simulation._plant",
)
#: Set by ``record``: the folder each worker writes its specializations into at its end.
RECORD_ENV = "PIEZOHYST_KERNEL_RECORD"


def dispatchers() -> dict[str, Any]:
    """Every numba dispatcher of :data:`MODULES`, by ``module:name``."""
    from numba.core.dispatcher import Dispatcher

    found = {}
    for name in MODULES:
        module = importlib.import_module(name)
        for attr, value in vars(module).items():
            if isinstance(value, Dispatcher) and value.__module__ == name:
                found[f"{name}:{attr}"] = value
    return found


def held() -> list[str]:
    """The specializations this process holds, one ``module:name<TAB>signature`` per line."""
    return [f"{key}\t{sig!r}" for key, d in dispatchers().items() for sig in d.signatures]


def parse(text: str) -> tuple[Any, ...] | None:
    """A signature's repr back to numba types; None for one a caller compiles (a literal)."""
    from numba.core import types

    namespace = {**vars(types), "bool": types.boolean}
    try:
        sig = eval(text, namespace)  # our own file's rows: numba's reprs
    except (SyntaxError, NameError, TypeError):
        return None
    return sig if isinstance(sig, tuple) else None


def entries() -> list[tuple[str, str]]:
    """The list's ``(module:name, signature)`` pairs, in its order."""
    rows = [line.split("\t") for line in LIST.read_text().splitlines() if line and line[0] != "#"]
    return [(row[0], row[1]) for row in rows]


def compile_part(part: int, parts: int) -> None:
    """Compile every ``parts``-th listed specialization, from ``part``, into numba's cache."""
    found = dispatchers()
    start = time.perf_counter()
    done, stale = 0, []
    for key, text in entries()[part::parts]:
        sig = parse(text)
        if key in found and sig is not None:
            try:
                found[key].compile(sig)
            except Exception:  # a kernel's arguments changed: its test compiles it
                stale.append(key)
                continue
            done += 1
    took = time.perf_counter() - start
    print(
        f"part {part + 1} of {parts}: {done} specializations in {took:.1f} s"
        + (f"; not compiled, their arguments changed: {', '.join(stale)}" if stale else "")
    )


def warm(parts: int = 2) -> None:
    """Compile the list in ``parts`` processes at once (one per core)."""
    start = time.perf_counter()
    procs = [
        subprocess.Popen([sys.executable, __file__, "compile", str(i), str(parts)], cwd=ROOT)
        for i in range(parts)
    ]
    codes = [p.wait() for p in procs]
    if any(codes):
        sys.exit(f"kernel warm-up failed (exit codes {codes})")
    print(f"numba kernels compiled into the cache in {time.perf_counter() - start:.1f} s")


def record() -> None:
    """Run the compiled suite, every worker writing what it compiled; merge into the list."""
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, RECORD_ENV: folder}
        subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadfile",
             "-p", "no:cacheprovider", "tests"],
            cwd=ROOT, env=env, check=True,
        )  # fmt: skip
        lines: dict[str, None] = {}
        for path in sorted(Path(folder).glob("*.txt")):
            lines.update(dict.fromkeys(filter(None, path.read_text().splitlines())))
    header = [line for line in LIST.read_text().splitlines() if line.startswith("#")]
    # The callers first, callees after: a caller compiles its callees on the way.
    body = sorted(lines, key=lambda line: (parse(line.split("\t")[1]) is None, line))
    LIST.write_text("\n".join([*header, *body]) + "\n")
    print(f"{len(body)} specializations written to {LIST.relative_to(ROOT)}")


if __name__ == "__main__":
    command = sys.argv[1] if len(sys.argv) > 1 else "warm"
    if command == "compile":
        compile_part(int(sys.argv[2]), int(sys.argv[3]))
    elif command == "record":
        record()
    else:
        warm()
