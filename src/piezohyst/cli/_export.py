"""The export commands: ``export-c`` (C99 sources, a shared library, a MEX gateway) and
``export-fmu`` (an FMI 2.0 Co-Simulation FMU)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import click

from ..control.compensator import CompensatorSettings
from ..control.selfsensing import LoopSettings
from ._support import EXISTING, FORCE, Context, _limit_options, _loop_options, _run, _suffix

#: Each export's words, by its file's suffix: what the file is, then the help of --float,
#: -o/--out and --controller
_WORDS = {
    ".c": ("the compensator is C source", "float arithmetic (MCUs without a double FPU).",
           "C file (the .h goes beside it).",
           "Export the self-sensing controller (charge feedback; needs --sample-rate)."),
    ".fmu": ("the compensator is an FMU", "float arithmetic in the step (doubles outside).",
             "FMU file; its name is the model's identifier (a C identifier).",
             "The self-sensing controller: a second input, the measured charge."),
}  # fmt: skip


def _export_options(suffix: str) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """The options both exports share: the model, its limits, float, the file, the
    controller and its loop, --force (the file's suffix and the words as each export says
    them, ``_WORDS``); the context object passed."""
    what, float_help, out_help, controller_help = _WORDS[suffix]

    def wrap(f: Callable[..., None]) -> Callable[..., None]:
        for option in reversed(
            (
                click.argument("model", type=EXISTING),
                _limit_options,
                click.option("--float", "use_float", is_flag=True, help=float_help),
                click.option(
                    "-o",
                    "--out",
                    type=click.Path(dir_okay=False, path_type=Path),
                    default=Path(f"ph_comp{suffix}"),
                    show_default=True,
                    callback=_suffix(suffix, what=what),
                    help=out_help,
                ),
                click.option("--controller", is_flag=True, help=controller_help),
                click.option(
                    "--models",
                    default=None,
                    help="With a stage map (calibrate-stage) as MODEL: each actuator's model "
                    "file, comma-separated; exports the stage's self-sensing loop (--leakage: "
                    "one file per actuator, comma-separated).",
                ),
                _loop_options,
                FORCE,
                click.pass_obj,
            )
        ):
            f = option(f)
        return f

    return wrap


def _export(
    ctx: Context,
    model: Path,
    out: Path,
    settings: CompensatorSettings,
    use_float: bool,
    controller: LoopSettings | None,
    loop: LoopSettings,
    **build: Any,
) -> tuple[Path, ...]:
    from ..workflows import export_file
    from ..workflows.stage_files import export_stage_file, is_stage_file
    from ..workflows.stage_loop_files import is_stage_map_file

    precision: Literal["float", "double"] = "float" if use_float else "double"
    models = build.pop("models", None)
    if is_stage_map_file(model):  # a stage on its charges: each actuator's loop
        return _export_stage_loop(ctx, model, out, settings, precision, loop, models, **build)
    if models is not None:
        raise click.UsageError(
            f"--models goes with a stage map (calibrate-stage); {model} is not one"
        )
    if is_stage_file(model):  # a coupled stage: its C, the coupling's inverse around each step
        flags = ["--controller"] if controller is not None else []
        if flags or settings.v_min is None or settings.v_max is None:
            said = (
                "--controller: a stage's loop runs on its actuators' charges (calibrate-stage, "
                "then export-c STAGE_MAP --models ...)"
                if flags
                else "the limits are needed"
            )
            raise click.UsageError(
                "a stage's model file exports (C, --shared, --mex, export-fmu) with --v-min and "
                f"--v-max (V, every actuator); {said}"
            )
        return tuple(_run(ctx, lambda: export_stage_file(
            model, out, v_min=settings.v_min, v_max=settings.v_max,  # type: ignore[arg-type]
            sample_rate=settings.sample_rate, slew_rate=settings.slew_rate,
            allow_extrapolation=settings.allow_extrapolation, precision=precision,
            shared=bool(build.get("shared")), mex=bool(build.get("mex")),
            force=bool(build.get("force")))))  # fmt: skip
    paths: tuple[Path, ...] = _run(
        ctx,
        lambda: export_file(
            model, out, settings=settings, precision=precision, controller=controller, **build
        ),
    )
    return paths


def _export_stage_loop(
    ctx: Context,
    model: Path,
    out: Path,
    settings: CompensatorSettings,
    precision: str,
    loop: LoopSettings,
    models: str | None,
    **build: Any,
) -> tuple[Path, ...]:
    """``export-c STAGE_MAP --models ax.json,ay.json``: the stage's self-sensing loop."""
    from ..workflows.stage_files import stage_columns
    from ..workflows.stage_loop_files import export_stage_loop_file
    from ._support import stage_loop_settings

    if models is None:
        raise click.UsageError(
            f"{model} is a stage map: give each actuator's model file with --models "
            "ax.json,ay.json (the ones calibrate-stage used)"
        )
    if settings.domain != "charge" or settings.gain is not None or loop.refresh_leakage:
        raise click.UsageError(
            "a stage map's loop takes its targets in the map's units (positions): --domain, "
            "--gain and --refresh-leakage are not for a stage"
        )
    return tuple(_run(ctx, lambda: export_stage_loop_file(
        model, out, models=[Path(p) for p in stage_columns(models, "--models")],
        sample_rate=settings.sample_rate, settings=stage_loop_settings(settings, loop),
        precision=precision, shared=bool(build.get("shared")), mex=bool(build.get("mex")),
        force=bool(build.get("force")))))  # fmt: skip


@click.command("export-c")
@_export_options(".c")
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
def export_c(
    ctx: Context,
    model: Path,
    out: Path,
    shared: bool,
    mex: bool,
    settings: CompensatorSettings,
    use_float: bool,
    controller: bool,
    models: str | None,
    loop: LoopSettings,
    force: bool,
) -> None:
    """Write a dependency-free C99 compensator (NAME.c and NAME.h) for a microcontroller.

    With --controller, the self-sensing controller: NAME_step(s, desired,
    measured) takes the charge read at each sample as well. MODEL a stage's model file:
    the coupled compensator; a stage map (calibrate-stage) with --models: the stage's
    self-sensing loop, NAME_step(s, desired, measured, command).

    \b
    Examples:
      piezohyst export-c model.json --v-min 0 --v-max 140 -o ph_comp.c
      piezohyst export-c model.json --controller --leakage leak.json \\
          --sample-rate 1000 -o ph_loop.c
      piezohyst export-c stage-map.json --models ax.json,ay.json --sample-rate 1000 -o ph_xy.c
    """
    paths = _export(ctx, model, out, settings, use_float, loop if controller else None, loop,
                    force=force, shared=shared, mex=mex, models=models)  # fmt: skip
    ctx.result("\n".join(str(p) for p in paths))


@click.command("export-fmu")
@_export_options(".fmu")
def export_fmu(
    ctx: Context,
    model: Path,
    settings: CompensatorSettings,
    use_float: bool,
    out: Path,
    controller: bool,
    models: str | None,
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
    paths = _export(ctx, model, out, settings, use_float, loop if controller else None, loop,
                    force=force, models=models)  # fmt: skip
    ctx.result(str(paths[0]))
