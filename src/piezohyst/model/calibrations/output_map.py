"""The map from the capacitor's charge to the displacement (eq. 6-7), as calibrated:
:class:`OutputMap` (its polynomial, uncertainty, calibrated range, a mechanical mode where the
record shows one, and file). It is identified by :func:`~.from_sensor.calibrate_gain`."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import FloatArray
from ...errors import (
    ExtrapolationWarning,
    ModelFileError,
    NotInvertibleError,
    ParameterError,
    PiezohystError,
    warn,
)
from ...io import JsonFile
from ..dynamics import OutputDynamics
from ..persistence import checksum, model_to_dict

__all__ = ["OUTPUT_MAP_FORMAT", "OutputMap", "model_fingerprint", "monotone_charges"]

OUTPUT_MAP_FORMAT = "piezohyst-output-map"
OUTPUT_MAP_VERSION = 1
#: The version a map with a mechanical mode is written as (a reader that knows no mode
#: refuses it rather than dropping the mode); both are read
OUTPUT_MAP_MODE_VERSION = 2
#: |coefficient / standard error| a curvature term needs to be kept (strong evidence)
EVIDENCE = 5.0
#: Highest polynomial order tried
MAX_ORDER = 3
#: Fewest samples a calibration takes
MIN_SAMPLES = 200
#: Longest sensor delay searched (s), and never more than a twentieth of the record
MAX_DELAY = 0.05
#: Share of the samples a sensor may sit at its extreme before it counts as saturated
SATURATED_SHARE = 0.01


@dataclass(frozen=True)
class OutputMap(JsonFile):
    r"""The map from a capacitor's charge to its displacement, with its uncertainty.

    :math:`s = \sum_k c_k u^k` with :math:`u = (q - q_0) / q_s`: ``coefficients``
    ``c_0`` (the offset: the displacement at ``center``), ``c_1``, ... in output
    units; built by :func:`calibrate_gain`. Where the record shows the structure ringing
    (a bender's first bending mode, a stage's flexure), the charge passes through that
    mode first (:attr:`mode`, unit gain at DC, :class:`~piezohyst.model.dynamics.
    OutputDynamics`): :math:`s = P(H q)`. A unit-gain filter commutes with a linear map,
    so for a linear map it is the mode on the displacement itself; for a curved one the
    two orders differ by the curvature times the mode's transient, and this order is the
    one whose inverse is exact (the mode's inverse after the map's).

    Attributes
    ----------
    coefficients : tuple of float
        Polynomial coefficients in ``u`` (output units), lowest order first.
    center, scale : float
        ``q_0`` and ``q_s`` (input units, C).
    covariance : tuple of tuple of float
        The coefficients' covariance (Newey-West).
    charge_range : (float, float)
        The capacitor charges the calibration covered (C).
    delay : float
        The sensor's delay behind the charge (s; whole samples).
    residual : float
        RMS misfit of the calibration (output units).
    n_samples, n_effective : int
        Samples used, and as many independent ones as their correlation is worth.
    evidence : dict
        ``|c_k / stderr|`` of each order's top coefficient as tried ("order 2": 1.3, ...).
    input_unit, output_unit : str
    model : str
        The model the charge went through (its growth terms removed, eq. 19): its class
        and the start of its file's checksum (:func:`model_fingerprint`); "" for a map
        made by hand or written before this field. A compensator built on another model
        says so: that model's hysteresis charge can differ in offset and scale.
    mode_f0, mode_zeta, mode_dt : float
        The mechanical mode between the charge and the displacement: resonance (Hz; 0:
        none), damping ratio, and the calibration's sample interval (s).
    """

    file_kind: ClassVar[str] = "an output map"

    coefficients: tuple[float, ...]
    center: float
    scale: float
    covariance: tuple[tuple[float, ...], ...]
    charge_range: tuple[float, float]
    delay: float = 0.0
    residual: float = math.nan
    n_samples: int = 0
    n_effective: int = 0
    evidence: dict[str, float] = field(default_factory=dict)
    input_unit: str = "C"
    output_unit: str = "m"
    model: str = ""
    mode_f0: float = 0.0
    mode_zeta: float = 0.0
    mode_dt: float = 0.0
    _edges: tuple[float, float, float, float, float, float] = field(
        init=False, repr=False, compare=False
    )
    _monotone: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        c = self.coefficients
        if len(c) < 2 or not all(math.isfinite(v) for v in c):
            msg = f"an OutputMap needs finite coefficients (offset, slope, ...). Got {c!r}."
            raise ParameterError(msg)
        if not (math.isfinite(self.scale) and self.scale > 0 and math.isfinite(self.center)):
            msg = f"an OutputMap needs a finite center and a scale > 0. Got {self.scale!r}."
            raise ParameterError(msg)
        lo, hi = self.charge_range
        if not lo < hi:
            msg = f"an OutputMap's charge_range must be (low, high). Got {self.charge_range!r}."
            raise ParameterError(msg)
        if c[1] == 0.0 and len(c) == 2:
            msg = "an OutputMap with a zero gain maps every charge to one displacement"
            raise ParameterError(msg)
        OutputDynamics(self.mode_f0, self.mode_zeta, self.mode_dt)  # its own checks
        # derived once (the map is frozen): a loop inverts it every sample, and these two
        # were most of a stepping self-sensing loop's time (polynomial derivatives each call)
        object.__setattr__(self, "_edges", self._find_edges())
        lo, hi = self.charge_range
        slopes = self.slope(np.linspace(lo, hi, 513))
        object.__setattr__(self, "_monotone", bool(np.all(slopes > 0) or np.all(slopes < 0)))

    # ------------------------------------------------------------------ numbers
    @property
    def mode(self) -> OutputDynamics:
        """The mechanical mode between the charge and the displacement (inactive: none)."""
        return OutputDynamics(self.mode_f0, self.mode_zeta, self.mode_dt)

    @property
    def order(self) -> int:
        """1 for a linear map, 2 with a quadratic (electrostrictive) term, ..."""
        return len(self.coefficients) - 1

    @property
    def gain(self) -> float:
        """Displacement per charge at the calibration's center (m/C): g of eq. 6-7."""
        return self.coefficients[1] / self.scale

    @property
    def gain_stderr(self) -> float:
        """The gain's standard error (m/C)."""
        return math.sqrt(max(self.covariance[1][1], 0.0)) / self.scale

    @property
    def monotone(self) -> bool:
        """True when the displacement rises (or falls) throughout the calibrated charges."""
        return self._monotone

    def _u(self, q: FloatArray) -> FloatArray:
        return (q - self.center) / self.scale

    def _poly(self, u: FloatArray) -> FloatArray:
        return np.asarray(np.polynomial.polynomial.polyval(u, np.asarray(self.coefficients)))

    def _dpoly(self, u: FloatArray) -> FloatArray:
        d = np.polynomial.polynomial.polyder(np.asarray(self.coefficients))
        return np.asarray(np.polynomial.polynomial.polyval(u, d), dtype=np.float64)

    def edges(self) -> tuple[float, float, float, float, float, float]:
        """The calibrated range's edges: ``(lo, hi, s_lo, s_hi, d_lo, d_hi)``, the lowest and
        highest calibrated charge (C), their displacements and the map's slope there (m/C),
        where the linear extension beyond the range starts.

        Returns
        -------
        tuple of float
        """
        return self._edges

    def _find_edges(self) -> tuple[float, float, float, float, float, float]:
        lo, hi = self.charge_range
        ul, uh = float(self._u(np.array(lo))), float(self._u(np.array(hi)))
        return (lo, hi, float(self._poly(np.array(ul))), float(self._poly(np.array(uh))),
                float(self._dpoly(np.array(ul))) / self.scale,
                float(self._dpoly(np.array(uh))) / self.scale)  # fmt: skip

    def slope(self, charge: ArrayLike) -> FloatArray:
        """d(displacement)/d(charge) (m/C) at ``charge``, inside the calibrated range.

        Parameters
        ----------
        charge : array_like
            Capacitor charges (C).

        Returns
        -------
        ndarray
        """
        q = np.asarray(charge, dtype=np.float64)
        return np.asarray(self._dpoly(self._u(q)) / self.scale)

    def predict(self, charge: ArrayLike) -> FloatArray:
        """The displacement for capacitor charges (C); beyond the calibrated range the map
        extends linearly from its edge, with an :class:`ExtrapolationWarning`.

        Parameters
        ----------
        charge : array_like

        Returns
        -------
        ndarray
        """
        q = np.asarray(charge, dtype=np.float64)
        lo, hi, s_lo, s_hi, d_lo, d_hi = self.edges()
        inside = np.clip(q, lo, hi)
        s = self._poly(self._u(inside))
        below, above = q < lo, q > hi
        if np.any(below) or np.any(above):
            self._warn_outside(f"charges down to {np.nanmin(q):.4g} / up to {np.nanmax(q):.4g}")
            s = np.where(below, s_lo + d_lo * (q - lo), s)
            s = np.where(above, s_hi + d_hi * (q - hi), s)
        return np.asarray(s)

    def respond(self, charge: ArrayLike, sample_interval: float | None = None) -> FloatArray:
        """The displacement for a record of capacitor charges: the charge through the map's
        mode (from rest at its first value), then the map (:meth:`predict`, which is the
        quasi-static displacement). Without a mode, the same as :meth:`predict`.

        Parameters
        ----------
        charge : array_like, shape (N,)
            C, one sample per ``sample_interval``.
        sample_interval : float, optional
            s; default the calibration's (``mode_dt``).

        Returns
        -------
        ndarray, shape (N,)
        """
        q = np.asarray(charge, dtype=np.float64)
        if not self.mode.active or q.ndim != 1 or q.size == 0:
            return self.predict(q)
        mode = self.mode
        if sample_interval is not None and sample_interval != self.mode_dt:
            mode = OutputDynamics(self.mode_f0, self.mode_zeta, float(sample_interval))
        lo, hi = self.charge_range
        if np.nanmin(q) < lo or np.nanmax(q) > hi:  # said for the charges given, not for the
            self._warn_outside(f"charges down to {np.nanmin(q):.4g} / up to {np.nanmax(q):.4g}")
        with warnings.catch_warnings():  # mode's ringing a little past them
            warnings.simplefilter("ignore", ExtrapolationWarning)
            return self.predict(mode.apply(q)[0])

    def stderr(self, charge: ArrayLike) -> FloatArray:
        """The map's standard error (output units) at ``charge``: how sure the displacement
        it gives there is (smallest inside the range, growing towards its edges).

        Parameters
        ----------
        charge : array_like
            Capacitor charges (C); clipped to the calibrated range.

        Returns
        -------
        ndarray
        """
        q = np.clip(np.asarray(charge, dtype=np.float64), *self.charge_range)
        u = self._u(q)
        powers = np.stack([u**k for k in range(self.order + 1)], axis=-1)
        cov = np.asarray(self.covariance)
        return np.asarray(
            np.sqrt(np.maximum(np.einsum("...i,ij,...j->...", powers, cov, powers), 0))
        )

    def displacement_range(self) -> tuple[float, float]:
        """The displacements the calibrated charges reach (output units).

        Returns
        -------
        (float, float)
        """
        lo, hi = self.charge_range
        s = self._poly(self._u(np.linspace(lo, hi, 513)))
        return float(s.min()), float(s.max())

    def inverse(self, displacement: ArrayLike, near: float | None = None) -> FloatArray:
        """The capacitor charge that gives ``displacement`` (C).

        On a monotone map, the one charge; beyond the calibrated displacements the
        linear extension from the edge, with an :class:`ExtrapolationWarning`. On a map
        that turns (the butterfly), the charge on the branch nearest ``near`` (the
        charge the actuator holds now); without ``near`` a displacement with two
        charges is refused.

        Parameters
        ----------
        displacement : array_like
        near : float, optional

        Returns
        -------
        ndarray
            NaN where ``displacement`` is NaN.

        Raises
        ------
        NotInvertibleError
            A displacement reached at two charges and no ``near``.
        """
        s = np.asarray(displacement, dtype=np.float64)
        flat = s.reshape(-1)
        if self.monotone:
            out, beyond = self._invert_monotone(flat)
            if beyond.any():
                self._warn_outside(f"displacements {np.nanmin(flat):.4g} to {np.nanmax(flat):.4g}")
            return out.reshape(s.shape)
        out = np.full(flat.shape, np.nan)
        lo, hi = self.charge_range
        for i, target in enumerate(flat):
            if math.isfinite(target):
                out[i] = near = self._solve_branch(float(target), near, lo, hi)
        return out.reshape(s.shape)

    def _invert_monotone(self, s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The charges for displacements on a monotone map (vectorised Newton inside the
        calibrated range, the linear extension beyond it); and whether any lay beyond."""
        if self.order == 1:
            c0, c1 = self.coefficients
            return monotone_charges(s, self.center, self.scale, c0, c1, self.edges())
        lo, hi, s_lo, s_hi, _, _ = edges = self.edges()
        low_end, high_end = min(s_lo, s_hi), max(s_lo, s_hi)
        inside = np.clip(np.where(np.isfinite(s), s, low_end), low_end, high_end)
        # Newton from the chord, kept inside the range; the map's slope never vanishes
        q = lo + (hi - lo) * (inside - s_lo) / (s_hi - s_lo)
        tol = 1e-13 * max(abs(high_end - low_end), 1e-300)
        for _ in range(50):
            f = self._poly(self._u(q)) - inside
            if float(np.max(np.abs(f))) <= tol:
                break
            q = np.clip(q - f / self.slope(q), lo, hi)
        return monotone_charges(s, self.center, self.scale, math.nan, math.nan, edges, q)

    def _solve_branch(self, target: float, near: float | None, lo: float, hi: float) -> float:
        c = np.array(self.coefficients, dtype=np.float64)
        c[0] -= target
        roots = np.polynomial.polynomial.polyroots(c)
        real = roots[np.abs(roots.imag) <= 1e-9 * max(1.0, float(np.abs(roots).max()))].real
        qs = self.center + self.scale * real
        ulo, uhi = lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)
        qs = qs[(qs >= ulo) & (qs <= uhi)]
        if qs.size == 0:  # out of reach: the calibrated charge whose displacement is nearest
            self._warn_outside(f"the displacement {target:.4g} {self.output_unit} (out of reach)")
            grid = np.linspace(lo, hi, 2049)
            return float(grid[np.argmin(np.abs(self._poly(self._u(grid)) - target))])
        if qs.size > 1 and near is None:
            msg = (
                f"the displacement {target:.4g} {self.output_unit} is reached at "
                f"{qs.size} charges ({', '.join(f'{q:.4g}' for q in np.sort(qs))} "
                f"{self.input_unit}): the map turns over the calibrated range (the butterfly "
                "of bipolar drive); give the charge the actuator holds now (near=)"
            )
            raise NotInvertibleError(msg)
        ref = qs[0] if near is None else near
        return float(qs[np.argmin(np.abs(qs - ref))])

    def _warn_outside(self, what: str) -> None:
        lo, hi = self.charge_range
        warn(
            f"OutputMap: {what} lie outside the calibrated charges [{lo:.4g}, {hi:.4g}] "
            f"{self.input_unit}; the map is extended linearly from its edge there (calibrate "
            "over the full drive to hold it)",
            ExtrapolationWarning,
        )

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready contents with a schema version and a checksum (see :meth:`from_dict`).

        Returns
        -------
        dict
        """
        body: dict[str, Any] = {
            "format": OUTPUT_MAP_FORMAT,
            "schema_version": OUTPUT_MAP_VERSION,
            "coefficients": list(self.coefficients),
            "center": self.center,
            "scale": self.scale,
            "covariance": [list(row) for row in self.covariance],
            "charge_range": list(self.charge_range),
            "delay": self.delay,
            "residual": None if math.isnan(self.residual) else self.residual,
            "n_samples": self.n_samples,
            "n_effective": self.n_effective,
            "evidence": dict(self.evidence),
            "input_unit": self.input_unit,
            "output_unit": self.output_unit,
            "model": self.model,
            "gain": self.gain,  # for a reader: derived, not read back
            "gain_stderr": self.gain_stderr,
        }
        if self.mode.active:  # written only where there is one: older maps keep their checksum
            body["schema_version"] = OUTPUT_MAP_MODE_VERSION
            body["mode"] = self.mode.to_dict()
        body["checksum"] = checksum(body)
        return body

    @classmethod
    def from_dict(cls, data: Any, where: str = "output map") -> OutputMap:
        """Rebuild from :meth:`to_dict` output; a bad field is named in one line.

        Parameters
        ----------
        data : dict
            The map's coefficients, center, scale, covariance and charge range, with its
            schema version and checksum.
        where : str
            Named in errors (a file name).

        Returns
        -------
        OutputMap

        Raises
        ------
        ModelFileError
        """
        if not isinstance(data, dict) or data.get("format") != OUTPUT_MAP_FORMAT:
            msg = f'{where}: not a piezohyst output map (expected "format": "{OUTPUT_MAP_FORMAT}")'
            raise ModelFileError(msg)
        if data.get("schema_version") not in (OUTPUT_MAP_VERSION, OUTPUT_MAP_MODE_VERSION):
            found = data.get("schema_version")
            msg = (f"{where}: schema_version {found!r} is not {OUTPUT_MAP_VERSION} or "
                   f"{OUTPUT_MAP_MODE_VERSION}")  # fmt: skip
            raise ModelFileError(msg)
        if "checksum" in data and data["checksum"] != checksum(data):
            msg = (
                f"{where}: checksum mismatch: the file was modified after it was saved "
                '(delete the "checksum" field to accept a deliberate edit)'
            )
            raise ModelFileError(msg)
        try:
            residual = data.get("residual")
            mode = data.get("mode") or {}
            if not isinstance(mode, dict):
                msg = f"'mode' must be an object with f0, zeta and sample_interval. Got {mode!r}."
                raise ParameterError(msg)
            return cls(
                coefficients=tuple(float(c) for c in data["coefficients"]),
                center=float(data["center"]),
                scale=float(data["scale"]),
                covariance=tuple(tuple(float(c) for c in row) for row in data["covariance"]),
                charge_range=(float(data["charge_range"][0]), float(data["charge_range"][1])),
                delay=float(data.get("delay", 0.0)),
                residual=math.nan if residual is None else float(residual),
                n_samples=int(data.get("n_samples", 0)),
                n_effective=int(data.get("n_effective", 0)),
                evidence={str(k): float(v) for k, v in (data.get("evidence") or {}).items()},
                input_unit=str(data.get("input_unit", "C")),
                output_unit=str(data.get("output_unit", "m")),
                model=str(data.get("model", "")),
                mode_f0=float(mode.get("f0", 0.0)),
                mode_zeta=float(mode.get("zeta", 0.0)),
                mode_dt=float(mode.get("sample_interval", 0.0)),
            )
        except KeyError as exc:
            msg = f"{where}: field {exc.args[0]!r} is missing"
            raise ModelFileError(msg) from None
        except (TypeError, ValueError, IndexError, ParameterError) as exc:
            msg = f"{where}: {str(exc).splitlines()[0]}"
            raise ModelFileError(msg) from None

    def check_model(self, model: Any) -> None:
        """Warn where ``model`` is not the model this map was calibrated through.

        Parameters
        ----------
        model : HysteresisModel
            The model a compensator or controller inverts with this map.
        """
        if not self.model:
            return
        used = model_fingerprint(model)
        if used != self.model:
            kind = self.model.split()[0]
            made = (f"another fit of {kind} ({self.model}), not this one ({used})"
                    if kind == used.split()[0] else f"{self.model}, not this {used}")  # fmt: skip
            warn(
                f"the output map was calibrated through {made}: the charge it maps can differ "
                "in offset and scale; run calibrate-gain with this model",
                UserWarning,
            )

    def summary(self) -> str:
        """One line: the gain with its standard error, the curvature, delay and range.

        Returns
        -------
        str
        """
        lo, hi = self.charge_range
        curve = "" if self.order == 1 else f", order {self.order} (curvature by evidence)"
        if self.mode.active:
            curve += f", a mode at {self.mode_f0:.4g} Hz (damping {self.mode_zeta:.3g})"
        return (
            f"gain {self.gain:.6g} ± {self.gain_stderr:.2g} {self.output_unit}/{self.input_unit}"
            f"{curve}, delay {1e3 * self.delay:.3g} ms, RMS misfit {self.residual:.3g} "
            f"{self.output_unit}, calibrated on [{lo:.4g}, {hi:.4g}] {self.input_unit}"
        )


def model_fingerprint(model: Any) -> str:
    """A fitted model's class and the first 12 hex digits of its file's checksum.

    Parameters
    ----------
    model : HysteresisModel
        Fitted; a stand-in that cannot be written as a model file gives its class alone.

    Returns
    -------
    str
        ``"BoucWenModel 3f2a9c01d4e7"``.
    """
    try:
        digest = str(model_to_dict(model)["checksum"]).removeprefix("sha256:")[:12]
    except (PiezohystError, AttributeError, TypeError):  # a stand-in without a file form
        return type(model).__name__
    return f"{type(model).__name__} {digest}"


def monotone_charges(
    s: Any, center: Any, scale: Any, c0: Any, c1: Any, edges: Any, inside_q: Any = None
) -> tuple[FloatArray, FloatArray]:
    """Charges for displacements ``s`` on monotone maps, and which (finite ones) lay beyond
    their calibrated displacements: inside, the linear map's ``center + scale (s - c0) / c1``
    (or ``inside_q``, a curved map's solution); beyond, the linear extension from the edge.
    Every argument broadcasts, so one call serves a bank's channels, one map each.

    Parameters
    ----------
    s : ndarray
        Displacements (NaN or infinite: NaN).
    center, scale, c0, c1 : float or ndarray
        The maps' center and scale (C) and linear coefficients (m).
    edges : tuple of (float or ndarray)
        ``(lo, hi, s_lo, s_hi, d_lo, d_hi)``: the calibrated charges, their displacements
        and the map's slopes there.
    inside_q : ndarray, optional
        The charges inside the range, already solved (a curved map).

    Returns
    -------
    (ndarray, ndarray of bool)
    """
    lo, hi, s_lo, s_hi, d_lo, d_hi = edges
    rising = np.asarray(s_hi) > np.asarray(s_lo)
    low_end, high_end = np.where(rising, s_lo, s_hi), np.where(rising, s_hi, s_lo)
    finite = np.isfinite(s)
    below = finite & (s < low_end)
    above = finite & (s > high_end)
    if inside_q is None:
        inside = np.clip(np.where(finite, s, low_end), low_end, high_end)
        q = center + scale * (inside - c0) / c1
    else:
        q = inside_q
    at_lo_end = np.where(rising, below, above)
    at_hi_end = np.where(rising, above, below)
    q = np.where(at_lo_end, lo + (s - s_lo) / d_lo, q)
    q = np.where(at_hi_end, hi + (s - s_hi) / d_hi, q)
    q = np.where(finite, q, np.nan)
    return np.asarray(q), np.asarray(below | above)
