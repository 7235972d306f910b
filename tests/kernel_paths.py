"""Choose the tests the JIT-off pass of ``make test`` runs, and write tests/kernel_paths.txt.

Runs the tests of the ``kernels`` modules (all but the heavy ones) with numba's JIT off,
under coverage with a context per test, then picks greedily the test that reaches the most
kernel lines not yet reached per second it adds: its own duration, and its module's
fixtures the first time a test of that module is chosen (a module's slowest setup: the
fixture it builds once for all its tests), until every kernel line the whole set reached is
reached. Run it from the repository's root, on a quiet machine (the durations are the
costs), after kernels or their tests change: ``python tests/kernel_paths.py`` (about six
minutes on two cores).
"""

from __future__ import annotations

import collections
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LIST = ROOT / "tests" / "kernel_paths.txt"
KERNELS = ("/piezohyst/_kernels/", "/piezohyst/simulation/_plant.py")


def main() -> None:
    import coverage

    data_file = ROOT / ".coverage.kernel_paths"
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1", "COVERAGE_FILE": str(data_file)}
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadfile",
         "-p", "no:cacheprovider", "-m", "kernels and not heavy", "--durations=0",
         "--cov", "--cov-context=test", "--cov-report=", "tests"],
        cwd=ROOT, env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    cost: collections.Counter[str] = collections.Counter()
    setup: dict[str, float] = {}
    for line in run.stdout.splitlines():
        m = re.match(r"([0-9.]+)s (call|setup|teardown)\s+(\S+)", line)
        if m and m.group(2) == "setup":
            setup[m.group(3)] = float(m.group(1))
        elif m:
            cost[m.group(3)] += float(m.group(1))
    fixtures: dict[str, float] = collections.defaultdict(float)  # a module's built-once setup
    for test, seconds in setup.items():
        fixtures[module(test)] = max(fixtures[module(test)], seconds)
    data = coverage.CoverageData(str(data_file))
    data.read()
    reached: dict[str, set[tuple[str, int]]] = collections.defaultdict(set)
    for f in data.measured_files():
        if any(k in f for k in KERNELS):
            for line_no, contexts in data.contexts_by_lineno(f).items():
                for context in filter(None, contexts):
                    reached[context.split("|")[0]].add((f, line_no))
    data_file.unlink()
    every = set().union(*reached.values())
    chosen: list[str] = []
    seen: set[tuple[str, int]] = set()
    paid: set[str] = set()

    def added(test: str) -> float:
        extra = 0.0 if module(test) in paid else fixtures[module(test)]
        return cost[test] + extra + 0.05

    while seen != every:
        best = max(reached, key=lambda t: len(reached[t] - seen) / added(t))
        chosen.append(best)
        paid.add(module(best))
        seen |= reached[best]
    header = [line for line in LIST.read_text().splitlines() if line.startswith("#")]
    LIST.write_text("\n".join([*header, *chosen]) + "\n")
    print(f"{len(chosen)} of {len(reached)} tests reach the {len(every)} kernel lines")


def module(test: str) -> str:
    """The test's file (its module fixtures are built once per file)."""
    return test.split("::")[0]


if __name__ == "__main__":
    main()
