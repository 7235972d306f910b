"""A model chosen for the user: every candidate scored on data it was not fitted on, inside
the record the user gives (never on what they will test on), the winner refitted on all.

Forward chaining, as a recording runs: fit on the first half, score the next quarter; fit
on the first three quarters, score the last. Each part starts where the input before it
left the actuator (the model runs on from its training start). The score is the scored
parts' NRMSE averaged with weights in proportion to how much of the record each part's fit
saw (:data:`WEIGHTS`: 0.4 and 0.6; the later fit is more like the final one, fitted on all);
the candidate with the lowest wins, a simpler one (earlier in :data:`CANDIDATES`) on a tie
within 2 %.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_signal, as_time, same_length
from .comparison import compare_models
from .errors import ExtrapolationWarning, InsufficientDataError, ParameterError
from .model import HysteresisModel, InitialState
from .persistence import model_class, model_names

__all__ = [
    "CANDIDATES",
    "FOLDS",
    "LOOP_CANDIDATES",
    "WEIGHTS",
    "Selection",
    "SelectionRow",
    "chosen",
    "forward_scores",
    "select_model",
]

#: Candidates, simplest first: a tie (within 2 %) goes to the earlier
CANDIDATES = ("classical-pi", "active-pi", "generalized-pi", "bouc-wen", "preisach", "duhem")
#: Candidates for the self-sensing loop (``select_model(..., candidates=LOOP_CANDIDATES)``):
#: the cores the loop runs compiled, less the Preisach model. Its Everett function is
#: interpolated linearly between nodes, so after a reversal its slope stays at one value
#: across a whole cell where an actuator's rises smoothly; the loop's correction passes
#: through the inverse, its gain multiplied by the actuator's slope over the model's, and it
#: chatters there. Measured on issue 26's plants, 60 s of decaying loops (units 0 and 4-6;
#: ``docs/realtime.md``): through the Preisach model 0.52-2.2 % width on the Duhem plant,
#: where Bouc-Wen, chosen among these, leaves 0.09-0.21 %; checked on units 1-3: the model
#: chosen among these 0.04-0.29 % on every plant, the Preisach model 0.76-0.92 % on the
#: Duhem plant
LOOP_CANDIDATES = ("classical-pi", "active-pi", "bouc-wen", "duhem")
#: (end of the fitted part, end of the scored part) as fractions of the record
FOLDS = ((0.5, 0.75), (0.75, 1.0))
#: Each part's weight in the score: the share of the record its fit saw. Chosen on units 4-6
#: of the simulated plants' batches: these weights, the plain mean, the last part alone and
#: the worst part chose within 1.25x of the best model's held-out error on 7, 6, 8 and 7 of
#: 10 rows, the worst row 1.71, 1.71, 2.43 and 2.33x; checked on units 1-3
#: (``docs/validation.md``)
WEIGHTS = tuple(end / sum(e for e, _ in FOLDS) for end, _ in FOLDS)
TIE = 0.02


@dataclass(frozen=True)
class SelectionRow:
    """One candidate's scores.

    Attributes
    ----------
    name : str
        Its CLI name.
    folds : tuple of float
        NRMSE on each scored part (NaN where the fit failed).
    score : float
        Their mean weighted by :data:`WEIGHTS` (inf when a fold failed).
    error : str
        Why a fit failed ("" when none did).
    """

    name: str
    folds: tuple[float, ...]
    score: float
    error: str = ""


@dataclass(frozen=True)
class Selection:
    """What :func:`select_model` chose, and why.

    Attributes
    ----------
    model : HysteresisModel
        The winner, fitted on the whole record.
    name : str
        Its CLI name.
    rows : tuple of SelectionRow
        Every candidate, best first.
    """

    model: HysteresisModel
    name: str
    rows: tuple[SelectionRow, ...]

    def table(self) -> str:
        """A Markdown table of the candidates, best first, the winner marked.

        Returns
        -------
        str
        """
        heads = " | ".join(f"part {k + 1}" for k in range(len(FOLDS)))
        weights = ", ".join(f"{w:.2g}" for w in WEIGHTS)
        lines = [f"| candidate | {heads} | score ({weights}) |", "|---" * (len(FOLDS) + 2) + "|"]
        for row in self.rows:
            mark = " (chosen)" if row.name == self.name else ""
            cells = " | ".join("-" if math.isnan(f) else f"{100 * f:.4g} %" for f in row.folds)
            mean = row.error or f"{100 * row.score:.4g} %"
            lines.append(f"| {row.name}{mark} | {cells} | {mean} |")
        return "\n".join(lines)


def _candidate(name: str, operators: int, units: tuple[str, str]) -> HysteresisModel:
    cls = model_class(name)
    accepted = cls().get_params()
    extra = {"n_operators": operators} if "n_operators" in accepted else {}
    model: HysteresisModel = cls(**extra, input_unit=units[0], output_unit=units[1])
    return model


def forward_scores(
    models: dict[str, HysteresisModel],
    x: FloatArray,
    y: FloatArray,
    t: FloatArray | None,
    initial_state: InitialState = "rest",
) -> list[SelectionRow]:
    """Each model's forward-chaining scores inside a record (:data:`FOLDS`), in order.

    Parameters
    ----------
    models : dict of str to HysteresisModel
        Estimators (cloned, not changed).
    x, y, t : ndarray
        The record.
    initial_state : {"rest", "periodic"} or History
        Where it starts.

    Returns
    -------
    list of SelectionRow
    """
    scores: dict[str, list[float]] = {n: [] for n in models}
    errors: dict[str, str] = {}
    for fit_end, score_end in FOLDS:
        stop = round(score_end * x.size)
        with warnings.catch_warnings():  # a scored part may leave the fitted region
            warnings.simplefilter("ignore", ExtrapolationWarning)
            result = compare_models(
                models, x[:stop], y[:stop], None if t is None else t[:stop],
                train=fit_end / score_end, initial_state=initial_state,
            )  # fmt: skip
        for row in result.rows:
            scores[row.name].append(math.nan if row.error else row.test_nrmse)
            if row.error:
                errors.setdefault(row.name, row.error)
    rows = []
    for n in models:
        folds = tuple(scores[n])
        finite = all(math.isfinite(f) for f in folds)
        why = errors.get(n, "" if finite else "non-finite prediction")
        score = float(np.dot(WEIGHTS, folds)) if finite else math.inf
        rows.append(SelectionRow(n, folds, score, why))
    return rows


def chosen(rows: Sequence[SelectionRow]) -> SelectionRow:
    """The first row (the simplest, in candidate order) within :data:`TIE` of the best."""
    best = min(r.score for r in rows)
    return next(r for r in rows if r.score <= best * (1 + TIE))


def select_model(
    x: ArrayLike,
    y: ArrayLike,
    t: ArrayLike | None = None,
    *,
    candidates: Sequence[str] = CANDIDATES,
    operators: int = 10,
    initial_state: InitialState = "rest",
    input_unit: str = "V",
    output_unit: str = "C",
) -> Selection:
    """Choose a model for a record: each candidate with its defaults, scored by forward
    chaining inside the record (:data:`FOLDS`), the best refitted on all of it.

    Parameters
    ----------
    x, y : array_like, shape (N,)
        Input and measured output.
    t : array_like, shape (N,), optional
        Times (s); needed by candidates with growth terms.
    candidates : sequence of str
        CLI model names (:func:`~piezohyst.persistence.model_names`).
    operators : int, default 10
        Play operators of the candidates that have them.
    initial_state : {"rest", "periodic"} or History
        Where the record starts (a History: the input before it).
    input_unit, output_unit : str
        The models' units.

    Returns
    -------
    Selection

    Raises
    ------
    ParameterError
        An unknown candidate.
    InsufficientDataError
        Every candidate failed.
    """
    names = list(dict.fromkeys(candidates))
    unknown = [n for n in names if n not in model_names()]
    if unknown or not names:
        msg = f"candidates must be model names from {model_names()}. Got {candidates!r}."
        raise ParameterError(msg)
    xs, ys = as_signal(x, "x"), as_signal(y, "y")
    same_length(xs, ys, "x", "y")
    ts = as_time(t, xs.size, required=False, owner="select_model")
    units = (input_unit, output_unit)
    rows = forward_scores(
        {n: _candidate(n, operators, units) for n in names}, xs, ys, ts, initial_state
    )
    ranked = sorted(rows, key=lambda r: r.score)
    if not math.isfinite(ranked[0].score):
        msg = f"no candidate could be fitted: {ranked[0].name}: {ranked[0].error}"
        raise InsufficientDataError(msg)
    winner = chosen(rows)
    model = _candidate(winner.name, operators, units)
    model.fit(xs, ys, t=ts, initial_state=initial_state)
    return Selection(model, winner.name, tuple(ranked))
