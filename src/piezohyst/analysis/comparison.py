"""Model comparison: several models identified on one record, scored on data they never saw.

What a researcher choosing between hysteresis models needs, in one call:
every model is fitted on the training part (a clone: the estimators passed
in are left untouched), run on over the test part from the state the training
part left it in (a forward split: the test part comes after the training part
in time, as in use), and scored there. A model that cannot be identified on
the record gets a row with its one-line error, and the others go on::

    cmp = ph.compare_models(
        {"active PI": ph.ActivePI(20), "Preisach": ph.PreisachModel()}, v, q, t=t
    )
    print(cmp.table())
    best = cmp.best().model

Each row says what the model absorbed besides hysteresis (growth terms,
creep, a delay or lag of the input, a mechanical mode): on a record at one
drive frequency a lag and hysteresis cannot be told apart, and a model
that fits better because it absorbed drift or lag should say so.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, same_length
from ..errors import ExtrapolationWarning, ParameterError, PiezohystError
from ..metrics import hysteresis_width, nrmse, rmse
from ..model.model import HysteresisModel, InitialState, is_model

__all__ = ["Comparison", "ComparisonRow", "compare_models"]


@dataclass(frozen=True)
class ComparisonRow:
    """One model of a :class:`Comparison`.

    Attributes
    ----------
    name : str
        The name it was given (or its class name).
    model : HysteresisModel or None
        The model fitted on the training part; None when fitting failed.
    train_nrmse, test_nrmse : float
        NRMSE (RMSE over the part's output span) on the training and test
        parts; NaN when fitting failed.
    train_rmse, test_rmse : float
        The same as RMSE in output units.
    test_width : float
        Loop width (fraction of the output span) of the model's error on the
        test part: hysteresis the model left (see
        :func:`~piezohyst.metrics.hysteresis_width`).
    fit_seconds : float
        Wall time of the fit.
    absorbed : str
        What the model took up besides rate-independent hysteresis ("" for
        nothing): growth terms (leakage, bias), rate-dependent terms it keeps
        (creep, relaxation), a delay or lag of the input, a mechanical mode.
    notes : str
        Warnings met on the way (e.g. the test part left the training region).
    error : str
        Why fitting failed ("" when it did not).
    test_residual : ndarray or None
        Measured minus predicted over the test part (output units); None when fitting
        failed.
    """

    name: str
    model: HysteresisModel | None
    train_nrmse: float = math.nan
    test_nrmse: float = math.nan
    train_rmse: float = math.nan
    test_rmse: float = math.nan
    test_width: float = math.nan
    fit_seconds: float = math.nan
    absorbed: str = ""
    notes: str = ""
    error: str = ""
    test_residual: FloatArray | None = field(default=None, repr=False, compare=False)

    def as_dict(self) -> dict[str, Any]:
        """The row as plain data (for CSV/Parquet), without the model.

        Returns
        -------
        dict
        """
        return {
            "model": self.name,
            "status": "failed" if self.error else "ok",
            "train_nrmse_pct": 100 * self.train_nrmse,
            "test_nrmse_pct": 100 * self.test_nrmse,
            "train_rmse": self.train_rmse,
            "test_rmse": self.test_rmse,
            "test_error_width_pct": 100 * self.test_width,
            "fit_seconds": self.fit_seconds,
            "absorbed": self.absorbed,
            "notes": self.notes,
            "error": self.error,
        }


@dataclass(frozen=True)
class Comparison:
    """The result of :func:`compare_models`.

    Attributes
    ----------
    rows : tuple of ComparisonRow
        In the order the models were given.
    train, test : tuple of int
        Sample ranges ``(start, stop)`` of the training and test parts (of the
        test record when one was given).
    separate_test : bool
        Whether the test part is a record of its own.
    output_unit : str
        Unit of the RMSE columns.
    recommended : str
        The model chosen by forward chaining inside the training part alone
        (:func:`~piezohyst.analysis.selection.forward_scores`; "" when not asked for).
    recommendation_notes : tuple of str
        How sure that choice is: the models the training part does not tell apart from
        it, and what the training part cannot test (:attr:`Selection.notes`).
    """

    rows: tuple[ComparisonRow, ...]
    train: tuple[int, int]
    test: tuple[int, int]
    separate_test: bool = False
    output_unit: str = ""
    recommended: str = ""
    recommendation_notes: tuple[str, ...] = ()

    def best(self) -> ComparisonRow:
        """The row with the smallest held-out NRMSE.

        Returns
        -------
        ComparisonRow

        Raises
        ------
        ParameterError
            When no model could be fitted.
        """
        ok = [r for r in self.rows if not r.error]
        if not ok:
            msg = "no model could be fitted: " + "; ".join(
                f"{r.name}: {r.error}" for r in self.rows
            )
            raise ParameterError(msg)
        return min(ok, key=lambda r: r.test_nrmse)

    @property
    def model(self) -> Any:
        """The best model (:meth:`best`'s, fitted on the training part): the same name as
        :attr:`Selection.model <piezohyst.analysis.selection.Selection.model>`."""
        return self.best().model

    def table(self) -> str:
        """A Markdown table, best held-out first, failed models last.

        Returns
        -------
        str
        """
        unit = f" ({self.output_unit})" if self.output_unit else ""
        lines = [
            f"| model | training NRMSE | held-out NRMSE | held-out RMSE{unit} "
            "| error loop width | absorbed | notes |",
            "|---|---|---|---|---|---|---|",
        ]
        ranked = sorted(self.rows, key=lambda r: (bool(r.error), r.test_nrmse))
        for r in ranked:
            if r.error:
                lines.append(f"| {r.name} | failed | | | | | {r.error} |")
                continue
            name = f"{r.name} (recommended)" if r.name == self.recommended else r.name
            lines.append(
                f"| {name} | {100 * r.train_nrmse:.4g} % | **{100 * r.test_nrmse:.4g} %** "
                f"| {r.test_rmse:.4g} | {100 * r.test_width:.3g} % | {r.absorbed or '-'} "
                f"| {r.notes} |"
            )
        ok = [r for r in ranked if not r.error]
        if self.recommended and ok and ok[0].name != self.recommended:
            pick = next((r for r in ok if r.name == self.recommended), None)
            theirs = "no fit" if pick is None else f"{100 * pick.test_nrmse:.4g} %"
            lines += ["", f"Recommended: {self.recommended}, chosen inside the training part "
                      "alone (forward chaining); the held-out part, which the choice never "
                      f"saw, ranks {ok[0].name} first ({100 * ok[0].test_nrmse:.4g} % against "
                      f"{theirs})."]  # fmt: skip
        if self.recommendation_notes:
            lines += ["", *self.recommendation_notes]
        return "\n".join(lines)


def _clone(model: HysteresisModel) -> HysteresisModel:
    return type(model)(**model.get_params(deep=False))


def _absorbed(model: HysteresisModel) -> str:
    """What a fitted model took up besides its hysteresis core, in words."""
    parts = []
    growth = [lab for term in model.terms_ if term.removed for lab in term.labels()]
    if growth:
        parts.append("growth " + ", ".join(growth))
    rate = [
        ", ".join(term.labels()) if term.width <= 4 else term.kind
        for term in model.terms_
        if term.rate_dependent and not term.removed
    ]
    if rate:
        parts.append("rate " + ", ".join(rate))
    dyn = model.input_dynamics_
    if dyn.active:
        parts.append(f"input lag {dyn.tau * 1e3:.3g} ms, delay {dyn.delay * 1e3:.3g} ms")
    mode = model.output_dynamics_
    if mode.active:
        parts.append(f"mode {mode.f0:.4g} Hz, damping {mode.zeta:.3g}")
    return "; ".join(parts)


def _named(
    models: Mapping[str, HysteresisModel] | Sequence[HysteresisModel],
) -> list[tuple[str, HysteresisModel]]:
    if isinstance(models, Mapping):
        items = [(str(k), m) for k, m in models.items()]
    else:
        items = []
        for m in models:
            base = str(getattr(type(m), "cli_name", "") or type(m).__name__)
            name, k = base, 2
            while any(name == n for n, _ in items):
                name, k = f"{base} ({k})", k + 1
            items.append((name, m))
    if not items:
        msg = "compare_models needs at least one model."
        raise ParameterError(msg)
    for name, m in items:
        if not is_model(m):
            msg = f"compare_models: {name!r} is not a piezohyst model (got {type(m).__name__})."
            raise ParameterError(msg)
    return items


def _train_stop(train: float, n: int) -> int:
    if isinstance(train, bool) or not isinstance(train, int | float) or not 0 < train < 1:
        msg = f"The 'train' fraction must be between 0 and 1 (exclusive). Got {train!r} instead."
        raise ParameterError(msg)
    stop = round(train * n)
    if stop < 2 or n - stop < 2:
        msg = (
            f"A training fraction of {train:g} of {n} samples leaves fewer than 2 samples "
            "in one part; give a longer record or another fraction."
        )
        raise ParameterError(msg)
    return stop


def _signals(
    x: ArrayLike, y: ArrayLike, t: ArrayLike | None, what: str
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    xs = as_signal(x, f"{what} x")
    ys = as_signal(y, f"{what} y")
    same_length(xs, ys, f"{what} x", f"{what} y")
    ts = None
    if t is not None:
        ts = as_signal(t, f"{what} t")
        same_length(xs, ts, f"{what} x", f"{what} t")
    return xs, ys, ts


def compare_models(
    models: Mapping[str, HysteresisModel] | Sequence[HysteresisModel],
    x: ArrayLike,
    y: ArrayLike,
    t: ArrayLike | None = None,
    *,
    train: float = 0.7,
    test: tuple[ArrayLike, ArrayLike, ArrayLike | None] | None = None,
    initial_state: InitialState = "rest",
    test_state: InitialState = "rest",
) -> Comparison:
    """Fit each model on a training part and score it on data it never saw.

    Parameters
    ----------
    models : mapping of str to HysteresisModel, or sequence of HysteresisModel
        Unfitted (or fitted: only the settings are used) estimators; each is
        cloned, the ones passed in are not changed. A sequence is named by
        each model's CLI name.
    x, y : array_like, shape (N,)
        Input and measured output of the record.
    t : array_like, shape (N,), optional
        Sample times (s); needed by rate-dependent models.
    train : float
        Without ``test``: the first ``train`` fraction of the record trains,
        the rest tests (a forward split). Ignored when ``test`` is given.
    test : tuple (x, y, t), optional
        A separate test record; the whole of ``x, y`` then trains.
    initial_state : {"rest", "periodic"}, History or array_like
        Where the training part starts (see
        :meth:`~piezohyst.model.presets.HysteresisModel.fit`).
    test_state : {"rest", "periodic"}, History or array_like
        Where a separate test record starts.

    Returns
    -------
    Comparison
        One row per model; failed fits are rows with their error.

    Raises
    ------
    ParameterError
        For no models, something that is not a model, or a split that leaves
        a part with fewer than 2 samples.
    """
    named = _named(models)
    xs, ys, ts = _signals(x, y, t, "training")
    if test is None:
        stop = _train_stop(train, xs.size)
        fit_part = slice(0, stop)
        ranges = ((0, stop), (stop, xs.size))
        xt = yt = tt = None
    else:
        if len(test) != 3:
            msg = "The 'test' record must be a tuple (x, y, t); t may be None."
            raise ParameterError(msg)
        xt, yt, tt = _signals(*test, "test")
        fit_part = slice(0, xs.size)
        ranges = ((0, xs.size), (0, xt.size))
    rows = []
    unit = ""
    for name, template in named:
        model = _clone(template)
        unit = unit or model.output_unit
        notes: set[str] = set()
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", ExtrapolationWarning)
                began = time.perf_counter()
                model.fit(
                    xs[fit_part],
                    ys[fit_part],
                    t=None if ts is None else ts[fit_part],
                    initial_state=initial_state,
                )
                seconds = time.perf_counter() - began
                if xt is None:  # run on from the training start over the test part
                    pred = model.predict(xs, t=ts)
                    y_train, p_train = ys[fit_part], pred[fit_part]
                    y_test, p_test = ys[fit_part.stop :], pred[fit_part.stop :]
                    x_test = xs[fit_part.stop :]
                else:
                    assert yt is not None
                    p_train = model.predict(xs, t=ts)
                    y_train = ys
                    p_test = model.predict(xt, t=tt, state=test_state)
                    y_test, x_test = yt, xt
            for w in caught:
                if issubclass(w.category, ExtrapolationWarning):
                    notes.add("left the training region")
                else:
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        except (PiezohystError, np.linalg.LinAlgError) as exc:
            rows.append(ComparisonRow(name, None, error=str(exc).splitlines()[0]))
            continue
        if not np.all(np.isfinite(p_test)):
            notes.add("non-finite prediction")
        rows.append(
            ComparisonRow(
                name,
                model,
                train_nrmse=nrmse(y_train, p_train),
                test_nrmse=nrmse(y_test, p_test),
                train_rmse=rmse(y_train, p_train),
                test_rmse=rmse(y_test, p_test),
                test_width=_error_width(x_test, y_test, p_test),
                fit_seconds=seconds,
                absorbed=_absorbed(model),
                notes="; ".join(sorted(notes)),
                test_residual=y_test - p_test,
            )
        )
    return Comparison(
        tuple(rows), ranges[0], ranges[1], separate_test=test is not None, output_unit=unit
    )


def _error_width(x: FloatArray, y: FloatArray, pred: FloatArray) -> float:
    """Loop width of the error over the measured span: hysteresis left unmodelled."""
    span = float(np.ptp(y))
    err = y - pred
    if span == 0 or not np.all(np.isfinite(err)):
        return math.nan
    return hysteresis_width(x, err) * float(np.ptp(err)) / span
