"""``piezohyst simulate`` and ``piezohyst excite``: the records the other commands read."""

from __future__ import annotations

from pathlib import Path

import click

from ..simulation.signals import SIGNALS
from ..workflows.excitation import KINDS, Excitation, excitation
from ._support import (
    COMMAND_SCALE,
    FORCE,
    OUT_FILE,
    Context,
    _run,
    out_file,
)


@click.command()
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


@click.command()
@click.option(
    "--kind",
    type=click.Choice(KINDS),
    default="identification",
    show_default=True,
    help="identification: holds, then loops at two frequencies; holds: the leakage "
    "staircase; multifreq: loops at 1, 10 and 40 times --frequency; multisine: a random-phase "
    "multisine on every multiple of --frequency to --band, for a structure's dynamics.",
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
@click.option(
    "--actuators",
    type=int,
    default=1,
    show_default=True,
    help="multisine: the actuators driven, each on its own lines (interleaved), one "
    "column each (voltage_0, voltage_1, ...).",
)
@click.option(
    "--band",
    type=float,
    default=None,
    help="multisine: its highest line, Hz (default 0.4 x --sample-rate).",
)
@click.option(
    "--periods",
    type=int,
    default=8,
    show_default=True,
    help="multisine: its steady periods (of 1 / --frequency s each), after one that "
    "fades it in and before one that fades it out.",
)
@click.option(
    "--seed", type=int, default=0, show_default=True, help="multisine: its random phases."
)
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
    actuators: int,
    band: float | None,
    periods: int,
    seed: int,
    out: Path,
    command_scale: str | None,
    force: bool,
) -> None:
    """Write a voltage excitation to play on the rig: time,voltage (s, V), or a voltage
    column per actuator for a multisine of several.

    It starts and ends at rest (0 V or the nearer limit), stays in [--v-min,
    --v-max] and under --slew-rate, and holds long enough for a leakage
    calibration. Load it into your DAQ software, record the charge (or
    position) it gives, then fit that record.

    \b
    Example:
      piezohyst excite --v-min 0 --v-max 140 --sample-rate 1000 -o excite.csv
      piezohyst excite --kind multisine --actuators 2 --v-min 45 --v-max 95 \\
          --sample-rate 1000 --band 300 -o stage-multisine.csv
    """
    from ..workflows import excite_file

    def make() -> Excitation:
        return excitation(kind, v_min=v_min, v_max=v_max, sample_rate=sample_rate,
                          slew_rate=slew_rate, frequency=frequency, hold=hold,
                          actuators=actuators, band=band, periods=periods, seed=seed)  # fmt: skip

    exc = _run(ctx, lambda: excite_file(out, make(), force=force, command_scale=command_scale))
    ctx.result(exc.summary())
    if command_scale is not None:
        ctx.info(f"written in the DAQ's volts: the piezo's divided by {command_scale}")
    ctx.info(f"saved {out}")
