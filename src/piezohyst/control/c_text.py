"""C text for the exported step: literals in the chosen precision, constant tables, and what
an engine gives the export (:class:`CParts`).

Each engine writes its own part of the generated ``.c`` (:meth:`~.engines.base.Inverse.c_parts`:
the constants of its arrays, its ``init`` statements and the shipped C files its step needs);
the export (:mod:`~piezohyst.control.export.c_code`) adds what belongs to the compensator (the
output mode, the desired value's map, the names) and asks nothing of the engine's arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

__all__ = ["CParts", "CText", "Precision", "init_extra"]

Precision = Literal["double", "float"]


@dataclass(frozen=True)
class CText:
    """Numbers as C text in one precision, and the generated names' prefix.

    Parameters
    ----------
    precision : {"double", "float"}
        The C type of every real.
    prefix : str
        The generated names' C prefix (``ph_comp``: ``ph_comp_t``, ``PH_COMP_N``).
    """

    precision: Precision
    prefix: str = "ph_comp"

    @property
    def upper(self) -> str:
        """The prefix in upper case (the header's macros)."""
        return self.prefix.upper()

    def literal(self, value: float) -> str:
        """One number as a C literal (``f``-suffixed in float; infinity as ``INFINITY``).

        Parameters
        ----------
        value : float

        Returns
        -------
        str
        """
        if self.precision == "float":
            return f"{float(np.float32(value))!r}f".replace("inff", "INFINITY")
        return repr(float(value))

    def array(self, values: np.ndarray) -> str:
        """A brace-enclosed initializer, four numbers to a line.

        Parameters
        ----------
        values : ndarray

        Returns
        -------
        str
        """
        items = [self.literal(float(v)) for v in values]
        lines = ["    " + ", ".join(items[k : k + 4]) + "," for k in range(0, len(items), 4)]
        return "{\n" + "\n".join(lines) + "\n}"

    def table(self, name: str, size: str, values: np.ndarray) -> str:
        """``static const real_t NAME[SIZE] = {...};``.

        Parameters
        ----------
        name, size : str
            The C name and its size expression.
        values : ndarray

        Returns
        -------
        str
        """
        return f"static const real_t {name}[{size}] = {self.array(values)};"

    def constants(self, **values: float) -> list[str]:
        """``static const real_t NAME = value;`` for each value.

        Parameters
        ----------
        **values : float

        Returns
        -------
        list of str
        """
        return [f"static const real_t {k} = {self.literal(float(v))};" for k, v in values.items()]


#: What every step's ``init`` sets beyond its core: the last command and the limits' counts
INIT_COUNTS = ("s->last = LAST0;", "s->nonfinite = 0;", "s->saturated = 0;", "s->slewed = 0;",
               "s->extrapolated = 0;")  # fmt: skip


def init_extra(statements: list[str]) -> str:
    """The ``INIT_EXTRA(s)`` macro: what ``init`` sets beyond the core's state (the last
    command and the limits' counts, then the engine's: feedback, dynamics, mode, lags).

    Parameters
    ----------
    statements : list of str
        C statements on ``s``, after ``INIT_COUNTS``.

    Returns
    -------
    str
    """
    body = "".join(f"    {line} \\\n" for line in (*INIT_COUNTS, *statements))
    return f"#define INIT_EXTRA(s) do {{ \\\n{body}}} while (0)"


@dataclass
class CParts:
    """An engine's part of the exported C.

    Attributes
    ----------
    lines : list of str
        The preamble's defines and constants, in order.
    init : list of str
        Statements ``init`` runs beyond the core's state (``INIT_EXTRA``).
    files : list of str
        The shipped C files, in order (``piezohyst/model/cores/c``).
    header : str
        The header template's first part, the engine's state (``play.h`` or ``packed.h``);
        ``step.h`` ends it: the input dynamics' and the output mode's state, the init, the step.
    fields : dict
        The template's fields the engine knows (the export adds the compensator's).
    """

    lines: list[str]
    init: list[str]
    files: list[str]
    header: str
    fields: dict[str, object] = field(default_factory=dict)
