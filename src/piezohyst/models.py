r"""Estimators: the classical and the active Prandtl-Ishlinskii models.

Both follow the scikit-learn estimator contract without inheriting from it:
``__init__`` only stores its arguments, :meth:`fit` checks them, identifies the
parameters and returns ``self``; learned values end in ``_``; using a model
before :meth:`fit` raises :class:`~piezohyst.errors.NotFittedError`.

Initial state
-------------
A fitted model stores the operator states it started the training record from:
each play operator *at rest at the record's first input* (``z_i = x[0]``), i.e.
the actuator sat at its first voltage with its memory wiped. On another record
the paper's eq. 10 applies: the stored state is clamped into
``[x0 - r_i, x0 + r_i]`` at the first sample. For a unipolar drive starting at
0 V this is the paper's :math:`y_0 = 0`. Pass ``state=`` to
:meth:`~ClassicalPI.propagate` to start from anything else.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from . import _kernels
from ._validation import FloatArray, as_signal, as_time, check_float, check_int, same_length
from .errors import (
    ModelFileError,
    NotFittedError,
    ParameterError,
    PiezohystError,
    ShapeError,
    TimeAxisError,
)
from .hysteresis import PIHysteresis, Propagation
from .identification import default_thresholds, identify, time_steps
from .metrics import rmse

__all__ = ["ActivePI", "ClassicalPI", "load_model"]

SCHEMA = "piezohyst-model"
SCHEMA_VERSION = 1
_REGISTRY: dict[str, type[HysteresisModel]] = {}


def _register(cls: type[HysteresisModel]) -> type[HysteresisModel]:
    _REGISTRY[cls.__name__] = cls
    return cls


class HysteresisModel:
    """Common contract of every piezohyst model (fit, predict, save, load)."""

    rate_dependent: ClassVar[bool] = False
    _fitted_attribute: ClassVar[str] = "operator_"

    def _check_fitted(self) -> None:
        if not hasattr(self, self._fitted_attribute):
            msg = (
                f"This {type(self).__name__} instance is not fitted yet. Call 'fit' with "
                "input and output data first, or load a saved model with ph.load_model."
            )
            raise NotFittedError(msg)

    # The subclasses fill these in.
    def get_params(self) -> dict[str, Any]:
        raise NotImplementedError

    def _fitted_dict(self) -> dict[str, Any]:
        raise NotImplementedError

    def _set_fitted(self, data: dict[str, Any]) -> None:
        raise NotImplementedError

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    # ------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """The fitted model as plain JSON data, with schema version and checksum."""
        self._check_fitted()
        from . import __version__

        body: dict[str, Any] = {
            "format": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "model": type(self).__name__,
            "piezohyst_version": __version__,
            "params": self.get_params(),
            "fitted": self._fitted_dict(),
        }
        body["checksum"] = _checksum(body)
        return body

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> HysteresisModel:
        """Rebuild a fitted model from :meth:`to_dict` output (checked)."""
        return _model_from_dict(data, expected=cls)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model as JSON (never pickle); written atomically."""
        text = json.dumps(self.to_dict(), indent=2, allow_nan=False)
        atomic_write_text(Path(path), text + "\n")


def atomic_write_text(path: Path, text: str) -> None:
    """Write to a temporary file beside ``path`` and rename it into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _checksum(body: dict[str, Any]) -> str:
    content = {k: v for k, v in body.items() if k != "checksum"}
    canon = json.dumps(content, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return "sha256:" + hashlib.sha256(canon.encode()).hexdigest()


def _reject_constant(name: str) -> float:
    msg = f"the model file holds the non-number {name}"
    raise ModelFileError(msg)


def load_model(path: str | os.PathLike[str]) -> HysteresisModel:
    """Load a model written by ``save``.

    Raises
    ------
    ModelFileError
        If the file is missing, not JSON, of another schema or version, fails its
        checksum (edited after saving: delete the ``checksum`` field to accept
        a deliberate edit), or holds inconsistent parameters.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        msg = f"model file not found: {p}"
        raise ModelFileError(msg) from None
    except (OSError, UnicodeDecodeError) as exc:
        msg = f"cannot read model file {p}: {exc}"
        raise ModelFileError(msg) from None
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        msg = f"{p} is not a piezohyst model (not valid JSON: {exc.msg} at line {exc.lineno})"
        raise ModelFileError(msg) from None
    try:
        return _model_from_dict(data, expected=None)
    except ModelFileError as exc:
        msg = f"{p}: {exc}"
        raise ModelFileError(msg) from None


