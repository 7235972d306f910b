"""Hypothesis profiles.

``ci`` (the default, and what ``make test`` runs): derandomized, so every run of the suite
tries the same examples on every machine, and no example database, so nothing a previous
run found changes what this one tries. With the JIT off (``make test``'s second run, which
exists to see the kernels' Python lines, each example interpreted and traced by coverage)
the ``ci`` profile tries a quarter of the examples: the compiled run has searched with all
of them, and the first examples Hypothesis tries (the shrunk, simplest, and edge cases)
reach the lines. ``dev`` (``HYPOTHESIS_PROFILE=dev``): random, five times the examples,
with the database, for a longer hunt before a change lands. A ``--hypothesis-seed`` on the
command line picks the examples of either.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# Kernels compile on first call (numba): no per-example deadline.
_COMMON = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow]}
_JIT_OFF = os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")
settings.register_profile("ci", max_examples=15 if _JIT_OFF else 60, derandomize=True,
                          database=None, **_COMMON)  # fmt: skip
settings.register_profile("dev", max_examples=300, **_COMMON)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# One BLAS (and OpenMP) thread per xdist worker: `make test` runs as many workers as cores,
# and each worker's BLAS starting a thread per core as well oversubscribes them; OpenBLAS's
# spinning threads then wait on each other. Measured on the 2-core CI machine: the compiled
# pass took 167 s with the default threads and 66 s with one (2026-11-25). Set before the
# commands the docs' tests start, too (they inherit the environment).
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


#: Module fixtures that fit long records to measure accuracy: seconds compiled, half a minute
#: each with numba's JIT off. Their tests are ``heavy``.
HEAVY_FIXTURES = {"lagged_bench", "mode_models"}


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "kernels: a module whose tests run the numba kernels; make test runs them again with "
        "the JIT off, under coverage, to measure the kernels' Python lines (a compiled kernel "
        "is invisible to coverage), all but the heavy ones",
    )
    config.addinivalue_line(
        "markers",
        "kernel_paths: listed in tests/kernel_paths.txt: the tests of the kernels modules that "
        "reach every kernel line; make test runs them with the JIT off",
    )
    config.addinivalue_line(
        "markers",
        "heavy: a long fit or run that checks accuracy, not a kernel's paths: compiled only, "
        "and not traced by coverage (pytest-cov's no_cover)",
    )


#: The tests ``make test`` runs again with the JIT off (tests/kernel_paths.txt says how chosen).
KERNEL_PATHS = [
    line
    for line in (Path(__file__).with_name("kernel_paths.txt")).read_text().splitlines()
    if line and not line.startswith("#")
]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    listed = set(KERNEL_PATHS)
    for item in items:
        if HEAVY_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.heavy)
        if item.get_closest_marker("heavy"):  # accuracy, not paths: not traced by coverage
            item.add_marker(pytest.mark.no_cover)
        if item.nodeid in listed:
            item.add_marker(pytest.mark.kernel_paths)
    if "kernel_paths" in (config.getoption("markexpr") or ""):
        missing = listed - {item.nodeid for item in items}
        if missing:
            msg = f"tests/kernel_paths.txt lists tests not collected: {sorted(missing)}"
            raise pytest.UsageError(msg)


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Under ``tests/kernel_warmup.py record``: write the kernel specializations held."""
    folder = os.environ.get("PIEZOHYST_KERNEL_RECORD")
    if folder:
        from tests.kernel_warmup import held

        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        Path(folder, f"{worker}.txt").write_text("\n".join(held()) + "\n")
