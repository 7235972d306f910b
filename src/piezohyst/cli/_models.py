"""``piezohyst fit``, ``compare``, ``predict`` and ``fit-many``: models from records, and records
from models."""

from __future__ import annotations

import glob
import math
import sys
from pathlib import Path

import click

from ..io import DataSpec
from ..model.presets import model_names
from ._support import (
    EXISTING,
    FORCE,
    OUT_FILE,
    OUT_FILE_JSON,
    Context,
    _data_options,
    _fit_auto,
    _model_options,
    _run,
    _suffix,
    describe,
    initial_state_option,
    input_dynamics_option,
    operators_option,
    out_file,
    parse_terms,
    progress_steps,
    rows_progress,
    terms_options,
    working,
)


@click.command()
@click.argument("data", type=EXISTING)
@_model_options(
    "Model to identify (auto: each scored inside the record, the best kept; structure: "
    "several --input and --output columns, the structure's coupled dynamics with each "
    "actuator's hysteresis in the loop).",
    auto=True,
    structure=True,
)
@terms_options
@click.option(
    "--relaxation",
    type=float,
    default=None,
    help="preisach: time constant in s of a relaxing part of the hysteresis (a second Preisach "
    "density on the lagged voltage), e.g. 0.1.",
)
@input_dynamics_option(
    "Delay/lag between the logged command and the piezo, identified with the model "
    "(record several drive frequencies); record: identified when the record drives several "
    "rates, else none.",
    default="record",
)
@click.option(
    "--output-dynamics",
    type=click.Choice(["none", "second-order"]),
    default="none",
    show_default=True,
    help="A mechanical mode between the hysteresis and a displacement output "
    "(record up to near the resonance).",
)
@initial_state_option(
    ["rest", "periodic"],
    "periodic: the record is one period of a drive that was already running (it "
    "starts mid-cycle); the operators start in the periodic steady state.",
)
@click.option("--scan-frequency", type=click.FloatRange(min=0.0, min_open=True), default=None,
              help="With input dynamics: their gain and phase at this frequency (Hz), with the "
              "loop width their uncertainty allows.")  # fmt: skip
@_data_options
@OUT_FILE_JSON
@FORCE
@click.pass_obj
def fit(
    ctx: Context,
    data: Path,
    model_name: str,
    operators: int,
    growth: str,
    creep: str,
    relaxation: float | None,
    input_dynamics: str,
    output_dynamics: str,
    initial_state: str,
    scan_frequency: float | None,
    data_spec: DataSpec,
    out: Path,
    force: bool,
) -> None:
    """Identify a model from DATA and save it as JSON.

    \b
    Example:
      piezohyst fit run.csv --model active-pi --operators 20 -o model.json
      piezohyst fit scan.tdms --group Scan --input Ch0 --output Ch1 -o m.json
      piezohyst fit run.csv --model generalized-pi --creep 0.1,1,10 -o g.json
      piezohyst fit run.csv --model preisach --relaxation 0.1 -o p.json
    """
    from ..workflows import fit_file

    if model_name == "structure":
        chosen = click.get_current_context().get_parameter_source("operators")
        loop = None if chosen is click.core.ParameterSource.DEFAULT else operators  # its own
        _fit_structure(ctx, data, loop, initial_state, data_spec, out, force)
        return
    if "," in (data_spec.input_column or "") + (data_spec.output_column or ""):
        given = {"--growth": growth != "default", "--creep": bool(creep),
                 "--relaxation": relaxation is not None,
                 "--model auto": model_name == "auto"}  # fmt: skip
        named = [option for option, set_ in given.items() if set_]
        if named:
            raise click.UsageError(
                f"{', '.join(named)}: a stage (several --input and --output columns) fits "
                "each actuator's model with its defaults (and the lag and mode you name: "
                "--input-dynamics, --output-dynamics) and the coupling; name one model "
                "(--model classical-pi), or choose each actuator's with piezohyst select on "
                "its own columns"
            )
        # a stage's actuators default to the CoupledModel's own (ClassicalPI): the default
        # ActivePI keeps creep operators on a displacement record, and its numeric inverse
        # tracked a 2 Hz raster to 1.23 % where ClassicalPI's analytic one gave 0.78 %
        chosen = click.get_current_context().get_parameter_source("model_name")
        if chosen is click.core.ParameterSource.DEFAULT:
            model_name = "classical-pi"
        # a stage's lag is identified where named (--input-dynamics record is one
        # actuator's evidence rule, not yet a stage's)
        dynamics = ("none" if input_dynamics == "record" else input_dynamics, output_dynamics)
        _fit_stage(ctx, data, model_name, operators, dynamics, data_spec, out, force)
        return
    terms, taus = parse_terms(growth, creep)
    if model_name == "auto":
        given = {"--growth": growth not in ("default", "auto"), "--creep": bool(taus),
                 "--relaxation": relaxation is not None,
                 "--output-dynamics": output_dynamics != "none"}  # fmt: skip
        named = [option for option, set_ in given.items() if set_]
        if named:  # each candidate takes its defaults: a setting of one model is not theirs
            raise click.UsageError(
                f"{', '.join(named)} set one model's terms: with --model auto each candidate "
                "takes its defaults (creep variants among them; --growth auto lets each choose "
                "its growth terms by evidence); name the model to set them, or compare the "
                "candidates with them (piezohyst compare)"
            )
        model = _fit_auto(ctx, data, operators, initial_state, input_dynamics, data_spec, out,
                          force, growth)  # fmt: skip
        if scan_frequency is not None and model.input_dynamics_.active:
            ctx.result(f"input dynamics {model.input_dynamics_.response_interval(scan_frequency)}")
        return
    from ..io import estimated_rows
    from ..workflows.model_files import KEEP_ROWS

    # a window of up to KEEP_ROWS rows is read once and kept; a longer one streams 3 passes
    passes = 1 if (estimated_rows(data) or 0) <= KEEP_ROWS else 3
    label = f"fitting {model_name} to {data.name}"
    notes: list[str] = []
    with rows_progress(ctx, label, data, passes) as progress:
        model = _run(
            ctx,
            lambda: fit_file(
                data,
                out,
                model=model_name,
                operators=operators,
                data_spec=data_spec,
                growth_terms=terms,
                creep=taus,
                relaxation=relaxation,
                input_dynamics=input_dynamics,
                output_dynamics=output_dynamics,
                initial_state=initial_state,
                force=force,
                progress=progress,
                say=notes.append,
            ),
        )
    ctx.result(describe(model))
    for note in notes:  # what --input-dynamics record decided, after the result
        ctx.info(note)
    if scan_frequency is not None and model.input_dynamics_.active:
        ctx.result(f"input dynamics {model.input_dynamics_.response_interval(scan_frequency)}")
    if ctx.verbose:
        for label, text in model.operator_.describe(model.input_unit, model.output_unit)[1:]:
            ctx.result(f"{label} {text}")
    ctx.info(f"saved {out}")


