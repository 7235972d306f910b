"""Units of data columns: read from headers (``time [ms]``, ``Field (mT)``) or declared,
converted with pint so that models always see seconds.

Time is converted to s (a time column in any other dimension is an error),
an input in a voltage unit to V, an output in a charge unit to C or in a
length unit to m. Anything else (a field in mT, a polarisation in µC/cm²) is
kept as given, with its unit as the label. pint is imported only when a unit
needs converting.
"""

from __future__ import annotations

import re
from functools import cache
from typing import Any, Literal

import numpy as np

from ._validation import FloatArray
from .errors import DataFileError

__all__ = [
    "LENGTHS",
    "Role",
    "is_length",
    "scaled",
    "split_unit",
    "suffix_units",
    "to_standard",
]

Role = Literal["time", "input", "output"]

_IN_HEADER = re.compile(r"^\s*(?P<name>.*?\S)\s*(?:\[(?P<u1>[^\]]+)\]|\((?P<u2>[^)]+)\))\s*$")
_TARGETS: dict[str, tuple[str, ...]] = {"time": ("s",), "input": ("V",), "output": ("C", "m")}
_SAME = {"s", "V", "C", "m"}
#: Units a column's name may end in after an underscore (``time_s``, ``voltage_mV``): time,
#: voltage, charge and length with the prefixes records use; no other (``v_in`` is not in
#: inches, ``channel_A`` not in amperes)
SUFFIX_UNITS = frozenset(
    [p + u for u in ("s",) for p in ("", "m", "u", "µ", "n")]
    + [p + u for u in ("V",) for p in ("", "m", "u", "µ", "k")]
    + [p + u for u in ("C",) for p in ("", "m", "u", "µ", "n", "p")]
    + [p + u for u in ("m",) for p in ("", "m", "u", "µ", "n", "p")]
)
#: Units that mark an output as a displacement (a record's unit, or a model's output_unit)
LENGTHS = frozenset(
    {"m", "mm", "um", "µm", "μm", "nm", "pm", "micron", "microns", "metre", "meter"}
)


def is_length(unit: str | None) -> bool:
    """True when ``unit`` is a length: the record is a displacement, not a charge.

    Parameters
    ----------
    unit : str or None

    Returns
    -------
    bool

    Examples
    --------
    >>> is_length("um"), is_length("C"), is_length(None)
    (True, False, False)
    """
    return unit is not None and unit.strip() in LENGTHS


def split_unit(header: str) -> tuple[str, str | None]:
    """A column header's name and unit: ``"time [ms]"`` -> ``("time", "ms")``.

    Parameters
    ----------
    header : str
        ``name [unit]`` or ``name (unit)``; anything else has no unit.

    Returns
    -------
    tuple
        The name and the unit (None when the header names none).

    Examples
    --------
    >>> split_unit("Field (mT)"), split_unit("voltage")
    (('Field', 'mT'), ('voltage', None))
    """
    m = _IN_HEADER.match(header)
    if m is None:
        return header, None
    unit = (m.group("u1") or m.group("u2")).strip()
    return m.group("name"), unit or None


def _suffix_unit(name: str) -> tuple[str, str] | None:
    """``voltage_mV`` -> ``("voltage", "mV")`` where the suffix is in :data:`SUFFIX_UNITS`."""
    stem, sep, unit = name.rpartition("_")
    if sep and stem.strip("_") and unit in SUFFIX_UNITS:
        return stem, unit
    return None


def suffix_units(columns: list[str]) -> dict[str, tuple[str, str]]:
    """The columns named ``name_unit`` (``time_s``, ``voltage_V``, ``displacement_nm``, as
    exports from scripts often are): each such column's name and unit, by its header.

    Only the units of :data:`SUFFIX_UNITS` count, and only where the name says it
    unambiguously: not where a column of that name exists, where two columns share it
    (``voltage_V`` and ``voltage_mV``), or where a column of the same stem ends in
    something else (``channel_A``, ``channel_B``, ``channel_C``: channel names).

    Parameters
    ----------
    columns : list of str

    Returns
    -------
    dict
        ``{header: (name, unit)}``.

    Examples
    --------
    >>> suffix_units(["time_s", "voltage_V", "charge_nC", "v_in"])
    {'time_s': ('time', 's'), 'voltage_V': ('voltage', 'V'), 'charge_nC': ('charge', 'nC')}
    >>> suffix_units(["channel_A", "channel_B", "channel_C"])
    {}
    """
    found = {c: hit for c in columns if (hit := _suffix_unit(c)) is not None}
    stems = [stem for stem, _ in found.values()]
    taken = set(columns)
    others = {c.rpartition("_")[0] for c in columns if c not in found and "_" in c}
    return {c: (stem, unit) for c, (stem, unit) in found.items()
            if stems.count(stem) == 1 and stem not in taken and stem not in others}  # fmt: skip


@cache
def _registry() -> Any:
    import pint

    return pint.UnitRegistry()


#: what a column may be once scaled, by role, for messages
_WANTED = {"input": "a voltage (V)", "output": "a charge (C) or a displacement (m)"}


