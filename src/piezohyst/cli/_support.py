"""What the ``piezohyst`` commands share: the context, progress, one-line errors, and the
option bundles (data columns and window, voltage limits, the loop, the model's settings).
"""

from __future__ import annotations

import functools
import shlex
import sys
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal, cast

import click

from ..control.arguments import Domain
from ..control.compensator import CompensatorSettings
from ..control.selfsensing import LoopSettings
from ..errors import PiezohystError
from ..io import DataSpec, estimated_rows
from ..model.calibrations.output_map import OutputMap
from ..model.presets import HysteresisModel, model_names
from ..units import is_length


class Context:
    """Options shared by every command."""

    def __init__(self, quiet: bool, verbose: bool, debug: bool) -> None:
        self.quiet = quiet
        self.verbose = verbose
        self.debug = debug

    def info(self, message: str) -> None:
        """A note on standard error (not with --quiet)."""
        if not self.quiet:
            click.echo(message, err=True)

    def result(self, message: str) -> None:
        """A command's result on standard output (not with --quiet: its files say it)."""
        if not self.quiet:
            click.echo(message)


@contextmanager
def progress_steps(ctx: Context, total: int) -> Iterator[Callable[[str], None]]:
    """A rich progress bar on a terminal; silent when piped or quiet (steps still logged
    with --verbose)."""
    if ctx.quiet or not sys.stderr.isatty():
        if ctx.verbose and not ctx.quiet:
            yield lambda msg: click.echo(f"... {msg}", err=True)
        else:
            yield lambda _msg: None
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


@contextmanager
def working(ctx: Context, label: str) -> Iterator[None]:
    """A spinner with the time elapsed on a terminal, for work whose length cannot be counted
    (fitting several models); nothing when piped or quiet."""
    if ctx.quiet or not sys.stderr.isatty():
        yield
        return
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                  console=Console(stderr=True), transient=True) as bar:  # fmt: skip
        bar.add_task(label, total=None)
        yield


#: Records shorter than this read in moments: no progress line when the output is piped
QUIET_ROWS = 100_000


@contextmanager
def rows_progress(
    ctx: Context, label: str, path: Path | None = None, passes: int = 1
) -> Iterator[Callable[[int], None]]:
    """Progress over the rows read: on a terminal a bar with percentage and time left when
    the file's length can be estimated (a count of rows otherwise); piped, one line when a
    long record starts and one when it is done. ``passes``: how often the rows are read."""
    rows = None if path is None else estimated_rows(path)
    total = None if rows is None else rows * passes
    if ctx.quiet:
        yield lambda _rows: None
        return
    if not sys.stderr.isatty():
        if total is None or rows is None or rows < QUIET_ROWS:
            yield lambda _rows: None
            return
        click.echo(f"{label}: about {rows:,} rows", err=True)
        began = time.perf_counter()
        yield lambda _rows: None
        click.echo(f"{label}: done in {time.perf_counter() - began:.1f} s", err=True)
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        Progress,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        [SpinnerColumn(), TextColumn("{task.description}"), TextColumn("{task.completed:,} rows")]
        if total is None
        else [
            TextColumn("{task.description}"),
            BarColumn(),
            TaskProgressColumn(),
            TimeRemainingColumn(),
        ]
    )
    with Progress(
        *columns, TimeElapsedColumn(), console=Console(stderr=True), transient=True
    ) as bar:
        task = bar.add_task(label, total=total)

        def update(done: int) -> None:
            if total is not None and done > (bar.tasks[0].total or 0):
                bar.update(task, total=1.05 * done)  # more than estimated: never past 100 %
            bar.update(task, completed=done)

        yield update


def _command_line() -> str:
    """The command as typed (recorded in reports), or the parsed command when embedded."""
    if Path(sys.argv[0]).name == "piezohyst":
        return shlex.join(["piezohyst", *sys.argv[1:]])
    ctx = click.get_current_context()
    words = ["piezohyst", *ctx.command_path.split()[1:]]  # the root's name is the program's
    return " ".join(words + [f"--{k}={v}" for k, v in ctx.params.items() if v not in (None, False)])