def _fit_structure(
    ctx: Context, data: Path, operators: int | None, initial_state: str, data_spec: DataSpec,
    out: Path, force: bool,
) -> None:  # fmt: skip
    """``fit --model structure --input vx,vy --output x,y``: :func:`fit_structure_file`."""
    from ..workflows.stage_files import fit_structure_file, stage_columns

    structure = _run(
        ctx,
        lambda: fit_structure_file(
            data, out,
            inputs=stage_columns(data_spec.input_column, "--input"),
            outputs=stage_columns(data_spec.output_column, "--output"),
            operators=operators, initial_state=initial_state, data_spec=data_spec,
            force=force,
        ),
    )  # fmt: skip
    ctx.result(structure.describe())
    ctx.info(f"saved {out}")


def _fit_stage(
    ctx: Context, data: Path, model_name: str, operators: int, dynamics: tuple[str, str],
    data_spec: DataSpec, out: Path, force: bool,
) -> None:  # fmt: skip
    """``fit --input vx,vy --output x,y``: a coupled stage (:func:`fit_stage_file`)."""
    from ..workflows.stage_files import fit_stage_file, stage_columns

    stage = _run(
        ctx,
        lambda: fit_stage_file(
            data, out,
            inputs=stage_columns(data_spec.input_column, "--input"),
            outputs=stage_columns(data_spec.output_column, "--output"),
            model=model_name, operators=operators, data_spec=data_spec, force=force,
            input_dynamics=dynamics[0], output_dynamics=dynamics[1],
        ),
    )  # fmt: skip
    ctx.result(stage.describe())
    ctx.info(f"saved {out}")