def _model_from_dict(data: Any, expected: type[HysteresisModel] | None) -> HysteresisModel:
    if not isinstance(data, dict) or data.get("format") != SCHEMA:
        msg = f'not a piezohyst model (expected "format": "{SCHEMA}")'
        raise ModelFileError(msg)
    version = data.get("schema_version")
    if version != SCHEMA_VERSION:
        msg = (
            f"unsupported model schema version {version!r}; this piezohyst reads "
            f"version {SCHEMA_VERSION}"
        )
        raise ModelFileError(msg)
    if "checksum" in data and data["checksum"] != _checksum(data):
        msg = (
            "checksum mismatch: the file was modified after it was saved "
            '(delete the "checksum" field to accept a deliberate edit)'
        )
        raise ModelFileError(msg)
    name = data.get("model")
    cls = _REGISTRY.get(name) if isinstance(name, str) else None
    if cls is None:
        msg = f"unknown model type {name!r}; known: {sorted(_REGISTRY)}"
        raise ModelFileError(msg)
    if expected is not None and not issubclass(cls, expected):
        msg = f"the data holds a {name}, not a {expected.__name__}"
        raise ModelFileError(msg)
    try:
        params = data["params"]
        if not isinstance(params, dict):
            raise TypeError("'params' is not an object")
        model = cls(**params)
        model._set_fitted(data["fitted"])
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        if isinstance(exc, PiezohystError):
            detail = str(exc)
        elif isinstance(exc, KeyError):
            detail = f"missing field {exc}"
        else:
            detail = str(exc)
        msg = f"malformed {name} model: {detail}"
        raise ModelFileError(msg) from None
    return model


def _float_field(data: dict[str, Any], key: str) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        msg = f"field '{key}' must be a finite number, got {value!r}"
        raise ModelFileError(msg)
    return float(value)


