"""The exported C is C: shipped files, compiled on their own, every configuration."""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import piezohyst as ph
from piezohyst.control.export import export_c
from piezohyst.simulation import make_signal

SRC = Path(ph.__file__).parent
C_DIR = SRC / "model" / "cores" / "c"
COMPILERS = [c for c in (shutil.which("gcc"), shutil.which("clang")) if c]
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-c"]
#: a C function definition or a C for loop inside a Python string: C source that should
#: live in a .c file (the generated preamble holds declarations and data only)
C_IN_STRING = re.compile(
    r"\b(static|void|real_t|int|double|float|unsigned)\s+\**\w+\s*\([^)]*\)\s*\{"
    r"|\bfor\s*\([^;)]*;[^;)]*;"
)


def test_no_python_module_holds_c_source() -> None:
    found = []
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                if C_IN_STRING.search(node.value):
                    found.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert not found, found


def test_the_c_files_ship_with_the_package() -> None:
    names = {p.name for p in C_DIR.iterdir()}
    assert {"play.c", "play.h", "packed.c", "packed.h", "ieee.c", "mode.c", "duhem.c",
            "preisach.c", "preisach_grid.c", "boucwen.c"} <= names  # fmt: skip
    text = (SRC.parent.parent / "pyproject.toml").read_text()
    assert '"model/cores/c/*.c", "model/cores/c/*.h"' in text
    # the hosts' wrappers: the shared library's API, the MEX gateway, the FMI 2.0 functions
    hosts = {p.name for p in (SRC / "control" / "export" / "c").iterdir()}
    assert {"shared_api.c", "mex_gateway.c", "fmi2_cs.c"} <= hosts
    assert '"control/export/c/*.c"' in text


def _record() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t, v = make_signal("decaying", duration=6.0, rate=1000.0)
    rec = ph.simulate(v, t)
    return rec.voltage, rec.charge, rec.t


def _configurations() -> dict[str, object]:
    v, q, t = _record()
    lo, hi = float(v.min()), float(v.max())
    active = ph.ActivePI(6).fit(v, q, t=t)
    pre = ph.PreisachModel(nodes=8, creep=(0.05,), relaxation=0.2, relaxation_nodes=5)
    cfg: dict[str, object] = {
        "play": ph.Compensator(active, v_min=lo, v_max=hi),
        "play-slew": ph.Compensator(active, v_min=lo, v_max=hi, slew_rate=1e4, sample_rate=1e3),
        "play-controller": ph.SelfSensingController(active, v_min=lo, v_max=hi, sample_rate=1e3),
        "duhem": ph.Compensator(ph.DuhemModel(grid=(4, 3)).fit(v, q, t=t), v_min=lo, v_max=hi),
        "bouc-wen": ph.Compensator(ph.BoucWenModel().fit(v, q, t=t), v_min=lo, v_max=hi),
        "preisach-relaxing-creep": ph.Compensator(
            pre.fit(v, q, t=t), v_min=lo, v_max=hi, sample_rate=1e3
        ),
        "play-asymmetry-creep": ph.Compensator(
            ph.GeneralizedPI(6, creep=(0.05, 0.5), growth_terms=()).fit(v, q, t=t),
            v_min=lo,
            v_max=hi,
            slew_rate=1e4,
            sample_rate=1e3,
        ),
        "play-asymmetry": ph.Compensator(
            ph.GeneralizedPI(6, growth_terms=()).fit(v, q, t=t), v_min=lo, v_max=hi
        ),
    }
    # the controller in metres through a map with a mode, linear (not folded) and curved
    reach = active.hysteresis_.predict(np.linspace(lo, hi, 101))
    c, h = 0.5 * float(reach.min() + reach.max()), 0.5 * float(np.ptp(reach))
    mode = {"mode_f0": 150.0, "mode_zeta": 0.05, "mode_dt": 1e-3}
    for name, coef in (("linear", (125.0 * c, 125.0 * h)),
                       ("curved", (125.0 * c, 125.0 * h, 3.0 * h))):  # fmt: skip
        om = ph.OutputMap(coef, c, h, ((0.0,) * len(coef),) * len(coef),
                          (float(reach.min()), float(reach.max())), **mode)  # fmt: skip
        cfg[f"play-controller-{name}-map-mode"] = ph.SelfSensingController(
            active, v_min=lo, v_max=hi, sample_rate=1e3, output_map=om
        )
    return cfg


