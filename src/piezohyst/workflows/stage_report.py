"""``piezohyst report`` for several actuators: a coupled stage's model
(:class:`~piezohyst.CoupledModel`) or a structure's coupled dynamics
(:class:`~piezohyst.StructureModel`) scored on a record, each axis drawn, in
``report.html``, ``report.md`` and ``metrics.json``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validation import FloatArray
from ..errors import ParameterError
from ..io import DataSpec
from ..model.structure import StructureModel
from ._base import PathLike, guard_outputs
from .stage_files import _is_structure, _read_stage, _stage

if TYPE_CHECKING:
    from ..analysis.report import Report
    from .report_files import ReportResult

__all__ = ["stage_report"]

#: The modes a structure's report lists, the lowest first (the rest are counted)
LISTED_MODES = 12
#: The record's lowest estimated frequencies its low-frequency gain is averaged over
LOW_BINS = 5
#: Frequencies of the frequency-response figure, log-spaced from a 2000th of the sample rate
#: to half of it
RESPONSE_POINTS = 400


def stage_report(
    model_path: PathLike,
    data: PathLike,
    out: PathLike,
    *,
    inputs: Sequence[str],
    outputs: Sequence[str],
    data_spec: DataSpec | None = None,
    command: str | None = None,
    force: bool = False,
    initial_state: str = "rest",
) -> ReportResult:
    """A stage's or structure's model scored on a record: per axis its NRMSE and figures
    (the position over time with the residual, and the axis against its own actuator's
    voltage), and the model: a stage's coupling and each actuator's model; a structure's
    order, static gain, modes and frequency response (with operators in the loop, for small
    strokes, where they stick, and large ones, where they slide), beside the record's own
    estimate of the response (:func:`~piezohyst.analysis.response.measured_response`) and
    compared with it.

    Parameters
    ----------
    model_path : str or os.PathLike
        A coupled model file (``fit --input vx,vy --output x,y``) or a structure model file
        (``fit ... --model structure``).
    data : str or os.PathLike
        The record.
    out : str or os.PathLike
        The report's folder (written whole, or not at all).
    inputs, outputs : sequence of str
        The actuators' voltage columns and the axes' position columns, in the model's order.
    data_spec : DataSpec, optional
    command : str, optional
        The command line, recorded in the report.
    force : bool
        Replace a folder piezohyst did not write.
    initial_state : {"rest", "periodic"}
        A structure's start: at rest, or the record as one period of a steady state (a
        multisine's period). A coupled stage's channels start as they were fitted.

    Returns
    -------
    ReportResult
    """
    from datetime import UTC, datetime

    from ..analysis.report import Report, file_facts
    from ..io import atomic_folder
    from ._base import check_folder
    from .report_files import ReportResult

    if initial_state not in ("rest", "periodic"):
        msg = f"'initial_state' must be 'rest' or 'periodic'. Got {initial_state!r}."
        raise ParameterError(msg)
    guard_outputs([check_folder(out, "the figures and the report")], [model_path, data],
                  force=force)  # fmt: skip
    structure = _is_structure(model_path)
    model = StructureModel.load(model_path) if structure else _stage(model_path)
    if isinstance(model, StructureModel):
        n, m = model.n_inputs_, model.n_outputs_
    else:
        n, m = len(model.channels_), model.coupling_.shape[0]
        if initial_state != "rest":
            msg = "a coupled stage's channels start as they were fitted: no 'periodic' start"
            raise ParameterError(msg)
    if len(inputs) != n or len(outputs) != m:
        msg = (
            f"{model_path} is a {'structure' if structure else 'stage'} of {n} actuators and "
            f"{m} axes: got {len(inputs)} input and {len(outputs)} output columns"
        )
        raise ParameterError(msg)
    t, u, y, unit = _read_stage(data, inputs, outputs, data_spec or DataSpec())
    assert y is not None
    if isinstance(model, StructureModel):
        pred = model.predict(u, t=t, state=initial_state)
    else:
        pred = model.predict(u, t=t)
    unit = unit or "m"
    kind = "a structure" if structure else "a stage"
    with atomic_folder(out) as folder:
        rep = Report(f"{kind} of {u.shape[1]} actuators on {Path(data).name}", folder)
        rep.metadata = {
            "written": datetime.now(UTC).isoformat(timespec="seconds"),
            "command": command or "(called from Python)",
            "data_file": file_facts(data), "model_file": file_facts(model_path),
            "columns": {"inputs": list(inputs), "outputs": list(outputs)},
            "time_window_s": [float(t[0]), float(t[-1])],
            **({"initial_state": initial_state} if structure else {}),
        }  # fmt: skip
        rep.add("samples", "samples", int(t.size))
        if isinstance(model, StructureModel):
            _structure_said(rep, model, u, y, pred, inputs, outputs, unit)
        else:
            rep.tables["Stage"] = [
                ("coupling (rows: axes, columns: actuators)", _matrix(model.coupling_)),
                *((f"actuator {k} ({inputs[k]})", type(ch).__name__)
                  for k, ch in enumerate(model.channels_)),
            ]  # fmt: skip
            _cross(rep, model.coupling_, "largest cross term of the coupling")
        _axes(rep, t, u, y, pred, inputs, outputs, unit, structure)
        files = [Path(out) / f.name for f in rep.write()]
    return ReportResult({m.key: m.value for m in rep.metrics}, files)


def _matrix(a: FloatArray) -> str:
    return "; ".join("[" + ", ".join(f"{x:.4g}" for x in row) + "]" for row in a)


def _cross(rep: Report, gain: FloatArray, label: str, key: str = "largest_cross_term_pct") -> None:
    """The largest off-diagonal term of each axis's row over its own actuator's (%)."""
    cross = [abs(gain[i, j]) / abs(gain[i, i]) for i in range(min(gain.shape))
             for j in range(gain.shape[1]) if j != i and gain[i, i] != 0]  # fmt: skip
    if cross:
        rep.add(key, label, 100 * float(max(cross)), "%")


def _axes(
    rep: Report, t: FloatArray, u: FloatArray, y: FloatArray, pred: FloatArray,
    inputs: Sequence[str], outputs: Sequence[str], unit: str, structure: bool,
) -> None:  # fmt: skip
    """Per axis: its NRMSE (and, for a structure, the identification benchmarks' score over
    the standard deviation), the axis over time with its residual, and against its own
    actuator's voltage."""
    from ..metrics import nrmse

    measured = {"color": "0.2", "lw": 0.8, "zorder": 3}
    model_line = {"color": "C0", "lw": 3.0, "alpha": 0.45, "zorder": 2}
    for i, axis in enumerate(outputs):
        score = 100 * nrmse(y[:, i], pred[:, i])
        rep.add(f"nrmse_{axis}_pct", f"NRMSE of {axis} (RMSE / its span)", score, "%")
        sd = float(np.std(y[:, i]))
        if structure and sd > 0:
            rms = float(np.sqrt(np.mean((y[:, i] - pred[:, i]) ** 2)))
            rep.add(f"nrmse_sd_{axis}_pct", f"NRMSE of {axis} (RMSE / its standard deviation, "
                    "the identification benchmarks' score)", 100 * rms / sd, "%")  # fmt: skip
        rep.figure(f"fit_{axis}.png", f"{axis} over time, and the residual "
                   f"(NRMSE {score:.3g} %)", [
            {"curves": [(t, y[:, i], "measured", measured),
                        (t, pred[:, i], "model", model_line)],
             "xlabel": "time", "xunit": "s", "ylabel": axis, "yunit": unit},
            {"curves": [(t, y[:, i] - pred[:, i], "measured - model",
                         {"lw": 0.7, "color": "C3"})],
             "xlabel": "time", "xunit": "s", "ylabel": "residual", "yunit": unit},
        ], stacked=True)  # fmt: skip
        if i < u.shape[1]:
            rep.figure(f"loop_{axis}.png", f"{axis} against {inputs[i]}: data (dark line) "
                       "and model (blue band); the other actuators move it too", [
                {"curves": [(u[:, i], y[:, i], "measured", measured),
                            (u[:, i], pred[:, i], "model", model_line)],
                 "xlabel": inputs[i], "xunit": "V", "ylabel": axis, "yunit": unit,
                 "title": ""},
            ])  # fmt: skip


