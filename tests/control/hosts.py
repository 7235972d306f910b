"""What the host tests share (the shared library, the MEX gateway, the FMU): one record, every
model kind issue 41 names fitted on it, and a desired trajectory inside each one's region."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

import piezohyst as ph
from piezohyst.simulation import make_signal

#: Every kind issue 41 names, by the name the tests use
KINDS: dict[str, Callable[[], ph.HysteresisModel]] = {
    "active-pi": lambda: ph.ActivePI(20),
    "generalized-pi+creep": lambda: ph.GeneralizedPI(
        12, growth_terms=("integral",), creep=(0.05, 0.5, 5.0)
    ),
    "preisach": lambda: ph.PreisachModel(),
    "preisach+relaxation": lambda: ph.PreisachModel(relaxation=0.1, relaxation_nodes=8),
    "duhem": lambda: ph.DuhemModel(),
    "bouc-wen": lambda: ph.BoucWenModel(),
}


def record() -> Any:
    """12 s of decaying loops on the bench."""
    return ph.simulate(signal="decaying", duration=12.0, seed=3)


def fitted(rec: Any, names: list[str] | None = None) -> dict[str, ph.HysteresisModel]:
    """The kinds fitted on ``rec`` (the fits' own notes are not under test)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {
            name: KINDS[name]().fit(rec.voltage, rec.charge, t=rec.t)
            for name in (names or list(KINDS))
        }


def desired(model: ph.HysteresisModel, n: int = 3000, fs: float = 1000.0) -> np.ndarray:
    """Decaying loops inside the identified region, a NaN now and then (held)."""
    lo, hi = model.input_range_
    _, shape = make_signal("decaying", amplitude=1.0, duration=n / fs)
    v = lo + (hi - lo) * (0.5 + 0.45 * shape / np.abs(shape).max())
    d = model.hysteresis_.predict(v, t=np.arange(v.size) / fs)
    d[::89] = np.nan
    return np.ascontiguousarray(d[:n])


@functools.cache  # fitted once per worker: the tests only read it
def mode_model() -> ph.ClassicalPI:
    """A model with a mechanical mode (the bench's 150 Hz, from 6 s of three rates on the
    laser), and no lag: the hosts' preview for a mode, tested on its own."""
    from piezohyst.simulation import simulate

    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=6.0)
    rec = simulate(v, t, preset="T226-H4-203X-mode", seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a lag it does not hold: it says so; not the point
        model = ph.ClassicalPI(6, output_unit="m", output_dynamics="second-order")
        return model.fit(rec.voltage, rec.displacement, t=rec.t)


def mode_target(model: ph.HysteresisModel, n: int, fs: float = 1000.0) -> np.ndarray:
    """A 5 Hz sine inside the model's reach, in its output units."""
    return np.asarray(
        model.operator_.predict(70.0 + 40.0 * np.sin(2 * np.pi * 5 * np.arange(n) / fs))
    )


@functools.cache  # fitted once per worker: the tests only read it
def dynamic_record() -> Any:
    """The simulated stage with lags and modes (``XY_DYNAMIC``) on 12 s of each axis's own
    three-rate signal (2.5/25/100 Hz on x, 1.9/19/76 Hz on y: the rates tell a lag and a mode
    from hysteresis, the two inputs do not move together)."""
    from piezohyst.simulation import XY_DYNAMIC, simulate_stage

    t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
    _, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=12.0)
    return simulate_stage(np.column_stack([a, b]), t, presets=XY_DYNAMIC, seed=0)


#: Each actuator's lag and mode, fitted with its hysteresis
DYNAMICS: dict[str, Any] = {"output_unit": "m", "input_dynamics": "first-order",
                            "output_dynamics": "second-order"}  # fmt: skip


