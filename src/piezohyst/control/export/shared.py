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
* ``int NAME_counts(const NAME_t *, unsigned long counts[4])``: what the limits held since
  the last reset (non-finite targets, targets out of reach, commands cut by the slew
  limit, targets beyond the output map's calibrated range): a host sees when they bite;
* ``const char *NAME_version(void)``: what was exported, by which piezohyst.

The conventions are those of liblsl, OSQP and the NI-DAQmx C API: state per handle, integer
status codes, the caller owns every buffer.

:func:`write_mex` writes a MEX gateway instead, for MATLAB's ``mex`` and Octave's
``mkoctfile --mex``: ``v = NAME(target)`` returns the commands for a vector and keeps the
state between calls, ``NAME('reset')`` goes back to the exported state, and a wrong
argument is an error in the host (``mexErrMsgIdAndTxt``), never a crash.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from importlib import resources
from pathlib import Path
from string import Template
from typing import TYPE_CHECKING, cast

from ..._version import __version__
from ...errors import ParameterError
from ..c_text import Precision
from ..compensator import Compensator
from .c_code import c_paths, export_c

if TYPE_CHECKING:
    from ..selfsensing import SelfSensingController

__all__ = ["STATUS", "compiler", "library_path", "write_mex", "write_shared"]

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


def _c_template(name: str) -> Template:
    """A C template shipped with the package (``piezohyst/control/c``)."""
    return Template((resources.files("piezohyst.control.export") / "c" / name).read_text("utf-8"))


def _version_text(what: str) -> str:
    """What was exported, by which piezohyst, as a C string literal's contents."""
    return f"piezohyst {__version__}: {what}".replace("\\", "/").replace('"', "'")


def _block_next(prefix: str) -> str:
    """A mode's step argument in a block: the next target, the block's own preview as
    Python's ``process`` (the block's last: NaN, extrapolated)."""
    return f", ({prefix}_real)(k + 1 < n ? target[k + 1] : NAN)"


def _api(prefix: str, controller: bool, what: str, mode: bool = False) -> tuple[str, str]:
    """The API's declarations (for the header) and definitions (after the source)."""
    charge_arg = "const double *charge, " if controller else ""
    charge_null = " || charge == NULL" if controller else ""
    charge_use = ", (" + prefix + "_real)charge[k]" if controller else ""
    if mode:  # a mode's step takes the next target too (a controller's: after the charge)
        charge_use += _block_next(prefix)
    version = _version_text(what)
    declarations = f"""
/* Shared-library API (piezohyst export-c --shared): one handle per channel. */
#ifdef __cplusplus
extern "C" {{
#endif
{prefix}_t *{prefix}_new(void);
void {prefix}_free({prefix}_t *s);
void {prefix}_reset({prefix}_t *s);
int {prefix}_process({prefix}_t *s, const double *target, {charge_arg}double *volts, long n);
int {prefix}_counts(const {prefix}_t *s, unsigned long counts[4]);
const char *{prefix}_version(void);
#ifdef __cplusplus
}}
#endif
"""
    definitions = _c_template("handle.c").substitute(prefix=prefix) + _c_template(
        "shared_api.c"
    ).substitute(
        prefix=prefix,
        charge_arg=charge_arg,
        charge_null=charge_null,
        charge_use=charge_use,
        version=version,
    )
    return declarations, definitions


def compiler() -> str:
    """The system C compiler ($CC, else cc, gcc or clang).

    Returns
    -------
    str

    Raises
    ------
    ParameterError
        None found.
    """
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
        A model the C export does not cover, no C compiler, or a build that fails (its first
        error named). A model with an output mode: ``process`` takes each target's next from
        the block, as Python's ``process`` does (the block's last: extrapolated).
    """
    from ...io import atomic_write_text

    comp = cast(Compensator, getattr(compensator, "compensator", compensator))
    controller = comp is not compensator
    c_path, h_path, prefix = c_paths(path)
    code = export_c(compensator, precision=precision, prefix=prefix)
    kind = "self-sensing controller" if controller else "compensator"
    what = f"{prefix}, the {kind} of a {type(comp.model).__name__}"
    declarations, definitions = _api(prefix, controller, what, comp.mode.active)
    guard_end = code.header.rindex("#endif")
    header = code.header[:guard_end] + declarations + "\n" + code.header[guard_end:]
    atomic_write_text(h_path, header)
    atomic_write_text(c_path, code.source + definitions)
    lib = library_path(c_path, prefix)
    build_library([c_path], lib)
    return c_path, h_path, lib


def build_library(sources: list[Path], lib: Path) -> None:
    """Compile ``sources`` into the shared library ``lib`` with the system C compiler.

    Parameters
    ----------
    sources : list of Path
        C files, one translation unit each.
    lib : Path
        The library to write.

    Raises
    ------
    ParameterError
        No C compiler, or a build that fails (its first error named).
    """
    cmd = [compiler(), "-std=c99", "-O2", "-shared", "-fPIC", "-fvisibility=hidden",
           *(str(p) for p in sources), "-o", str(lib), "-lm"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        first = next((ln for ln in done.stderr.splitlines() if "error" in ln), done.stderr)
        msg = f"building {lib.name} failed: {first.strip()}"
        raise ParameterError(msg)


def mex_commands(name: str, prefix: str, version: str) -> str:
    """The MEX gateways' ``run_command`` (``c/mex_commands.c``): NAME('reset'), NAME('version').

    Parameters
    ----------
    name, prefix : str
        The gateway's function name and the step's prefix.
    version : str
        What ``NAME('version')`` returns.

    Returns
    -------
    str
    """
    text = _c_template("mex_commands.c").template.split("\n", 2)[2]
    return Template(text).substitute(name=name, prefix=prefix, version=version)


def _mex_gateway(name: str, prefix: str, controller: bool, what: str, mode: bool = False) -> str:
    """The MEX gateway's source: one translation unit with the exported step."""
    args = "target, charge" if controller else "target"
    nargs = 2 if controller else 1
    version = _version_text(what)
    measured = ", (" + prefix + "_real)charge[k]" if controller else ""
    if mode:  # the block is its own preview (see _block_next), after a controller's charge
        measured += _block_next(prefix)
    charge_check = (
        f"""
    if (mxGetNumberOfElements(prhs[1]) != n || !mxIsDouble(prhs[1]) || mxIsComplex(prhs[1])
        || mxIsSparse(prhs[1])) {{
        mexErrMsgIdAndTxt("{name}:charge", "the charge must be a real double vector "
                          "as long as the target");
    }}
    charge = mxGetPr(prhs[1]);"""
        if controller
        else ""
    )
    return _c_template("mex_gateway.c").substitute(
        run_command=mex_commands(name, prefix, version),
        name=name,
        version=version,
        args=args,
        prefix=prefix,
        nargs=nargs,
        charge_check=charge_check,
        measured=measured,
    )