def scaled(
    scale: str | float | None, unit: str | None, role: Literal["input", "output"], option: str
) -> tuple[float, str | None]:
    """What one unit of a column logged by a DAQ is worth: the factor to multiply it by and the
    unit it is then in (converted further by :func:`to_standard`).

    A DAQ logs volts: an amplifier's monitor at 1/100 of the piezo's voltage (``100``), a
    displacement sensor's output (``"10 um/V"``), a Sawyer-Tower circuit's output across its
    reference capacitor (``"4.7 uF"``, charge = capacitance x voltage), a sensor counting the
    other way (``-1``, or ``"-10 um/V"``). A scale with a unit multiplies the column's unit
    (``unit``, or V where the column states none); a plain number keeps it.

    Parameters
    ----------
    scale : str, float or None
        The column's scale (None: 1).
    unit : str or None
        The column's unit, from its header or as declared.
    role : {"input", "output"}
        What the column is: the scaled unit must be a voltage, or a charge or length.
    option : str
        The option's name, for messages (``--output-scale``, ``output_scale``).

    Returns
    -------
    tuple
        The factor and the unit the scaled values are in.

    Raises
    ------
    DataFileError
        A scale that cannot be read, is zero or not finite, or that makes the column
        something it cannot be (``10 um/V`` on an input).

    Examples
    --------
    >>> scaled("10 um/V", None, "output", "--output-scale")
    (1e-05, 'm')
    >>> scaled(100, "V", "input", "--input-scale")
    (100.0, 'V')
    """
    if scale is None:
        return 1.0, unit
    ureg = _registry()
    try:
        quantity = ureg.Quantity(scale) if isinstance(scale, str) else ureg.Quantity(float(scale))
        factor = float(quantity.magnitude)
    except Exception:  # pint raises several kinds for text it cannot read
        msg = f"{option} {scale!r} cannot be read: give a number or a quantity (100, 10 um/V)"
        raise DataFileError(msg) from None
    if not (np.isfinite(factor) and factor != 0.0):
        msg = f"{option} {scale!r} must be a finite number other than 0"
        raise DataFileError(msg)
    if quantity.dimensionless:
        return float(f"{quantity.to('').magnitude:.15g}"), unit
    column = unit if unit is not None else "V"  # a DAQ's channel is in volts
    try:
        total = quantity * ureg.Quantity(1.0, column)
    except Exception:
        msg = f"{option} {scale!r}: the column's unit {column!r} is not understood"
        raise DataFileError(msg) from None
    for target in _TARGETS[role]:
        if total.dimensionality == ureg.Quantity(1.0, target).dimensionality:
            # to 15 digits, as declared: 10 um/V is 1e-05 m/V, not 9.999999999999999e-06
            return float(f"{total.to(target).magnitude:.15g}"), target
    hint = {
        "input": "an amplifier's monitor's scale is a plain number (100 for 1/100)",
        "output": "a sensor's scale is per volt (10 um/V); a Sawyer-Tower circuit's is its "
        "reference capacitance (4.7 uF)",
    }
    gives = f"{option} {scale!r} on a column in {column} gives {total.units:~}"
    msg = f"{gives}, not {_WANTED[role]}: {hint[role]}"
    raise DataFileError(msg)


def to_standard(
    values: FloatArray, unit: str | None, role: Role, where: str
) -> tuple[FloatArray, str | None]:
    """Values in the unit piezohyst works in, and that unit's label.

    Parameters
    ----------
    values : ndarray
        The column.
    unit : str or None
        Its unit (None: unknown, returned as they are).
    role : {"time", "input", "output"}
        What the column is.
    where : str
        File and column, for messages.

    Returns
    -------
    tuple
        Converted values and their unit: s for time; V for a voltage input;
        C or m for a charge or length output; otherwise the values unchanged
        and ``unit`` as the label.

    Raises
    ------
    DataFileError
        A time column whose unit is not a unit of time, or is not understood.
    """
    if unit is None or (unit in _SAME and unit in _TARGETS[role]):
        return values, unit
    ureg = _registry()
    try:
        quantity = ureg.Quantity(1.0, unit)
    except Exception:  # pint raises several kinds for text it cannot read
        if role == "time":
            msg = f"{where}: unknown time unit {unit!r} (use s, ms, us, min...)"
            raise DataFileError(msg) from None
        return values, unit
    for target in _TARGETS[role]:
        reference = ureg.Quantity(1.0, target)
        if quantity.dimensionality == reference.dimensionality:
            factor = float(quantity.to(target).magnitude)
            return np.asarray(values * factor, dtype=np.float64), target
    if role == "time":
        msg = f"{where} is in {unit!r}, which is not a unit of time"
        raise DataFileError(msg)
    # a unit of a quantity the column cannot be (mA for a charge, C for a voltage) is an
    # error; other labels (a.u., counts, a polarization, a field) pass unchanged
    wrong = {"input": ("A", "C", "s", "m"), "output": ("A", "s")}[role]  # (a sensor's V is fine)
    for other in wrong:
        if quantity.dimensionality == ureg.Quantity(1.0, other).dimensionality:
            msg = (
                f"{where} is in {unit!r}, a unit of {quantity.dimensionality}, not "
                f"{_WANTED[role]}: check the column or its unit"
            )
            raise DataFileError(msg)
    return values, unit
