"""``piezohyst export-c`` and ``export-fmu``: the compensator (or the self-sensing controller)
as C, a shared library, a MEX gateway or an FMU, by the output file.
"""

from __future__ import annotations

from pathlib import Path

from ..control.c_text import Precision
from ..control.compensator import CompensatorSettings
from ..control.export.c_code import c_paths, write_c
from ..control.export.fmu import write_fmu
from ..control.export.shared import write_mex, write_shared
from ..control.selfsensing import LoopSettings
from ..errors import ParameterError
from ._base import (
    _DEFAULT_SETTINGS,
    PathLike,
    _load,
    guard_outputs,
)

__all__ = ["export_file"]


def export_file(
    model_path: PathLike,
    out: PathLike,
    *,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precision: Precision = "double",
    controller: LoopSettings | None = None,
    force: bool = False,
    shared: bool = False,
    mex: bool = False,
) -> tuple[Path, ...]:
    """Export the model's compensator: C sources ``NAME.c`` and ``NAME.h``
    (:mod:`~.control.export`), or where ``out`` ends in ``.fmu`` an FMI 2.0
    Co-Simulation FMU (:mod:`~.control.export.fmu`).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    out : str or os.PathLike
        The ``.c`` file, or the ``.fmu``.
    settings : CompensatorSettings
        Limits, domain, gain, slew rate (and the sample rate a controller or an FMU needs:
        one step of the FMU).
    precision : {"double", "float"}
        The C type of every real (an FMU's step; doubles outside).
    controller : LoopSettings, optional
        Export the self-sensing controller instead of the feedforward compensator.
    force : bool, default False
        Replace existing files piezohyst did not write.
    shared : bool, default False
        Add the shared-library API and build ``libNAME.so`` beside the sources
        (:mod:`~piezohyst.control.export.shared`).
    mex : bool, default False
        ``out`` is a MEX gateway (``NAME_mex.c``), written with the step it includes.

    Returns
    -------
    tuple of Path
        Source and header (and the library), or the FMU.
    """
    fmu = Path(out).suffix.lower() == ".fmu"
    if shared + mex + fmu > 1:
        msg = "--shared, --mex and an FMU build different things: choose one"
        raise ParameterError(msg)
    inputs: list[PathLike] = [model_path]
    if controller is not None and controller.leakage is not None:
        inputs.append(controller.leakage)
    if fmu:
        if Path(out).exists() and not force and not _our_fmu(Path(out)):
            msg = f"{out} exists and piezohyst did not write it: pass --force to replace it"
            raise ParameterError(msg)
    else:
        c_path, h_path, _ = c_paths(out)
        guard_outputs([c_path, h_path], inputs, force=force)
    model = _load(model_path)
    built = settings.build(model) if controller is None else controller.build(settings, model)
    if fmu:
        return (write_fmu(built, out, precision=precision),)
    if shared:
        return write_shared(built, out, precision=precision)
    if mex:
        return write_mex(built, out, precision=precision)
    return write_c(built, out, precision=precision)


def _our_fmu(path: Path) -> bool:
    """An FMU piezohyst wrote (its modelDescription names the tool): safe to replace."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            return 'generationTool="piezohyst' in z.read("modelDescription.xml").decode()
    except (OSError, KeyError, zipfile.BadZipFile, UnicodeDecodeError):
        return False