def _run(ctx: Context, fn: Callable[[], Any]) -> Any:
    """Run a command body: errors become one line on stderr and exit 1 (traceback: --debug).

    Warnings (an implausible sample interval, narrowed limits...) become one
    ``warning:`` line each on stderr.
    """
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = fn()
        said: dict[str, int] = {}  # each distinct warning once, in order, with its count
        for w in caught:
            said[str(w.message)] = said.get(str(w.message), 0) + 1
        for message, times in said.items():
            again = f" (said {times} times)" if times > 1 else ""
            click.echo(f"warning: {message}{again}", err=True)
        return result
    except (PiezohystError, OSError) as exc:
        if ctx.debug:
            raise
        hint = " (--force replaces it)" if getattr(exc, "replaceable", False) else ""
        click.echo(f"error: {exc}{hint}", err=True)
        sys.exit(1)
    except Exception as exc:  # a bug of ours: still one line, with the way to see more
        if ctx.debug:
            raise
        click.echo(
            f"error: unexpected {type(exc).__name__}: {exc} (rerun with --debug for the "
            "traceback, and please report it)",
            err=True,
        )
        sys.exit(1)


# ---------------------------------------------------------------- shared options
def _data_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--input/--output/--time/--rate/--group/--skip-rows/--output-file/--t-start/--t-stop, the
    units and the scales, gathered into one DataSpec."""
    options = [
        click.option(
            "--input",
            "input_column",
            default="voltage",
            show_default=True,
            help="Input column (name or 0-based index).",
        ),
        click.option(
            "--output",
            "output_column",
            default="charge",
            show_default=True,
            help="Output column (name or 0-based index).",
        ),
        click.option(
            "--time",
            "time_column",
            default="time",
            show_default=True,
            help="Time column in s (used when present).",
        ),
        click.option(
            "--rate",
            type=float,
            default=None,
            help="Sample rate in Hz, when the file has no time column.",
        ),
        click.option(
            "--group",
            default=None,
            help="Group (TDMS, HDF5) or table (aixACCT) to read (default: the first holding "
            "the columns, else the first with a time column).",
        ),
        click.option(
            "--skip-rows",
            type=click.IntRange(min=0),
            default=0,
            help="Text files: lines to skip before the table (a 'Key: value' preamble is "
            "found without it).",
        ),
        click.option(
            "--output-file",
            type=click.Path(dir_okay=False, path_type=str),
            default=None,
            help="A second file holding the output column, row for row with the first.",
        ),
        click.option("--t-start", type=float, default=None, help="Use samples from this time (s)."),
        click.option(
            "--t-stop", type=float, default=None, help="Use samples before this time (s)."
        ),
        click.option(
            "--input-unit",
            default=None,
            help="Unit of the input column (default: its header's, or V).",
        ),
        click.option(
            "--output-unit",
            default=None,
            help="Unit of the output column, e.g. C, uC, um (default: its header's).",
        ),
        click.option(
            "--time-unit",
            default=None,
            help="Unit of the time column (default: its header's, or s).",
        ),
        click.option(
            "--input-scale",
            default=None,
            help="What one unit of the input column is worth: 100 for an amplifier's monitor "
            "at 1/100 of the piezo's voltage.",
        ),
        click.option(
            "--output-scale",
            default=None,
            help="What one unit of the output column is worth, for a channel logged in V: "
            "'10 um/V' (a sensor), '4.7 uF' (a Sawyer-Tower's reference capacitor), -1 (a "
            "sensor counting the other way).",
        ),
        click.option(
            "--keep-outliers",
            is_flag=True,
            default=False,
            help="Keep the isolated outliers the record's check names (an ADC glitch); by "
            "default each is replaced by its neighbours' mean, so it sets no limit.",
        ),
    ]

    @functools.wraps(fn)
    def with_spec(
        *args: Any,
        input_column: str,
        output_column: str,
        time_column: str,
        rate: float | None,
        group: str | None,
        skip_rows: int,
        output_file: str | None,
        t_start: float | None,
        t_stop: float | None,
        input_unit: str | None,
        output_unit: str | None,
        time_unit: str | None,
        input_scale: str | None,
        output_scale: str | None,
        keep_outliers: bool,
        **kwargs: Any,
    ) -> Any:
        spec = DataSpec(
            input_column,
            output_column,
            time_column,
            rate,
            group,
            t_start,
            t_stop,
            input_unit,
            output_unit,
            time_unit,
            skip_rows,
            output_file,
            keep_outliers,
            input_scale,
            output_scale,
        )
        return fn(*args, data_spec=spec, **kwargs)

    wrapped: Callable[..., Any] = with_spec
    for option in reversed(options):
        wrapped = option(wrapped)
    return wrapped


def _gain_option(value: str | None) -> float | OutputMap | None:
    """--gain: a number (m/C) or an output map's file (calibrate-gain)."""
    if value is None:
        return None
    try:
        return float(value)
    except ValueError:
        pass
    path = Path(value)
    if not path.is_file():
        msg = f"--gain: {value!r} is neither a number (m/C) nor an output map's file"
        raise click.BadParameter(msg)
    try:
        return OutputMap.load(path)
    except PiezohystError as exc:
        raise click.BadParameter(str(exc)) from None


