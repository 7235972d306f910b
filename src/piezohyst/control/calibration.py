r"""From charge to position: the sensor once, then metres from the charge alone.

At zero stress the strain follows the electric displacement, S = g·D (eq. 6-7),
so once the map from the capacitor's charge to the displacement is known, a
compensator that linearises voltage → charge linearises voltage → position,
and the position sensor can go. :func:`calibrate_gain` identifies that map
from one record with a displacement sensor (voltage, charge and displacement
sampled together):

* the charge the map starts from is the capacitor's: the measured charge with
  the model's growth removed (eq. 19), so leaked charge moves nothing;
* the map is a polynomial in the charge, of the lowest order the record's
  evidence supports: linear ``g`` unless a curvature term's coefficient is
  many standard errors from zero (an electrostrictive part, S ∝ D², on
  semi-bipolar drive or near the coercive field); never curved by default;
* a sensor delay (whole samples; a sensor's lag is absorbed by the delay that
  fits best) if the record shows one, and an offset (the sensor's zero);
* standard errors from a covariance that allows for correlated residuals
  (Newey-West), so the uncertainty stated is not that of white noise.

The :class:`OutputMap` states its uncertainty at any charge
(:meth:`OutputMap.stderr`), the charge range it was calibrated on (beyond it,
it extends linearly from the range's edge and says so with an
:class:`~piezohyst.errors.ExtrapolationWarning`), whether it is monotone there
(on bipolar drive past the coercive field it is not: the butterfly), and saves
as JSON with a schema and a checksum, like a model file.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, as_time, same_length
from ..errors import (
    ExtrapolationWarning,
    InsufficientDataError,
    ModelFileError,
    NotInvertibleError,
    ParameterError,
    PiezohystError,
    warn,
)
from ..io import JsonFile
from ..model.persistence import checksum, model_to_dict

__all__ = ["OUTPUT_MAP_FORMAT", "Charges", "OutputMap", "calibrate_gain", "model_fingerprint"]

OUTPUT_MAP_FORMAT = "piezohyst-output-map"
OUTPUT_MAP_VERSION = 1
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
    units; built by :func:`calibrate_gain`.

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

    # ------------------------------------------------------------------ numbers
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
        lo, hi = self.charge_range
        s = self.slope(np.linspace(lo, hi, 513))
        return bool(np.all(s > 0) or np.all(s < 0))

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
        if data.get("schema_version") != OUTPUT_MAP_VERSION:
            found = data.get("schema_version")
            msg = f"{where}: schema_version {found!r} is not {OUTPUT_MAP_VERSION}"
            raise ModelFileError(msg)
        if "checksum" in data and data["checksum"] != checksum(data):
            msg = (
                f"{where}: checksum mismatch: the file was modified after it was saved "
                '(delete the "checksum" field to accept a deliberate edit)'
            )
            raise ModelFileError(msg)
        try:
            residual = data.get("residual")
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
        return (
            f"gain {self.gain:.6g} ± {self.gain_stderr:.2g} {self.output_unit}/{self.input_unit}"
            f"{curve}, delay {1e3 * self.delay:.3g} ms, RMS misfit {self.residual:.3g} "
            f"{self.output_unit}, calibrated on [{lo:.4g}, {hi:.4g}] {self.input_unit}"
        )


class Charges:
    """Desired displacements turned into capacitor charges through an :class:`OutputMap`,
    one sample or block after another: on a map that turns, each on the branch of the
    charge before it (a compensator's and a controller's front end).

    Parameters
    ----------
    output_map : OutputMap
    """

    def __init__(self, output_map: OutputMap) -> None:
        self.output_map = output_map
        self.last: float | None = None
        #: desired displacements beyond the calibrated ones since the last reset (the map
        #: extended linearly from its edge there, or out of reach on a map that turns)
        self.outside = 0
        self._said = False  # the first of them since the last reset was warned about
        lo_s, hi_s = (output_map.edges()[2:4] if output_map.monotone
                      else output_map.displacement_range())  # fmt: skip
        self._reach = (min(lo_s, hi_s), max(lo_s, hi_s))

    @classmethod
    def of(cls, output_map: Any, gain: float | None, model: Any = None) -> Charges | None:
        """The front end for a compensator's ``output_map`` argument (None without one).

        Parameters
        ----------
        output_map : OutputMap or None
        gain : float or None
            The compensator's ``gain`` argument: the map replaces it.
        model : HysteresisModel, optional
            The model the compensator inverts: said where the map was calibrated through
            another (:meth:`OutputMap.check_model`).

        Returns
        -------
        Charges or None

        Raises
        ------
        ParameterError
            Not an OutputMap, or given with a gain.
        """
        if output_map is None:
            return None
        if not isinstance(output_map, OutputMap):
            msg = (
                "'output_map' must be an OutputMap (see calibrate_gain). "
                f"Got {type(output_map).__name__}."
            )
            raise ParameterError(msg)
        if gain is not None:
            msg = "give the output_map or a gain, not both (the map holds the gain)"
            raise ParameterError(msg)
        if model is not None:
            output_map.check_model(model)
        return cls(output_map)

    def reset(self) -> None:
        """Forget the branch and the count (a compensator's reset)."""
        self.last = None
        self.outside = 0
        self._said = False

    def block(self, desired: FloatArray) -> FloatArray:
        """The charges for a block of desired displacements (NaN stays NaN).

        Parameters
        ----------
        desired : ndarray

        Returns
        -------
        ndarray
        """
        with warnings.catch_warnings():  # said here, once a run (a loop steps sample by sample)
            warnings.simplefilter("ignore", ExtrapolationWarning)
            q = self.output_map.inverse(desired, near=self.last)
        low, high = self._reach
        beyond = np.isfinite(desired) & ((desired < low) | (desired > high))  # NaN, inf: held
        self.outside += int(np.count_nonzero(beyond))
        if beyond.any() and not self._said:
            self._said = True
            far = desired[beyond]
            self.output_map._warn_outside(
                f"desired displacements from {far.min():.4g} to {far.max():.4g} "
                f"{self.output_map.output_unit} (the first since the start: later ones are "
                "counted, extrapolated_count, not said again)"
            )
        done = q[np.isfinite(q)]
        if done.size:
            self.last = float(done[-1])
        return np.ascontiguousarray(q)

    def one(self, desired: float, preview: ArrayLike | None) -> tuple[float, FloatArray | None]:
        """The charge for one desired displacement, and for its preview (on the same branch).

        Parameters
        ----------
        desired : float
        preview : array_like or None

        Returns
        -------
        (float, ndarray or None)
        """
        ahead = None
        if preview is not None:
            ahead = self.output_map.inverse(np.asarray(preview, dtype=np.float64), self.last)
        return float(self.block(np.array([float(desired)]))[0]), ahead


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


def _newey_west(x: FloatArray, e: FloatArray) -> tuple[FloatArray, int]:
    """The least-squares coefficients' covariance robust to correlated residuals, and the
    lag it spans (until the residuals' autocorrelation is lost in the noise)."""
    n = e.size
    rule = math.ceil(4.0 * (n / 100.0) ** (2.0 / 9.0))
    ec = e - e.mean()
    denom = float(ec @ ec) or 1e-300
    cap = max(rule, min(n // 20, 2000))
    lag = rule
    limit = 2.0 / math.sqrt(n)
    for k in range(1, cap + 1):
        if abs(float(ec[k:] @ ec[:-k]) / denom) < limit:
            lag = max(rule, k)
            break
    else:
        lag = cap
    xe = x * e[:, None]
    s = xe.T @ xe
    for k in range(1, lag + 1):
        g = xe[k:].T @ xe[:-k]
        s += (1.0 - k / (lag + 1.0)) * (g + g.T)
    bread = np.linalg.inv(x.T @ x)
    return bread @ s @ bread, lag


def calibrate_gain(
    model: Any,
    voltage: ArrayLike,
    charge: ArrayLike,
    displacement: ArrayLike,
    t: ArrayLike,
    *,
    max_order: int = MAX_ORDER,
    evidence: float = EVIDENCE,
    max_delay: float = MAX_DELAY,
    output_unit: str = "m",
) -> OutputMap:
    """Identify the map from the capacitor's charge to the displacement (eq. 6-7) from a
    record with a displacement sensor: the one step that needs the sensor.

    Parameters
    ----------
    model : HysteresisModel
        Fitted on voltage → charge (its growth terms are removed from ``charge``).
    voltage, charge, displacement, t : array_like, shape (N,)
        Sampled together: V, C, the sensor's reading (``output_unit``) and s.
    max_order : int, default 3
        Highest polynomial order tried; a term is kept only on evidence.
    evidence : float, default 5
        ``|coefficient / standard error|`` a curvature term needs.
    max_delay : float, default 0.05
        Longest sensor delay searched (s).
    output_unit : str, default "m"

    Returns
    -------
    OutputMap

    Raises
    ------
    InsufficientDataError
        Too short a record, a sensor that does not move or sits at its limit.
    """
    v = as_signal(voltage, "voltage")
    q = as_signal(charge, "charge")
    s = as_signal(displacement, "displacement")
    same_length(v, q, "voltage", "charge")
    same_length(v, s, "voltage", "displacement")
    ts = as_time(t, v.size, required=True, owner="calibrate_gain")
    assert ts is not None  # required
    if not callable(getattr(model, "remove_growth", None)):
        msg = f"calibrate_gain needs a fitted piezohyst model. Got {type(model).__name__}."
        raise ParameterError(msg)
    if isinstance(max_order, bool) or not isinstance(max_order, int) or not 1 <= max_order <= 5:
        msg = f"'max_order' must be an int in [1, 5]. Got {max_order!r}."
        raise ParameterError(msg)
    if v.size < MIN_SAMPLES:
        msg = (
            f"calibrate_gain needs at least {MIN_SAMPLES} samples to tell the map from the "
            f"sensor's noise. Got {v.size}."
        )
        raise InsufficientDataError(msg)
    qc = np.asarray(model.remove_growth(v, q, t=ts), dtype=np.float64)  # eq. 19
    _check_sensor(s, qc, output_unit)
    dt = float(np.median(np.diff(ts)))
    d_max = int(min(round(max_delay / dt), v.size // 20))
    lo, hi = float(qc.min()), float(qc.max())
    if not hi - lo > 1e-12 * max(abs(lo), abs(hi), 1e-300):
        msg = "the capacitor charge never moves: nothing maps it to a displacement"
        raise InsufficientDataError(msg)
    center, scale = 0.5 * (lo + hi), 0.5 * (hi - lo)
    leak = _leak_columns(v, q, ts)  # what the displacement tells the model's growth from

    def design(delay: int, order: int) -> tuple[FloatArray, FloatArray]:
        u = (qc[: qc.size - delay] - center) / scale
        x = np.column_stack([u**k for k in range(order + 1)] + [leak[: u.size]])
        return x, s[delay:]

    # the delay that fits best with the richest map (a delay is a shift, not a shape)
    sse = []
    for d in range(d_max + 1):
        x, y = design(d, max_order)
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        r = y - x @ coef
        sse.append(float(r @ r) / r.size)
    delay = int(np.argmin(sse))
    order, found = 1, {}
    fits: dict[int, tuple[Any, Any, FloatArray, int]] = {}
    for k in range(1, max_order + 1):
        x, y = design(delay, k)
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        r = y - x @ coef
        cov, lag = _newey_west(x, r)
        fits[k] = (coef, cov, r, lag)
        if k > 1:
            t_top = abs(float(coef[k])) / math.sqrt(max(float(cov[k, k]), 1e-300))
            found[f"order {k}"] = t_top
            if t_top < evidence:
                break
            order = k
    full, full_cov, r, lag = fits[order]
    coef, cov = full[: order + 1], full_cov[: order + 1, : order + 1]
    n = r.size
    rho = _lag1(r)
    n_eff = int(max(2, round(n * (1 - rho) / (1 + rho)))) if rho > 0 else n
    om = OutputMap(
        coefficients=tuple(float(c) for c in coef),
        center=center,
        scale=scale,
        covariance=tuple(tuple(float(c) for c in row) for row in cov),
        charge_range=(lo, hi),
        delay=delay * dt,
        residual=float(math.sqrt(float(r @ r) / n)),
        n_samples=n,
        n_effective=n_eff,
        evidence=found,
        input_unit=getattr(model, "output_unit", "C"),
        output_unit=output_unit,
        model=model_fingerprint(model),
    )
    sure = max(abs(c) / math.sqrt(max(float(cov[k, k]), 1e-300)) for k, c in enumerate(coef) if k)
    if sure < evidence:  # no term of the map stands out from its error
        msg = (
            f"the displacement does not follow the charge (gain {om.gain:.3g} ± "
            f"{om.gain_stderr:.2g} {output_unit}/{om.input_unit}, no term beyond "
            f"{evidence:g} standard errors): is the sensor on the actuator, and the right column?"
        )
        raise InsufficientDataError(msg)
    if not om.monotone:
        s_lo, s_hi = om.displacement_range()
        warn(
            f"calibrate_gain: the displacement does not follow the charge one way over the "
            f"record (it turns: the butterfly of bipolar drive past the coercive field); "
            f"displacements in [{s_lo:.4g}, {s_hi:.4g}] {output_unit} are reached on two "
            "branches, and a compensator keeps to the branch the charge is on",
            UserWarning,
        )
    return om


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


def _leak_columns(v: FloatArray, q: FloatArray, t: FloatArray) -> FloatArray:
    """The leakage shapes the model's growth terms may have missed (the terms of
    :data:`~piezohyst.model.leakage.LEAKAGE_TERMS`: ohmic, voltage-dependent, a bias
    current, the reference capacitor's discharge), each integrated by the backward
    rectangle rule the growth terms use (eq. 13) and scaled to its span. The displacement
    does not see leaked charge, so their coefficients take up whatever leakage the charge
    model got wrong, instead of the gain."""
    dt = np.diff(t)
    vs = max(float(np.abs(v).max()), 1e-300)
    cols = []
    for rate in (v, v * np.abs(v) / vs, np.ones_like(v), q - q[0]):
        c = np.concatenate([[0.0], np.cumsum(rate[1:] * dt)])
        span = float(np.ptp(c))
        cols.append(c / span if span > 0 else c)
    return np.column_stack(cols)


def _lag1(r: FloatArray) -> float:
    rc = r - r.mean()
    den = float(rc @ rc)
    return float(rc[1:] @ rc[:-1]) / den if den > 0 else 0.0


def _check_sensor(s: FloatArray, qc: FloatArray, unit: str) -> None:
    """Refuse a sensor reading that cannot calibrate: still, or sitting at its limit while
    the charge moves on (a hold at the top is not saturation: the charge holds too)."""
    span = float(np.ptp(s))
    noise = float(np.median(np.abs(np.diff(s)))) / 0.954 / math.sqrt(2.0)  # robust, per sample
    if not span > 20.0 * noise or span == 0.0:
        msg = (
            f"the displacement barely moves ({span:.3g} {unit} peak to peak against a noise "
            f"of {noise:.2g} {unit}): is the sensor on, and the right column?"
        )
        raise InsufficientDataError(msg)
    tol = 1e-9 * span
    for name, edge in (("top", float(s.max())), ("bottom", float(s.min()))):
        at = np.abs(s - edge) <= tol
        moving = at.any() and float(np.ptp(qc[at])) > 0.05 * float(np.ptp(qc))
        if at.sum() > max(SATURATED_SHARE * s.size, 10) and moving:
            runs = np.flatnonzero(at)
            msg = (
                f"the displacement sensor sits at its {name} reading {edge:.6g} {unit} for "
                f"{int(at.sum())} samples (first at sample {int(runs[0])}): saturated; "
                "calibrate within the sensor's range"
            )
            raise InsufficientDataError(msg)
