r"""Leakage current of a piezo capacitor, calibrated from constant-voltage holds.

While the voltage is held, the hysteresis is still, so all the measured
charge does is leak: through the piezo (ohmic and voltage-dependent
conductance), by the charge amplifier's bias current, and out of the
amplifier's reference capacitor through its insulation or feedback resistance
(time constant :math:`\tau = R_f C_f`, the amplifier's "time constant"):

.. math::

    \frac{dq}{dt} = G_0\,v + G_1\,\frac{v\,|v|}{s} + i_b - q / \tau .

The last term depends on the measured charge itself, which differs between
holds at one voltage reached from below and from above: that is how the holds
tell it from the others.

While the voltage cycles, leakage cannot be told from a model's minor-loop
error (that error drifts like a leak), which is why a closed loop on the
leakage-corrected charge (:class:`~piezohyst.selfsensing.SelfSensingController`)
wants its leakage from holds: :func:`calibrate_leakage` finds the holds in a
record, measures the charge's slope on each, and fits the selected terms.
"""

from __future__ import annotations

import itertools
import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ._lazy import LazyModule
from ._validation import FloatArray, as_signal, as_time, same_length
from .errors import InsufficientDataError, ModelFileError, ParameterError

if TYPE_CHECKING:
    from . import _kernels
    from . import _signalkernels as _signals
else:  # numba loads when a model first runs (see _lazy)
    _kernels = LazyModule("piezohyst._kernels", globals(), "_kernels")
    _signals = LazyModule("piezohyst._signalkernels", globals(), "_signals")

__all__ = ["LEAKAGE_TERMS", "Hold", "Leakage", "calibrate_leakage", "find_holds"]

LEAKAGE_TERMS = ("conductance", "quadratic", "bias", "discharge")


@dataclass(frozen=True)
class Hold:
    """One constant-voltage stretch of a record and the current measured on it.

    Attributes
    ----------
    start, stop : int
        Samples ``start:stop`` used for the slope (after the settling time).
    voltage : float
        Mean voltage (input units).
    charge : float
        Mean measured charge (output units).
    current : float
        Slope of the charge (output units per s).
    stderr : float
        Standard error of that slope.
    duration : float
        Seconds used.
    """

    start: int
    stop: int
    voltage: float
    charge: float
    current: float
    stderr: float
    duration: float