def _limit_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--v-min/--v-max/--domain/--gain/--slew-rate/--sample-rate, gathered into one settings."""
    options = [
        click.option(
            "--v-min",
            type=float,
            default=None,
            help="Lowest command in V (default: the model's training minimum).",
        ),
        click.option(
            "--v-max",
            type=float,
            default=None,
            help="Highest command in V (default: the model's training maximum).",
        ),
        click.option(
            "--domain",
            type=click.Choice(["charge", "displacement"]),
            default="charge",
            show_default=True,
            help="Units of the desired values.",
        ),
        click.option(
            "--gain",
            default=None,
            callback=lambda _c, _p, value: _gain_option(value),
            help="Displacement per charge in m/C (for --domain displacement), or the file "
            "calibrate-gain wrote (its map, curvature included; implies --domain displacement).",
        ),
        click.option(
            "--slew-rate",
            type=float,
            default=None,
            help="Largest change in V/s (default: the training record's fastest; per sample "
            "without --sample-rate).",
        ),
        click.option(
            "--sample-rate",
            type=float,
            default=None,
            help="Loop rate in Hz (for --slew-rate, and models with creep or relaxation).",
        ),
        click.option(
            "--allow-extrapolation",
            is_flag=True,
            help="Allow limits beyond the voltages the model was identified on.",
        ),
    ]

    @functools.wraps(fn)
    def with_settings(
        *args: Any,
        v_min: float | None,
        v_max: float | None,
        domain: str,
        gain: float | OutputMap | None,
        slew_rate: float | None,
        sample_rate: float | None,
        allow_extrapolation: bool,
        **kwargs: Any,
    ) -> Any:
        slew: float | Literal["trained"] = "trained" if slew_rate is None else slew_rate
        number, output_map = (None, gain) if isinstance(gain, OutputMap) else (gain, None)
        if output_map is not None:
            domain = "displacement"  # a map: the desired values are in its unit
        settings = CompensatorSettings(
            v_min, v_max, cast(Domain, domain), number, slew, sample_rate, allow_extrapolation,
            output_map,
        )  # fmt: skip
        return fn(*args, settings=settings, **kwargs)

    wrapped: Callable[..., Any] = with_settings
    for option in reversed(options):
        wrapped = option(wrapped)
    return wrapped


def _loop_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--leakage/--ki/--kp/--refresh-leakage, gathered into one LoopSettings."""
    options = [
        click.option(
            "--leakage",
            type=click.Path(dir_okay=False, path_type=Path),
            default=None,
            help="Leakage file from calibrate-leakage (default: the model's growth terms).",
        ),
        click.option(
            "--ki",
            type=click.FloatRange(0.0, 1.9),
            default=0.5,
            show_default=True,
            help="Integral gain per sample.",
        ),
        click.option(
            "--kp",
            type=click.FloatRange(0.0, 1.0),
            default=0.0,
            show_default=True,
            help="Proportional gain.",
        ),
        click.option(
            "--refresh-leakage",
            is_flag=True,
            help="Refine the bias current online from holds of the desired value.",
        ),
    ]

    @functools.wraps(fn)
    def with_loop(
        *args: Any,
        leakage: Path | None,
        ki: float,
        kp: float,
        refresh_leakage: bool,
        **kwargs: Any,
    ) -> Any:
        return fn(*args, loop=LoopSettings(leakage, ki, kp, refresh_leakage), **kwargs)

    wrapped: Callable[..., Any] = with_loop
    for option in reversed(options):
        wrapped = option(wrapped)
    return wrapped


FORCE = click.option(
    "--force", is_flag=True, help="Replace an existing output that piezohyst did not write."
)

COMMAND_SCALE = click.option(
    "--command-scale",
    default=None,
    help="The amplifier's gain, piezo volts per volt the DAQ plays (14; -14 for an inverting "
    "one): the voltages are written divided by it; --v-min, --v-max and --slew-rate stay the "
    "piezo's.",
)


