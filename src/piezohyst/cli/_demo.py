"""``piezohyst demo``: the paper's experiment on the simulated bench."""

from __future__ import annotations

from pathlib import Path

import click

from ._support import (
    Context,
    _run,
    operators_option,
    progress_steps,
)


@click.command()
@click.option(
    "-o",
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("demo-report"),
    show_default=True,
    help="Folder for figures, metrics.json and report.md.",
)
@operators_option(20, "Play operators of both models.")
@click.option(
    "--seed",
    type=click.IntRange(0, 2**32 - 1),
    default=0,
    show_default=True,
    help="Seed of the bench's measurement noise.",
)
@click.pass_obj
def demo(ctx: Context, out: Path, operators: int, seed: int) -> None:
    """Run the paper's experiment on the simulated bench and write a report.

    Identifies classical and active PI models from voltage and charge, removes
    the leakage growth, inverts the hysteresis, compensates a desired
    displacement without a position sensor, and checks it on the bench.

    \b
    Example:
      piezohyst demo --out demo-report
    """
    from ..workflows.demo import run_demo

    with progress_steps(ctx, total=6) as step:
        result = _run(ctx, lambda: run_demo(out, n_operators=operators, seed=seed, step=step))
    m = result.metrics
    ctx.info(
        f"active PI NRMSE {m['identification']['active_nrmse_pct']:.3f} % "
        f"(classical {m['identification']['classical_nrmse_pct']:.2f} %), leakage error "
        f"{m['leakage']['error_pct']:+.2f} %, compensated width "
        f"{m['compensation_fixed']['width_after_S_pct']:.2f} % of span "
        f"(from {m['compensation_fixed']['width_before_V_to_S_pct']:.1f} %)"
    )
    ctx.result(str(out / "report.md"))