@functools.cache  # fitted once per worker: the tests only read it
def dynamic_stage(operators: int = 12) -> tuple[ph.CoupledModel, dict[str, list[float]]]:
    """:func:`dynamic_record` fitted with each actuator's lag and mode, and the actuators'
    limits (the voltages each model was identified on)."""
    rec = dynamic_record()
    model = ph.CoupledModel([ph.ClassicalPI(operators, **DYNAMICS) for _ in range(2)])
    model.fit(rec.voltage, rec.position, t=rec.t)
    ranges = [channel.input_range_ for channel in model.channels_]
    return model, {"v_min": [lo for lo, _ in ranges], "v_max": [hi for _, hi in ranges]}


def run_stage_c(
    sources: list[Any], rows: np.ndarray, tmp_path: Any
) -> tuple[np.ndarray, list[int]]:
    """Build the stage's C with :func:`stage_harness` (``ahead`` where ``rows`` holds the
    next positions beside the desired ones) under ``-Wall -Wextra -Werror -pedantic``, feed it
    ``rows`` and return its commands and its counts."""
    import subprocess

    from ..helpers import CC

    (tmp_path / "main.c").write_text(stage_harness(ahead=rows.shape[1] == 4))
    exe = tmp_path / "stage"
    subprocess.run(
        [CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2",
         *(str(p) for p in sources if p.suffix == ".c"), str(tmp_path / "main.c"), "-o",
         str(exe), "-lm"],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    text = "".join(" ".join(repr(x) for x in row) + "\n" for row in rows.tolist())
    out = subprocess.run([str(exe)], input=text, check=True, capture_output=True, text=True)
    lines = out.stdout.split("\n")
    cmds = np.array([[float(x) for x in line.split()] for line in lines[: rows.shape[0]]])
    return cmds, [int(x) for x in lines[rows.shape[0]].split()]


#: Two actuators read by three sensors: x, y and a third between them (a tip-tilt mirror's
#: extra reading point, a stage's redundant capacitive sensor)
THREE = np.array([[1.0, -0.03], [0.04, 1.0], [0.6, 0.45]])


@functools.cache  # fitted once per worker: the tests only read it
def three_sensor_stage() -> ph.CoupledModel:
    """The static stage read by :data:`THREE`'s sensors, fitted on x's decaying loops and a
    1.3 Hz triangle on y."""
    from piezohyst.simulation import simulate_stage

    t, a = make_signal("decaying", duration=8.0)
    _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    rec = simulate_stage(np.column_stack([np.clip(2 * a, 0.0, 140.0), b]), t, coupling=THREE,
                         seed=0)  # fmt: skip
    return ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)


def stage_library(path: Any) -> Any:
    """The stage's shared library ``ph_xy`` through ctypes, its functions typed (as LabVIEW's
    or MATLAB's loadlibrary declare them)."""
    import ctypes

    lib = ctypes.CDLL(str(path))
    lib.ph_xy_new.restype = ctypes.c_void_p
    lib.ph_xy_process.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_long]
    lib.ph_xy_counts.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
    lib.ph_xy_reset.argtypes = lib.ph_xy_free.argtypes = [ctypes.c_void_p]
    return lib


def stage_harness(ahead: bool = False) -> str:
    """A C main for the stage ``ph_xy``: each stdin line one desired position (and, with
    ``ahead``, the next one: a mode's preview), each stdout line the commands, then the
    counts (outside, saturated per actuator, non-finite per actuator)."""
    read_next = (
        "        e[0] = (ph_xy_real)strtod(rest, &rest);\n"
        "        e[1] = (ph_xy_real)strtod(rest, NULL);\n"
        if ahead
        else ""
    )
    return f"""
#include <stdio.h>
#include <stdlib.h>
#include "ph_xy.h"
int main(void)
{{
    char line[512];
    ph_xy_t s;
    ph_xy_real d[2], e[2], v[2];
    ph_xy_init(&s);
    (void)e;
    while (fgets(line, sizeof line, stdin)) {{
        char *rest;
        d[0] = (ph_xy_real)strtod(line, &rest);
        d[1] = (ph_xy_real)strtod(rest, &rest);
{read_next}        ph_xy_step(&s, d{", e" if ahead else ""}, v);
        printf("%.17g %.17g\\n", (double)v[0], (double)v[1]);
    }}
    printf("%lu %lu %lu %lu %lu\\n", s.outside, s.a0.saturated, s.a1.saturated, s.a0.nonfinite,
           s.a1.nonfinite);
    return 0;
}}
"""