def write_mex(
    compensator: Compensator | SelfSensingController,
    path: str | os.PathLike[str],
    *,
    precision: Precision = "double",
) -> tuple[Path, Path, Path]:
    """Write a MEX gateway ``NAME.c`` and the step it includes (``STEP.c``, ``STEP.h``).

    ``NAME`` comes from ``path`` (``ph_comp_mex.c``: the function ``ph_comp_mex``); the
    step's files are named after it without ``_mex`` (``ph_comp.c``), or with ``_step``.

    Parameters
    ----------
    compensator : Compensator or SelfSensingController
    path : str or os.PathLike
        The gateway's ``.c`` file.
    precision : {"double", "float"}

    Returns
    -------
    tuple of Path
        Gateway, step source, step header.

    Raises
    ------
    ParameterError
        A model the C export does not cover. A model with an output mode: each call's vector
        is its own preview, as Python's ``process``.
    """
    from ...io import atomic_write_text
    from .c_code import write_c

    comp = cast(Compensator, getattr(compensator, "compensator", compensator))
    controller = comp is not compensator
    gate, _, name = c_paths(path)
    step_name = name[: -len("_mex")] if name.endswith("_mex") and len(name) > 4 else f"{name}_step"
    c_path, h_path = write_c(compensator, gate.with_name(f"{step_name}.c"), precision=precision)
    kind = "self-sensing controller" if controller else "compensator"
    what = f"{name}, the {kind} of a {type(comp.model).__name__}"
    atomic_write_text(gate, _mex_gateway(name, step_name, controller, what, comp.mode.active))
    return gate, c_path, h_path
