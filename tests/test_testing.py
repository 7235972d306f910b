"""piezohyst.testing.check_core: the core contract as a check a core's author runs."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pytest
from numpy.typing import ArrayLike

import piezohyst as ph
from piezohyst.model.cores.base import Propagation
from piezohyst.simulation import make_signal
from piezohyst.testing import CoreContractError, check_core

from .external_core import BacklashCore

pytestmark = pytest.mark.kernels

MODELS = {
    "play": lambda: ph.ClassicalPI(6),
    "preisach": lambda: ph.PreisachModel(nodes=8),
    "duhem": lambda: ph.DuhemModel(grid=(4, 3)),
    "bouc-wen": lambda: ph.BoucWenModel(),
}


@pytest.fixture(scope="module")
def record() -> ph.simulation.BenchRecord:
    t, v = make_signal("decaying", duration=4.0, rate=1000.0)
    return ph.simulate(v, t)


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_every_built_in_core_follows_the_contract(
    kind: str, record: ph.simulation.BenchRecord
) -> None:
    model = MODELS[kind]().fit(record.voltage, record.charge, t=record.t)
    lo, hi = model.input_range_
    check_core(model.operator_, _loops(lo, hi))


def _loops(lo: float, hi: float) -> np.ndarray:
    t = np.linspace(0.0, 1.0, 900)
    return lo + (hi - lo) * (0.1 + 0.8 * (0.5 - 0.5 * np.cos(2 * np.pi * 3 * t)) * (1 - 0.6 * t))


def test_a_core_written_outside_the_library_follows_it() -> None:
    v = 70.0 - 70.0 * np.cos(np.linspace(0.0, 6.0 * np.pi, 900))
    check_core(BacklashCore(14.0, 2e-8, 5e-8, 1e-7, np.array([v[0]])), v)
    check_core(BacklashCore(14.0, 2e-8, 5e-8, 1e-7, np.array([0.0])))  # the default probe


@dataclass(frozen=True, eq=False)
class _Forgetful(BacklashCore):
    """Starts every call from its initial state: chunks differ from one run."""

    kind: ClassVar[str] = "test-forgetful"

    def propagate(self, x: ArrayLike, state: ArrayLike | None = None) -> Propagation[np.ndarray]:
        return super().propagate(x, None)


@dataclass(frozen=True, eq=False)
class _Boastful(BacklashCore):
    """Claims a steeper least slope than it has."""

    kind: ClassVar[str] = "test-boastful"

    @property
    def min_slope(self) -> float:
        return 10 * (self.a + self.b)


@dataclass(frozen=True, eq=False)
class _Rounding(BacklashCore):
    """Writes its parameters rounded: read back, it predicts something else."""

    kind: ClassVar[str] = "test-rounding"

    def to_dict(self) -> dict[str, Any]:
        return {**super().to_dict(), "a": float(f"{self.a:.3g}") * 1.001}


@pytest.mark.parametrize(
    ("cls", "rule"),
    [(_Forgetful, "split into chunks"), (_Boastful, "must bound its slopes"),
     (_Rounding, "bit for bit")],
)  # fmt: skip
def test_a_core_that_breaks_the_contract_is_told_which_rule(cls: type, rule: str) -> None:
    core = cls(14.0, 2e-8, 5e-8, 1e-7, np.array([0.0]))
    with pytest.raises(CoreContractError, match=rule):
        check_core(core)
    with pytest.raises(CoreContractError, match="needs a piezohyst Core"):
        check_core("not a core")  # type: ignore[arg-type]


def test_the_kernel_warm_up_list_names_kernels_that_exist() -> None:
    """tests/kernel_signatures.txt: each row a dispatcher of today's kernels, its types read back.

    A row left behind by a renamed kernel would only slow ``make test`` (the tests compile it
    themselves), silently; this names it.
    """
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        pytest.skip("the JIT is off: no dispatchers to compare the list with")
    from . import kernel_warmup

    found = kernel_warmup.dispatchers()
    rows = kernel_warmup.entries()
    assert len(rows) > 40
    stale = [key for key, _ in rows if key not in found]
    assert not stale, f"re-run `python tests/kernel_warmup.py record`: gone: {stale}"
    unread = [text for _, text in rows if kernel_warmup.parse(text) is None]
    assert len(unread) < len(rows) / 4, unread
    assert kernel_warmup.parse("(Array(float64, 1, 'C', False, aligned=True), bool)") is not None
    assert kernel_warmup.parse("Literal[bool](True)") is None
