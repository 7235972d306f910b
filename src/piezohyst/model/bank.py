"""A bank of models: one model per channel, one structure, each channel its own parameters.

A deformable mirror's hundreds of stacks, a production line's units, the axes
of a stage: each actuator has its own hysteresis, but all are described by one
kind of model. :class:`ModelBank` fits that model to every column of a
(samples × channels) recording and keeps the fitted models together, with
their fit quality, in one file.

Every channel is identified exactly as a single model fitted to that column
alone would be (``bank[i]`` *is* that model), so everything a model does,
``bank[i]`` does; the bank adds batch prediction, a per-channel summary, one
file for all channels, and the multi-channel compensator
(``ph.BankCompensator(bank, ...)``).
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import FloatArray, as_time
from ..errors import (
    ExtrapolationWarning,
    ModelFileError,
    NonFiniteError,
    NotFittedError,
    ParameterError,
    PiezohystError,
    ShapeError,
)
from ..io import atomic_write, atomic_write_text
from ..metrics import hysteresis_width
from .model import HysteresisModel, is_model
from .persistence import model_from_dict, model_to_dict

__all__ = ["BANK_FORMAT", "ModelBank", "load_bank"]

#: The ``format`` field of a bank file.
BANK_FORMAT = "piezohyst-bank"
BANK_VERSION = 1
_ARRAY_SUFFIXES = (".h5", ".hdf5", ".npz")


def _as_channels(values: ArrayLike, name: str) -> FloatArray:
    """A (samples, channels) float64 array, finite (the first bad value named by row and column)."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        msg = f"'{name}' must be a 2-D array of numbers (samples × channels). Got {exc}."
        raise ShapeError(msg) from None
    if arr.ndim != 2:
        msg = f"'{name}' must be a 2-D array (samples × channels). Got shape {arr.shape}."
        raise ShapeError(msg)
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        msg = f"'{name}' must hold at least one sample and one channel. Got shape {arr.shape}."
        raise ShapeError(msg)
    bad = ~np.isfinite(arr)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        msg = (
            f"'{name}' must be finite. Got {arr[row, col]} at sample {row}, channel {col} "
            f"({int(bad.sum())} non-finite values in all)."
        )
        raise NonFiniteError(msg)
    return arr


def _clone(template: HysteresisModel) -> HysteresisModel:
    return type(template)(**template.get_params())


def model_width(model: HysteresisModel, *, cycles: int = 2, samples: int = 400) -> float:
    """The width of a model's pure hysteresis over its identified voltage range.

    The hysteresis part (growth terms dropped) is driven by ``cycles``
    triangular cycles over ``input_range_`` from its initial state; the width
    of the last cycle, as a fraction of its output span
    (:func:`~piezohyst.metrics.hysteresis_width`). NaN when the range is
    unknown or the model is rate dependent (its width depends on the rate).

    Parameters
    ----------
    model : HysteresisModel
        A fitted model.
    cycles, samples : int
        Cycles run, samples per cycle.

    Returns
    -------
    float
    """
    lo, hi = model.input_range_
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        return math.nan
    pure = model.hysteresis_
    if pure.rate_dependent_:
        return math.nan
    half = samples // 2
    cycle = np.concatenate([np.linspace(lo, hi, half), np.linspace(hi, lo, half)])
    x = np.tile(cycle, cycles)
    with warnings.catch_warnings():  # a full-range loop may leave what the data covered
        warnings.simplefilter("ignore", ExtrapolationWarning)
        y = pure.predict(x)
    return hysteresis_width(x[-samples:], y[-samples:])


