"""Kernel modules loaded when a model first runs, not when piezohyst is imported.

Every model module uses numba kernels, and importing numba costs more than the rest of
``import piezohyst`` together. :mod:`piezohyst._kernels` binds a :class:`LazyModule` under
each kernel module's name, and the modules that need kernels import it as usual
(``from .._kernels import play as K``). The first attribute looked up through a stand-in
imports the kernel module (the import system's locks make that safe from several threads at
once), puts the real module in its place in the package, and copies the module's names into
the stand-in, so a module holding the stand-in finds every later name in its ``__dict__``
as fast as in the module's own.
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any


class LazyModule(ModuleType):
    """A stand-in for module ``name`` bound as ``alias`` in the namespace ``where``.

    Once loaded it becomes a plain module holding the real one's names (its class is
    switched back to ``ModuleType``), so a lookup through it is as fast as through the
    module itself.
    """

    def __init__(self, name: str, where: dict[str, Any], alias: str) -> None:
        super().__init__(name)
        self._name = name
        self._where = where
        self._alias = alias

    def load(self) -> ModuleType:
        """The real module, now bound in ``where`` instead of this stand-in."""
        module = importlib.import_module(self._name)
        self._where[self._alias] = module
        self.__dict__.update(vars(module))  # later lookups find the names here:
        self.__class__ = ModuleType  # type: ignore[assignment]  # a module's fast lookup
        return module

    def __getattr__(self, attr: str) -> Any:
        return getattr(self.load(), attr)

    def __repr__(self) -> str:
        return f"<kernels {self._name!r}, loaded at first use>"