@click.command()
@click.argument("data", type=EXISTING)
@click.option(
    "--models",
    default=",".join([*model_names(), "generalized-pi+creep", "bouc-wen+creep"]),
    show_default=True,
    help="Models to compare, a comma list of " + ", ".join(model_names()) + "; a name+creep "
    "adds creep operators timed by the record (Kuhnen's modified PI: generalized-pi+creep).",
)
@operators_option(help="Play operators, for the models that have them.")
@click.option(
    "--train",
    type=click.FloatRange(0, 1, min_open=True, max_open=True),
    default=0.7,
    show_default=True,
    help="Training fraction of DATA; the rest (later in time) is held out.",
)
@click.option(
    "--test",
    "test_data",
    type=EXISTING,
    default=None,
    help="A separate held-out record (same columns); DATA then trains whole.",
)
@input_dynamics_option(
    "Delay/lag between the logged command and the piezo, identified with each model."
)
@initial_state_option(
    ["rest", "periodic"],
    "Where the training part starts (periodic: one period of a running drive).",
)
@_data_options
@out_file(
    "Also write the table: .md (Markdown), .csv or .parquet (with fit times).", required=False
)
@FORCE
@click.pass_obj
def compare(
    ctx: Context,
    data: Path,
    models: str,
    operators: int,
    train: float,
    test_data: Path | None,
    input_dynamics: str,
    initial_state: str,
    data_spec: DataSpec,
    out: Path | None,
    force: bool,
) -> None:
    """Fit several models on DATA and score each on data it never saw.

    Prints a table, best held-out NRMSE first, with what each model absorbed
    besides hysteresis (growth terms, creep, input lag).

    \b
    Example:
      piezohyst compare run.csv
      piezohyst compare run.csv --models active-pi,preisach --train 0.5 -o cmp.md
      piezohyst compare run.csv --test run2.csv --input-dynamics auto
    """
    from ..workflows import compare_file

    names = [m.strip() for m in models.split(",") if m.strip()]
    with working(ctx, f"fitting {len(names)} models on {data.name}, scoring each held out"):
        result = _run(
            ctx,
            lambda: compare_file(
                data,
                out,
                models=names,
                train=train,
                test_data=test_data,
                data_spec=data_spec,
                operators=operators,
                input_dynamics=input_dynamics,
                initial_state=initial_state,
                force=force,
            ),
        )
    a, b = result.train
    c, d = result.test
    held = f"{test_data.name if test_data else data.name} samples {c}-{d}"
    ctx.result(f"trained on {data.name} samples {a}-{b}, held out: {held}")
    if a > 0 and initial_state == "rest":
        ctx.info(f"the training part starts from the state the input before sample {a} left")
    ctx.result(result.table())
    if out is not None:
        ctx.info(f"saved {out}")


@click.command()
@click.argument("model", type=EXISTING)
@click.argument("data", type=EXISTING)
@initial_state_option(
    ["model", "rest", "periodic"],
    "Where the model starts: its training record's start, at rest, or (DATA is one "
    "period of a drive already running) the periodic steady state.",
)
@_data_options
@OUT_FILE
@FORCE
@click.pass_obj
def predict(
    ctx: Context,
    model: Path,
    data: Path,
    initial_state: str,
    data_spec: DataSpec,
    out: Path,
    force: bool,
) -> None:
    """Predict the output of MODEL for the input in DATA; write time,predicted[,measured].

    \b
    Example:
      piezohyst predict model.json run2.csv -o pred.csv
      piezohyst predict stage.json run2.csv --input vx,vy --output x,y -o pred.csv
    """
    from ..workflows import Prediction, predict_file
    from ..workflows.stage_files import is_stage_file

    if is_stage_file(model):
        _predict_stage(ctx, model, data, data_spec, out, force, initial_state)
        return

    with rows_progress(ctx, f"reading {data.name}", data) as progress:
        cols: Prediction = _run(
            ctx,
            lambda: predict_file(
                model,
                data,
                out,
                data_spec=data_spec,
                initial_state=initial_state,
                force=force,
                progress=progress,
            ),
        )
    if math.isfinite(cols.rmse):
        ctx.result(
            f"NRMSE {100 * cols.nrmse:.4g} % (RMSE {cols.rmse:.4g} {cols.unit}) "
            f"over {cols.samples} samples, t = {cols.scored[0]:.6g}-{cols.scored[1]:.6g} s"
        )
    ctx.info(f"run from {cols.start}")
    ctx.info(f"saved {out}")


def _predict_stage(
    ctx: Context, model: Path, data: Path, data_spec: DataSpec, out: Path, force: bool,
    initial_state: str = "rest",
) -> None:  # fmt: skip
    """``predict stage.json --input vx,vy [--output x,y]``: :func:`predict_stage_file`."""
    from ..workflows.stage_files import predict_stage_file, stage_columns

    outputs = data_spec.output_column
    run = _run(
        ctx,
        lambda: predict_stage_file(
            model, data, out,
            inputs=stage_columns(data_spec.input_column, "--input"),
            outputs=None if outputs in (None, "charge") else stage_columns(outputs, "--output"),
            data_spec=data_spec, force=force, initial_state=initial_state,
        ),
    )  # fmt: skip
    if run.nrmse:
        per_axis = ", ".join(f"{100 * e:.4g} %" for e in run.nrmse)
        ctx.result(f"NRMSE per axis {per_axis} over {run.samples} samples")
    ctx.info(f"saved {out}")


