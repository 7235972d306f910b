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
leakage-corrected charge (:class:`~piezohyst.control.selfsensing.SelfSensingController`)
wants its leakage from holds: :func:`calibrate_leakage` finds the holds in a
record, measures the charge's slope on each, and fits the selected terms.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import FloatArray, as_signal, as_time, same_length
from ...errors import ModelFileError, ParameterError
from ...io import JsonFile

__all__ = ["LEAKAGE_TERMS", "Hold", "Leakage"]

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
class Leakage(JsonFile):
    r"""A leakage current :math:`G_0 v + G_1 v|v|/s + i_b - q/\tau` and its integral.

    Made by :func:`calibrate_leakage`, or from a fitted model's growth terms
    by :meth:`from_model`, or by hand. Accepted by
    :meth:`~piezohyst.model.presets.HysteresisModel.remove_growth` and
    :class:`~piezohyst.control.selfsensing.SelfSensingController`.

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
    covariance : tuple of tuple of float
        Covariance of (conductance, quadratic, bias, discharge) from the calibration
        (zero rows for terms it did not fit); empty when not calibrated.
    drift_covariance : tuple of tuple of float
        The covariance :meth:`charge_stderr` uses: ``covariance``, or where the
        calibration's choice left out terms the holds still determine, the fit of every
        term's plus the outer product of the two fits' difference (a term left out is
        too small for the holds' currents to tell, not known to be 0, and it adds up in
        the charge over a minute); empty when not calibrated.
    """

    file_kind: ClassVar[str] = "a leakage file"

    conductance: float = 0.0
    quadratic: float = 0.0
    bias: float = 0.0
    scale: float = 1.0
    discharge: float = 0.0
    input_unit: str = "V"
    output_unit: str = "C"
    holds: tuple[Hold, ...] = field(default=(), compare=False)
    residual: float = field(default=math.nan, compare=False)
    covariance: tuple[tuple[float, ...], ...] = field(default=(), compare=False)
    drift_covariance: tuple[tuple[float, ...], ...] = field(default=(), compare=False)

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

    def stderr(self) -> dict[str, float]:
        """Each term's standard error from the calibration (0 for a term left out; empty
        when the leakage was not calibrated from holds).

        Returns
        -------
        dict
        """
        if not self.covariance:
            return {}
        diag = np.diag(np.asarray(self.covariance, dtype=np.float64))
        return {n: float(math.sqrt(max(d, 0.0))) for n, d in zip(LEAKAGE_TERMS, diag, strict=True)}

    def current_stderr(self, v: ArrayLike, q: ArrayLike | float = 0.0) -> FloatArray:
        """Standard error of :meth:`current` at ``v`` (and ``q``), from the calibration's
        covariance (NaN when the leakage was not calibrated from holds).

        Parameters
        ----------
        v : array_like
            Voltages (input units).
        q : array_like or float, default 0
            Measured charge (output units).

        Returns
        -------
        ndarray
        """
        x = np.asarray(v, dtype=np.float64)
        if not self.covariance:
            return np.full(x.shape, np.nan)
        qq = np.broadcast_to(np.asarray(q, dtype=np.float64), x.shape)
        g = self._columns(x, np.asarray(qq))
        cov = np.asarray(self.covariance, dtype=np.float64)
        return np.asarray(np.sqrt(np.maximum(np.einsum("...i,ij,...j->...", g, cov, g), 0.0)))

    def charge_stderr(self, v: ArrayLike, t: ArrayLike, q: ArrayLike | None = None) -> FloatArray:
        """Standard error of :meth:`charge` along a path, from the calibration's covariance
        (NaN when the leakage was not calibrated from holds).

        The leaked charge is linear in the coefficients, so its variance at each sample is
        ``g' C g``, ``g`` the integrated terms (as :meth:`charge` integrates them) and ``C``
        their covariance. A self-sensing loop holds the charge less this estimate: this is
        how far its position may drift along the path (1 sigma, times the gain), however
        well the current at each hold was known. It counts the terms the calibration left
        out too (:attr:`drift_covariance`).

        Parameters
        ----------
        v, t, q : array_like, shape (N,)
            As for :meth:`charge` (``q`` needed when the discharge was calibrated).

        Returns
        -------
        ndarray, shape (N,)
            Output units.
        """
        cov = np.asarray(self.drift_covariance or self.covariance, dtype=np.float64)
        x, qs, dt = self._path(v, t, q, cov.size > 0 and cov[3, 3] != 0.0, "charge_stderr")
        if not cov.size:
            return np.full(x.shape, np.nan)
        g = np.cumsum(self._columns(x, qs) * dt[:, None], axis=0)
        return np.asarray(np.sqrt(np.maximum(np.einsum("ki,ij,kj->k", g, cov, g), 0.0)))

    def _columns(self, x: FloatArray, q: FloatArray) -> FloatArray:
        """Each term's column at voltages ``x`` and charges ``q`` (its current per unit)."""
        return np.stack([x, x * np.abs(x) / self.scale, np.ones_like(x), -q], axis=-1)

    def _path(
        self, v: ArrayLike, t: ArrayLike, q: ArrayLike | None, needs_q: bool, owner: str
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """A path's voltages, charges (0 without ``q``) and sample intervals, checked."""
        x = as_signal(v, "v")
        ts = as_time(t, x.size, required=True, owner=f"Leakage.{owner}")
        assert ts is not None
        if q is None and needs_q:
            msg = "this leakage has a discharge term: pass the measured charge q"
            raise ParameterError(msg)
        qs = np.zeros_like(x) if q is None else as_signal(q, "q")
        same_length(x, qs, "v", "q")
        return x, qs, np.diff(ts, prepend=ts[0])

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
        x, qs, dt = self._path(v, t, q, self.discharge != 0.0, "charge")
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
        out["covariance"] = [list(row) for row in self.covariance]
        out["drift_covariance"] = [list(row) for row in self.drift_covariance]
        return {"format": "piezohyst-leakage", "kind": "leakage", **out}

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "leakage") -> Leakage:
        """Rebuild from :meth:`to_dict` output; a bad field is named.

        Parameters
        ----------
        data : dict
            The terms' coefficients and units, with the calibration's holds and covariances
            where it had them.
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
        extra = set(fields) - known - {"holds", "residual", "covariance", "drift_covariance"}
        if extra:
            msg = f"{where}: unknown field {sorted(extra)[0]!r}"
            raise ModelFileError(msg)
        try:
            holds = tuple(Hold(**h) for h in fields.get("holds") or ())
            residual = fields.get("residual")
            cov, drift = (
                tuple(tuple(float(c) for c in row) for row in fields.get(name) or ())
                for name in ("covariance", "drift_covariance")
            )
            return cls(
                **{k: fields[k] for k in known if k in fields},
                holds=holds,
                residual=math.nan if residual is None else float(residual),
                covariance=cov,
                drift_covariance=drift,
            )
        except (TypeError, ParameterError) as exc:
            msg = f"{where}: {exc}"
            raise ModelFileError(msg) from None