def sines_in_reach(
    comp: Any, n: int, rates: tuple[float, float], depth: float, fs: float = 1000.0
) -> np.ndarray:
    """``n`` rows of a sine per axis (``rates``, Hz) about the middle of a stage
    compensator's reach, ``depth`` of each axis's reach either side: a target inside it."""
    (x0, x1), (y0, y1) = comp.reach
    k = np.arange(n)
    wave = np.column_stack([np.sin(2 * np.pi * rates[0] * k / fs),
                            np.sin(2 * np.pi * rates[1] * k / fs)])  # fmt: skip
    return np.asarray(np.array([x0, y0]) + np.array([x1 - x0, y1 - y0]) * (0.5 + depth * wave))


@functools.cache  # fitted once per worker: the tests only read it
def fast_stage_rig() -> tuple[list[ph.ActivePI], ph.StageMap, Any]:
    """The stage with lags and modes (``XY_DYNAMIC``) on its charges: the paper's model per
    actuator with its amplifier's lag, fitted on its own voltage -> charge, and the stage's
    map (each actuator's mode found in it), from :func:`dynamic_record`."""
    rec = dynamic_record()
    models = [ph.ActivePI(10, input_dynamics="first-order").fit(rec.voltage[:, i],
                                                                rec.charge[:, i], t=rec.t)
              for i in range(2)]  # fmt: skip
    stage = ph.calibrate_stage(models, rec.voltage, rec.charge, rec.position, rec.t)
    return models, stage, rec


def stage_loop(fast: bool = False) -> tuple[Any, np.ndarray, np.ndarray]:
    """A stage's self-sensing loop (``ph.CoupledSelfSensingController``, the paper's model per
    actuator, slew-limited) at its reset state, a Lissajous with a stretch beyond x's reach
    and a NaN hold, and the charges a closed-loop run on the simulated stage read before each
    row (what a host's loop feeds back). ``fast``: the stage with lags and modes
    (:func:`fast_stage_rig`; each actuator's step then takes the next position too)."""
    from piezohyst.simulation import XY_DYNAMIC, Stage, run_stage_loop, simulate_stage

    if fast:
        models, stage, _ = fast_stage_rig()
    else:
        t, a = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=8.0)
        _, b = make_signal("multifreq", amplitude=140.0, frequency=1.9, duration=8.0)
        rec = simulate_stage(np.column_stack([a, b]), t, seed=0)
        models = [ph.ActivePI(10).fit(rec.voltage[:, i], rec.charge[:, i], t=rec.t)
                  for i in range(2)]  # fmt: skip
        stage = ph.calibrate_stage(models, rec.voltage, rec.charge, rec.position, rec.t)
    ctl = ph.CoupledSelfSensingController(
        models, stage, sample_rate=1000.0, slew_rate=2e4,
        v_min=[m.input_range_[0] for m in models], v_max=[m.input_range_[1] for m in models],
    )  # fmt: skip
    (x0, x1), (y0, y1) = ctl.reach
    phase = 2 * np.pi * np.arange(1200) / 1000.0
    own = np.column_stack([x0 + (x1 - x0) * (0.5 + 0.3 * np.sin(10 * phase)),
                           y0 + (y1 - y0) * (0.5 + 0.3 * np.sin(7.5 * phase + 0.5))])  # fmt: skip
    d = own @ stage.coupling.T + stage.offset
    d[500:540, 0] = x1 * 1.2  # beyond x's reach
    d[800, 1] = np.nan
    plant = Stage(XY_DYNAMIC if fast else None, seed=4, voltage=ctl.last_command)
    first = plant.reading.charge.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # out of reach on purpose, the map beyond its charges
        run = run_stage_loop(ctl, d, plant)
    ctl.reset()
    return ctl, d, np.vstack([first, run.charge[:-1]])


