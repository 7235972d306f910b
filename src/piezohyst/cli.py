"""The ``piezohyst`` command: a thin shell over the library.

Every command is one call of a library function; errors a user can cause
print one line on stderr and exit 1 (usage errors exit 2), with the
traceback only under ``--debug``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click

from . import __version__
from .errors import PiezohystError


class Context:
    """Options shared by every command."""

    def __init__(self, quiet: bool, verbose: bool, debug: bool) -> None:
        self.quiet = quiet
        self.verbose = verbose
        self.debug = debug

    def info(self, message: str) -> None:
        if not self.quiet:
            click.echo(message, err=True)


@contextmanager
def progress_steps(ctx: Context, total: int) -> Iterator[Callable[[str], None]]:
    """A progress display: a rich bar on a terminal, plain lines when piped, none if quiet."""
    if ctx.quiet:
        yield lambda _msg: None
        return
    if not sys.stderr.isatty():
        count = [0]

        def plain(msg: str) -> None:
            count[0] += 1
            click.echo(f"[{count[0]}/{total}] {msg}", err=True)

        yield plain
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=False,
    ) as bar:
        task = bar.add_task("starting", total=total)
        started = [False]

        def rich_step(msg: str) -> None:
            if started[0]:
                bar.advance(task)
            started[0] = True
            bar.update(task, description=msg)

        yield rich_step
        bar.update(task, completed=total, description="done")


def _run(ctx: Context, fn: Callable[[], Any]) -> Any:
    """Run a command body: known errors become one line on stderr and exit 1."""
    try:
        return fn()
    except (PiezohystError, OSError) as exc:
        if ctx.debug:
            raise
        click.echo(f"error: {exc}", err=True)
        sys.exit(1)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="piezohyst")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
@click.option("-v", "--verbose", is_flag=True, help="Print more detail.")
@click.option("--debug", is_flag=True, help="Show tracebacks on errors.")
@click.pass_context
def main(click_ctx: click.Context, quiet: bool, verbose: bool, debug: bool) -> None:
    """Model and cancel hysteresis in piezoelectric actuators.

    \b
    Example:
      piezohyst demo --out demo-report
    """
    click_ctx.obj = Context(quiet=quiet, verbose=verbose, debug=debug)


@main.command()
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("demo-report"),
    show_default=True,
    help="Folder for figures, metrics.json and report.md.",
)
@click.option(
    "--operators",
    type=click.IntRange(1, 1000),
    default=20,
    show_default=True,
    help="Play operators of both models.",
)
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="Seed of the bench's measurement noise.")  # fmt: skip
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
    from .demo import run_demo

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
    click.echo(str(out / "report.md"))


if __name__ == "__main__":  # pragma: no cover
    main()
