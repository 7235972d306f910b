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