@_register
class ClassicalPI(HysteresisModel):
    r"""Classical (passive, rate-independent) Prandtl-Ishlinskii model, eq. 11-12.

    .. math:: y(t) = c + \sum_{i=0}^{n-1} w_i\, H_{r_i}[x](t), \qquad r_0 = 0

    Parameters
    ----------
    n_operators : int, default 10
        Number of play operators including the linear one (:math:`r_0 = 0`), in
        [1, 1000]. Ignored when ``thresholds`` is given.
    thresholds : array_like, optional
        Explicit thresholds (input units), strictly increasing from 0. Default:
        :func:`~piezohyst.identification.default_thresholds` of the training input.
    min_slope : float, default 1e-3
        Lower bound of every loading-curve slope, as a fraction of the mean
        slope ``span(y) / span(x)``. It guarantees the analytic inverse.
    input_unit, output_unit : str
        Units recorded with the model (default ``"V"`` and ``"C"``).

    Attributes
    ----------
    thresholds_, weights_ : ndarray
        Identified thresholds (input units) and weights (output/input units).
    offset_ : float
        Output offset (output units).
    initial_state_ : ndarray
        Operator states before the first training sample (input units).
    operator_ : PIHysteresis
        The immutable identified operator.
    rmse_, nrmse_ : float
        Training fit quality: RMSE (output units) and RMSE / output span.
    input_range_ : tuple of float
        Smallest and largest training input (V): where the model was seen
        working, and the default voltage limits of the compensator commands.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> v = 70 - 70 * np.cos(np.linspace(0, 6 * np.pi, 600))
    >>> true = ph.PIHysteresis([0, 20, 40], [1.0, 0.5, -0.3])
    >>> model = ph.ClassicalPI(thresholds=[0, 20, 40]).fit(v, true.predict(v))
    >>> bool(model.nrmse_ < 1e-9)
    True
    """

    def __init__(
        self,
        n_operators: int = 10,
        thresholds: ArrayLike | None = None,
        min_slope: float = 1e-3,
        input_unit: str = "V",
        output_unit: str = "C",
    ) -> None:
        self.n_operators = n_operators
        self.thresholds = thresholds
        self.min_slope = min_slope
        self.input_unit = input_unit
        self.output_unit = output_unit

    def get_params(self) -> dict[str, Any]:
        """Constructor arguments (JSON-ready)."""
        thr = self.thresholds
        return {
            "n_operators": self.n_operators,
            "thresholds": None if thr is None else np.asarray(thr, dtype=float).tolist(),
            "min_slope": self.min_slope,
            "input_unit": self.input_unit,
            "output_unit": self.output_unit,
        }

    # ------------------------------------------------------------------- fit
    def _check_params(self, x: FloatArray) -> FloatArray:
        owner = type(self).__name__
        for name in ("input_unit", "output_unit"):
            if not isinstance(getattr(self, name), str):
                msg = (
                    f"The '{name}' parameter of {owner} must be a str. "
                    f"Got {getattr(self, name)!r} instead."
                )
                raise ParameterError(msg)
        check_float(self.min_slope, "min_slope", owner, 0.0, 1.0, low_open=True)
        if self.thresholds is None:
            n = check_int(self.n_operators, "n_operators", owner, 1, 1000)
            return default_thresholds(x, n)
        thr = as_signal(self.thresholds, "thresholds")
        if thr.size > 1000 or thr[0] != 0.0 or (thr.size > 1 and np.any(np.diff(thr) <= 0)):
            msg = (
                f"The 'thresholds' parameter of {owner} must be 1 to 1000 strictly increasing "
                f"values starting at 0. Got {thr.tolist()[:8]}{'...' if thr.size > 8 else ''}."
            )
            raise ParameterError(msg)
        return thr

    def _inputs(
        self, x: ArrayLike, y: ArrayLike, t: ArrayLike | None
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        xs = as_signal(x, "x")
        ys = as_signal(y, "y")
        same_length(xs, ys, "x", "y")
        ts = as_time(t, xs.size, required=self.rate_dependent, owner=type(self).__name__)
        return xs, ys, ts

    def _initial_state(
        self, thr: FloatArray, xs: FloatArray, initial_state: ArrayLike | None
    ) -> FloatArray:
        if initial_state is None:
            return np.full(thr.size, xs[0])
        z0 = as_signal(initial_state, "initial_state")
        if z0.size != thr.size:
            msg = f"'initial_state' must hold one state per operator ({thr.size}). Got {z0.size}."
            raise ShapeError(msg)
        return z0

    def fit(
        self,
        x: ArrayLike,
        y: ArrayLike,
        t: ArrayLike | None = None,
        *,
        initial_state: ArrayLike | None = None,
    ) -> ClassicalPI:
        """Identify weights and offset from input ``x`` (V) and output ``y``.

        ``t`` (s) is accepted for a uniform interface and ignored: the model is
        rate independent. ``initial_state`` gives the operator states (V) before
        the first sample when the record continues a known history (see
        :func:`~piezohyst.identification.history_state`); by default the
        actuator rests at ``x[0]``.
        Returns ``self``.
        """
        xs, ys, _ = self._inputs(x, y, t)
        thr = self._check_params(xs)
        z0 = self._initial_state(thr, xs, initial_state)
        sol = identify(xs, ys, thr, min_slope=self.min_slope, initial_state=z0)
        self._set_operator(PIHysteresis(thr, sol.weights, sol.offset, z0))
        self._record_fit(xs, ys, None)
        return self

    def _record_fit(self, x: FloatArray, y: FloatArray, t: FloatArray | None) -> None:
        """Training range and fit quality of the model just identified."""
        self.input_range_ = (float(x.min()), float(x.max()))
        self.rmse_ = rmse(self.predict(x, t=t), y)
        self.nrmse_ = self.rmse_ / max(float(np.ptp(y)), 1e-300)

    def _set_operator(self, op: PIHysteresis) -> None:
        self.operator_ = op
        self.thresholds_ = op.thresholds
        self.weights_ = op.weights
        self.offset_ = op.offset
        self.initial_state_ = op.initial_state

    # --------------------------------------------------------------- predict
    def predict(self, x: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """Modelled output for input ``x`` (V) from the stored initial state."""
        return self.propagate(x, t).output

    def propagate(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ArrayLike | None = None
    ) -> Propagation:
        """Output and final operator state; chunked calls equal one call.

        ``state`` (input units, one per operator) defaults to ``initial_state_``.
        """
        self._check_fitted()
        xs = as_signal(x, "x", allow_empty=True)
        as_time(t, xs.size, required=False, owner=type(self).__name__)
        return self.operator_.propagate(xs, state)

    def inverse(self) -> ClassicalPI:
        """The analytic inverse (eq. 18) as a fitted :class:`ClassicalPI`.

        Its ``predict(desired_output)`` returns the input (V) that produces it.
        """
        self._check_fitted()
        inv = ClassicalPI(
            n_operators=self.operator_.n_operators,
            min_slope=self.min_slope,
            input_unit=self.output_unit,
            output_unit=self.input_unit,
        )
        inv._set_operator(self.operator_.inverse())
        inv.rmse_ = float("nan")
        inv.nrmse_ = float("nan")
        inv.input_range_ = (float("nan"), float("nan"))
        return inv

    @classmethod
    def from_operator(cls, op: PIHysteresis, **params: Any) -> ClassicalPI:
        """A fitted model around given parameters (e.g. a known actuator)."""
        model = cls(n_operators=op.n_operators, **params)
        model._set_operator(op)
        model.rmse_ = float("nan")
        model.nrmse_ = float("nan")
        model.input_range_ = (float("nan"), float("nan"))
        return model

    # ----------------------------------------------------------- persistence
    def _fitted_dict(self) -> dict[str, Any]:
        out = self.operator_.to_dict()
        out["rmse"] = None if math.isnan(self.rmse_) else self.rmse_
        out["nrmse"] = None if math.isnan(self.nrmse_) else self.nrmse_
        lo, hi = self.input_range_
        out["input_range"] = None if math.isnan(lo) else [lo, hi]
        return out

    def _set_fitted(self, data: dict[str, Any]) -> None:
        if not isinstance(data, dict):
            raise ModelFileError("'fitted' is not an object")
        op = PIHysteresis(
            thresholds=data["thresholds"],
            weights=data["weights"],
            offset=_float_field(data, "offset"),
            initial_state=data["initial_state"],
        )
        self._set_operator(op)
        self.rmse_ = float("nan") if data.get("rmse") is None else _float_field(data, "rmse")
        self.nrmse_ = float("nan") if data.get("nrmse") is None else _float_field(data, "nrmse")
        rng = data.get("input_range")
        if rng is None:
            self.input_range_ = (float("nan"), float("nan"))
        else:
            if not isinstance(rng, list) or len(rng) != 2:
                raise ModelFileError("field 'input_range' must be [min, max]")
            lo = _float_field({"input_range": rng[0]}, "input_range")
            hi = _float_field({"input_range": rng[1]}, "input_range")
            if lo > hi:
                raise ModelFileError("field 'input_range' must be [min, max] with min <= max")
            self.input_range_ = (lo, hi)


@_register
class ActivePI(ClassicalPI):
    r"""Active (time-dependent) Prandtl-Ishlinskii model, eq. 13-16.

    A classical PI model plus one integrator with growth rate :math:`R`:

    .. math::

        y(t) = c + \sum_i w_i\, H_{r_i}[x](t) + R\, y_2(t), \qquad
        y_2(t_k) = y_2(t_{k-1}) + x(t_k)\,(t_k - t_{k-1}), \quad y_2(t_0) = 0

    For a charge output, :math:`R` is the leakage conductance (C/(V s) = S) of
    the resistor in parallel with the piezo (Fig. 3). All parameters are
    identified jointly (eq. 16-17) with the slope constraints that guarantee
    the inverse of the hysteresis part. The time stamps may be non-uniform.

    Parameters are those of :class:`ClassicalPI`.

    Attributes
    ----------
    growth_rate_ : float
        :math:`R` in output units per (input unit x s); S for V to C.
    hysteresis_ : ClassicalPI
        The pure hysteresis part :math:`y_1` (eq. 19), leakage removed; its
        ``inverse()`` is the feedforward compensator of eq. 18.

    Notes
    -----
    The fitted model's ``propagate`` state is a flat array: the operator
    states, then the integral :math:`y_2` (input unit x s), then the last
    time stamp (s; NaN before any sample has run). ``inverse()`` inverts the
    hysteresis part only (the same as ``hysteresis_.inverse()``): leaked charge
    moves nothing, so the compensator drops the growth term.
    """

    rate_dependent: ClassVar[bool] = True

    def fit(
        self,
        x: ArrayLike,
        y: ArrayLike,
        t: ArrayLike | None = None,
        *,
        initial_state: ArrayLike | None = None,
    ) -> ActivePI:
        """Identify weights, offset and growth rate jointly; ``t`` (s) is required.

        ``initial_state`` as for :meth:`ClassicalPI.fit`.
        """
        xs, ys, ts = self._inputs(x, y, t)
        assert ts is not None
        thr = self._check_params(xs)
        z0 = self._initial_state(thr, xs, initial_state)
        sol = identify(xs, ys, thr, dt=time_steps(ts), min_slope=self.min_slope, initial_state=z0)
        self._set_operator(PIHysteresis(thr, sol.weights, sol.offset, z0))
        self.growth_rate_ = sol.growth_rate
        self._record_fit(xs, ys, ts)
        return self

    def _set_operator(self, op: PIHysteresis) -> None:
        super()._set_operator(op)
        self.hysteresis_ = ClassicalPI.from_operator(
            op,
            min_slope=self.min_slope,
            input_unit=self.input_unit,
            output_unit=self.output_unit,
        )

    def growth(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ArrayLike | None = None
    ) -> FloatArray:
        r"""The leakage term :math:`R\,y_2(t)` alone (output units), eq. 19."""
        self._check_fitted()
        xs = as_signal(x, "x")
        ts = as_time(t, xs.size, required=True, owner="ActivePI")
        assert ts is not None
        integral = np.empty_like(xs)
        start, t_prev = self._integral_state(state)
        _kernels.running_integral(xs, time_steps(ts, t_prev), start, integral)
        return np.asarray(self.growth_rate_ * integral)

    def _integral_state(self, state: ArrayLike | None) -> tuple[float, float | None]:
        """Integral and last time stamp of a state; NaN time means nothing ran yet."""
        if state is None:
            return 0.0, None
        s = np.asarray(state, dtype=np.float64)
        n = self.operator_.n_operators
        if s.shape != (n + 2,):
            msg = (
                f"'state' of ActivePI must hold {n} operator states, the integral and the "
                f"last time stamp ({n + 2} values). Got shape {s.shape}."
            )
            raise ShapeError(msg)
        as_signal(s[:-1], "state")
        t_last = None if np.isnan(s[-1]) else float(as_signal(s[-1:], "state")[0])
        return float(s[-2]), t_last

    def propagate(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ArrayLike | None = None
    ) -> Propagation:
        """Output and final state ``[operator states..., integral, last t]``."""
        self._check_fitted()
        xs = as_signal(x, "x", allow_empty=True)
        ts = as_time(t, xs.size, required=True, owner="ActivePI")
        assert ts is not None
        start, t_prev = self._integral_state(state)
        if xs.size == 0:
            return Propagation(xs, self._full_state(state))
        if t_prev is not None and ts[0] <= t_prev:
            msg = (
                f"'t' must continue after the state's last time {t_prev!r}. "
                f"Got t[0]={float(ts[0])!r}."
            )
            raise TimeAxisError(msg)
        integral = np.empty_like(xs)
        end = _kernels.running_integral(xs, time_steps(ts, t_prev), start, integral)
        ops = None if state is None else np.asarray(state, dtype=np.float64)[:-2]
        hyst = self.operator_.propagate(xs, ops)
        out = hyst.output + self.growth_rate_ * integral
        return Propagation(out, np.concatenate([hyst.state, [end, ts[-1]]]))

    def _full_state(self, state: ArrayLike | None) -> FloatArray:
        if state is None:  # nothing ran yet: no last time stamp
            return np.concatenate([self.operator_.initial_state, [0.0, np.nan]])
        return np.array(state, dtype=np.float64)

    def predict(self, x: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """Modelled output (hysteresis plus growth) for input ``x`` (V) at times ``t`` (s)."""
        return self.propagate(x, t).output

    def remove_growth(self, x: ArrayLike, y: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        r"""Eq. 19: the measured output minus the identified growth, :math:`y - R y_2`.

        For a charge record this is the pure capacitor charge (Fig. 8).
        """
        ys = as_signal(y, "y")
        g = self.growth(x, t)
        same_length(g, ys, "x", "y")
        return np.asarray(ys - g)

    def _fitted_dict(self) -> dict[str, Any]:
        out = super()._fitted_dict()
        out["growth_rate"] = self.growth_rate_
        return out

    def _set_fitted(self, data: dict[str, Any]) -> None:
        super()._set_fitted(data)
        self.growth_rate_ = _float_field(data, "growth_rate")