@pytest.mark.skipif(not COMPILERS, reason="no C compiler on this machine")
@pytest.mark.parametrize("precision", ["double", "float"])
def test_every_configuration_compiles_warning_free(tmp_path: Path, precision: str) -> None:
    """Each exported configuration, with gcc (and clang where present), -Werror."""
    for name, comp in _configurations().items():
        code = export_c(comp, precision=precision, prefix="ph_x")  # type: ignore[arg-type]
        (tmp_path / "ph_x.h").write_text(code.header)
        source = tmp_path / "ph_x.c"
        source.write_text(code.source)
        for cc in COMPILERS:
            run = subprocess.run([cc, *FLAGS, str(source), "-o", str(tmp_path / "ph_x.o")],
                                 capture_output=True, text=True, check=False)  # fmt: skip
            assert run.returncode == 0, f"{name} {precision} {cc}: {run.stderr}"


def _readme_needs() -> dict[str, set[str]]:
    """The fragments each fragment needs before it, as the C folder's README states them."""
    needs: dict[str, set[str]] = {}
    for line in (C_DIR / "README.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 4 and cells[0].startswith("`") and cells[0] != "fragment":
            needs[cells[0].strip("`")] = set(re.findall(r"`([\w.]+\.[ch])`", cells[2]))
    return needs


@pytest.mark.skipif(not COMPILERS, reason="no C compiler on this machine")
def test_each_fragment_compiles_with_the_preamble_and_what_the_readme_says_it_needs(
    tmp_path: Path,
) -> None:
    """Every C fragment of every exported configuration compiles on its own: the generated
    preamble (the header, the names, the engine's constants), then only the fragments the
    README lists as its needs, then the fragment (issue 56). A need the README forgets fails
    to compile; unused helpers of a listed need are allowed (-Wno-unused-function)."""
    needs = _readme_needs()
    shipped = {p.name: p.read_text() for p in C_DIR.iterdir() if p.suffix in (".c", ".h")}
    assert set(needs) == {n for n in shipped if n not in ("play.h", "packed.h", "step.h")}
    v, q, t = _record()
    configs = _configurations()
    lo, hi = float(v.min()), float(v.max())
    lagged = ph.ActivePI(6, input_dynamics="first-order").fit(v, q, t=t)
    configs["play-dynamic"] = ph.Compensator(lagged, v_min=lo, v_max=hi, sample_rate=1e3)
    configs["play-dynamic-controller"] = ph.SelfSensingController(
        lagged, v_min=lo, v_max=hi, sample_rate=1e3
    )
    seen: set[str] = set()
    for name, comp in configs.items():
        code = export_c(comp, precision="double", prefix="ph_x")  # type: ignore[arg-type]
        (tmp_path / "ph_x.h").write_text(code.header)
        src, order, at, first = code.source, [], 0, -1
        while True:  # the fragments in the order the export placed them
            hits = [(i, n) for n, text in shipped.items() if (i := src.find(text, at)) >= 0]
            if not hits:
                break
            i, n = min(hits)
            first = i if first < 0 else first
            order.append(n)
            at = i + len(shipped[n])
        preamble = src[:first]
        for k, fragment in enumerate(order):
            listed = [n for n in order[:k] if n in needs[fragment]]
            unit = tmp_path / "unit.c"
            unit.write_text(preamble + "\n".join(shipped[n] for n in [*listed, fragment]))
            run = subprocess.run(
                [COMPILERS[0], *FLAGS, "-Wno-unused-function", "-fsyntax-only", str(unit)],
                capture_output=True, text=True, check=False,
            )  # fmt: skip
            assert run.returncode == 0, f"{name}: {fragment} after {listed}: {run.stderr[:400]}"
            seen.add(fragment)
    # every fragment but the mode's is exercised here (the mode's C: tests/model/test_dynamics.py)
    assert seen >= set(needs) - {"mode.c"}, set(needs) - seen
