"""``piezohyst report``: a model scored on a record, with its figures."""

from __future__ import annotations

from pathlib import Path

import click

from ..io import DataSpec
from ..model.calibrations.output_map import OutputMap
from ._support import (
    EXISTING,
    FORCE,
    Context,
    _command_line,
    _data_options,
    _gain_option,
    _run,
    initial_state_option,
    rows_progress,
)


@click.command()
@click.argument("model", type=EXISTING)
@click.argument("data", type=EXISTING)
@_data_options
@click.option(
    "-o",
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the figures, metrics.json and report.md.",
)
@click.option(
    "--gain",
    default=None,
    callback=lambda _c, _p, value: _gain_option(value),
    help="Also the displacement predicted from the voltage, in metres: m/C, or the map "
    "calibrate-gain wrote.",
)
@click.option(
    "--displacement-column",
    default=None,
    help="A displacement sensor's column to score that displacement against (needs --gain).",
)
@click.option(
    "--displacement-unit",
    default=None,
    help="Its unit if the header does not say (m, um, nm...).",
)
@click.option(
    "--displacement-scale",
    default=None,
    help="What one unit of it is worth, for a sensor logged in V: '10 um/V'.",
)
@initial_state_option(
    ["rest", "periodic"],
    "A structure model's start (periodic: DATA is one period of a drive already running, "
    "a multisine's period); other models start as they were fitted.",
)
@FORCE
@click.pass_obj
def report(
    ctx: Context,
    model: Path,
    data: Path,
    data_spec: DataSpec,
    out: Path,
    gain: float | OutputMap | None,
    displacement_column: str | None,
    displacement_unit: str | None,
    displacement_scale: str | None,
    initial_state: str,
    force: bool,
) -> None:
    """Figures (loop, fit, residual, growth removal) and metrics of MODEL on DATA; with
    --gain, the displacement in metres too.

    A stage's model file (``fit --input vx,vy --output x,y``) or a structure's (``--model
    structure``) takes the same columns and scores each axis; a structure's report adds its
    static gain, modes and frequency response.

    \b
    Example:
      piezohyst report model.json run2.csv --out model-report
      piezohyst report stage.json run2.csv --input vx,vy --output x,y --out stage-report
      piezohyst report model.json sensor.csv --gain gain.json \\
          --displacement-column displacement --out report-m
    """
    from ..workflows import model_report
    from ..workflows.stage_files import is_stage_file, stage_columns
    from ..workflows.stage_report import stage_report

    command = _command_line()
    if is_stage_file(model):  # a coupled stage: each axis scored, the coupling said
        given = [o for o, v in (("--gain", gain), ("--displacement-column", displacement_column))
                 if v is not None]  # fmt: skip
        if given:
            raise click.UsageError(f"{', '.join(given)}: not for a stage's model file")
        outputs = _run(ctx, lambda: stage_columns(data_spec.output_column, "--output"))
        res = _run(ctx, lambda: stage_report(
            model, data, out, inputs=stage_columns(data_spec.input_column, "--input"),
            outputs=outputs, data_spec=data_spec, command=command, force=force,
            initial_state=initial_state))  # fmt: skip
        per_axis = ", ".join(f"{o} {res.metrics[f'nrmse_{o}_pct']:.4g} %" for o in outputs)
        ctx.result(f"NRMSE {per_axis}; report in {out / 'report.html'}")
        return
    if initial_state != "rest":
        raise click.UsageError(f"--initial-state {initial_state}: for a structure model's report")
    with rows_progress(ctx, f"reading {data.name}, then drawing the report", data) as progress:
        res = _run(
            ctx,
            lambda: model_report(
                model,
                data,
                out,
                data_spec=data_spec,
                command=command,
                force=force,
                progress=progress,
                gain=gain,
                displacement_column=displacement_column,
                displacement_unit=displacement_unit,
                displacement_scale=displacement_scale,
            ),
        )
    metres = res.metrics.get("displacement_nrmse_offset_free_pct")
    also = "" if metres is None else f"; displacement NRMSE {metres:.4g} % (offsets removed)"
    ctx.result(f"NRMSE {res.metrics['nrmse_pct']:.4g} %{also}; report in {out / 'report.html'}")
