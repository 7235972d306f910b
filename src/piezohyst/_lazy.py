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
import sys
from collections.abc import Callable
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


def attach(
    package: str, names: dict[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A package's ``__getattr__`` and ``__dir__`` (PEP 562) that import each public name
    from its module at first use, as scientific Python's ``lazy_loader.attach`` does.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    names : dict
        Each public name and the module (relative to ``package``, with a leading dot)
        that defines it; a name that is itself a submodule maps to that submodule with
        the suffix ``":module"``. Any other submodule is loaded at first use too
        (``piezohyst.control.learning`` after ``import piezohyst``).

    Returns
    -------
    (callable, callable)
        ``__getattr__`` and ``__dir__`` for the package's namespace. A name, once imported,
        is bound in the package, so later lookups do not come back here.
    """

    def __getattr__(name: str) -> Any:
        where = names.get(name)
        if where is None:  # a submodule, loaded at first use as the import system would
            if name.startswith("__"):
                msg = f"module {package!r} has no attribute {name!r}"
                raise AttributeError(msg)
            try:
                module = importlib.import_module(f"{package}.{name}")
            except ModuleNotFoundError as exc:
                if exc.name != f"{package}.{name}":
                    raise
                msg = f"module {package!r} has no attribute {name!r}"
                raise AttributeError(msg) from None
            setattr(sys.modules[package], name, module)
            return module
        module_name, _, kind = where.partition(":")
        module = importlib.import_module(module_name, package)
        value = module if kind == "module" else getattr(module, name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__
