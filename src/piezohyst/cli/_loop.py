"""``piezohyst simulate-loop``: a controller run on a simulated actuator."""

from __future__ import annotations

import math
from pathlib import Path

import click

from ..control.compensator import CompensatorSettings
from ..control.selfsensing import LoopSettings
from ._support import (
    EXISTING,
    FORCE,
    OUT_FILE,
    Context,
    _limit_options,
    _loop_options,
    _run,
)


@click.command("simulate-loop")
@click.argument("model", type=EXISTING)
@click.argument("target", type=EXISTING)
@click.option("--column", default=None, help="Desired column (default: 'desired' or the only one).")
@_limit_options
@_loop_options
@click.option("--feedforward", is_flag=True, help="Run the feedforward compensator alone.")
@click.option("--preset", default="T226-H4-203X", show_default=True, help="Bench preset.")
@click.option(
    "--extra-bias",
    type=float,
    default=0.0,
    show_default=True,
    help="Bias current in A added to the bench's (a change the model never saw).",
)
@click.option(
    "--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True, help="Noise seed."
)
@click.option(
    "--plant",
    type=EXISTING,
    default=None,
    help="A model file standing in for your actuator (your own fitted model): the loop runs "
    "on it instead of the built-in bench, another actuator (--preset, --extra-bias, --seed "
    "are the bench's).",
)
@click.option(
    "--models",
    default=None,
    help="With a stage map (calibrate-stage) as MODEL: each actuator's model file, "
    "comma-separated; the loop runs on the built-in XY stage (--column x,y).",
)
@OUT_FILE
@FORCE
@click.pass_obj
def simulate_loop(
    ctx: Context,
    model: Path,
    target: Path,
    column: str | None,
    settings: CompensatorSettings,
    loop: LoopSettings,
    feedforward: bool,
    preset: str,
    extra_bias: float,
    seed: int,
    plant: Path | None,
    models: str | None,
    out: Path,
    force: bool,
) -> None:
    """Drive the simulated bench with the self-sensing controller (or feedforward alone).

    Each sample the controller gets the charge the bench read after the
    previous command; the laser reading is written for checking only. The
    bench is another actuator than yours: --plant runs your own model as the
    plant instead.

    \b
    Example:
      piezohyst simulate-loop model.json target.csv --leakage leak.json -o loop.csv
      piezohyst simulate-loop model.json target.csv --feedforward --plant model.json -o ff.csv
    """
    from ..workflows import simulate_loop_file
    from ..workflows.stage_loop_files import is_stage_map_file

    if is_stage_map_file(model):
        _simulate_stage(ctx, model, target, column, settings, loop, feedforward, seed, models,
                        out, force, other=plant is not None or extra_bias != 0.0)  # fmt: skip
        return

    run = _run(
        ctx,
        lambda: simulate_loop_file(
            model,
            target,
            out,
            column=column,
            settings=settings,
            loop=None if feedforward else loop,
            preset=preset,
            extra_bias=extra_bias,
            seed=seed,
            force=force,
            plant=plant,
        ),
    )
    ctx.info(f"simulated actuator: {run.plant}")
    what = "feedforward" if feedforward else "closed loop"
    line = f"{what}: width desired->displacement {100 * run.width:.3g} %"
    if math.isfinite(run.nrmse):
        line += f", tracking NRMSE {100 * run.nrmse:.3g} %"
    if run.arrived:
        line += (
            f" (the first {run.arrived} samples, the ramp from rest at the slew limit, left out)"
        )
    ctx.result(f"{line}; {run.saturated} samples saturated")
    ctx.info(f"saved {out}")


def _simulate_stage(
    ctx: Context, model: Path, target: Path, column: str | None, settings: CompensatorSettings,
    loop: LoopSettings, feedforward: bool, seed: int, models: str | None, out: Path,
    force: bool, *, other: bool,
) -> None:  # fmt: skip
    """``simulate-loop STAGE_MAP target.csv --models ax.json,ay.json --column x,y``."""
    from ..workflows.stage_files import stage_columns
    from ..workflows.stage_loop_files import simulate_stage_loop_file
    from ._support import stage_loop_settings

    if models is None or column is None or other:
        raise click.UsageError(
            f"{model} is a stage map: give each actuator's model file (--models ax.json,ay.json)"
            " and the target's axis columns (--column x,y); it runs on the built-in XY stage "
            "(--plant and --extra-bias are one actuator's)"
        )
    run = _run(ctx, lambda: simulate_stage_loop_file(
        model, target, out, models=[Path(p) for p in stage_columns(models, "--models")],
        columns=stage_columns(column, "--column"), feedforward=feedforward,
        settings=stage_loop_settings(settings, loop), seed=seed, force=force))  # fmt: skip
    ctx.info(f"simulated stage: {run.stage}: another stage than yours")
    what = "feedforward" if feedforward else "charge loops"
    axes = stage_columns(column, "--column")
    said = ", ".join(
        f"{c} NRMSE {100 * e:.3g} %"
        + (f" width {100 * w:.3g} %" if w == w else f" (held: moved {100 * d:.3g} %)")
        for c, e, w, d in zip(axes, run.nrmse, run.width, run.moved, strict=True)
    )
    counts = run.loop.saturated_count.tolist()
    ctx.result(f"{what}: {said}; at a voltage limit per actuator {counts}")
    ctx.info(f"saved {out}")
