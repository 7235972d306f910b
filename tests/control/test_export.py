"""Generated C compensator: compiles cleanly and agrees with the Python compensator."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.control.export import export_c, write_c
from piezohyst.simulation import make_signal

from ..helpers import CC, HARNESS

# these tests drive targets past the voltage and slew limits on purpose (safety, exactness
# where no limit acts); that the limits then say so is tested in test_records.py
pytestmark = [
    pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning"),
    pytest.mark.skipif(CC is None, reason="no C compiler on this machine"),
    pytest.mark.kernels,
]


def fitted_model() -> ph.ActivePI:
    rec = ph.simulate(duration=8.0, seed=1)
    return ph.ActivePI(12).fit(rec.voltage, rec.charge, t=rec.t)


def desired_values(model: ph.ActivePI) -> np.ndarray:
    rng = np.random.default_rng(0)
    t = np.arange(3000) / 1000.0
    v = 70 * (1 - np.cos(2 * np.pi * 0.7 * t)) * (0.6 + 0.4 * np.sin(2 * np.pi * 0.13 * t))
    q = model.hysteresis_.predict(v)
    q[::97] = np.nan
    q[5::211] = np.inf
    q[7::301] = -1e30  # unreachable: saturates (and representable in float)
    q[9::401] = 1e-3
    return np.concatenate([q, q[:500] + 1e-8 * rng.standard_normal(500)])


def run_c(
    tmp_path: Path,
    comp: ph.Compensator,
    values: np.ndarray,
    precision: str,
    flags: tuple[str, ...] = ("-O2",),
) -> tuple:
    c_path, h_path = write_c(comp, tmp_path / "ph_comp.c", precision=precision)  # type: ignore[arg-type]
    (tmp_path / "main.c").write_text(HARNESS.replace("NAME", "ph_comp"))
    exe = tmp_path / "comp"
    subprocess.run(
        [
            CC,
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            *flags,
            str(c_path),
            str(tmp_path / "main.c"),
            "-o",
            str(exe),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    text = "\n".join(repr(float(v)) for v in values) + "\n"
    out = subprocess.run([str(exe)], input=text, check=True, capture_output=True, text=True)
    lines = out.stdout.split("\n")
    cmds = np.array([float(x) for x in lines[: values.size]])
    counters = tuple(int(x) for x in lines[values.size].split())
    assert h_path.exists()
    return cmds, counters


@pytest.mark.parametrize("slew", [None, 2000.0])
def test_double_matches_python(tmp_path: Path, slew: float | None) -> None:
    model = fitted_model()
    kwargs = {} if slew is None else {"slew_rate": slew, "sample_rate": 1000.0}
    comp = ph.Compensator(model, v_min=0.0, v_max=140.0, **kwargs)  # type: ignore[arg-type]
    values = desired_values(model)
    c_cmds, (nonfinite, saturated, extrapolated) = run_c(tmp_path, comp, values, "double")
    py = comp.process(values)
    # tol: C and numba round apart (FMA, order); 1e-9 V covers a replay of ulp differences over the
    # record
    np.testing.assert_allclose(c_cmds, py, rtol=0, atol=1e-9)
    assert (nonfinite, saturated) == (comp.nonfinite_count, comp.saturated_count)
    assert nonfinite > 0 and saturated > 0 and extrapolated == comp.extrapolated_count == 0
    assert np.all((c_cmds >= 0.0) & (c_cmds <= 140.0))


@pytest.mark.parametrize("precision", ["double", "float"])
def test_nan_guard_survives_fast_math(tmp_path: Path, precision: str) -> None:
    """-ffast-math lets a compiler drop isfinite(): the guard must not depend on it."""
    model = fitted_model()
    comp = ph.Compensator(model, v_min=0.0, v_max=140.0)
    values = desired_values(model)
    cmds, (nonfinite, *_) = run_c(tmp_path, comp, values, precision, ("-O2", "-ffast-math"))
    bad = ~np.isfinite(values)
    assert nonfinite == int(bad.sum()) > 0
    held = np.flatnonzero(bad)
    held = held[held > 0]
    np.testing.assert_array_equal(cmds[held], cmds[held - 1])  # the last command, not 140 V
    assert np.all(np.isfinite(cmds)) and cmds.min() >= 0.0 and cmds.max() <= 140.0
    # tol: float's precision on commands up to 140 V, a few operations per step
    np.testing.assert_allclose(cmds, comp.process(values), rtol=0, atol=1e-3)


def test_float_matches_python(tmp_path: Path) -> None:
    model = fitted_model()
    comp = ph.Compensator(model, v_min=0.0, v_max=140.0)
    values = desired_values(model)
    c_cmds, _ = run_c(tmp_path, comp, values, "float")
    py = comp.process(values)
    # tol: float's 6e-8 relative precision, a few operations per step
    np.testing.assert_allclose(c_cmds, py, rtol=1e-4, atol=1e-4 * 140.0)
    assert np.all((c_cmds >= 0.0) & (c_cmds <= 140.0))


def test_displacement_domain_and_prefix(tmp_path: Path) -> None:
    model = fitted_model()
    comp = ph.Compensator(model, v_min=0.0, v_max=140.0, domain="displacement", gain=125.0)
    code = export_c(comp, prefix="stage_x")
    assert "stage_x_step" in code.source and "typedef double stage_x_real;" in code.header
    d = 125.0 * (
        model.hysteresis_.predict(np.linspace(0, 120, 50)) - model.hysteresis_.predict([0.0])[0]
    )
    c_cmds, _ = run_c(tmp_path, comp, d, "double")
    # tol: C and numba round apart (FMA, order); 1e-9 V covers a replay of ulp differences over the
    # record
    np.testing.assert_allclose(c_cmds, comp.process(d), rtol=0, atol=1e-9)


def test_bad_export_arguments() -> None:
    comp = ph.Compensator(fitted_model(), v_min=0.0, v_max=140.0)
    with pytest.raises(ph.ParameterError, match="precision"):
        export_c(comp, precision="half")  # type: ignore[arg-type]
    with pytest.raises(ph.ParameterError, match="C identifier"):
        export_c(comp, prefix="3-bad")


@pytest.mark.parametrize("name", ["duhem", "bouc_wen", "preisach"])
def test_a_packed_cores_loop_is_refused_in_c_not_dropped(name: str, tmp_path: Path) -> None:
    """The C of the self-sensing controller is play operators' alone: on a Preisach, Duhem
    or Bouc-Wen core its export said nothing and wrote the feedforward step (no reading, the
    feedback gone). It is refused by name, on every host (C, shared library, FMU)."""
    from piezohyst.control.export import write_fmu, write_shared

    model = ph.load_model(Path(__file__).parents[1] / "fixtures" / "schema2" / f"{name}.json")
    lo, hi = model.input_range_
    ctl = ph.SelfSensingController(model, v_min=lo, v_max=hi, sample_rate=250.0)
    for write in (write_c, write_shared, write_fmu):
        with pytest.raises(ph.ParameterError, match=r"covers play-operator models.*Python"):
            write(ctl, tmp_path / "ph_loop.c")  # type: ignore[operator]
    assert not list(tmp_path.iterdir())  # nothing written
    # the feedforward compensator of the same model still exports
    assert write_c(ph.Compensator(model, v_min=lo, v_max=hi, sample_rate=250.0),
                   tmp_path / "ph_comp.c")[0].exists()  # fmt: skip


CONTROLLER_HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include "NAME.h"
int main(void)
{
    char line[256];
    NAME_t s;
    NAME_init(&s);
    while (fgets(line, sizeof line, stdin)) {
        char *rest;
        NAME_real d = (NAME_real)strtod(line, &rest);
        NAME_real m = (NAME_real)strtod(rest, &rest);
#if NEXT
        NAME_real e = (NAME_real)strtod(rest, NULL); /* the next desired value (a mode) */
        printf("%.17g\n", (double)NAME_step(&s, d, m, e));
#else
        printf("%.17g\n", (double)NAME_step(&s, d, m));
#endif
    }
    printf("%lu %lu %lu %lu %lu\n", s.nonfinite, s.saturated, s.faults, s.refreshes,
           s.extrapolated);
    return 0;
}
"""


