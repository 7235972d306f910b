"""``piezohyst compensate``: the commands that make a model's actuator follow a target."""

from __future__ import annotations

import math
from pathlib import Path

import click

from ..control.compensator import CompensatorSettings
from ._support import (
    COMMAND_SCALE,
    EXISTING,
    FORCE,
    OUT_FILE,
    Context,
    _limit_options,
    _run,
    rows_progress,
)


@click.command()
@click.argument("model", type=EXISTING)
@click.argument("target", type=EXISTING)
@click.option("--column", default=None, help="Desired column (default: 'desired' or the only one).")
@_limit_options
@click.option(
    "--present-voltage",
    type=float,
    default=None,
    help="The actuator's voltage now, V (default: at rest, 0 V or the nearer limit).",
)
@click.option(
    "--no-precondition",
    is_flag=True,
    help="Skip the precondition cycle (the ramp-in from the present voltage stays).",
)
@click.option(
    "--target-unit",
    default=None,
    help="Unit of the desired column, e.g. um, nm, uC (default: its header's).",
)
@click.option(
    "--target-offset",
    type=float,
    default=0.0,
    show_default=True,
    help="Added to every desired value, in the target's unit (a target relative to another zero).",
)
@OUT_FILE
@COMMAND_SCALE
@FORCE
@click.pass_obj
def compensate(
    ctx: Context,
    model: Path,
    target: Path,
    column: str | None,
    settings: CompensatorSettings,
    present_voltage: float | None,
    no_precondition: bool,
    target_unit: str | None,
    target_offset: float,
    out: Path,
    command_scale: str | None,
    force: bool,
) -> None:
    """Feedforward voltage for the desired trajectory in TARGET; write time,command,desired.

    Safe by default: commands stay in [--v-min, --v-max], which default to the
    voltages the model was identified on (wider limits need
    --allow-extrapolation); the slew limit defaults to the training record's
    fastest change; the file starts with a ramp from the present voltage (at
    rest, 0 V, unless --present-voltage) and a precondition cycle over the
    voltages the trajectory needs (rows with an empty 'desired'); NaN targets
    hold the last command; a trajectory that saturates most samples is an
    error. TARGET needs a time column (s), or give --sample-rate.

    A coupled stage's model file (``fit --input vx,vy --output x,y``) takes one desired
    column per axis (--column x,y) and writes one command column per actuator, after a
    ramp from rest; --v-min and --v-max are then needed.

    \b
    Example:
      piezohyst compensate model.json target.csv --domain displacement \\
          --gain 125 --v-min 0 --v-max 140 -o command.csv
      piezohyst compensate stage.json raster.csv --column x,y --v-min 0 --v-max 140 \\
          -o commands.csv
    """
    from ..workflows import compensate_file
    from ..workflows.stage_files import is_stage_file

    if is_stage_file(model):
        _compensate_stage(ctx, model, target, column, settings, out, force)
        return

    with rows_progress(ctx, f"reading {target.name}", target) as progress:
        result = _run(
            ctx,
            lambda: compensate_file(
                model,
                target,
                out,
                column=column,
                settings=settings,
                precondition=not no_precondition,
                present_voltage=present_voltage,
                target_unit=target_unit,
                target_offset=target_offset,
                force=force,
                progress=progress,
                command_scale=command_scale,
            ),
        )
    comp = result.compensator
    slew = (
        f"{comp.max_step * result.sample_rate:.4g} V/s" if math.isfinite(comp.max_step) else "none"
    )
    ctx.result(
        f"commands in [{comp.v_min:g}, {comp.v_max:g}] V; of the {comp.sent_count} sent, "
        f"{comp.saturated_count} held by the voltage limits; of the {comp.command_count} on "
        f"the trajectory, {comp.slew_limited_count} by the slew limit ({slew}); "
        f"{comp.nonfinite_count} for non-finite desired values"
        + (
            f"; {comp.extrapolated_count} beyond the output map's calibrated range (the map "
            "extended linearly there)"
            if comp.output_map is not None
            else ""
        )
    )
    if result.preamble:
        ctx.info(
            f"{result.preamble} samples ({result.preamble / result.sample_rate:.3g} s) of "
            "ramp-in and preconditioning come first"
        )
    if command_scale is not None:
        ctx.info(f"written in the DAQ's volts: the piezo's divided by {command_scale}")
    ctx.info(f"saved {out}")


def _compensate_stage(
    ctx: Context, model: Path, target: Path, column: str | None,
    settings: CompensatorSettings, out: Path, force: bool,
) -> None:  # fmt: skip
    """``compensate stage.json target.csv --column x,y``: :func:`compensate_stage_file`."""
    from ..workflows.stage_files import compensate_stage_file, stage_columns

    if settings.v_min is None or settings.v_max is None:
        raise click.UsageError("a stage's commands need --v-min and --v-max (V, every actuator)")
    run = _run(
        ctx,
        lambda: compensate_stage_file(
            model, target, out, columns=stage_columns(column, "--column"),
            v_min=settings.v_min, v_max=settings.v_max,  # type: ignore[arg-type]
            sample_rate=settings.sample_rate, slew_rate=settings.slew_rate,
            allow_extrapolation=settings.allow_extrapolation, force=force,
        ),
    )  # fmt: skip
    comp = run.compensator
    assert comp is not None
    per = "; ".join(
        f"actuator {k}: {int(comp.saturated_count[k])} at a voltage limit, "
        f"{int(comp.slew_limited_count[k])} slew-limited"
        for k in range(comp.last_command.size)
    )
    ctx.result(
        f"{run.samples} rows ({run.preamble} of ramp-in first); {per}; "
        f"{comp.outside_count} desired positions outside the stage's reach"
    )
    ctx.info(f"saved {out}")