@functools.cache  # built once per worker: the tests only read it (and reset the loop)
def mode_loop() -> tuple[Any, np.ndarray, np.ndarray]:
    """One actuator's self-sensing loop in metres through an output map with a mode (the
    bench with its 150 Hz bending mode, ``calibrate_gain`` finding it), at its reset state;
    a 10 Hz triangle ramped in from rest with a NaN hold; and the charges a closed-loop run
    on the bench read before each sample."""
    from piezohyst.simulation import Bench, run_loop

    t, v = make_signal("multifreq", amplitude=140.0, frequency=2.5, duration=12.0)
    rec = ph.simulate(v, t, preset="T226-H4-203X-mode", seed=0)
    model = ph.ActivePI(10, input_dynamics="first-order").fit(rec.voltage, rec.charge, t=rec.t)
    om = ph.calibrate_gain(model, rec.voltage, rec.charge, rec.displacement, rec.t)
    ctl = ph.SelfSensingController(model, v_min=model.input_range_[0],
                                   v_max=model.input_range_[1], sample_rate=1000.0,
                                   output_map=om, slew_rate=2e4)  # fmt: skip
    lo, hi = om.displacement_range()
    k = np.arange(1500)
    tri = lo + (hi - lo) * (0.2 + 0.6 * np.abs((k / 1000.0 * 10.0) % 1.0 * 2 - 1))
    ramp = np.minimum(k / 300.0, 1.0)
    d = np.asarray(lo + ramp * (tri - lo))
    d[900] = np.nan
    bench = Bench("T226-H4-203X-mode", seed=4, voltage=ctl.last_command)
    first = bench.reading.charge
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the rest a hair below the calibrated charges
        run = run_loop(ctl, d, bench)
    ctl.reset()
    return ctl, d, np.concatenate([[first], run.charge[:-1]])


def check_stage_loop_library(
    lib_path: Any, ctl: Any, d: np.ndarray, measured: np.ndarray, py: np.ndarray,
    outside: int, runs: int = 1,
) -> None:  # fmt: skip
    """A stage loop's shared library (ctypes, as LabVIEW or MATLAB's loadlibrary call it)
    fed the targets and the charges read before each row: Python's commands (``py``) and
    counts, ``runs`` times with a reset between (the same each time)."""
    import ctypes

    lib = stage_library(lib_path)
    lib.ph_xy_process.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_long]
    handle = lib.ph_xy_new()
    target, q = np.ascontiguousarray(d), np.ascontiguousarray(measured)
    volts = np.empty_like(py)
    for _ in range(runs):
        assert lib.ph_xy_process(handle, target.ctypes.data, q.ctypes.data, volts.ctypes.data,
                                 d.shape[0]) == 0  # fmt: skip
        # tol: 1e-9 V over 1.2-1.5 s, as issue 41 states for the single loop (its integral
        # carries the C's and numba's ulp apart, well under it)
        np.testing.assert_allclose(volts, py, rtol=0, atol=1e-9)
        counts = np.zeros(7, dtype=np.uint64)
        assert lib.ph_xy_counts(handle, counts.ctypes.data) == 0
        assert counts[0] == ctl.outside_count == outside
        assert counts[[1, 4]].tolist() == ctl.nonfinite_count.tolist()
        assert counts[[2, 5]].tolist() == ctl.saturated_count.tolist()
        lib.ph_xy_reset(handle)
    assert lib.ph_xy_process(handle, target.ctypes.data, None, volts.ctypes.data, 1) == -1
    lib.ph_xy_free(handle)