def _suffix(*allowed: str, what: str) -> Callable[[click.Context, click.Parameter, Any], Any]:
    """A click callback refusing a file name whose suffix ``what`` cannot be written as."""

    def check(_ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        if value is not None and Path(value).suffix.lower() not in allowed:
            names = " or ".join([", ".join(allowed[:-1]), allowed[-1]] if allowed[1:] else allowed)
            msg = f"{what}: name it {names} (got {Path(value).name!r})"
            raise click.BadParameter(msg, param=param)
        return value

    return check


TABLE_SUFFIXES = (".csv", ".npz", ".parquet")


def out_file(
    help: str, *suffixes: str, what: str = "", required: bool = True
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``-o/--out``: the file a command writes (``suffixes`` the kinds it may be, ``what``
    said when another is given)."""
    extra: dict[str, Any] = {"required": True} if required else {"default": None}
    return click.option(
        "-o",
        "--out",
        "out",
        type=click.Path(dir_okay=False, path_type=Path),
        callback=_suffix(*suffixes, what=what) if suffixes else None,
        help=help,
        **extra,
    )


OUT_FILE = out_file(
    "Output file (.csv, .npz or .parquet).",
    *TABLE_SUFFIXES,
    what="a table is written as CSV, NPZ or Parquet",
)
OUT_FILE_JSON = out_file("Output file (.json).", ".json", what="this file is JSON")


EXISTING = click.Path(exists=False, dir_okay=False, path_type=Path)


Decorator = Callable[[Callable[..., Any]], Callable[..., Any]]


def operators_option(
    default: int = 10, help: str = "Play operators, the linear one included."
) -> Decorator:
    """--operators: play operators of the models that have them."""
    return click.option("--operators", type=click.IntRange(1, 1000), default=default,
                        show_default=True, help=help)  # fmt: skip


def input_dynamics_option(help: str, default: str = "none") -> Decorator:
    """--input-dynamics: the delay/lag between the logged command and the piezo (``record``,
    where a command offers it: ``auto`` when the record drives several rates, else none)."""
    kinds = ["none", "delay", "first-order", "delay+first-order", "auto"]
    if default == "record":
        kinds.append("record")
    return click.option("--input-dynamics", type=click.Choice(kinds), default=default,
                        show_default=True, help=help)  # fmt: skip


def terms_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--growth and --creep, shared by fit and fit-many (see :func:`parse_terms`)."""
    fn = click.option(
        "--creep",
        default="",
        help="generalized-pi, preisach, duhem, bouc-wen: creep time constants in s, e.g. 0.1,1,10.",
    )(fn)
    return click.option(
        "--growth",
        default="default",
        show_default=True,
        help="generalized-pi, preisach, duhem, bouc-wen: growth terms, 'default' (the model's: "
        "on a charge the leak's integral, with its rise where the record's holds show one; "
        "generalized-pi chooses by forward chaining), 'auto' (chosen by forward chaining; with "
        "--model auto, for every candidate that has growth terms), 'none' or a comma list of "
        "integral,time,abs_integral.",
    )(fn)


def parse_terms(growth: str, creep: str) -> tuple[str | tuple[str, ...], tuple[float, ...]]:
    """--growth and --creep as the models take them: the growth terms ('default', 'auto', or a
    tuple; 'none' the empty one) and the creep time constants (s)."""
    try:
        taus = tuple(float(c) for c in creep.split(",") if c.strip())
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {creep!r}",
                                 param_hint="--creep") from None  # fmt: skip
    if growth in ("auto", "default"):
        return growth, taus
    if growth == "none":
        return (), taus
    return tuple(g.strip() for g in growth.split(",") if g.strip()), taus


def initial_state_option(choices: list[str], help: str) -> Decorator:
    """--initial-state: where a model starts (the first choice is the default)."""
    return click.option("--initial-state", type=click.Choice(choices), default=choices[0],
                        show_default=True, help=help)  # fmt: skip


def _model_options(
    model_help: str, auto: bool = False, structure: bool = False
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """--model and --operators, shared by fit and fit-many (``auto``: choose one;
    ``structure``: a structure's coupled dynamics, for several columns)."""

    def decorate(fn: Callable[..., Any]) -> Callable[..., Any]:
        fn = operators_option()(fn)
        extra = [*(["auto"] if auto else []), *(["structure"] if structure else [])]
        return click.option(
            "--model",
            "model_name",
            type=click.Choice([*model_names(), *extra]),
            default="active-pi",
            show_default=True,
            help=model_help,
        )(fn)

    return decorate


def _fit_auto(
    ctx: Context,
    data: Path,
    operators: int,
    initial_state: str,
    input_dynamics: str,
    data_spec: DataSpec,
    out: Path,
    force: bool,
    growth: str = "default",
) -> HysteresisModel:
    """fit --model auto: every model scored inside the record (each with the input dynamics
    asked for, and with --growth auto its growth terms chosen by evidence), the best saved;
    returns it."""
    from ..workflows import select_file

    notes: list[str] = []
    with (
        working(ctx, f"choosing a model for {data.name}: each candidate on the record's folds"),
        rows_progress(ctx, f"reading {data.name}", data) as progress,
    ):
        sel = _run(
            ctx,
            lambda: select_file(
                data,
                out,
                data_spec=data_spec,
                operators=operators,
                initial_state=initial_state,
                input_dynamics=input_dynamics,
                growth_terms=growth,
                force=force,
                progress=progress,
                say=notes.append,
            ),
        )
    ctx.result(sel.table())
    for note in notes:  # what --input-dynamics record decided
        ctx.info(note)

    ctx.result(describe(sel.model))
    ctx.info(f"saved {out}")
    return cast(HysteresisModel, sel.model)


def _shape(term: Any) -> str:
    """A shape term in a line: its kind and size (creep: its time constants)."""
    taus = getattr(term, "taus", None)
    if term.kind == "creep" and taus is not None:
        return "creep (time constants " + ", ".join(f"{tau:.3g}" for tau in taus) + " s)"
    return f"{term.kind} ({term.width} coefficients)"


def describe(model: HysteresisModel) -> str:
    """One line on a fitted model's quality and terms, from its public attributes."""
    core = model.operator_.summary
    text = (
        f"{type(model).__name__}: {core}, "
        f"NRMSE {100 * model.nrmse_:.4g} %, RMSE {model.rmse_:.4g} {model.output_unit}"
    )
    growth = model.growth_coefficients()
    if growth:
        text += ", growth terms: " + ", ".join(f"{k} {v:.4g} {u}" for k, (v, u) in growth.items())
    elif "growth_terms" in model.get_params():
        text += ", growth terms: none"
    if model.selection_:  # chosen by forecasting the record's later part: say by how much
        scores = ", ".join(f"{k} {v:.3g}" for k, v in model.selection_.items())
        text += f" (chosen by forecasting the record's later part, held-out RMSE: {scores})"
    shape = [term for term in model.terms_ if not term.removed]
    if shape:
        text += "; shape terms: " + ", ".join(_shape(t) for t in shape)
    if is_length(model.output_unit) and not growth:  # what the domain rule did, said
        text += "; no leak term (a displacement sees no leaked charge)"
    dyn = model.input_dynamics_
    mode = model.output_dynamics_
    if mode.active:
        text += f"; output mode {mode.f0:.4g} Hz, damping {mode.zeta:.3g}"
    if dyn.active:
        se_d, se_tau = (1.96e3 * v for v in dyn.stderr())  # 95 %, ms (NaN: unknown)
        lag = f"{1e3 * dyn.tau:.4g}" + (f" ± {se_tau:.2g}" if se_tau == se_tau else "")
        delay = f"{1e3 * dyn.delay:.4g}" + (f" ± {se_d:.2g}" if se_d == se_d else "")
        text += f"; input dynamics {dyn.kind}: lag {lag} ms, delay {delay} ms"
    return text


def stage_loop_settings(settings: CompensatorSettings, loop: LoopSettings) -> Any:
    """A stage's loop settings from the limit and loop options (``--leakage lx.json,ly.json``:
    one file per actuator).

    Parameters
    ----------
    settings : CompensatorSettings
    loop : LoopSettings

    Returns
    -------
    StageLoopSettings
    """
    from ..workflows.stage_files import stage_columns
    from ..workflows.stage_loop_files import StageLoopSettings

    leak = None if loop.leakage is None else stage_columns(str(loop.leakage), "--leakage")
    return StageLoopSettings(
        v_min=settings.v_min, v_max=settings.v_max, slew_rate=settings.slew_rate,
        allow_extrapolation=settings.allow_extrapolation,
        leakage=None if leak is None else tuple(Path(p) for p in leak), ki=loop.ki, kp=loop.kp,
    )  # fmt: skip
