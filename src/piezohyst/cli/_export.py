"""The export commands: ``export-c`` (C99 sources, a shared library, a MEX gateway) and
``export-fmu`` (an FMI 2.0 Co-Simulation FMU)."""

from __future__ import annotations

from pathlib import Path

import click

from ..control.compensator import CompensatorSettings
from ..control.selfsensing import LoopSettings
from ._support import EXISTING, FORCE, Context, _limit_options, _loop_options, _run, _suffix


@click.command("export-c")
@click.argument("model", type=EXISTING)
@_limit_options
@click.option(
    "--float", "use_float", is_flag=True, help="float arithmetic (MCUs without a double FPU)."
)
@click.option(
    "-o",
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=Path("ph_comp.c"),
    show_default=True,
    callback=_suffix(".c", what="the compensator is C source"),
    help="C file (the .h goes beside it).",
)
@click.option(
    "--controller",
    is_flag=True,
    help="Export the self-sensing controller (charge feedback; needs --sample-rate).",
)
@click.option(
    "--shared",
    is_flag=True,
    help="Also build libNAME.so with the system C compiler: NAME_new/free/reset/process/"
    "version, for LabVIEW, MATLAB loadlibrary, ctypes (docs/realtime.md).",
)
@click.option(
    "--mex",
    is_flag=True,
    help="OUT is a MEX gateway (NAME_mex.c) for MATLAB's mex and Octave's mkoctfile --mex: "
    "v = NAME_mex(target), NAME_mex('reset').",
)
@_loop_options
@FORCE
@click.pass_obj
def export_c(
    ctx: Context,
    model: Path,
    settings: CompensatorSettings,
    use_float: bool,
    out: Path,
    controller: bool,
    shared: bool,
    mex: bool,
    loop: LoopSettings,
    force: bool,
) -> None:
    """Write a dependency-free C99 compensator (NAME.c and NAME.h) for a microcontroller.

    With --controller, the self-sensing controller: NAME_step(s, desired,
    measured) takes the charge read at each sample as well.

    \b
    Examples:
      piezohyst export-c model.json --v-min 0 --v-max 140 -o ph_comp.c
      piezohyst export-c model.json --controller --leakage leak.json \\
          --sample-rate 1000 -o ph_loop.c
    """
    from ..workflows import export_c_file

    paths = _run(
        ctx,
        lambda: export_c_file(
            model,
            out,
            settings=settings,
            precision="float" if use_float else "double",
            controller=loop if controller else None,
            force=force,
            shared=shared,
            mex=mex,
        ),
    )
    ctx.result("\n".join(str(p) for p in paths))


@click.command("export-fmu")
@click.argument("model", type=EXISTING)
@_limit_options
@click.option(
    "--float", "use_float", is_flag=True, help="float arithmetic in the step (doubles outside)."
)
@click.option(
    "-o",
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=Path("ph_comp.fmu"),
    show_default=True,
    callback=_suffix(".fmu", what="the compensator is an FMU"),
    help="FMU file; its name is the model's identifier (a C identifier).",
)
@click.option(
    "--controller",
    is_flag=True,
    help="The self-sensing controller: a second input, the measured charge.",
)
@_loop_options
@FORCE
@click.pass_obj
def export_fmu(
    ctx: Context,
    model: Path,
    settings: CompensatorSettings,
    use_float: bool,
    out: Path,
    controller: bool,
    loop: LoopSettings,
    force: bool,
) -> None:
    """Write an FMI 2.0 Co-Simulation FMU of the compensator, for Simulink's FMU Import
    block, dSPACE VEOS/SCALEXIO, OpenModelica or FMPy.

    Input target, output voltage (with --controller a second input, charge); one
    fmi2DoStep of 1/--sample-rate is one compensator step (another step size is an FMI
    error). Built for this machine with the system C compiler; sources/ inside the FMU
    build it for another.

    \b
    Example:
      piezohyst export-fmu model.json --v-min 0 --v-max 140 --sample-rate 1000 -o ph_comp.fmu
    """
    from ..workflows import export_fmu_file

    path = _run(
        ctx,
        lambda: export_fmu_file(
            model,
            out,
            settings=settings,
            precision="float" if use_float else "double",
            controller=loop if controller else None,
            force=force,
        ),
    )
    ctx.result(str(path))