def _expand_patterns(records: tuple[Path, ...]) -> tuple[Path, ...]:
    """RECORDS with each pattern no file is named by (``line/*.csv``, which a Windows shell
    passes on as it is) replaced by the files it matches, in order of their names."""
    out: list[Path] = []
    for record in records:
        text = str(record)
        if record.exists() or not any(ch in text for ch in "*?["):
            out.append(record)
            continue
        found = sorted(Path(m) for m in glob.glob(text))
        if not found:
            raise click.BadParameter(f"no file matches {text!r}", param_hint="RECORDS")
        out.extend(found)
    return tuple(dict.fromkeys(out))


@click.command("fit-many")
@click.argument("records", nargs=-1, required=True, type=EXISTING)
@click.option(
    "-o",
    "--out-dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for one model per unit (<unit>.json) and the summary.",
)
@_model_options("Model to identify for every unit.")
@terms_options
@input_dynamics_option(
    "Delay/lag between the logged command and the piezo, identified with each unit's model "
    "(record several drive frequencies)."
)
@click.option(
    "--channel",
    "channels",
    multiple=True,
    metavar="IN:OUT",
    help="An input:output column pair; each pair is a unit of every file (repeatable). "
    "Default: each file is one unit (--input/--output columns).",
)
@click.option(
    "--summary",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    callback=_suffix(".csv", ".parquet", what="the summary is a CSV or Parquet table"),
    help="Summary table (.csv or .parquet). Default: OUT_DIR/summary.csv.",
)
@click.option(
    "--scheduler",
    default=None,
    metavar="ADDRESS",
    help="A running dask.distributed scheduler (tcp://host:8786). Default: a local pool of "
    "processes, one per core.",
)
@click.option(
    "--workers", type=click.IntRange(1, 1024), default=None,
    help="Processes of the local pool (default: one per core).",
)  # fmt: skip
@_data_options
@FORCE
@click.pass_obj
def fit_many_cmd(
    ctx: Context,
    records: tuple[Path, ...],
    out_dir: Path,
    model_name: str,
    operators: int,
    growth: str,
    creep: str,
    input_dynamics: str,
    channels: tuple[str, ...],
    summary: Path | None,
    scheduler: str | None,
    workers: int | None,
    data_spec: DataSpec,
    force: bool,
) -> None:
    """Fit one model per unit of many RECORDS, on Dask; write a summary table.

    Each unit (a file, or an IN:OUT column pair of every file) is fitted
    alone with the same settings. A unit that cannot be fitted is a row of
    the summary with its reason and the others go on; the exit status is 1
    when any unit failed. Units far from the fleet's median (fit error,
    hysteresis width, leakage) are flagged in the 'outlier' column.

    \b
    Example:
      piezohyst fit-many line/*.csv --operators 20 -o models/
      piezohyst fit-many mirror.parquet --channel v0:q0 --channel v1:q1 -o m/
      piezohyst fit-many units/*.csv -o models/ --scheduler tcp://10.0.0.5:8786
      piezohyst fit-many line/*.csv --model generalized-pi --creep 0.1,1,10 -o m/
    """
    from ..workflows.fleet import fit_many

    terms, taus = parse_terms(growth, creep)
    records = _expand_patterns(records)
    pairs: list[tuple[str, str]] = []
    for c in channels:
        x_col, sep, y_col = c.partition(":")
        if not sep or not x_col or not y_col:
            raise click.BadParameter(f"expected IN:OUT, got {c!r}", param_hint="--channel")
        pairs.append((x_col, y_col))
    with progress_steps(ctx, len(records) * max(len(pairs), 1)) as step:
        result = _run(
            ctx,
            lambda: fit_many(
                records,
                out_dir,
                model=model_name,
                operators=operators,
                growth_terms=terms,
                creep=taus,
                input_dynamics=input_dynamics,
                data_spec=data_spec,
                channels=pairs,
                summary=summary,
                scheduler=scheduler,
                workers=workers,
                force=force,
                progress=lambda done, total: step(f"fitted {done}/{total} units"),
            ),
        )
    ok = len(result.rows) - len(result.failed)
    ctx.result(
        f"fitted {ok} of {len(result.rows)} units; {len(result.failed)} failed, "
        f"{len(result.outliers)} flagged as outliers"
    )
    for row in result.failed:
        ctx.result(f"  failed  {row['unit']}: {row['error']}")
    for row in result.outliers:
        ctx.result(f"  outlier {row['unit']}: {row['outlier']} (NRMSE {row['nrmse'] * 100:.3f} %)")
    ctx.info(
        f"saved {ok} model{'' if ok == 1 else 's'} in {out_dir} and the summary {result.summary}"
    )
    if result.failed:
        sys.exit(1)
