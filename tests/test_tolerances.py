"""Every floating-point comparison in the tests says what bounds its tolerance.

A tolerance is a claim: rounding of so many operations, a replay that integrates an ulp per
step, a problem's conditioning, the noise of a simulated sensor. A bare constant that
happened to pass on one machine fails on another CPU or BLAS. So a statement that sets
``atol``/``rtol`` (other than ``rtol=0``) or calls ``pytest.approx`` carries a comment on
its own lines or just above it (a run of such statements, line after line, may share one).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

TOLERANCE = re.compile(r"atol=|rtol=(?!0\b)|approx\(")
HERE = Path(__file__).parent


def _unexplained(path: Path) -> list[int]:
    src = path.read_text(encoding="utf-8")
    lines = src.splitlines()
    simple = (ast.Assert, ast.Expr, ast.Assign, ast.AugAssign, ast.AnnAssign, ast.Return)
    ends: dict[int, bool] = {}  # last line of a tolerance statement -> explained
    bad = []
    nodes = [n for n in ast.walk(ast.parse(src)) if isinstance(n, simple)]
    for node in sorted(nodes, key=lambda n: n.lineno):
        end = node.end_lineno or node.lineno
        own = lines[node.lineno - 1 : end]
        if not any(TOLERANCE.search(line) for line in own):
            continue
        above = lines[node.lineno - 2].lstrip() if node.lineno >= 2 else ""
        ok = (
            any("#" in line for line in own)
            or above.startswith("#")
            or ends.get(node.lineno - 1, False)  # a run of statements shares one comment
        )
        ends[end] = ok
        if not ok:
            bad.append(node.lineno)
    return bad


def test_every_tolerance_names_its_bound() -> None:
    files = [p for p in sorted(HERE.rglob("test_*.py")) if p.name != Path(__file__).name]
    assert len(files) >= 39  # every package's tests, not only the top folder's
    found = {p.name: lines for p in files if (lines := _unexplained(p))}
    assert not found, f"tolerances without a reason (file: statement lines): {found}"