def _run_controller_c(
    tmp_path: Path, c_path: Path, desired: np.ndarray, measured: np.ndarray,
    flags: tuple[str, ...], nxt: np.ndarray | None = None,
) -> tuple[np.ndarray, tuple[int, ...]]:  # fmt: skip
    """The exported controller compiled with CONTROLLER_HARNESS, run on (desired, measured;
    with ``nxt``, each sample's next desired value too, for an output map's mode): its
    commands and its counters (nonfinite, saturated, faults, refreshes, extrapolated)."""
    (tmp_path / "main.c").write_text(CONTROLLER_HARNESS.replace("NAME", "ph_ctl"))
    exe = tmp_path / "ctl"
    subprocess.run(
        [CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", *flags,
         f"-DNEXT={int(nxt is not None)}", str(c_path), str(tmp_path / "main.c"), "-o", str(exe)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    cols = [desired, measured] if nxt is None else [desired, measured, nxt]
    text = "".join(" ".join(repr(float(x)) for x in row) + "\n" for row in zip(*cols, strict=True))
    out = subprocess.run([str(exe)], input=text, check=True, capture_output=True, text=True)
    lines = out.stdout.split("\n")
    c_cmds = np.array([float(x) for x in lines[: desired.size]])
    return c_cmds, tuple(int(x) for x in lines[desired.size].split())


@pytest.mark.parametrize(
    ("flags", "refresh", "samples", "atol", "curved"),
    # The kernels may contract and reassociate (FASTMATH), so compiled Python and C part by
    # an ulp from the first sample, differently on each CPU (pure Python equals the C to the
    # bit); a replay of recorded measurements (no plant to answer) integrates that rounding:
    # measured 7.4e-9 V over 3.5 s on an AMD EPYC, under 1e-9 V on the machines before it.
    # The bounds leave a factor of about 7; a wrong term or branch costs volts.
    [
        (("-O2",), False, 3500, 5e-8, False),
        (("-O2", "-ffast-math"), False, 3500, 5e-8, False),
        # the refresh's regression turns rounding into a bias difference (~1e-10 relative)
        # that the replay then integrates (3.4e-10 V over 1.7 s on the EPYC)
        (("-O2",), True, 1700, 5e-9, False),
        # targets in metres through a curved map (strain g (q + 0.15 q^2 / q_ref)): its
        # inverse in C (Newton) rounds apart from Python's by an ulp of the charge
        (("-O2",), False, 3500, 5e-8, True),
        # in metres through a linear map with a mode (150 Hz, 5 % damping), its inverse on
        # the map's charges: the C does not fold that map, so that it rounds as Python (the
        # replay amplifies any difference in the targets: folded, the C parted by 3e-7 V)
        (("-O2",), False, 3500, 5e-8, "mode"),
    ],
)
@pytest.mark.filterwarnings("ignore::piezohyst.errors.ExtrapolationWarning")  # far targets
def test_controller_matches_python(
    tmp_path: Path, flags: tuple[str, ...], refresh: bool, samples: int, atol: float,
    curved: bool | str,
) -> None:  # fmt: skip
    model = fitted_model()
    leak = ph.Leakage(6e-10, 2e-10, 3e-11, scale=140.0, discharge=2e-5)
    kw: dict[str, object] = {"leakage": leak, "slew_rate": 2e4, "refresh_leakage": refresh,
                             "hold_time": 0.2}  # fmt: skip
    desired = desired_values(model)[:samples]
    if curved:  # the same charges, asked for in metres through a monotone quadratic map
        reach = model.hysteresis_.predict(np.linspace(0.0, 140.0, 281))
        lo, hi = float(reach.min()), float(reach.max())
        c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
        if curved == "mode":  # or a linear one through a mode
            om = ph.OutputMap((125.0 * c, 125.0 * h), c, h, ((0.0,) * 2,) * 2, (lo, hi),
                              mode_f0=150.0, mode_zeta=0.05, mode_dt=1e-3)  # fmt: skip
        else:
            om = ph.OutputMap((125.0 * c, 125.0 * h, 0.15 * 125.0 * h * h / hi), c, h,
                              ((0.0,) * 3,) * 3, (lo, hi))  # fmt: skip
            assert om.monotone and om.order == 2
        with np.errstate(invalid="ignore"):  # the NaN and inf targets stay what they are
            kw["output_map"], desired = om, om.predict(desired)
    ctl = ph.SelfSensingController(model, v_min=0.0, v_max=140.0, sample_rate=1000.0, **kw)  # type: ignore[arg-type]
    desired[1000:1600] = desired[999]  # a hold: the online refresh acts
    c_path, _ = write_c(ctl, tmp_path / "ph_ctl.c")  # the state before any step
    # the measurements a plant gives in the loop: 5 % more charge than the model, a leak,
    # noise, and dropped or broken readings
    rng = np.random.default_rng(2)
    plant = model.hysteresis_
    state = None
    reading = 0.0
    measured = np.empty_like(desired)
    py = np.empty_like(desired)
    nxt = np.append(desired[1:], np.nan) if curved == "mode" else None
    assert ctl.previews == (1 if curved == "mode" else 0)
    for k, d in enumerate(desired):
        measured[k] = np.nan if k % 53 == 0 else (np.inf if k % 151 == 3 else reading)
        py[k] = ctl.step(d, measured[k], None if nxt is None else nxt[k : k + 1])
        run = plant.propagate(np.array([py[k]]), None, state)
        state = run.state
        reading = 1.05 * float(run.output[0]) + 4e-11 * k + 1e-9 * rng.standard_normal()
    c_cmds, counters = _run_controller_c(tmp_path, c_path, desired, measured, flags, nxt)
    # tol: as chosen per case above (a replay of ulp differences)
    np.testing.assert_allclose(c_cmds, py, rtol=0, atol=atol)
    assert counters == (
        ctl.nonfinite_count,
        ctl.saturated_count,
        ctl.measurement_faults,
        ctl.leakage_refreshes,
        ctl.extrapolated_count,
    )
    assert ctl.measurement_faults > 0 and (ctl.leakage_refreshes > 0) == refresh


def test_a_c_name_that_clashes_with_the_steps_own_is_refused(tmp_path: Path) -> None:
    from piezohyst.control.export import write_c

    h = ph.PIHysteresis([0.0, 20.0], [1e-8, 5e-9])
    comp = ph.Compensator(ph.ClassicalPI.from_operator(h), v_min=0.0, v_max=140.0)
    for name in ("core", "real", "hysteresis"):  # core_step, real_t, hysteresis_step are taken
        with pytest.raises(ph.ParameterError, match="clashes with the exported step"):
            write_c(comp, tmp_path / f"{name}.c")
    write_c(comp, tmp_path / "ph_comp.c")  # the name the docs use


@pytest.mark.filterwarnings("ignore::piezohyst.errors.LimitWarning")  # the replay asks beyond
def test_the_controller_through_an_amplifiers_lag_matches_python(tmp_path: Path) -> None:
    """Issue 55: the self-sensing loop inverts the model's input lag; its C does the same (the
    leakage at the piezo's voltage, a held sample still moving the lag). A whole-sample delay
    would need the preview the C step has no room for: refused by name."""
    t, v = make_signal("multifreq", amplitude=140.0, frequency=0.5, duration=12.0)
    rec = ph.simulate(v, t, preset="T226-H4-203X-amp4ms", seed=0)
    model = ph.ActivePI(8, input_dynamics="first-order").fit(rec.voltage, rec.charge, t=rec.t)
    lo, hi = model.input_range_
    leak = ph.Leakage(6e-10, 2e-10, 3e-11, scale=140.0, discharge=2e-5)
    ctl = ph.SelfSensingController(model, v_min=lo, v_max=hi, sample_rate=1000.0, leakage=leak,
                                   slew_rate=2e4)  # fmt: skip
    top, rest = (float(q) for q in model.operator_.predict(np.array([hi, lo])))
    _, shape = make_signal("fixed", amplitude=1.0, frequency=40.0, duration=2.0)
    desired = rest + (top - rest) * (-0.05 + 1.1 * shape)  # beyond the reach at both ends
    desired[[100, 700]] = [np.nan, np.inf]
    c_path, _ = write_c(ctl, tmp_path / "ph_ctl.c")
    rng = np.random.default_rng(3)
    measured = desired * 1.03 + 2e-9 * rng.standard_normal(desired.size)
    measured[::97] = np.nan
    py = np.array([ctl.step(d, m) for d, m in zip(desired, measured, strict=True)])
    c_cmds, counters = _run_controller_c(tmp_path, c_path, desired, measured, ("-O2",))
    # tol: a replay of ulp differences (FASTMATH kernels against the C), as the test above
    np.testing.assert_allclose(c_cmds, py, rtol=0, atol=5e-8)
    assert counters[:3] == (ctl.nonfinite_count, ctl.saturated_count, ctl.measurement_faults)
    assert ctl.nonfinite_count == 2 and ctl.saturated_count > 0 and ctl.measurement_faults > 0
    delayed = ph.ActivePI(8, input_dynamics="delay+first-order").fit(
        rec.voltage[3:], rec.charge[:-3], t=rec.t[3:]
    )
    with pytest.raises(ph.ParameterError, match="not a delay of 3 whole samples"):
        write_c(ph.SelfSensingController(delayed, v_min=lo, v_max=hi, sample_rate=1000.0),
                tmp_path / "ph_delayed.c")  # fmt: skip
