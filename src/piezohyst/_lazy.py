"""Kernel modules loaded when a model first runs, not when piezohyst is imported.

Every model module uses numba kernels, and importing numba costs more than the rest of
``import piezohyst`` together. A module that needs kernels binds a :class:`LazyModule`
under the kernel module's usual name; the first attribute looked up through it imports the
kernel module (the import system's locks make that safe from several threads at once) and
puts the real module in its place in that namespace, so later lookups cost nothing extra.
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any


class LazyModule:
    """A stand-in for module ``name`` bound as ``alias`` in the namespace ``where``."""

    def __init__(self, name: str, where: dict[str, Any], alias: str) -> None:
        self._name = name
        self._where = where
        self._alias = alias

    def load(self) -> ModuleType:
        """The real module, now bound in ``where`` instead of this stand-in."""
        module = importlib.import_module(self._name)
        self._where[self._alias] = module
        return module

    def __getattr__(self, attr: str) -> Any:
        return getattr(self.load(), attr)

    def __repr__(self) -> str:
        return f"<kernels {self._name!r}, loaded at first use>"
