"""The ``piezohyst`` command: a thin shell over the library.

Every command is one call of a library function; errors a user can cause
print one line on stderr and exit 1 (usage errors exit 2), with the
traceback only under ``--debug``.
"""

from __future__ import annotations

import glob
import math
import sys
from pathlib import Path

import click

from .._version import __version__
from ..control.calibration import OutputMap
from ..control.compensator import CompensatorSettings
from ..control.selfsensing import LoopSettings
from ..io import DataSpec
from ..model.models import model_names
from ..simulation.signals import SIGNALS
from ..workflows.excitation import KINDS, Excitation, excitation
from ._support import (
    COMMAND_SCALE,
    EXISTING,
    FORCE,
    OUT_FILE,
    OUT_FILE_JSON,
    Context,
    _command_line,
    _data_options,
    _fit_auto,
    _gain_option,
    _limit_options,
    _loop_options,
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


# ---------------------------------------------------------------------- commands
@main.command()
@click.option("--preset", default="T226-H4-203X", show_default=True, help="Bench preset.")
@click.option(
    "--signal",
    type=click.Choice(list(SIGNALS)),
    default="hold",
    show_default=True,
    help="Excitation.",
)
@click.option("--amplitude", type=float, default=None, help="Amplitude in V (default: preset).")
@click.option("--frequency", type=float, default=0.5, show_default=True, help="Frequency in Hz.")
@click.option("--duration", type=float, default=20.0, show_default=True, help="Length in s.")
@click.option("--rate", type=float, default=None, help="Sample rate in Hz (default: preset).")
@click.option(
    "--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True, help="Noise seed."
)
@click.option(
    "--unit",
    type=click.IntRange(0, 2**32 - 1),
    default=0,
    show_default=True,
    help="Which actuator of a production batch: its leakage, capacitance and loop differ "
    "(0: the preset).",
)
@OUT_FILE
@FORCE
@click.pass_obj
def simulate(
    ctx: Context,
    preset: str,
    signal: str,
    amplitude: float | None,
    frequency: float,
    duration: float,
    rate: float | None,
    seed: int,
    unit: int,
    out: Path,
    force: bool,
) -> None:
    """Run the simulated bench; write time,voltage,charge,displacement (s, V, C, m).

    \b
    Example:
      piezohyst simulate --signal multi --duration 12 -o run.csv
    """
    from ..simulation import PRESETS
    from ..workflows import simulate_file

    rec = _run(
        ctx,
        lambda: simulate_file(
            out,
            preset=preset,
            signal=signal,
            amplitude=amplitude,
            frequency=frequency,
            duration=duration,
            rate=rate,
            seed=seed,
            unit=unit,
            force=force,
        ),
    )
    ctx.info(
        f"{rec.t.size} samples at {rec.preset.rate:g} Hz, true leakage {rec.true_growth_rate:.4g} S"
    )
    if (
        preset in PRESETS and rec.preset.c_ref != PRESETS[preset].c_ref
    ):  # the leaked charge would clip the ADC
        ctx.info(f"reference capacitor {rec.preset.c_ref * 1e6:.3g} uF, so the charge never clips")
    ctx.result(str(out))


@main.command()
@click.option(
    "--kind",
    type=click.Choice(KINDS),
    default="identification",
    show_default=True,
    help="identification: holds, then loops at two frequencies; holds: the leakage "
    "staircase; multifreq: loops at 1, 10 and 40 times --frequency.",
)
@click.option("--v-min", type=float, required=True, help="Lowest voltage, V.")
@click.option("--v-max", type=float, required=True, help="Highest voltage, V.")
@click.option("--sample-rate", type=float, required=True, help="The DAQ's output rate, Hz.")
@click.option(
    "--slew-rate", type=float, default=None, help="Fastest change allowed, V/s (default: none)."
)
@click.option(
    "--frequency", type=float, default=1.0, show_default=True, help="Base loop frequency, Hz."
)
@click.option("--hold", type=float, default=5.0, show_default=True, help="Each hold's length, s.")
@out_file(
    "Output file (.csv, .mat, .tdms, .npz or .parquet).",
    *(".csv", ".mat", ".tdms", ".npz", ".parquet"),
    what="an excitation file",
)
@COMMAND_SCALE
@FORCE
@click.pass_obj
def excite(
    ctx: Context,
    kind: str,
    v_min: float,
    v_max: float,
    sample_rate: float,
    slew_rate: float | None,
    frequency: float,
    hold: float,
    out: Path,
    command_scale: str | None,
    force: bool,
) -> None:
    """Write a voltage excitation to play on the rig: time,voltage (s, V).

    It starts and ends at rest (0 V or the nearer limit), stays in [--v-min,
    --v-max] and under --slew-rate, and holds long enough for a leakage
    calibration. Load it into your DAQ software, record the charge (or
    position) it gives, then fit that record.

    \b
    Example:
      piezohyst excite --v-min 0 --v-max 140 --sample-rate 1000 -o excite.csv
    """
    from ..workflows import excite_file

    def make() -> Excitation:
        return excitation(kind, v_min=v_min, v_max=v_max, sample_rate=sample_rate,
                          slew_rate=slew_rate, frequency=frequency, hold=hold)  # fmt: skip

    exc = _run(ctx, lambda: excite_file(out, make(), force=force, command_scale=command_scale))
    ctx.result(exc.summary())
    if command_scale is not None:
        ctx.info(f"written in the DAQ's volts: the piezo's divided by {command_scale}")
    ctx.info(f"saved {out}")


@main.command()
@click.argument("data", type=EXISTING)
@_model_options(
    "Model to identify (auto: each scored inside the record, the best kept).", auto=True
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


@main.command()
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


@main.command()
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
    """
    from ..workflows import Prediction, predict_file

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


@main.command()
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

    \b
    Example:
      piezohyst compensate model.json target.csv --domain displacement \\
          --gain 125 --v-min 0 --v-max 140 -o command.csv
    """
    from ..workflows import compensate_file

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


@main.command()
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
    force: bool,
) -> None:
    """Figures (loop, fit, residual, growth removal) and metrics of MODEL on DATA; with
    --gain, the displacement in metres too.

    \b
    Example:
      piezohyst report model.json run2.csv --out model-report
      piezohyst report model.json sensor.csv --gain gain.json \\
          --displacement-column displacement --out report-m
    """
    from ..workflows import model_report

    command = _command_line()
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


@main.command("fit-many")
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


@main.command("simulate-loop")
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


@main.command()
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


from ._calibrate import calibrate_gain, calibrate_leakage  # noqa: E402 - after main
from ._export import export_c, export_fmu  # noqa: E402 - registered after main
from ._learn import learn  # noqa: E402 - registered after main is defined

main.add_command(calibrate_leakage)
main.add_command(calibrate_gain)
main.add_command(export_c)
main.add_command(export_fmu)
main.add_command(learn)

if __name__ == "__main__":  # pragma: no cover
    main()