def _structure_said(
    rep: Report, model: StructureModel, u: FloatArray, y: FloatArray, pred: FloatArray,
    inputs: Sequence[str], outputs: Sequence[str], unit: str,
) -> None:  # fmt: skip
    """A structure's order, operators, static gain and modes (tables and metrics); its
    frequency response (a figure) beside the record's own estimate of it; and where the
    record holds one, the two compared (the model's estimated from its simulated outputs the
    same way, like with like)."""
    from ..analysis.response import measured_response

    st = model.structure_
    gain = st.dc_gain()
    rep.add("order", "order of the state space", model.order_)
    rep.add("operators_per_actuator", "play operators per actuator in the loop",
            model.operators_)  # fmt: skip
    rep.add("fit_nrmse_pct", "the fit's own NRMSE on its records (RMSE / standard deviation)",
            model.output_nrmse_, "%")  # fmt: skip
    _cross(rep, gain, "largest cross term of the model's static gain (over the axis's own "
           "actuator)")  # fmt: skip
    paths = f"rows: {', '.join(outputs)}; columns: {', '.join(inputs)}"
    rows = [("model", model.describe()),
            (f"the model's static gain, at 0 Hz ({unit}/V; {paths})", _matrix(gain))]  # fmt: skip
    measured = measured_response(u, y, model.sample_rate_)
    if measured.frequency.size:
        simulated = measured_response(u, pred, model.sample_rate_)
        low = slice(0, LOW_BINS)
        f_lo, f_hi = measured.frequency[0], measured.frequency[:LOW_BINS][-1]
        there = f"{f_lo:.3g}-{f_hi:.3g} Hz"
        gains = [measured.response[low].real.mean(axis=0)]
        rows.append((f"gain at {there}, the record's own estimate ({unit}/V)",
                     _matrix(gains[0])))  # fmt: skip
        _cross(rep, gains[0], f"largest cross term at {there}, the record's own estimate",
               key="measured_cross_term_pct")  # fmt: skip
        if np.array_equal(simulated.frequency, measured.frequency):
            gains.append(simulated.response[low].real.mean(axis=0))
            rows.append((f"gain at {there}, the model's, estimated the same way",
                         _matrix(gains[1])))  # fmt: skip
            _cross(rep, gains[1], f"largest cross term at {there}, the model's",
                   key="model_cross_term_pct")  # fmt: skip
            diff = simulated.response - measured.response
            for i, o in enumerate(outputs):
                err = np.sqrt(np.mean(np.abs(diff[:, i]) ** 2))
                size = np.sqrt(np.mean(np.abs(measured.response[:, i]) ** 2))
                rep.add(f"response_error_{o}_pct", f"the model's response to {o} against the "
                        "record's own estimate (RMS over the estimated frequencies, over the "
                        "estimate's)", 100 * float(err / size), "%")  # fmt: skip
        rows.append(("the record's own estimate", f"Welch's H1 over {measured.segment}-sample "
                     f"segments: {measured.frequency.size} frequencies from {f_lo:.4g} to "
                     f"{measured.frequency[-1]:.4g} Hz, median coherence "
                     f"{float(np.median(measured.coherence)):.3g}"))  # fmt: skip
    else:
        rows.append(("the record's own estimate", "none: the record is too short, or its "
                     "inputs move together at every frequency (one realization of one "
                     "multisine on every input: give each actuator its own lines, as excite "
                     "--kind multisine does)"))  # fmt: skip
    rep.tables["Structure"] = rows
    cases = [("operators sliding (large strokes)", "large")]
    if model.operators_:
        cases.append(("operators stuck (small strokes)", "small"))
    modes_said = []
    top = float(measured.frequency[-1]) if measured.frequency.size else np.inf
    for label, strokes in cases:
        modes = model.modes(strokes=strokes)
        said = ", ".join(f"{f:.5g} Hz ({z:.3g})" + ("*" if f > top else "")
                         for f, z in modes[:LISTED_MODES])  # fmt: skip
        more = f" and {len(modes) - LISTED_MODES} more" if len(modes) > LISTED_MODES else ""
        modes_said.append((f"modes, damping ratio: {label}", (said or "none") + more))
    if any(f > top for case in cases for f, _ in model.modes(strokes=case[1])):
        modes_said.append(("*", f"above the highest frequency the record holds ({top:.4g} Hz): "
                           "the realization's, not measured"))  # fmt: skip
    rep.tables["Modes"] = modes_said
    fs = model.sample_rate_
    f = np.geomspace(fs / 2000, 0.499 * fs, RESPONSE_POINTS)
    curves = []
    styles: list[dict[str, Any]] = [{"lw": 1.2}, {"lw": 0.9, "ls": "--"}]
    for (label, strokes), style in zip(cases, styles, strict=False):
        g = np.abs(model.frequency_response(f, strokes=strokes))
        short = label.split(" (")[0]
        for i, o in enumerate(outputs):
            for j, v in enumerate(inputs):
                tag = f"{v} -> {o}" + (f", {short}" if len(cases) > 1 else "")
                color = f"C{(i * len(inputs) + j) % 10}"
                curves.append((f, g[:, i, j], tag, {**style, "color": color}))
    dots = {"ls": "", "marker": ".", "ms": 2.5}
    for i in range(len(outputs) if measured.frequency.size else 0):
        for j in range(len(inputs)):
            color = f"C{(i * len(inputs) + j) % 10}"
            curves.append((measured.frequency, np.abs(measured.response[:, i, j]), "_",
                           {**dots, "color": color}))  # fmt: skip
    said = " (solid: operators sliding, large strokes; dashed: stuck, small strokes)"
    rep.figure("response.png", "the structure's frequency response, each actuator to each "
               "axis" + (said if len(cases) > 1 else "") + "; dots: the record's own "
               "estimate", [{"curves": curves, "xlabel": "frequency", "xunit": "Hz",
                             "ylabel": "gain", "yunit": f"{unit}/V", "xscale": "log",
                             "yscale": "log", "title": ""}])  # fmt: skip
