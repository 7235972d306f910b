"""The ``piezohyst`` group: its options, and every command registered on it."""

from __future__ import annotations

import click

from .._version import __version__
from ._calibrate import calibrate_gain, calibrate_leakage, calibrate_stage
from ._compensate import compensate
from ._demo import demo
from ._export import export_c, export_fmu
from ._learn import learn
from ._loop import simulate_loop
from ._models import compare, fit, fit_many_cmd, predict
from ._records import excite, simulate
from ._report import report
from ._support import Context


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="piezohyst")
@click.option(
    "-q",
    "--quiet",
    is_flag=True,
    help="Print nothing but errors and warnings (a limit that held commands is always said).",
)
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


for _command in (simulate, excite, fit, compare, predict, compensate, report, fit_many_cmd,
                 simulate_loop, demo, calibrate_leakage, calibrate_gain, calibrate_stage,
                 export_c, export_fmu, learn):  # fmt: skip
    main.add_command(_command)
