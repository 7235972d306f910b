"""``piezohyst learn``: learning from repetition across trial files (a thin shell over
:func:`piezohyst.workflows.learning_files.learn_file`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import click

from ..control.compensator import CompensatorSettings
from ._support import COMMAND_SCALE, EXISTING, FORCE, Context, _limit_options, _run, out_file


def _auto_or_float(value: str) -> float | Literal["auto"]:
    if value == "auto":
        return "auto"
    try:
        return float(value)
    except ValueError:
        raise click.BadParameter(f"expected auto or a number. Got {value!r}.") from None


@click.command("learn")
@click.argument("model", type=EXISTING)
@click.argument("recorded", type=EXISTING, required=False)
@click.option(
    "--state",
    "state",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="The learner's state file (JSON), kept between trials.",
)
@click.option(
    "--desired",
    type=EXISTING,
    default=None,
    help="The trajectory, one period (first call only; column --column, and time).",
)
@click.option("--column", default="desired", show_default=True, help="Desired column.")
@click.option(
    "--leakage",
    type=EXISTING,
    default=None,
    help="A leakage file (calibrate-leakage); default the model's growth terms.",
)
@click.option(
    "--lag",
    type=float,
    default=0.0,
    show_default=True,
    help="A lag the model does not hold, in s (a rate-independent model behind an amplifier).",
)
@click.option(
    "--learning-gain",
    default="auto",
    show_default=True,
    help="Fraction of the error learned per trial, or auto.",
)
@click.option(
    "--cutoff",
    default="auto",
    show_default=True,
    help="The robustness filter's cutoff in Hz, or auto.",
)
@click.option(
    "--voltage-column",
    default="voltage",
    show_default=True,
    help="The recording's column of the voltage sent.",
)
@click.option(
    "--reading-column",
    default="charge",
    show_default=True,
    help="The recording's column learned from.",
)
@click.option(
    "--voltage-scale",
    default=None,
    help="What one unit of the voltage column is worth: 100 for an amplifier's monitor at 1/100.",
)
@click.option(
    "--reading-scale",
    default=None,
    help="What one unit of the reading column is worth, for a channel logged in V: '4.7 uF' "
    "(a Sawyer-Tower's reference capacitor), '10 um/V' (a sensor, with --sensor).",
)
@click.option(
    "--voltage-tolerance",
    type=click.FloatRange(min=0.0),
    default=None,
    help="How far (V) the recorded voltage may stray from the commands, beyond its noise "
    "(default: 10x its noise, at least 1e-4 of the voltage range; kept in the state file).",
)
@click.option(
    "--sensor", is_flag=True, help="The reading is a displacement sensor's (m), not the charge."
)
@click.option(
    "--no-lead-in",
    is_flag=True,
    help="Learn from the first trial too (the actuator already runs the scan).",
)
@click.option(
    "--no-probe",
    is_flag=True,
    help="Send the lead-in without its probe (small sines whose response measures the "
    "loop's timing; give it on every call of a run).",
)
@click.option(
    "--no-lag-measurement",
    is_flag=True,
    help="Learn from the first trial after the lead-in even where the model holds no lag "
    "(by default that trial measures the loop's lag, and the model holds it from the next "
    "trial on: see LearningCompensator's measure_lag); give it on every call of a run.",
)
@click.option(
    "--noise-gate",
    type=click.FloatRange(min=0.0, max=100.0),
    default=0.0,
    show_default=True,
    help="Learn a frequency of the error only where its power is above this many times the "
    "measurement noise's (9: three times its amplitude): the commands then carry less of the "
    "noise (less jitter), the loop may be wider (see LearningCompensator); give it on every "
    "call of a run.",
)
@click.option(
    "--law",
    type=click.Choice(["auto", "harmonic", "jacobian"]),
    default="auto",
    show_default=True,
    help="How the error is learned: harmonic corrects the reference through the model's "
    "inverse; jacobian moves the commands through the model's Jacobian along them (an "
    "actuator whose output runs on past its reversals too; trials of up to 4000 samples, "
    "no --lag); auto: jacobian where it can, else harmonic; give it on every call of a run.",
)
@_limit_options
@out_file("The next trial's commands (CSV: time, command, desired).")
@COMMAND_SCALE
@FORCE
@click.pass_obj
def learn(
    ctx: Context,
    model: Path,
    recorded: Path | None,
    state: Path,
    desired: Path | None,
    column: str,
    leakage: Path | None,
    lag: float,
    learning_gain: str,
    cutoff: str,
    voltage_column: str,
    reading_column: str,
    voltage_scale: str | None,
    reading_scale: str | None,
    voltage_tolerance: float | None,
    sensor: bool,
    no_lead_in: bool,
    no_probe: bool,
    no_lag_measurement: bool,
    noise_gate: float,
    law: str,
    settings: CompensatorSettings,
    out: Path,
    command_scale: str | None,
    force: bool,
) -> None:
    """Learn from the trial RECORDED and write the next trial's commands.

    A repeated scan (one period per trial, trials sent back to back): the first
    call takes --desired and writes the first trial; each later call takes the
    DAQ's recording of the trial just sent (its voltage column: the commands
    written, or the voltage measured while sending them, within its noise) and
    the charge measured over it, and writes the next. The
    state file names the model, settings and trajectory it belongs to. A
    reading the DAQ lost is written NaN and not learned from (an empty cell is
    refused as a damaged row). The first trial is the lead-in, not learned from.

    A coupled stage's model file (``fit --input vx,vy --output x,y``) learns a scan of every
    axis: --column x,y names the desired columns (the first call), the recording holds one
    voltage column per actuator (--voltage-column, default voltage_0,voltage_1,...) and the
    positions read (--reading-column, default the desired columns' names), and the commands
    file one column per actuator.

    \b
    Example:
      piezohyst learn model.json --desired scan.csv --state learn.json -o next.csv
      piezohyst learn model.json trial.csv --state learn.json -o next.csv
      piezohyst learn stage.json --desired raster.csv --column x,y --v-min 0 --v-max 140 \\
        --state learn.json -o next.csv
    """
    from ..workflows.learning_files import learn_file
    from ..workflows.stage_files import is_stage_file

    if is_stage_file(model):
        given = click.get_current_context().get_parameter_source
        default = click.core.ParameterSource.DEFAULT
        unused = [f"--{name.replace('_', '-')}" for name, value in (
            ("leakage", leakage), ("voltage_scale", voltage_scale),
            ("reading_scale", reading_scale), ("command_scale", command_scale),
            ("sensor", sensor)) if value]  # fmt: skip
        if unused:
            raise click.UsageError(
                f"a stage learns from its sensors' positions in the model's units: "
                f"{', '.join(unused)} not taken"
            )
        options = {"learning_gain": _auto_or_float(learning_gain),
                   "cutoff": _auto_or_float(cutoff), "lead_in": not no_lead_in,
                   "probe": not no_probe, "measure_lag": not no_lag_measurement,
                   "noise_gate": noise_gate, "law": law}  # fmt: skip
        if lag:
            options["lag"] = lag
        _learn_stage(ctx, model, state, out, recorded, desired, settings, force, options,
                     None if given("column") == default else column,
                     None if given("voltage_column") == default else voltage_column,
                     None if given("reading_column") == default else reading_column,
                     voltage_tolerance)  # fmt: skip
        return

    result = _run(
        ctx,
        lambda: learn_file(
            model,
            state,
            out,
            recorded=recorded,
            desired=desired,
            column=column,
            settings=settings,
            leakage=leakage,
            lag=lag,
            learning_gain=_auto_or_float(learning_gain),
            cutoff=_auto_or_float(cutoff),
            voltage_column=voltage_column,
            reading_column=reading_column,
            voltage_scale=voltage_scale,
            reading_scale=reading_scale,
            sensor=sensor,
            lead_in=not no_lead_in,
            probe=not no_probe,
            measure_lag=not no_lag_measurement,
            noise_gate=noise_gate,
            law=law,  # type: ignore[arg-type]
            voltage_tolerance=voltage_tolerance,
            force=force,
            command_scale=command_scale,
        ),
    )
    trial, learner = result.trial, result.learner
    if trial is not None:
        if trial.skipped and trial.index == 0 and learner.settings["lead_in"]:
            ctx.result(
                f"trial 0: the lead-in (error {trial.error:.3%}: the actuator arriving), not "
                "learned from"
            )
        elif trial.skipped and learner.timing is not None and learner.timing.trial == trial.index:
            ctx.result(
                f"trial {trial.index}: error {trial.error:.3%}; it measured the loop's lag "
                f"({learner.timing.lag * 1e3:.3g} ms, which the model does not hold): not "
                "learned from, the next trial's commands invert it"
            )
        elif trial.skipped:
            ctx.result(f"trial {trial.index}: {trial.learned} readings to learn from: skipped")
        else:
            back = " (rolled back, gain halved)" if trial.rolled_back else ""
            held = f"; the limits held {trial.saturated} commands" if trial.saturated else ""
            ctx.result(
                f"trial {trial.index}: error {trial.error:.3%}, loop width {trial.width:.3%}, "
                f"learned from {trial.learned} samples{back}{held}"
            )
    if learner.design is not None and trial is not None:
        ctx.info(learner.describe())
    ctx.result(f"trial {learner.trials}'s commands: {out}")


def _learn_stage(
    ctx: Context, model: Path, state: Path, out: Path, recorded: Path | None,
    desired: Path | None, settings: CompensatorSettings, force: bool, options: dict[str, Any],
    column: str | None, voltage_column: str | None, reading_column: str | None,
    voltage_tolerance: float | None,
) -> None:  # fmt: skip
    """``learn stage.json ... --column x,y``: :func:`learn_stage_file`."""
    from ..workflows.stage_files import stage_columns
    from ..workflows.stage_learning import learn_stage_file

    if settings.v_min is None or settings.v_max is None:
        raise click.UsageError("a stage's commands need --v-min and --v-max (V, every actuator)")

    def names(spec: str | None, what: str) -> list[str] | None:
        return None if spec is None else stage_columns(spec, what)

    run = _run(
        ctx,
        lambda: learn_stage_file(
            model, state, out, recorded=recorded, desired=desired,
            columns=names(column, "--column"), v_min=settings.v_min,  # type: ignore[arg-type]
            v_max=settings.v_max,  # type: ignore[arg-type]
            sample_rate=settings.sample_rate, slew_rate=settings.slew_rate,
            allow_extrapolation=settings.allow_extrapolation,
            voltage_columns=names(voltage_column, "--voltage-column"),
            reading_columns=names(reading_column, "--reading-column"),
            voltage_tolerance=voltage_tolerance, force=force, **options,
        ),
    )  # fmt: skip
    trial, learner = run.trial, run.learner
    if trial is not None:
        errors = ", ".join(f"{100 * e:.3g} %" for e in trial.error)
        held = "; ".join(f"actuator {k}: the limits held {int(c)} commands"
                         for k, c in enumerate(trial.saturated) if c)  # fmt: skip
        said = "the lead-in, not learned from" if trial.skipped else "learned from"
        ctx.result(
            f"trial {trial.index}: error per axis {errors} of what the stage reaches there "
            f"({said})" + (f"; {held}" if held else "")
        )
        ctx.info(learner.describe())
    ctx.result(f"trial {learner.trials}'s commands: {out}")
