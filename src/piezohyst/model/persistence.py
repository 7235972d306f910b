"""Model files and the model registry: JSON (never pickle), schema version, checksum.

The registry maps class names (in files) and CLI names (``--model``) to model
classes; every :class:`~piezohyst.model.presets.HysteresisModel` subclass registers
itself. This module works on models through their public methods only and
sits below :mod:`piezohyst.model.presets`, which calls it for ``save``/``to_dict``.

Schema 2 (written since 0.2) stores the core and a list of terms, each with
its kind, settings and coefficients, so a model holding a custom term loads
wherever that term's class is defined. Schema 1 files (0.1.0: ClassicalPI,
ActivePI, GeneralizedPI with fixed fields) are converted on reading and
predict identically. Every error names the file and the field.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import ModelFileError, NotFittedError, ParameterError, PiezohystError
from ..io import atomic_write_text
from .cores.base import BUILTIN, CORES, Core, core_class
from .dynamics import InputDynamics, OutputDynamics
from .terms import Term, make_term

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "checked",
    "checksum",
    "load_model",
    "model_class",
    "model_from_dict",
    "model_names",
    "model_to_dict",
    "register",
    "save_model",
    "signed",
]

# A model is any registered class with the HysteresisModel methods used below;
# typed loosely here because this module sits beneath the models.
Model = Any

_REGISTRY: dict[str, type] = {}


def _registry() -> dict[str, type]:
    """The registered model classes, the library's own loaded first (``import piezohyst``
    loads them at first use, so a file may be read before any model was named)."""
    importlib.import_module("piezohyst.model.presets")
    return _REGISTRY


def register(cls: type) -> type:
    """Make a model class loadable by its class name and usable by its ``cli_name``.

    Parameters
    ----------
    cls : type
        A :class:`~piezohyst.model.presets.HysteresisModel` subclass.

    Returns
    -------
    type
        ``cls``.
    """
    _REGISTRY[cls.__name__] = cls
    return cls


def model_class(name: str) -> Any:
    """The model class of a CLI name (``"active-pi"``) or class name (``"ActivePI"``).

    Parameters
    ----------
    name : str
        As in a file's ``model`` field or the CLI's ``--model``.

    Returns
    -------
    type
        A :class:`~piezohyst.model.presets.HysteresisModel` subclass.

    Raises
    ------
    ParameterError
        For an unknown name; the message lists the known ones.
    """
    for cls in _registry().values():
        if name in (cls.__name__, getattr(cls, "cli_name", "")):
            return cls
    msg = f"unknown model {name!r}; choose one of: {', '.join(model_names())}"
    raise ParameterError(msg)


def model_names() -> tuple[str, ...]:
    """CLI names of every model that can be fitted from a file (``--model``).

    Returns
    -------
    tuple of str
    """
    return tuple(
        str(getattr(c, "cli_name", "")) for c in _registry().values() if getattr(c, "cli_name", "")
    )


SCHEMA = "piezohyst-model"
SCHEMA_VERSION = 2


def checksum(body: dict[str, Any]) -> str:
    """A file body's checksum (every field but ``checksum``, canonical JSON, SHA-256).

    Parameters
    ----------
    body : dict

    Returns
    -------
    str
    """
    content = {k: v for k, v in body.items() if k != "checksum"}
    canon = json.dumps(content, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return "sha256:" + hashlib.sha256(canon.encode()).hexdigest()


def signed(body: dict[str, Any]) -> dict[str, Any]:
    """``body`` with its :func:`checksum` added (the last field), for a file's writer.

    Parameters
    ----------
    body : dict

    Returns
    -------
    dict
        ``body`` itself.
    """
    body["checksum"] = checksum(body)
    return body


def checked(data: Any, fmt: str, where: str, kind: str) -> dict[str, Any]:
    """A file body of format ``fmt`` whose checksum matches, or a one-line error naming
    ``where`` and the ``kind`` of file it is not.

    Parameters
    ----------
    data : Any
        What the file held.
    fmt : str
        The format field it must carry.
    where : str
        Named in errors (a file's path).
    kind : str
        The file's kind, as said in errors ("coupled model").

    Returns
    -------
    dict

    Raises
    ------
    ModelFileError
        Another format, or a checksum that does not match its contents.
    """
    if not isinstance(data, dict) or data.get("format") != fmt:
        msg = f"{where}: not a piezohyst {kind} file"
        raise ModelFileError(msg)
    if data.get("checksum") != checksum(data):
        msg = f"{where}: the checksum does not match its contents (edited or damaged)"
        raise ModelFileError(msg)
    return data


def _nullable(value: float) -> float | None:
    return None if math.isnan(value) else value


def model_to_dict(model: Model) -> dict[str, Any]:
    """A fitted model as schema-2 JSON data with a checksum.

    Parameters
    ----------
    model : HysteresisModel
        Fitted (raises NotFittedError otherwise).

    Returns
    -------
    dict
    """
    if not model.is_fitted:
        msg = f"This {type(model).__name__} instance is not fitted yet: nothing to save."
        raise NotFittedError(msg)
    lo, hi = model.input_range_
    body: dict[str, Any] = {
        "format": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "model": type(model).__name__,
        "piezohyst_version": __version__,
        "params": model.params_to_json(),
        "fitted": {
            "core": {"kind": model.operator_.kind, **model.operator_.to_dict()},
            "terms": [
                {"kind": term.kind, "params": term.get_params(), "coefficients": coef.tolist()}
                for term, coef in zip(model.terms_, model.coefs_, strict=True)
            ],
            "selection": model.selection_,
            "selection_folds": model.selection_folds_,
            "selection_splits": model.selection_splits_,
            "rmse": _nullable(model.rmse_),
            "nrmse": _nullable(model.nrmse_),
            "input_range": None if math.isnan(lo) else [lo, hi],
            "max_slew_rate": _nullable(model.max_slew_rate_),
            "max_step": _nullable(model.max_step_),
            "train_window": [_nullable(v) for v in model.train_window_],
            "input_dynamics": model.input_dynamics_.to_dict(),
            "output_dynamics": model.output_dynamics_.to_dict(),
        },
    }
    body["checksum"] = checksum(body)
    return body


def save_model(model: Model, path: str | os.PathLike[str]) -> Path:
    """Write ``model`` as JSON, atomically, with the umask's permissions.

    Parameters
    ----------
    model : HysteresisModel
    path : str or os.PathLike

    Returns
    -------
    Path
    """
    text = json.dumps(model_to_dict(model), indent=2, allow_nan=False)
    return atomic_write_text(path, text + "\n")


class _Reader:
    """Typed field access that names the field in every error."""

    def __init__(self, data: Any, where: str) -> None:
        if not isinstance(data, dict):
            msg = f"field '{where}' must be an object, got {type(data).__name__}"
            raise ModelFileError(msg)
        self.data = data
        self.where = where

    def name(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def get(self, key: str) -> Any:
        if key not in self.data:
            msg = f"missing field '{self.name(key)}'"
            raise ModelFileError(msg)
        return self.data[key]

    def number(self, key: str, *, optional: bool = False) -> float:
        value = self.data.get(key) if optional else self.get(key)
        if optional and value is None:
            return math.nan
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            msg = f"field '{self.name(key)}' must be a finite number, got {value!r}"
            raise ModelFileError(msg)
        return float(value)

    def numbers(self, key: str) -> np.ndarray:
        value = self.get(key)
        if not isinstance(value, list) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in value
        ):
            msg = f"field '{self.name(key)}' must be a list of finite numbers"
            raise ModelFileError(msg)
        return np.asarray(value, dtype=np.float64)

    def child(self, key: str) -> _Reader:
        return _Reader(self.get(key), self.name(key))


def _range(fitted: _Reader) -> tuple[float, float]:
    rng = fitted.data.get("input_range")
    if rng is None:
        return (math.nan, math.nan)
    if not isinstance(rng, list) or len(rng) != 2:
        msg = f"field '{fitted.name('input_range')}' must be [min, max]"
        raise ModelFileError(msg)
    pair = _Reader({"min": rng[0], "max": rng[1]}, fitted.name("input_range"))
    lo, hi = pair.number("min"), pair.number("max")
    if lo > hi:
        msg = f"field '{fitted.name('input_range')}' must be [min, max] with min <= max"
        raise ModelFileError(msg)
    return lo, hi


def _core(reader: _Reader) -> Core:
    """The core a file's ``core`` (or schema-1 ``fitted``) object describes, by its kind."""
    kind = str(reader.data.get("kind", "play"))
    cls = core_class(kind)
    if cls is None:
        msg = (
            f"field '{reader.name('kind')}' names an unknown core {kind!r} "
            f"(known: {sorted(set(BUILTIN) | set(CORES))})"
        )
        raise ModelFileError(msg)
    data = dict(reader.data)
    for key, form in cls.file_fields.items():  # the fields it declares, checked by name
        data[key] = reader.number(key) if form == "number" else reader.numbers(key)
    try:
        return cls.from_dict(data)
    except KeyError as exc:
        msg = f"missing field '{reader.name(str(exc.args[0]))}'"
        raise ModelFileError(msg) from None
    except (PiezohystError, TypeError, ValueError) as exc:
        msg = f"field '{reader.where or 'fitted'}': {exc}"
        raise ModelFileError(msg) from None


def _schema1_terms(name: str, fitted: _Reader) -> list[dict[str, Any]]:
    """The terms of a 0.1.0 file, in the order its columns were fitted."""
    if name == "ActivePI":
        return [{"kind": "integral", "params": {}, "coefficients": [fitted.number("growth_rate")]}]
    if name != "GeneralizedPI":
        return []
    knots = fitted.numbers("knots")
    scale = fitted.number("static_scale")
    up, down = fitted.numbers("static_up"), fitted.numbers("static_down")
    taus, gains = fitted.numbers("creep_taus"), fitted.numbers("creep_gains")
    growth = fitted.get("growth_terms")
    coefs = fitted.numbers("growth_coefs")
    if not isinstance(growth, list) or len(growth) != coefs.size or up.size != knots.size:
        msg = "inconsistent GeneralizedPI terms (sizes)"
        raise ModelFileError(msg)
    terms: list[dict[str, Any]] = []
    if knots.size:
        terms.append(
            {
                "kind": "asymmetry",
                "params": {"n_knots": int(knots.size), "knots": knots.tolist(), "scale": scale},
                "coefficients": [*up.tolist(), *down.tolist()],
            }
        )
    if taus.size:
        terms.append(
            {"kind": "creep", "params": {"taus": taus.tolist()}, "coefficients": gains.tolist()}
        )
    for kind, c in zip(growth, coefs.tolist(), strict=True):
        params = {"scale": scale} if kind == "abs_integral" else {}
        terms.append({"kind": kind, "params": params, "coefficients": [c]})
    return terms


def _terms(entries: Any) -> tuple[tuple[Term, ...], tuple[np.ndarray, ...]]:
    if not isinstance(entries, list):
        raise ModelFileError("field 'fitted.terms' must be a list")
    terms, coefs = [], []
    for j, entry in enumerate(entries):
        reader = _Reader(entry, f"fitted.terms[{j}]")
        kind = reader.get("kind")
        params = reader.data.get("params") or {}
        try:
            term = make_term(str(kind), params)
        except PiezohystError as exc:
            msg = f"field '{reader.where}': {exc}"
            raise ModelFileError(msg) from None
        coef = reader.numbers("coefficients")
        if coef.size != term.width:
            msg = f"field '{reader.where}.coefficients' must hold {term.width} values"
            raise ModelFileError(msg)
        if np.any(coef < term.lower_bounds()):
            msg = f"field '{reader.where}.coefficients' violates the term's bounds (signs)"
            raise ModelFileError(msg)
        terms.append(term)
        coefs.append(coef)
    return tuple(terms), tuple(coefs)


def model_from_dict(data: Any, expected: type | None = None) -> Model:
    """Rebuild a fitted model from file data (schema 1 or 2), checked.

    Parameters
    ----------
    data : dict
        Parsed JSON.
    expected : type, optional
        Raise unless the data holds this class (or a subclass).

    Returns
    -------
    HysteresisModel
        Fitted, ready to predict and compensate.

    Raises
    ------
    ModelFileError
        Naming the field that is missing, malformed or inconsistent.
    """
    if not isinstance(data, dict) or data.get("format") != SCHEMA:
        msg = f'not a piezohyst model (expected "format": "{SCHEMA}")'
        raise ModelFileError(msg)
    version = data.get("schema_version")
    if version not in (1, 2):
        msg = (
            f"unsupported model schema version {version!r}; this piezohyst reads versions 1 "
            f"and {SCHEMA_VERSION}"
        )
        raise ModelFileError(msg)
    if "checksum" in data and data["checksum"] != checksum(data):
        msg = (
            "checksum mismatch: the file was modified after it was saved "
            '(delete the "checksum" field to accept a deliberate edit)'
        )
        raise ModelFileError(msg)
    top = _Reader(data, "")
    name = top.get("model")
    try:
        cls = model_class(str(name))
    except PiezohystError as exc:
        raise ModelFileError(f"field 'model': {exc}") from None
    if expected is not None and not issubclass(cls, expected):
        msg = f"the data holds a {name}, not a {expected.__name__}"
        raise ModelFileError(msg)
    params = top.child("params").data
    fitted = top.child("fitted")
    if version == 1:
        core = _core(fitted)
        entries: Any = _schema1_terms(str(name), fitted)
    else:
        core = _core(fitted.child("core"))
        entries = fitted.get("terms")
    terms, coefs = _terms(entries)
    try:
        model = cls(**cls.params_from_json(params))
        model.check_params()
    except (TypeError, ValueError) as exc:
        msg = f"field 'params': {exc}"
        raise ModelFileError(msg) from None
    facts: dict[str, Any] = {}
    selection = fitted.data.get("selection") or {}
    if isinstance(selection, dict):
        facts["selection"] = {str(k): float(v) for k, v in selection.items()}
    splits = fitted.data.get("selection_splits") or []
    if isinstance(splits, list):
        facts["selection_splits"] = [int(k) for k in splits]
    folds = fitted.data.get("selection_folds") or {}
    if isinstance(folds, dict):
        facts["selection_folds"] = {
            str(k): [float(x) for x in v] for k, v in folds.items() if isinstance(v, list)
        }
    facts["rmse"] = fitted.number("rmse", optional=True)
    facts["nrmse"] = fitted.number("nrmse", optional=True)
    facts["input_range"] = _range(fitted)
    facts["max_slew_rate"] = fitted.number("max_slew_rate", optional=True)
    facts["max_step"] = fitted.number("max_step", optional=True)  # older files lack it
    facts["train_window"] = _window(fitted)
    for name, kind in (("input_dynamics", InputDynamics), ("output_dynamics", OutputDynamics)):
        data = fitted.data.get(name)  # absent from older files: none
        if data is None:
            continue
        try:
            facts[name] = kind.from_dict(dict(data))
        except (TypeError, ValueError) as exc:
            msg = f"field '{fitted.name(name)}': {exc}"
            raise ModelFileError(msg) from None
    model.set_fitted(core, terms, coefs, **facts)
    return model


def _window(fitted: _Reader) -> tuple[float, float]:
    """The times (s) of the first and last training samples (NaN: unknown, older files)."""
    window = fitted.data.get("train_window")
    if window is None:
        return (math.nan, math.nan)
    if (
        not isinstance(window, list)
        or len(window) != 2
        or not all(
            v is None or (isinstance(v, int | float) and not isinstance(v, bool)) for v in window
        )
    ):
        msg = f"field '{fitted.name('train_window')}' must be [first, last] times (s) or nulls"
        raise ModelFileError(msg)
    first, last = (math.nan if v is None else float(v) for v in window)
    return first, last


def _reject_constant(name: str) -> float:
    msg = f"the model file holds the non-number {name}"
    raise ModelFileError(msg)


def load_model(path: str | os.PathLike[str]) -> Model:
    """Load a model written by ``save`` (this version or 0.1.0).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.json`` file written by ``save``.

    Returns
    -------
    HysteresisModel
        An instance of the class the file names.

    Raises
    ------
    ModelFileError
        If the file is missing, not JSON, of another schema or version, fails its
        checksum (edited after saving: delete the ``checksum`` field to accept
        a deliberate edit), or holds inconsistent parameters; the message names
        the file and the field.
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
    except ModelFileError as exc:
        raise ModelFileError(f"{p}: {exc}") from None
    try:
        return model_from_dict(data, expected=None)
    except ModelFileError as exc:
        msg = f"{p}: {exc}"
        raise ModelFileError(msg) from None
