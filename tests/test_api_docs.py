"""Every public callable documents its parameters and what it returns (numpydoc)."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator
from typing import Any

import piezohyst as ph
from piezohyst import (
    analysis,
    control,
    io,
    metrics,
    model,
    plotting,
    simulation,
    testing,
    workflows,
)
from piezohyst.analysis import selection
from piezohyst.control import compensator, export
from piezohyst.io import blocks, screening
from piezohyst.model import bank, persistence, presets, terms
from piezohyst.model.cores import play, solve
from piezohyst.workflows import fleet

#: the top package, every subpackage's face, and the modules whose own names are public too
MODULES = [ph, analysis, control, model, simulation, workflows, presets, terms, solve, blocks, play,
           compensator, export, persistence, io, bank, fleet, screening, testing, selection,
           metrics, plotting]  # fmt: skip


def _documented_objects() -> Iterator[tuple[str, Any]]:
    seen: set[int] = set()
    for module in MODULES:
        for name in getattr(module, "__all__", []):
            obj = getattr(module, name)
            if id(obj) in seen or not (inspect.isclass(obj) or inspect.isroutine(obj)):
                continue
            seen.add(id(obj))
            yield f"{module.__name__}.{name}", obj
            if inspect.isclass(obj) and obj.__module__.startswith("piezohyst"):
                for attr, member in vars(obj).items():
                    if attr.startswith("_") or not inspect.isfunction(member):
                        continue
                    yield f"{module.__name__}.{name}.{attr}", member


def _needs(func: Callable[..., Any]) -> tuple[bool, bool]:
    sig = inspect.signature(func)
    params = [p for p in sig.parameters.values() if p.name not in ("self", "cls")]
    returns = sig.return_annotation not in (None, "None", inspect.Signature.empty)
    return bool(params), returns


def test_public_callables_have_numpydoc_sections() -> None:
    missing = []
    for name, obj in _documented_objects():
        doc = inspect.getdoc(obj) or ""
        if not doc:
            missing.append(f"{name}: no docstring")
            continue
        if doc.startswith("See :meth:") or ("See :meth:" in doc.splitlines()[0]):
            continue  # an override documented where it is declared
        if inspect.isclass(obj):
            if issubclass(obj, BaseException):
                continue  # constructed with a message, as every exception
            # a record type (dataclass, named tuple) documents its fields as Attributes
            record = hasattr(obj, "__dataclass_fields__") or hasattr(obj, "_fields")
            sections = ("Attributes", "Parameters") if record else ("Parameters",)
            if getattr(obj, "_is_protocol", False):  # a structural type, never constructed
                if "Attributes" not in doc and "Methods" not in doc:
                    missing.append(f"{name}: a protocol without Attributes or Methods")
                continue
            init = obj.__init__
            if init is object.__init__ or not _needs(init)[0]:
                continue
            if not any(sec in doc for sec in sections):
                missing.append(f"{name}: no {' or '.join(sections)} section")
            continue
        needs_params, needs_returns = _needs(obj)
        if needs_params and "Parameters" not in doc:
            missing.append(f"{name}: no Parameters section")
        if needs_returns and "Returns" not in doc and "Yields" not in doc:  # generators yield
            missing.append(f"{name}: no Returns section")
    assert not missing, "\n".join(missing)
