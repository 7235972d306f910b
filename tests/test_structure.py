"""The shape of the library, measured: what the one-core-protocol design promises."""

from __future__ import annotations

import ast
from pathlib import Path

import piezohyst as ph

SRC = Path(ph.__file__).parent
MODULES = sorted(SRC.rglob("*.py"))
#: classes whose type must not choose behaviour (checks at the API edge are counted too)
MODEL_CORE_COMPENSATOR = {
    "HysteresisModel", "Estimator", "ClassicalPI", "ActivePI", "GeneralizedPI", "PIModel",
    "PreisachModel", "DuhemModel", "BoucWenModel", "ModelBank", "Core", "PackedCore",
    "PIHysteresis", "PreisachHysteresis", "DuhemHysteresis", "BoucWenHysteresis",
    "Compensator", "SelfSensingController", "BankCompensator", "BankController", "ChannelBank",
}  # fmt: skip


def _isinstance_on_classes() -> list[str]:
    found = []
    for path in MODULES:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") in {
                "isinstance", "issubclass"}:  # fmt: skip
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                if names & MODEL_CORE_COMPENSATOR:
                    found.append(f"{path.relative_to(SRC)}:{node.lineno}")
    return found


def test_modules_and_classes_fit_in_one_sitting() -> None:
    for path in MODULES:
        text = path.read_text()
        assert len(text.splitlines()) <= 1000, f"{path.relative_to(SRC)} is longer than 1000 lines"
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                size = (node.end_lineno or node.lineno) - node.lineno + 1
                assert size <= 600, f"{path.relative_to(SRC)}:{node.name} has {size} lines"


def test_no_class_swaps_itself_in_new() -> None:
    for path in MODULES:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef):
                assert node.name != "__new__", f"{path.relative_to(SRC)}:{node.lineno}"


def test_behaviour_is_not_chosen_by_model_core_or_compensator_class() -> None:
    found = _isinstance_on_classes()
    assert len(found) <= 5, found
