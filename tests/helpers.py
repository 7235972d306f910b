"""What several test modules use: the CLI run in this process, its one-line errors, the C
harness that runs an exported step, and a lab file's layout. Test modules import these from
here, not from one another."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path
from typing import Any

import numba
import numpy as np
from click.testing import CliRunner, Result

from piezohyst.cli import main
from piezohyst.control.export import write_c

#: numba's JIT is off: the run that measures the kernels' Python lines (``make test``'s
#: second run, tests/kernel_paths.txt). A module's fixtures may then fit on a shorter record:
#: the tests that run there check structural properties (chunks, files, counts, inversion,
#: C export, the loop), which hold for any fitted model; the tests that need a long
#: record's accuracy are not on that list
UNCOMPILED = bool(numba.config.DISABLE_JIT)

#: the system C compiler, or None (the C tests skip without one)
CC = shutil.which("cc") or shutil.which("gcc")

HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include "NAME.h"
int main(void)
{
    char line[128];
    NAME_t s;
    NAME_init(&s);
    while (fgets(line, sizeof line, stdin)) {
        NAME_real d = (NAME_real)strtod(line, NULL);
        printf("%.17g\n", (double)NAME_step(&s, d));
    }
    printf("%lu %lu %lu\n", s.nonfinite, s.saturated, s.extrapolated);
    return 0;
}
"""


def run(*args: str | Path) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args])


def assert_clean_error(res: Result, *fragments: str, code: int = 1) -> None:
    assert res.exit_code == code, res.output
    err = res.stderr.strip()
    assert "Traceback" not in res.output and "Traceback" not in err
    if code == 1:
        assert len(err.splitlines()) == 1, err
        for fragment in fragments:
            assert fragment in err, err


def one_line_error(res: Result, *fragments: str) -> str:
    assert res.exit_code == 1, res.output
    err = res.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in res.output, err
    for fragment in fragments:
        assert fragment in err, err
    return err


def compare_c_with_python(
    comp: Any, desired: np.ndarray, tmp_path: Path, precision: str, hi: float, name: str = "ph_comp"
) -> np.ndarray:
    """Export ``comp`` to C as ``name``, compile it strictly, run ``desired`` through both: the
    commands agree to 1e-9 V in double (to float precision in float), and so do the counters."""
    c_path, _ = write_c(comp, tmp_path / f"{name}.c", precision=precision)  # type: ignore[arg-type]
    (tmp_path / "main.c").write_text(HARNESS.replace("NAME", name))
    exe = tmp_path / name
    cmd = [CC or "cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2",
           str(c_path), str(tmp_path / "main.c"), "-o", str(exe), "-lm"]  # fmt: skip
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    fed = desired
    m = int(getattr(comp, "delay_samples", 0))
    if m:  # the C step is given the value desired m samples on (its header says so), as
        # process() previews its block: beyond the end extrapolated linearly
        ahead = desired[-1] + np.arange(1, m + 1) * (desired[-1] - desired[-2])
        fed = np.concatenate([desired, ahead])[m:]
    text = "\n".join(repr(float(x)) for x in fed) + "\n"
    out = subprocess.run([str(exe)], input=text, check=True, capture_output=True, text=True)
    lines = out.stdout.split("\n")
    c_cmds = np.array([float(x) for x in lines[: desired.size]])
    py = comp.process(desired)
    atol = 1e-9 if precision == "double" else 1e-4 * hi
    # tol: C and numba round apart (FMA, order, libm); double: 1e-9 V covers a replay of ulp
    # differences; float: its 1e-7 precision over the range
    np.testing.assert_allclose(c_cmds, py, rtol=0, atol=atol)
    counts = tuple(int(x) for x in lines[desired.size].split())
    assert counts == (comp.nonfinite_count, comp.saturated_count, comp.extrapolated_count)
    return c_cmds


def aixacct_like(path: Path, rec: object) -> None:
    """A file laid out as aixACCT TF Analyzer exports are (Latin-1, 'Table N' blocks)."""
    t, v, q = rec.t[:400], rec.voltage[:400], rec.charge[:400] * 1e6  # type: ignore[attr-defined]
    lines = ["PiezoResult", "", "Table 1",
             "Table No [#]\tVc+ [V]\tPr+ [uC/cm2]\t", "1.000000e+000\t1.1e+003\t1.3e+001\t",
             "", "ProgramMode: 0", "", "Table 1", "Timestamp: 08/23/2019 14:17:12",
             "SampleName: TEST", "Area [mm2]: 60",
             "Time [s]\tV+ [V]\tV- [V]\tP1 [µC]\t"]  # fmt: skip
    lines += [
        f"{a:.6e}\t{b:.6e}\t0.000000e+000\t{c:.6e}\t" for a, b, c in zip(t, v, q, strict=True)
    ]
    lines += ["", "Table 2", "SampleName: TEST2", "Time [s]\tV+ [V]\tV- [V]\tP1 [µC]\t"]
    lines += [
        f"{a:.6e}\t{b:.6e}\t0.000000e+000\t{c:.6e}\t"
        for a, b, c in zip(t, v / 2, q / 2, strict=True)
    ]
    path.write_bytes("\r\n".join(lines).encode("latin-1"))
