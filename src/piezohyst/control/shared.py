"""The compensator as a C shared library: one opaque handle per channel, for any host.

LabVIEW's Call Library Function Node, MATLAB's ``loadlibrary``, Python's ctypes and
Julia's ``ccall`` all call a C shared library the same way. :func:`write_shared` writes
the exported step (:mod:`piezohyst.control.export`) with a small API after it and builds
``libNAME.so`` (``NAME.dll`` on Windows, ``libNAME.dylib`` on macOS) beside it with the
system C compiler, exporting only ``NAME_``-prefixed symbols:

* ``NAME_t *NAME_new(void)``: a handle in the exported state (NULL if out of memory);
* ``void NAME_free(NAME_t *)``; ``void NAME_reset(NAME_t *)``: back to the exported state;
* ``int NAME_process(NAME_t *, const double *target, double *volts, long n)`` (the
  controller's takes ``const double *charge`` after ``target``): ``n`` commands, 0 on
  success, -1 for a NULL pointer, -2 for ``n < 0``; no allocation, no callbacks;
* ``const char *NAME_version(void)``: what was exported, by which piezohyst.

The conventions are those of liblsl, OSQP and the NI-DAQmx C API: state per handle, integer
status codes, the caller owns every buffer.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, cast

from .._version import __version__
from ..errors import ParameterError
from .compensator import Compensator
from .export import Precision, c_paths, export_c

if TYPE_CHECKING:
    from .selfsensing import SelfSensingController

__all__ = ["STATUS", "library_path", "write_shared"]

#: What ``NAME_process`` returns
STATUS = {"ok": 0, "null pointer": -1, "negative count": -2}


def library_path(c_path: Path, prefix: str) -> Path:
    """Where the shared library of ``prefix`` goes, beside its source (platform's name).

    Parameters
    ----------
    c_path : Path
    prefix : str

    Returns
    -------
    Path
    """
    if sys.platform == "win32":  # pragma: no cover - built and tested on Linux here
        return c_path.with_name(f"{prefix}.dll")
    suffix = ".dylib" if sys.platform == "darwin" else ".so"
    return c_path.with_name(f"lib{prefix}{suffix}")


def _api(prefix: str, controller: bool, what: str) -> tuple[str, str]:
    """The API's declarations (for the header) and definitions (after the source)."""
    charge_arg = "const double *charge, " if controller else ""
    charge_null = " || charge == NULL" if controller else ""
    charge_use = ", (" + prefix + "_real)charge[k]" if controller else ""
    version = f"piezohyst {__version__}: {what}".replace("\\", "/").replace('"', "'")
    declarations = f"""
/* Shared-library API (piezohyst export-c --shared): one handle per channel. */
#ifdef __cplusplus
extern "C" {{
#endif
{prefix}_t *{prefix}_new(void);
void {prefix}_free({prefix}_t *s);
void {prefix}_reset({prefix}_t *s);
int {prefix}_process({prefix}_t *s, const double *target, {charge_arg}double *volts, long n);
const char *{prefix}_version(void);
#ifdef __cplusplus
}}
#endif
"""
    definitions = f"""
/* ---- shared-library API (piezohyst export-c --shared) ---- */
#include <stdlib.h>
#if defined(_WIN32)
#define PH_EXPORT __declspec(dllexport)
#else
#define PH_EXPORT __attribute__((visibility("default")))
#endif

/* A handle in the exported state; NULL if memory ran out. */
PH_EXPORT {prefix}_t *{prefix}_new(void)
{{
    {prefix}_t *s = ({prefix}_t *)malloc(sizeof({prefix}_t));
    if (s != NULL) {{
        {prefix}_init(s);
    }}
    return s;
}}

PH_EXPORT void {prefix}_free({prefix}_t *s)
{{
    free(s);
}}

/* Back to the exported state (the counters too). */
PH_EXPORT void {prefix}_reset({prefix}_t *s)
{{
    if (s != NULL) {{
        {prefix}_init(s);
    }}
}}

/* n commands (V) into volts: 0; -1 for a NULL pointer, -2 for n < 0. */
PH_EXPORT int {prefix}_process({prefix}_t *s, const double *target, {charge_arg}double *volts,
                               long n)
{{
    long k;
    if (s == NULL || target == NULL || volts == NULL{charge_null}) {{
        return -1;
    }}
    if (n < 0) {{
        return -2;
    }}
    for (k = 0; k < n; ++k) {{
        volts[k] = (double){prefix}_step(s, ({prefix}_real)target[k]{charge_use});
    }}
    return 0;
}}

PH_EXPORT const char *{prefix}_version(void)
{{
    return "{version}";
}}
"""
    return declarations, definitions


def _compiler() -> str:
    """The system C compiler ($CC, else cc, gcc or clang)."""
    for name in (os.environ.get("CC", ""), "cc", "gcc", "clang"):
        found = shutil.which(name) if name else None
        if found:
            return found
    msg = (
        "no C compiler found (cc, gcc or clang; or set CC): the sources are written, build "
        "them with: cc -std=c99 -O2 -shared -fPIC -fvisibility=hidden NAME.c -o libNAME.so -lm"
    )
    raise ParameterError(msg)


def write_shared(
    compensator: Compensator | SelfSensingController,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> tuple[Path, Path, Path]:
    """Write ``NAME.c`` and ``NAME.h`` with the shared-library API and build the library.

    Parameters
    ----------
    compensator : Compensator or SelfSensingController
    path : str or os.PathLike
        The ``.c`` file; the header and the library go beside it.
    precision : {"double", "float"}
        The C type of the step's reals (the API takes and returns doubles).

    Returns
    -------
    tuple of Path
        Source, header, library.

    Raises
    ------
    ParameterError
        A model the C export does not cover, an output mode (its step needs the next
        desired value), no C compiler, or a build that fails (its first error named).
    """
    from ..io import atomic_write_text

    comp = cast(Compensator, getattr(compensator, "compensator", compensator))
    controller = comp is not compensator
    if comp.mode.active:
        msg = (
            "the shared library's process() takes one desired value per command: a model with "
            "an output mode needs the next one too; export its sources (export-c) instead"
        )
        raise ParameterError(msg)
    c_path, h_path, prefix = c_paths(path)
    code = export_c(compensator, precision=precision, prefix=prefix)
    kind = "self-sensing controller" if controller else "compensator"
    what = f"{prefix}, the {kind} of a {type(comp.model).__name__}"
    declarations, definitions = _api(prefix, controller, what)
    guard_end = code.header.rindex("#endif")
    header = code.header[:guard_end] + declarations + "\n" + code.header[guard_end:]
    atomic_write_text(h_path, header)
    atomic_write_text(c_path, code.source + definitions)
    lib = library_path(c_path, prefix)
    cmd = [_compiler(), "-std=c99", "-O2", "-shared", "-fPIC", "-fvisibility=hidden",
           str(c_path), "-o", str(lib), "-lm"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        first = next((ln for ln in done.stderr.splitlines() if "error" in ln), done.stderr)
        msg = f"building {lib.name} failed: {first.strip()}"
        raise ParameterError(msg)
    return c_path, h_path, lib
