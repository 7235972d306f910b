"""The calibration commands: ``calibrate-leakage`` (holds), ``calibrate-gain`` (a
displacement sensor, once) and ``calibrate-stage`` (a stage's sensors, once)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from ..io import DataSpec
from ..model.calibrations.leakage import LEAKAGE_TERMS
from ._support import EXISTING, FORCE, OUT_FILE_JSON, Context, _data_options, _run


def _settle(value: str) -> float | str:
    """--settle: "auto" or a fraction in [0, 1)."""
    if value == "auto":
        return value
    try:
        fraction = float(value)
    except ValueError:
        fraction = -1.0
    if not 0.0 <= fraction < 1.0:
        msg = f"expected auto or a fraction in [0, 1), got {value!r}"
        raise click.BadParameter(msg, param_hint="--settle")
    return fraction


@click.command("calibrate-leakage")
@click.argument("data", type=EXISTING)
@_data_options
@click.option(
    "--terms",
    default=",".join(LEAKAGE_TERMS),
    show_default=True,
    help="Leakage terms to fit, separated by commas.",
)
@click.option(
    "--min-hold",
    type=click.FloatRange(0.0, min_open=True),
    default=1.0,
    show_default=True,
    help="Shortest hold used, in s (after settling).",
)
@click.option(
    "--settle",
    default="auto",
    show_default=True,
    callback=lambda _c, _p, value: _settle(value),
    help="Fraction of each hold skipped at its start, or auto: per hold, until its slope "
    "agrees with its end (a hold still settling is then named).",
)
@OUT_FILE_JSON
@FORCE
@click.pass_obj
def calibrate_leakage(
    ctx: Context,
    data: Path,
    data_spec: DataSpec,
    terms: str,
    min_hold: float,
    settle: float | str,
    out: Path,
    force: bool,
) -> None:
    """Calibrate the leakage current from the constant-voltage holds of a record.

    While the voltage is held the hysteresis is still: the charge's slope on
    each hold is the leakage current there. Record holds of several seconds
    at several levels, up and down again (e.g. 0, 35, 70, 105, 140, 105, 70,
    35, 0 V, 10 s each).

    \b
    Example:
      piezohyst calibrate-leakage holds.csv -o leak.json
    """
    from ..workflows import calibrate_leakage_file

    names = tuple(t.strip() for t in terms.split(",") if t.strip())
    leak = _run(
        ctx,
        lambda: calibrate_leakage_file(
            data,
            out,
            data_spec=data_spec,
            terms=names,
            min_duration=min_hold,
            settle=settle,
            force=force,
        ),
    )
    errors = leak.stderr()
    for name, (value, unit) in leak.coefficients().items():
        sure = f" ± {errors[name]:.2g}" if errors.get(name) else ""
        ctx.result(f"{name:12s} {value:.4g}{sure} {unit}")
    ctx.result(
        f"from {len(leak.holds)} holds at "
        f"{', '.join(f'{h.voltage:.4g}' for h in leak.holds)} {leak.input_unit}; "
        f"RMS misfit {leak.residual:.3g} {leak.output_unit}/s"
    )
    ctx.info(f"saved {out}")


def _mode_option(between: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``--output-dynamics``: a mode between ``between`` (calibrate_gain's argument)."""
    return click.option(
        "--output-dynamics",
        type=click.Choice(["auto", "none", "second-order"]),
        default="auto",
        show_default=True,
        help=f"A mechanical mode between {between}: auto keeps one where the record shows it, "
        "on evidence.",
    )