class ModelBank:
    """C models of one structure, one per channel, fitted from (samples × C) records.

    Parameters
    ----------
    template : HysteresisModel
        An unfitted model: its settings (class, operators, terms...) are
        given to every channel. ``fit`` never changes it.

    Attributes
    ----------
    models_ : list of HysteresisModel
        The fitted channels (also ``bank[i]``).
    failed_ : dict
        Channel index to the one-line reason, for channels that could not be
        fitted with ``on_error="skip"`` (their entry in ``models_`` is None).

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> t = np.arange(2000) / 1000.0
    >>> v = 70.0 - 70.0 * np.cos(2 * np.pi * t)        # two cycles from rest
    >>> units = [ph.PIHysteresis([0.0, 20.0, 40.0], [g * 1e-8, 4e-9, 2e-9]) for g in (1.0, 1.2)]
    >>> V = np.column_stack([v, v])
    >>> Q = np.column_stack([u.predict(v) for u in units])
    >>> bank = ph.ModelBank(ph.ClassicalPI(3, thresholds=[0.0, 20.0, 40.0])).fit(V, Q)
    >>> len(bank), bank[1].weights_.round(12).tolist()
    (2, [1.2e-08, 4e-09, 2e-09])
    >>> table = bank.summary()
    >>> bool((table["nrmse"] < 1e-12).all()), table["width"].round(3).tolist()
    (True, [0.146, 0.127])
    """

    def __init__(self, template: HysteresisModel) -> None:
        if not is_model(template):
            msg = (
                "The 'template' of ModelBank must be a piezohyst model such as "
                f"ph.ActivePI(n_operators=20). Got {type(template).__name__} instead."
            )
            raise ParameterError(msg)
        self.template = template

    # ------------------------------------------------------------ building
    @classmethod
    def from_models(cls, models: Sequence[HysteresisModel]) -> ModelBank:
        """A bank of already fitted models (one per channel, one class and operator count).

        Parameters
        ----------
        models : sequence of HysteresisModel

        Returns
        -------
        ModelBank
        """
        models = list(models)
        if not models:
            msg = "a model bank needs at least one model. Got none."
            raise ParameterError(msg)
        first = models[0]
        for i, m in enumerate(models):
            if not is_model(m) or not m.is_fitted:
                msg = f"channel {i} of the bank is not a fitted piezohyst model."
                raise ParameterError(msg)
            size, size0 = m.operator_.initial_state.size, first.operator_.initial_state.size
            if type(m) is not type(first) or size != size0:
                msg = (
                    f"channel {i} is a {type(m).__name__} with {size} core states; "
                    f"channel 0 a {type(first).__name__} with {size0}: a bank holds "
                    "one structure"
                )
                raise ParameterError(msg)
        bank = cls(_clone(first))
        bank.models_ = list[HysteresisModel | None](models)
        bank.failed_ = {}
        return bank

    def fit(
        self,
        X: ArrayLike,
        Y: ArrayLike,
        t: ArrayLike | None = None,
        *,
        on_error: str = "raise",
    ) -> ModelBank:
        """Fit one model per column.

        Parameters
        ----------
        X, Y : array_like, shape (samples, C)
            Input (V) and output of every channel, sampled together.
        t : array_like, shape (samples,), optional
            The shared sample times (s), for rate-dependent models.
        on_error : {"raise", "skip"}
            A channel that cannot be fitted (a dead or disconnected actuator
            records no excitation) raises, naming the channel; or, with
            ``"skip"``, is left out: its model is None and the reason is in
            ``failed_``.

        Returns
        -------
        ModelBank
            ``self``, fitted.
        """
        if on_error not in ("raise", "skip"):
            msg = f"'on_error' must be 'raise' or 'skip'. Got {on_error!r}."
            raise ParameterError(msg)
        xs = _as_channels(X, "X")
        ys = _as_channels(Y, "Y")
        if xs.shape != ys.shape:
            msg = f"'X' and 'Y' must have the same shape. Got {xs.shape} and {ys.shape}."
            raise ShapeError(msg)
        ts = as_time(t, xs.shape[0], required=False, owner="ModelBank")
        self.template.check_params()
        models: list[HysteresisModel | None] = []
        failed: dict[int, str] = {}
        for c in range(xs.shape[1]):
            model = _clone(self.template)
            try:
                model.fit(np.ascontiguousarray(xs[:, c]), np.ascontiguousarray(ys[:, c]), t=ts)
            except PiezohystError as exc:
                if on_error == "raise":
                    raise type(exc)(f"channel {c}: {exc}") from None
                failed[c] = str(exc)
                models.append(None)
                continue
            models.append(model)
        if len(failed) == len(models):
            msg = f"no channel could be fitted; channel 0: {failed[0]}"
            raise ParameterError(msg)
        self.models_ = models
        self.failed_ = failed
        return self

    # ------------------------------------------------------------- access
    def _check_fitted(self) -> list[HysteresisModel | None]:
        models: list[HysteresisModel | None] | None = getattr(self, "models_", None)
        if models is None:
            msg = "This ModelBank is not fitted yet. Call 'fit' with (samples × channels) data."
            raise NotFittedError(msg)
        return models

    @property
    def is_fitted(self) -> bool:
        """True once :meth:`fit` ran (or the bank was loaded)."""
        return hasattr(self, "models_")

    def __len__(self) -> int:
        return len(self._check_fitted())

    @overload
    def __getitem__(self, index: int) -> HysteresisModel: ...

    @overload
    def __getitem__(self, index: slice | Sequence[int]) -> ModelBank: ...

    def __getitem__(self, index: int | slice | Sequence[int]) -> HysteresisModel | ModelBank:
        models = self._check_fitted()
        if not isinstance(index, int | np.integer):
            sub = ModelBank(self.template)
            everything = range(len(models))
            picked = (
                everything[index]
                if isinstance(index, slice)
                else [everything[int(i)] for i in index]
            )
            sub.models_ = [models[i] for i in picked]
            sub.failed_ = {j: self.failed_[i] for j, i in enumerate(picked) if i in self.failed_}
            return sub
        model = models[index]
        if model is None:
            i = index % len(models)
            msg = f"channel {i} was not fitted: {self.failed_.get(i, 'unknown reason')}"
            raise NotFittedError(msg)
        return model

    def __iter__(self) -> Iterator[HysteresisModel]:
        for i in range(len(self)):
            yield self[i]

    def __repr__(self) -> str:
        n = len(self.models_) if self.is_fitted else "unfitted"
        return f"ModelBank({self.template!r}, channels={n})"

    @property
    def fitted_channels(self) -> list[int]:
        """Indices of the channels that have a model."""
        return [i for i, m in enumerate(self._check_fitted()) if m is not None]

    def complete_models(self) -> list[HysteresisModel]:
        """Every channel's model; raises naming the channels that failed to fit.

        Returns
        -------
        list of HysteresisModel
        """
        models = self._check_fitted()
        if self.failed_:
            bad = sorted(self.failed_)
            msg = (
                f"channels {bad} have no model ({self.failed_[bad[0]]}); take the others with "
                "bank[bank.fitted_channels] or refit"
            )
            raise NotFittedError(msg)
        return [m for m in models if m is not None]

    # ------------------------------------------------------------ running
    def predict(self, X: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """Every channel's modelled output from its initial state.

        Parameters
        ----------
        X : array_like, shape (samples, C)
        t : array_like, shape (samples,), optional

        Returns
        -------
        ndarray, shape (samples, C)
        """
        models = self.complete_models()
        xs = _as_channels(X, "X")
        if xs.shape[1] != len(models):
            msg = f"'X' must have one column per channel ({len(models)}). Got {xs.shape[1]}."
            raise ShapeError(msg)
        out = np.empty_like(xs)
        for c, m in enumerate(models):
            out[:, c] = m.predict(np.ascontiguousarray(xs[:, c]), t=t)
        return out

    def summary(self) -> dict[str, NDArray[Any]]:
        """One row per channel: fit quality, range, hysteresis width, growth coefficients.

        Returns
        -------
        dict of ndarray
            ``channel``, ``fitted`` (bool), ``rmse``, ``nrmse`` (of the fit),
            ``v_min``/``v_max`` (the identified range), ``width`` (the pure
            hysteresis' loop width over that range, :func:`model_width`),
            and one column per growth coefficient (e.g. ``integral``, the
            active model's R). NaN for channels without a model.
        """
        models = self._check_fitted()
        c = len(models)
        cols: dict[str, NDArray[Any]] = {
            "channel": np.arange(c),
            "fitted": np.array([m is not None for m in models]),
        }
        for name in ("rmse", "nrmse", "v_min", "v_max", "width"):
            cols[name] = np.full(c, np.nan)
        growth: dict[str, FloatArray] = {}
        for i, m in enumerate(models):
            if m is None:
                continue
            cols["rmse"][i] = m.rmse_
            cols["nrmse"][i] = m.nrmse_
            cols["v_min"][i], cols["v_max"][i] = m.input_range_
            cols["width"][i] = model_width(m)
            for label, (value, _unit) in m.growth_coefficients().items():
                growth.setdefault(label, np.full(c, np.nan))[i] = value
        cols.update(growth)
        return cols

    # -------------------------------------------------------- persistence
    def to_dict(self) -> dict[str, Any]:
        """The bank as JSON data: the template's settings and one model document per channel.

        Returns
        -------
        dict
        """
        models = self._check_fitted()
        return {
            "format": BANK_FORMAT,
            "version": BANK_VERSION,
            "template": {
                "model": type(self.template).__name__,
                "params": self.template.params_to_json(),
            },
            "channels": [None if m is None else model_to_dict(m) for m in models],
            "failed": {str(k): v for k, v in self.failed_.items()},
        }

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the bank as one file, atomically.

        ``.json``: one document (best for tens of channels). ``.h5``/``.hdf5``
        (HDF5) or ``.npz``: for large banks; besides the channel documents
        (the authority, checksummed), arrays of shape (C, n) ``thresholds``,
        ``weights``, ``initial_state`` and (C,) ``offset``, ``rmse``,
        ``nrmse``, for MATLAB or a real-time computer to read directly.

        Parameters
        ----------
        path : str or os.PathLike
            Its suffix picks the format (above).

        Returns
        -------
        Path
            The file written.
        """
        data = self.to_dict()
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix not in (".json", *_ARRAY_SUFFIXES):
            msg = f"a bank is saved as .json, .h5, .hdf5 or .npz. Got {p.name!r}."
            raise ParameterError(msg)
        if suffix == ".json":
            return atomic_write_text(p, json.dumps(data, indent=1, allow_nan=False) + "\n")
        arrays = self._arrays(data)

        def write(tmp: Path) -> None:
            if suffix == ".npz":
                with tmp.open("wb") as fh:
                    np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]
                return
            import h5py

            with h5py.File(tmp, "w") as f:
                for key, value in arrays.items():
                    if value.dtype.kind == "U":
                        f.create_dataset(
                            key,
                            data=value.astype(object),
                            dtype=h5py.string_dtype(),
                            compression="gzip",
                        )
                    else:
                        f.create_dataset(key, data=value, compression="gzip")

        return atomic_write(p, write)

    def _arrays(self, data: dict[str, Any]) -> dict[str, NDArray[Any]]:
        channels = data["channels"]
        header = {k: data[k] for k in ("format", "version", "template", "failed")}
        arrays: dict[str, NDArray[Any]] = {
            "bank": np.array([json.dumps(header, allow_nan=False)]),
            "channels": np.array(
                [json.dumps(ch, allow_nan=False, separators=(",", ":")) for ch in channels]
            ),
        }
        models = self._check_fitted()
        first = next((m for m in models if m is not None), None)
        numeric = {} if first is None else {
            name.rstrip("_"): np.asarray(value) for name, value in
            first.operator_.fitted_attributes().items() if isinstance(value, np.ndarray | float)
        }  # fmt: skip
        if numeric:  # the core's own arrays too (play operators), one row per channel
            numeric["initial_state"] = np.asarray(first.initial_state_)  # type: ignore[union-attr]
            for name, value in numeric.items():
                blank = np.full(value.shape, np.nan)
                arrays[name] = np.array([
                    blank if m is None else np.asarray(
                        m.initial_state_ if name == "initial_state"
                        else m.operator_.fitted_attributes()[name + "_"])
                    for m in models
                ])  # fmt: skip
        arrays["rmse"] = np.array([math.nan if m is None else m.rmse_ for m in models])
        arrays["nrmse"] = np.array([math.nan if m is None else m.nrmse_ for m in models])
        return arrays

    @classmethod
    def from_dict(cls, data: Any, where: str = "bank") -> ModelBank:
        """Rebuild a bank from :meth:`to_dict` data (every channel checked).

        Parameters
        ----------
        data : dict
        where : str
            Named in errors (the file).

        Returns
        -------
        ModelBank
        """
        if not isinstance(data, dict) or data.get("format") != BANK_FORMAT:
            msg = f"{where} is not a piezohyst model bank (no 'format': {BANK_FORMAT!r})"
            raise ModelFileError(msg)
        if data.get("version") != BANK_VERSION:
            msg = f"{where}: bank version {data.get('version')!r} is not supported (1 is)"
            raise ModelFileError(msg)
        from .persistence import model_class

        try:
            tpl = data["template"]
            template: HysteresisModel = model_class(tpl["model"])(
                **model_class(tpl["model"]).params_from_json(tpl["params"])
            )
            channels = data["channels"]
            failed = {int(k): str(v) for k, v in data.get("failed", {}).items()}
        except (KeyError, TypeError, ValueError, ParameterError) as exc:
            msg = f"{where}: malformed bank header ({exc})"
            raise ModelFileError(msg) from None
        if not isinstance(channels, list) or not channels:
            msg = f"{where}: 'channels' must be a non-empty list"
            raise ModelFileError(msg)
        models: list[HysteresisModel | None] = []
        for i, doc in enumerate(channels):
            if doc is None:
                models.append(None)
                continue
            try:
                models.append(model_from_dict(doc, expected=type(template)))
            except ModelFileError as exc:
                msg = f"{where}, channel {i}: {exc}"
                raise ModelFileError(msg) from None
        bank = cls(template)
        bank.models_ = models
        bank.failed_ = failed
        return bank


def load_bank(path: str | os.PathLike[str]) -> ModelBank:
    """Load a bank written by :meth:`ModelBank.save` (``.json``, ``.h5``/``.hdf5`` or ``.npz``).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    ModelBank

    Raises
    ------
    ModelFileError
        Missing, unreadable or malformed file, or a channel failing its
        checksum; the message names the file and the channel.
    """
    p = Path(path)
    if not p.exists():
        msg = f"model bank file not found: {p}"
        raise ModelFileError(msg)
    suffix = p.suffix.lower()
    try:
        if suffix == ".json":
            data = json.loads(p.read_text(encoding="utf-8"))
        elif suffix in _ARRAY_SUFFIXES:
            data = _read_arrays(p, suffix)
        else:
            msg = f"{p}: a bank file ends in .json, .h5, .hdf5 or .npz"
            raise ModelFileError(msg)
    except ModelFileError:
        raise
    except (OSError, ValueError, KeyError, UnicodeDecodeError) as exc:
        msg = f"cannot read model bank {p}: {exc}"
        raise ModelFileError(msg) from None
    return ModelBank.from_dict(data, where=str(p))


def _read_arrays(p: Path, suffix: str) -> dict[str, Any]:
    if suffix == ".npz":
        with np.load(p, allow_pickle=False) as f:
            header = str(f["bank"][0])
            channels = [str(s) for s in f["channels"]]
    else:
        from ..io import parse_isolated

        header, channels = parse_isolated("bank_hdf5", p, "HDF5")
    data: dict[str, Any] = json.loads(header)
    data["channels"] = [json.loads(s) for s in channels]
    return data