@dataclass(frozen=True)
class Leakage:
    r"""A leakage current :math:`G_0 v + G_1 v|v|/s + i_b - q/\tau` and its integral.

    Made by :func:`calibrate_leakage`, or from a fitted model's growth terms
    by :meth:`from_model`, or by hand. Accepted by
    :meth:`~piezohyst.models.HysteresisModel.remove_growth` and
    :class:`~piezohyst.selfsensing.SelfSensingController`.

    Attributes
    ----------
    conductance : float
        :math:`G_0`, output units per (input unit · s): S for V and C.
    quadratic : float
        :math:`G_1`, same unit: the conductance's rise, reached at :math:`|v| = s`.
    bias : float
        :math:`i_b`, output units per s (A): e.g. the charge amplifier's bias current.
    discharge : float
        :math:`1/\tau` (1/s): the measuring circuit loses this fraction of
        the measured charge per second (0: an ideal charge amplifier).
    scale : float
        :math:`s` (input units).
    input_unit, output_unit : str
    holds : tuple of Hold
        The holds it was calibrated on (empty when not calibrated).
    residual : float
        RMS misfit of the hold currents (output units per s); NaN when not calibrated.
    """

    conductance: float = 0.0
    quadratic: float = 0.0
    bias: float = 0.0
    scale: float = 1.0
    discharge: float = 0.0
    input_unit: str = "V"
    output_unit: str = "C"
    holds: tuple[Hold, ...] = field(default=(), compare=False)
    residual: float = field(default=math.nan, compare=False)

    def __post_init__(self) -> None:
        for name in ("conductance", "quadratic", "bias", "scale", "discharge"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                msg = f"Leakage's {name!r} must be a number. Got {value!r}."
                raise ParameterError(msg)
            if not math.isfinite(value):
                msg = f"Leakage's {name!r} must be finite. Got {value!r}."
                raise ParameterError(msg)
        if not self.scale > 0:
            msg = f"Leakage's 'scale' must be > 0 (input units). Got {self.scale!r}."
            raise ParameterError(msg)

    def current(self, v: ArrayLike, q: ArrayLike | float = 0.0) -> FloatArray:
        """Leakage current at voltages ``v`` and measured charges ``q`` (output units per s).

        Parameters
        ----------
        v : array_like
            Voltages (input units).
        q : array_like or float, default 0
            Measured charge (output units), for the discharge term.

        Returns
        -------
        ndarray
        """
        x = np.asarray(v, dtype=np.float64)
        return np.asarray(
            self.conductance * x
            + self.quadratic * x * np.abs(x) / self.scale
            + self.bias
            - self.discharge * np.asarray(q, dtype=np.float64)
        )

    def charge(self, v: ArrayLike, t: ArrayLike, q: ArrayLike | None = None) -> FloatArray:
        """Charge leaked since the first sample: the paper's backward-rectangle integral (eq. 13).

        ``L[k] = L[k-1] + i(v[k], q[k]) (t[k] - t[k-1])``, ``L[0] = 0``: the
        same rule as the models' growth terms.

        Parameters
        ----------
        v : array_like, shape (N,)
            Voltages (input units).
        t : array_like, shape (N,)
            Times (s), strictly increasing.
        q : array_like, shape (N,), optional
            The measured charge, needed when ``discharge`` is not 0.

        Returns
        -------
        ndarray, shape (N,)
            Output units.
        """
        x = as_signal(v, "v")
        ts = as_time(t, x.size, required=True, owner="Leakage.charge")
        assert ts is not None
        if q is None and self.discharge != 0.0:
            msg = "this leakage has a discharge term: pass the measured charge q"
            raise ParameterError(msg)
        qs = 0.0 if q is None else as_signal(q, "q")
        if not isinstance(qs, float):
            same_length(x, qs, "v", "q")
        dt = np.diff(ts, prepend=ts[0])
        return np.asarray(np.cumsum(self.current(x, qs) * dt))

    def coefficients(self) -> dict[str, tuple[float, str]]:
        """Each term's value and unit, by name (``conductance``, ``quadratic``, ``bias``).

        Returns
        -------
        dict
        """
        per_v = f"{self.output_unit}/({self.input_unit}*s)"
        return {
            "conductance": (self.conductance, per_v),
            "quadratic": (self.quadratic, per_v),
            "bias": (self.bias, f"{self.output_unit}/s"),
            "discharge": (self.discharge, "1/s"),
        }

    @classmethod
    def from_model(cls, model: Any) -> Leakage:
        """The leakage a fitted model identified: its growth terms read as currents.

        ``integral`` (the paper's R) is the conductance, ``abs_integral`` the
        quadratic term with its scale, ``time`` the bias current.

        Parameters
        ----------
        model : HysteresisModel
            A fitted model.

        Returns
        -------
        Leakage
            Zero for a model without growth terms.

        Raises
        ------
        ParameterError
            A growth term that is not a leakage current.
        """
        values = {"integral": 0.0, "abs_integral": 0.0, "time": 0.0}
        scale = 1.0
        for term, coef in zip(model.terms_, model.coefs_, strict=True):
            if not term.removed:
                continue
            if term.kind not in values:
                msg = (
                    f"the growth term {term.kind!r} is not a leakage current the self-sensing "
                    "loop can remove (it knows integral, abs_integral and time): pass a "
                    "Leakage calibrated from holds (calibrate_leakage)"
                )
                raise ParameterError(msg)
            values[term.kind] = float(coef[0])
            if term.kind == "abs_integral":
                scale = float(term.scale)
        return cls(
            values["integral"],
            values["abs_integral"],
            values["time"],
            scale,
            0.0,
            model.input_unit,
            model.output_unit,
        )

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready contents (see :meth:`from_dict`).

        Returns
        -------
        dict
        """
        out = asdict(self)
        out["holds"] = [asdict(h) for h in self.holds]
        out["residual"] = None if math.isnan(self.residual) else self.residual
        return {"format": "piezohyst-leakage", "kind": "leakage", **out}

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "leakage") -> Leakage:
        """Rebuild from :meth:`to_dict` output; a bad field is named.

        Parameters
        ----------
        data : dict
        where : str
            Named in errors (a file name).

        Returns
        -------
        Leakage

        Raises
        ------
        ModelFileError
        """
        if not isinstance(data, dict) or data.get("kind") != "leakage":
            msg = f'{where}: not a piezohyst leakage file (no "kind": "leakage")'
            raise ModelFileError(msg)
        fields = {k: v for k, v in data.items() if k not in ("kind", "format")}
        known = {
            "conductance",
            "quadratic",
            "bias",
            "scale",
            "discharge",
            "input_unit",
            "output_unit",
        }
        extra = set(fields) - known - {"holds", "residual"}
        if extra:
            msg = f"{where}: unknown field {sorted(extra)[0]!r}"
            raise ModelFileError(msg)
        try:
            holds = tuple(Hold(**h) for h in fields.get("holds") or ())
            residual = fields.get("residual")
            return cls(
                **{k: fields[k] for k in known if k in fields},
                holds=holds,
                residual=math.nan if residual is None else float(residual),
            )
        except (TypeError, ParameterError) as exc:
            msg = f"{where}: {exc}"
            raise ModelFileError(msg) from None

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write as JSON (atomically).

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        Path
        """
        from .io import atomic_write_text

        return atomic_write_text(path, json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Leakage:
        """Read a file written by :meth:`save`.

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        Leakage

        Raises
        ------
        ModelFileError
        """
        p = Path(path)
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            msg = f"{p}: cannot read a leakage file ({str(exc).splitlines()[0]})"
            raise ModelFileError(msg) from None
        return cls.from_dict(data, str(p))


def find_holds(
    t: ArrayLike,
    v: ArrayLike,
    *,
    tolerance: float | None = None,
    min_duration: float = 1.0,
    settle: float = 0.25,
) -> list[tuple[int, int]]:
    """Stretches where the voltage stays constant, without their settling start.

    Parameters
    ----------
    t, v : array_like, shape (N,)
        Times (s) and voltages.
    tolerance : float, optional
        How far the voltage may wander from the hold's first sample; default
        0.1 % of the record's span (a DAC's or monitor's noise).
    min_duration : float, default 1.0
        Shortest hold kept (s), counted after the settling.
    settle : float, default 0.25
        Fraction of each hold dropped at its start, where creep and the
        amplifier still settle after the step.

    Returns
    -------
    list of (start, stop)
        Sample ranges ``start:stop``.
    """
    ts = as_time(t, np.size(v), required=True, owner="find_holds")
    x = as_signal(v, "v")
    assert ts is not None
    tol = 1e-3 * float(np.ptp(x)) if tolerance is None else float(tolerance)
    if not 0.0 <= settle < 1.0:
        msg = f"'settle' must be a fraction in [0, 1). Got {settle!r}."
        raise ParameterError(msg)
    edges = np.empty(x.size + 1, dtype=np.int64)
    count = _signals.constant_runs(x, tol, edges)
    holds = []
    for k, j in itertools.pairwise(edges[: count + 1]):
        if j - k >= 3:
            first = k + math.ceil(settle * (j - k))
            if j - first >= 3 and ts[j - 1] - ts[first] >= min_duration:
                holds.append((int(first), int(j)))
    return holds


def calibrate_leakage(
    t: ArrayLike,
    v: ArrayLike,
    q: ArrayLike,
    *,
    terms: Sequence[str] = LEAKAGE_TERMS,
    holds: Sequence[tuple[int, int]] | None = None,
    tolerance: float | None = None,
    min_duration: float = 1.0,
    settle: float = 0.25,
    scale: float | None = None,
    input_unit: str = "V",
    output_unit: str = "C",
) -> Leakage:
    r"""Fit the leakage current from the charge's slope on constant-voltage holds.

    On each hold the slope of a straight line through the charge is the
    current there; the selected terms of
    :math:`G_0 v + G_1 v|v|/s + i_b - q/\tau` are then fitted to those
    currents, each hold weighted by its duration. The discharge term needs
    holds at one voltage with different charges (reached from below and from
    above); the others need as many voltage levels as terms. A hold's slope
    is uncertain by about ``noise * sqrt(12 / samples) / duration``, so a few
    long holds beat many short ones.

    Parameters
    ----------
    t, v, q : array_like, shape (N,)
        Times (s), voltages and measured charge.
    terms : sequence of str, default all
        Of ``"conductance"``, ``"quadratic"``, ``"bias"``, ``"discharge"``.
    holds : sequence of (start, stop), optional
        The holds as sample ranges; default found by :func:`find_holds`.
    tolerance, min_duration, settle
        Passed to :func:`find_holds`.
    scale : float, optional
        :math:`s`; default the largest |v| of the record.
    input_unit, output_unit : str
        Units of ``v`` and ``q``.

    Returns
    -------
    Leakage
        With the holds used and the fit's RMS residual.

    Raises
    ------
    ParameterError
        Unknown terms.
    InsufficientDataError
        Too few holds, or holds at too few distinct voltages, to determine
        the requested terms.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(12000) / 1000.0
    >>> v = np.repeat([0.0, 50.0, 100.0], 4000)
    >>> q = np.cumsum((2e-9 * v + 1e-11) * 1e-3)
    >>> leak = calibrate_leakage(t, v, q, terms=("conductance", "bias"))  # 3 levels, no way down
    >>> round(leak.conductance / 1e-9, 6), round(leak.bias / 1e-11, 6), len(leak.holds)
    (2.0, 1.0, 3)
    """
    chosen = tuple(terms)
    unknown = [name for name in chosen if name not in LEAKAGE_TERMS]
    if unknown or not chosen or len(set(chosen)) != len(chosen):
        msg = f"'terms' must be distinct names from {LEAKAGE_TERMS}. Got {chosen!r} instead."
        raise ParameterError(msg)
    x = as_signal(v, "v")
    y = as_signal(q, "q")
    same_length(x, y, "v", "q")
    ts = as_time(t, x.size, required=True, owner="calibrate_leakage")
    assert ts is not None
    s = float(np.max(np.abs(x))) if scale is None else float(scale)
    s = s if s > 0 else 1.0
    ranges = (
        find_holds(ts, x, tolerance=tolerance, min_duration=min_duration, settle=settle)
        if holds is None
        else [(int(a), int(b)) for a, b in holds]
    )
    found = []
    for a, b in ranges:
        if not 0 <= a < b <= x.size or b - a < 3:
            msg = f"a hold must be a range start:stop of at least 3 samples. Got {a}:{b}."
            raise ParameterError(msg)
        tt = ts[a:b] - ts[a:b].mean()
        qq = y[a:b] - y[a:b].mean()
        sxx = float(tt @ tt)
        slope = float(tt @ qq) / sxx
        resid = qq - slope * tt
        stderr = math.sqrt(float(resid @ resid) / max(b - a - 2, 1) / sxx)
        found.append(
            Hold(
                a,
                b,
                float(x[a:b].mean()),
                float(y[a:b].mean()),
                slope,
                stderr,
                float(ts[b - 1] - ts[a]),
            )
        )
    span = float(np.ptp(x)) or 1.0
    levels = _distinct([h.voltage for h in found], 0.02 * span)
    by_voltage = [name for name in chosen if name != "discharge"]
    if len(levels) < len(by_voltage) or len(found) < len(chosen):
        where = ", ".join(f"{lv:.4g}" for lv in levels) or "none"
        msg = (
            f"{len(found)} hold(s) at {len(levels)} distinct voltage(s) ({where} {input_unit}) "
            f"cannot determine {len(chosen)} leakage term(s) ({', '.join(chosen)}): record "
            "holds of several seconds at more levels, up and down again (e.g. 0, 25, 50, 75, "
            "100, 75, 50, 25, 0 % of the range), or ask for fewer terms"
        )
        raise InsufficientDataError(msg)
    volts = np.array([h.voltage for h in found])
    columns = {
        "conductance": volts,
        "quadratic": volts * np.abs(volts) / s,
        "bias": np.ones_like(volts),
        "discharge": -np.array([h.charge for h in found]),
    }
    a_mat = np.column_stack([columns[name] for name in chosen])
    rhs = np.array([h.current for h in found])
    w = np.sqrt(np.array([h.duration for h in found]))
    design = a_mat * w[:, None]
    norms = np.linalg.norm(design, axis=0)
    sv = np.linalg.svd(design / np.where(norms > 0, norms, 1.0), compute_uv=False)
    if norms.min() == 0 or sv[-1] < 1e-3 * sv[0]:
        msg = (
            f"the {len(found)} holds cannot tell the terms {', '.join(chosen)} apart"
            + (
                ": the discharge term needs holds at one voltage with different charges "
                "(hold each level once on the way up and once on the way down)"
                if "discharge" in chosen
                else ""
            )
            + "; or ask for fewer terms"
        )
        raise InsufficientDataError(msg)
    coef, *_ = np.linalg.lstsq(design, rhs * w, rcond=None)
    values = dict.fromkeys(LEAKAGE_TERMS, 0.0)
    values.update({name: float(c) for name, c in zip(chosen, coef, strict=True)})
    misfit = rhs - a_mat @ coef
    return Leakage(
        values["conductance"],
        values["quadratic"],
        values["bias"],
        s,
        values["discharge"],
        input_unit,
        output_unit,
        holds=tuple(found),
        residual=float(np.sqrt(np.mean(misfit**2))),
    )


def _distinct(values: Sequence[float], gap: float) -> list[float]:
    """Values more than ``gap`` apart (sorted; each cluster by its first member)."""
    out: list[float] = []
    for value in sorted(values):
        if not out or value - out[-1] > gap:
            out.append(value)
    return out