@click.command("calibrate-gain")
@click.argument("model", type=EXISTING)
@click.argument("data", type=EXISTING)
@_data_options
@click.option(
    "--displacement-column",
    default="displacement",
    show_default=True,
    help="The displacement sensor's column.",
)
@click.option(
    "--displacement-unit",
    default=None,
    help="Its unit if the header does not say (m, um, nm); converted to m.",
)
@click.option(
    "--displacement-scale",
    default=None,
    help="What one unit of it is worth, for a sensor logged in V: '10 um/V'.",
)
@_mode_option("the charge and the displacement (the sensor rings, the charge does not)")
@OUT_FILE_JSON
@FORCE
@click.pass_obj
def calibrate_gain(
    ctx: Context,
    model: Path,
    data: Path,
    data_spec: DataSpec,
    displacement_column: str,
    displacement_unit: str | None,
    displacement_scale: str | None,
    output_dynamics: str,
    out: Path,
    force: bool,
) -> None:
    """Calibrate the map from the capacitor's charge to the displacement, once, from a
    record with a displacement sensor (eq. 6-7: S = g D).

    DATA holds voltage, charge and displacement sampled together; MODEL was
    fitted on voltage -> charge (its growth is removed from the charge). The
    map is linear (g, in m/C, with its standard error) unless the record's
    evidence asks for curvature; a sensor delay and offset are found too, and
    a mechanical mode where the sensor rings (a bender's first bending mode):
    the self-sensing loop then inverts it from the desired trajectory.
    Then compensate in metres with the sensor unplugged: --gain gain.json.

    \b
    Example:
      piezohyst calibrate-gain model.json sensor.csv --displacement-column position -o gain.json
    """
    from ..workflows import calibrate_gain_file

    om = _run(
        ctx,
        lambda: calibrate_gain_file(
            model,
            data,
            out,
            displacement_column=displacement_column,
            displacement_unit=displacement_unit,
            displacement_scale=displacement_scale,
            data_spec=data_spec,
            force=force,
            output_dynamics=output_dynamics,
        ),
    )
    ctx.result(om.summary())
    s_lo, s_hi = om.displacement_range()
    ctx.result(
        f"holds for displacements [{s_lo:.4g}, {s_hi:.4g}] {om.output_unit}; "
        f"{om.n_samples} samples (worth {om.n_effective} independent ones)"
    )
    ctx.info(f"saved {out}")


@click.command("calibrate-stage")
@click.argument("data", type=EXISTING)
@_data_options
@click.option(
    "--models",
    required=True,
    help="Each actuator's model file (fitted on its own voltage -> charge), comma-separated.",
)
@click.option(
    "--charge",
    "charge_columns",
    required=True,
    help="Each actuator's charge column, comma-separated, in the models' order.",
)
@_mode_option("each actuator's charge and what it moves (the stage rings, the charges do not)")
@OUT_FILE_JSON
@FORCE
@click.pass_obj
def calibrate_stage(
    ctx: Context,
    data: Path,
    data_spec: DataSpec,
    models: str,
    charge_columns: str,
    output_dynamics: str,
    out: Path,
    force: bool,
) -> None:
    """Calibrate a stage's positions from its actuators' charges, once, from a record with
    the stage's sensors: each actuator's charge to what it moves, then the coupling.

    DATA holds each actuator's voltage (--input vx,vy) and charge (--charge qx,qy) and each
    axis's position (--output x,y, actuator i's own axis i-th), sampled together. Then the
    stage runs on its charges alone, its sensors unplugged: export-c STAGE_MAP --models ...
    writes each actuator's self-sensing loop behind the coupling's inverse.

    \b
    Example:
      piezohyst calibrate-stage stage.csv --models ax.json,ay.json --input vx,vy \\
          --charge qx,qy --output x,y -o stage-map.json
    """
    from ..workflows.stage_files import stage_columns
    from ..workflows.stage_loop_files import calibrate_stage_file

    stage = _run(
        ctx,
        lambda: calibrate_stage_file(
            data,
            out,
            models=[Path(p) for p in stage_columns(models, "--models")],
            inputs=stage_columns(data_spec.input_column, "--input"),
            charges=stage_columns(charge_columns, "--charge"),
            outputs=stage_columns(data_spec.output_column, "--output"),
            data_spec=data_spec,
            force=force,
            output_dynamics=output_dynamics,
        ),
    )
    ctx.result(stage.describe())
    ctx.info(f"saved {out}")
