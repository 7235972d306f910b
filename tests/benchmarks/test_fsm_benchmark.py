"""The fine-steering-mirror benchmark's script (issue 57) on a small generated mirror: three
inputs, three outputs, a few hundred samples, four realizations (a 3 x 3 response per line
needs three to be determined: the benchmark's own groups of three) and two periods per
level, in the benchmark's own file layout. The benchmark's data never enter the tests (its training
sets are not the project's to ship, its test sets are not to be looked at); this holds the
script's pipeline and its score to what they claim: the frequency responses it identifies
are the mirror's, and its score of a model is the benchmark's."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
N = 256  # samples per period
R = 4  # realizations: three to train, one held out
FS = 6400.0
LEVELS = (100, 200, 300)


def _mirror(u: np.ndarray, gain: float) -> np.ndarray:
    """Three outputs of three inputs through one lightly damped mode each and 5 % cross
    terms, the steady state over a period (u: (N, 3)); ``gain`` the level's stiffness."""
    f = np.fft.rfftfreq(u.shape[0], 1 / FS)
    modes = np.array([900.0, 1200.0, 1500.0])
    coupling = np.array([[1.0, 0.05, -0.03], [0.04, 1.0, 0.05], [-0.05, 0.03, 1.0]])
    h = gain / (1 - (f[:, None] / modes) ** 2 + 0.06j * f[:, None] / modes)  # (F, 3)
    spectrum = np.fft.rfft(u, axis=0) * h  # each input's own mode
    return np.fft.irfft(spectrum @ coupling.T, n=u.shape[0], axis=0)


def _write(folder: Path, seed: int = 0) -> None:
    """u/y_{level}mV_train.npy, shape (N, 3, R realizations, 2 periods): random-phase
    multisines on every line but 0 and N/2 (as the benchmark's excite 0.78-3000 Hz of 3200),
    the gain 2 % higher per level (what hysteresis does)."""
    rng = np.random.default_rng(seed)
    lines = np.arange(1, N // 2)
    for k, level in enumerate(LEVELS):
        u = np.empty((N, 3, R, 2))
        y = np.empty_like(u)
        for r in range(R):
            spec = np.zeros((N // 2 + 1, 3), dtype=complex)
            spec[lines] = np.exp(2j * np.pi * rng.random((lines.size, 3)))
            one = np.fft.irfft(spec, n=N, axis=0)
            one *= level * 1e-3 / one.std(axis=0)
            out = _mirror(one, 1.0 + 0.02 * k)
            for p in range(2):
                u[:, :, r, p] = one
                y[:, :, r, p] = out + 1e-4 * out.std() * rng.standard_normal(out.shape)
        np.save(folder / f"u_{level}mV_train.npy", u)
        np.save(folder / f"y_{level}mV_train.npy", y)


def test_the_script_scores_a_generated_mirror(tmp_path: Path) -> None:
    _write(tmp_path)
    cmd = [sys.executable, str(ROOT / "benchmarks" / "fsm_benchmark.py"), str(tmp_path),
           "--train", "0,1,2", "--validate", "3", "--operators", "3", "--rounds", "2"]  # fmt: skip
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=600).stdout
    rows = {}
    for line in out.splitlines():  # the score table: a 56-character name, then per level
        figures = line[56:].split()[:3]
        if len(figures) == 3 and all(f.replace(".", "", 1).isdigit() for f in figures):
            rows[line[:56].strip()] = [float(f) for f in figures]
    linear = rows["linear (nonparametric FRF), all levels"]
    own = rows["linear FRF, each level alone (own level)"]
    noise = rows["noise floor (periods apart, /sqrt 2)"]
    # tol: the generated mirror is linear at each level, 2 % stiffer per level: one response
    # per level is exact up to the 1e-4 noise and the line's leakage-free estimate (measured
    # 0.03-0.10 %), and the pooled response misses the levels by a share of the 2 % steps
    # (measured 2.8 / 1.2 / 1.1 %: the loudest level weighs most in the least squares)
    assert max(own) < 0.5 and max(noise) < 0.05
    assert all(0.5 < x < 5.0 for x in linear) and linear[0] > linear[2]
    # the library's StructureModel: the mirror's three modes, in state space of order 6,
    # each level weighed by its own spread, so the compromise sits at the middle level
    # (measured 2.16 / 0.96 / 2.20 %); the operators in the loop are not kept (linear mirror)
    structure = [v for k, v in rows.items() if k.startswith("StructureModel order 6, ")]
    assert len(structure) == 2 and "StructureModel order 6, operators asked, none kept" in rows
    ours = rows["StructureModel order 6, operators asked, none kept"]
    assert max(ours) < max(linear) and ours[1] < min(ours[0], ours[2])
    described = [line for line in out.splitlines() if "StructureModel: 3 inputs" in line]
    assert len(described) == 2
    for d in described:  # the mirror's modes, on the model's four digits
        found = [(float(f), float(z)) for f, z in re.findall(r"([\d.]+) Hz \(([\d.]+)\)", d)]
        # tol: the 1e-4 noise moves a mode by far less than 0.1 Hz and its damping by 1e-4
        assert len(found) == 3 and all(
            abs(f - f0) < 0.5 and abs(z - 0.03) < 0.002
            for (f, z), f0 in zip(found, (900.0, 1200.0, 1500.0), strict=True)
        )
    peaks = [
        line.split(":")[1] for line in out.splitlines() if line.strip()[:3] in ("100", "200", "300")
    ]
    # the resonances, on the 25 Hz grid of the lines: the mirror's own 900, 1200, 1500 Hz
    assert len(peaks) == 3 and all(p.split(",") == [" 900.0", " 1200.0", " 1500.0"] for p in peaks)


def test_overlapping_realizations_are_refused(tmp_path: Path) -> None:
    _write(tmp_path)
    cmd = [sys.executable, str(ROOT / "benchmarks" / "fsm_benchmark.py"), str(tmp_path),
           "--train", "0,1", "--validate", "1,3"]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert res.returncode != 0 and "share a realization" in res.stderr
    assert pytest.importorskip("numpy") is np
