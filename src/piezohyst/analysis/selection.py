"""A model chosen for the user: every candidate scored on data it was not fitted on, inside
the record the user gives (never on what they will test on), the winner refitted on all.

Forward chaining, as a recording runs: fit on the first half of the record's input turns,
score up to three quarters of them; fit up to three quarters, score the rest
(:data:`FOLDS`, :func:`fold_bounds`). Hysteresis is learnt from reversals, not from
seconds: a record whose fast loops come last (what ``piezohyst excite`` writes) is split
where its turns are, and each fit has seen loops of the kind it is scored on. A record with
fewer than :data:`MIN_TURNS` turns is split by its samples instead. Each part starts where
the input before it left the actuator (the model runs on from its training start). The
score is the mean of the scored parts' NRMSE (:data:`WEIGHTS`); the candidate with the
lowest wins, a simpler one (earlier in :data:`CANDIDATES`) on a tie within 2 %. Where the
record does not tell the winner from others (below), the one of them that forecast the
record's latest part best is taken (:func:`latest_of_close`), and the notes say so. Where
the record never comes back to an end of its range after its first turn (decaying loops
that reach 0 V on their first rise only), the scores cannot rank how the candidates predict
loops from there: among the candidates scoring within :data:`MEDIAN_WITHIN` of the best,
the one whose loops from that end lie nearest the candidates' median is taken
(:func:`median_choice`), and the notes say so; where the choice's variant with creep
operators is among those the record does not tell apart, the variant
(:func:`creep_where_undecided`).

How sure the choice is: each scored part is cut into blocks at the input's turns (a
half-cycle each), and every candidate's margin over the chosen one gets a paired
block-jackknife standard error (:func:`jackknife`): the same blocks left out of both
scores in turn. A margin within :data:`SURE` standard errors is one the record cannot
decide. What a record cannot test at all is said in :attr:`Selection.notes`: a record
with no minor loops scores how a candidate follows the major loop, not how it predicts
smaller ones.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, as_time, same_length
from ..errors import (
    ExtrapolationWarning,
    IdentifiabilityWarning,
    InsufficientDataError,
    ParameterError,
    RecordWarning,
)
from ..model.fit_record import screened
from ..model.model import HysteresisModel, InitialState
from ..model.persistence import model_class, model_names
from ..model.terms import creep_time_constants
from .beyond import (
    MEDIAN_WITHIN,
    creep_where_undecided,
    median_choice,
    median_said,
    probe_loops,
    rise_not_held,
)
from .comparison import compare_models
from .turns import (
    EVEN_BLOCKS,
    MAJOR,
    MIN_TURNS,
    NOISE_REACH,
    SEVERAL_RATES,
    TURN_BAND,
    _record_notes,
    _turns,
    block_starts,
    drive_rates,
    input_noise,
    record_notes,
    several_rates,
    turn_band,
    unseen_ends,
)

__all__ = [
    "CANDIDATES",
    "CREEP",
    "EVEN_BLOCKS",
    "FOLDS",
    "LOOP_CANDIDATES",
    "MAJOR",
    "MEDIAN_WITHIN",
    "MIN_TURNS",
    "NOISE_REACH",
    "SEVERAL_RATES",
    "SURE",
    "TURN_BAND",
    "WEIGHTS",
    "Part",
    "Selection",
    "SelectionRow",
    "candidate_model",
    "chosen",
    "creep_constants",
    "creep_where_undecided",
    "decide",
    "drive_rates",
    "fold_bounds",
    "forward_scores",
    "input_noise",
    "is_candidate",
    "jackknife",
    "latest_of_close",
    "median_choice",
    "median_said",
    "probe_loops",
    "record_notes",
    "select_model",
    "several_rates",
    "turn_band",
    "undecided",
    "unseen_ends",
    "verdict",
    "with_margins",
]

#: Candidates, simplest first: a tie (within 2 %) goes to the earlier
CANDIDATES = ("classical-pi", "active-pi", "generalized-pi", "bouc-wen", "preisach", "duhem",
              "generalized-pi+creep", "bouc-wen+creep")  # fmt: skip
#: A candidate name with this suffix: the model with creep operators whose time constants the
#: record's time axis sets (:func:`creep_constants`; Kuhnen's modified PI model for the PI
#: family, the field's standard for piezo displacement); skipped on a record without times
CREEP = "+creep"
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
#: (end of the fitted part, end of the scored part) as fractions of the record's input turns
#: (of its samples where it has fewer than :data:`MIN_TURNS`)
FOLDS = ((0.5, 0.75), (0.75, 1.0))
#: Each part's weight in the score: equal. Chosen on units 4-6 of the simulated plants'
#: batches with the folds placed by turns: the plain mean, weights 0.4 and 0.6 (the share of
#: the turns each fit saw), the last part alone and the worst part chose within 1.25x of the
#: best model's held-out error on 9, 8, 7 and 9 of 10 rows, the worst row 1.71, 2.62, 2.62
#: and 1.71x (``benchmarks/selection_scores.py``); checked on units 1-3
#: (``docs/validation.md``) and on units 7-9, never scored before: 9, 8, 7 and 7 of 10
WEIGHTS = (0.5, 0.5)
TIE = 0.02
#: A margin within this many of its standard errors is one the record does not decide
SURE = 2.0


@dataclass(frozen=True)
class Part:
    """One scored part of a candidate, cut into blocks for the jackknife.

    Attributes
    ----------
    squares : ndarray
        Sum of the squared error over each block (output units squared).
    counts : ndarray
        Samples in each block.
    span : float
        The measured output's span over the part (output units): NRMSE's denominator.
    """

    squares: FloatArray
    counts: FloatArray
    span: float

    def left_out(self) -> FloatArray:
        """The part's NRMSE with each block left out in turn.

        Returns
        -------
        ndarray, shape (blocks,)
        """
        total, n = float(self.squares.sum()), float(self.counts.sum())
        rest = np.maximum(total - self.squares, 0.0) / (n - self.counts)
        return np.asarray(np.sqrt(rest) / self.span, dtype=np.float64)

    @property
    def nrmse(self) -> float:
        """The part's NRMSE, all blocks in."""
        return math.sqrt(float(self.squares.sum()) / float(self.counts.sum())) / self.span


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
    stderr : float
        The score's block-jackknife standard error (NaN where a part has one block or a
        fold failed).
    margin : float
        The score minus the chosen candidate's (0 for it; NaN until chosen).
    margin_stderr : float
        The margin's paired block-jackknife standard error.
    parts : tuple of Part
        The scored parts' blocks (empty when a fold failed).
    """

    name: str
    folds: tuple[float, ...]
    score: float
    error: str = ""
    stderr: float = math.nan
    margin: float = math.nan
    margin_stderr: float = math.nan
    parts: tuple[Part, ...] = field(default=(), repr=False, compare=False)

    @property
    def decided(self) -> bool:
        """Whether the record tells this candidate from the chosen one: its margin beyond
        :data:`SURE` standard errors (False for the chosen one itself)."""
        return bool(abs(self.margin) > SURE * self.margin_stderr)


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
        Every candidate, best first, with its margin over the chosen one.
    notes : tuple of str
        What the record cannot test (no minor loops, too few turns to split by).
    """

    model: HysteresisModel
    name: str
    rows: tuple[SelectionRow, ...]
    notes: tuple[str, ...] = ()

    @property
    def undecided(self) -> tuple[str, ...]:
        """The candidates this record does not tell from the chosen one (their margin
        within :data:`SURE` standard errors, or of unknown error), best first."""
        return undecided(self.rows, self.name)

    def said(self) -> tuple[str, ...]:
        """What the table says under its rows: the candidates not told apart from the
        chosen one, then :attr:`notes`.

        Returns
        -------
        tuple of str
            Sentences (:func:`verdict`).
        """
        return verdict(self.rows, self.name, self.notes)

    def table(self) -> str:
        """A Markdown table of the candidates, best first, the winner marked.

        Returns
        -------
        str
        """
        heads = " | ".join(f"part {k + 1}" for k in range(len(FOLDS)))
        weights = ", ".join(f"{w:.2g}" for w in WEIGHTS)
        lines = [
            f"| candidate | {heads} | score ({weights}) | vs chosen (± s.e.) |",
            "|---" * (len(FOLDS) + 3) + "|",
        ]
        for row in self.rows:
            chosen_row = row.name == self.name
            mark = " (chosen)" if chosen_row else ""
            cells = " | ".join("-" if math.isnan(f) else f"{100 * f:.4g} %" for f in row.folds)
            mean = row.error or f"{100 * row.score:.4g} %"
            if chosen_row or not math.isfinite(row.margin):
                versus = "-"
            else:
                versus = f"{100 * row.margin:+.3g} ± {100 * row.margin_stderr:.2g} %"
            lines.append(f"| {row.name}{mark} | {cells} | {mean} | {versus} |")
        said = self.said()
        return "\n".join(lines + (["", *said] if said else []))


def creep_constants(t: FloatArray) -> tuple[float, float, float]:
    """Three creep time constants inside a record with times ``t``
    (:func:`~piezohyst.model.terms.creep_time_constants`).

    Parameters
    ----------
    t : ndarray
        The record's times (s).

    Returns
    -------
    tuple of float
    """
    return creep_time_constants(float(t[-1] - t[0]), t.size)


def candidate_model(
    name: str,
    operators: int,
    units: tuple[str, str],
    t: FloatArray | None = None,
    **settings: Any,
) -> HysteresisModel:
    """The model a candidate name stands for, with its defaults: ``operators`` play operators
    where it has them, and with :data:`CREEP` creep operators timed by the record ``t``.

    Parameters
    ----------
    name : str
        A model name (:func:`~piezohyst.model.persistence.model_names`), optionally with
        :data:`CREEP`.
    operators : int
    units : (str, str)
        Input and output units.
    t : ndarray, optional
        The record's times (for the creep time constants).
    **settings
        Further settings every candidate takes (``input_dynamics``; ``growth_terms``, for
        the candidates that have them).

    Returns
    -------
    HysteresisModel
    """
    base = name.removesuffix(CREEP)
    cls = model_class(base)
    accepted = cls().get_params()
    extra: dict[str, Any] = {"n_operators": operators} if "n_operators" in accepted else {}
    if "growth_terms" in settings and "growth_terms" not in accepted:  # a model without them
        settings = {k: v for k, v in settings.items() if k != "growth_terms"}
    if base != name and t is not None:
        extra["creep"] = creep_constants(t)
    model: HysteresisModel = cls(**extra, **settings, input_unit=units[0], output_unit=units[1])
    return model


def is_candidate(name: str) -> bool:
    """A model name, or one with :data:`CREEP` whose model takes creep operators.

    Parameters
    ----------
    name : str

    Returns
    -------
    bool
    """
    base = name.removesuffix(CREEP)
    if base not in model_names():
        return False
    return base == name or "creep" in model_class(base)().get_params()


def fold_bounds(x: FloatArray) -> list[tuple[int, int]]:
    """Where each of :data:`FOLDS` ends its fitted and its scored part, in samples.

    A fraction ``f`` of the turns ends at the extreme of turn ``round(f * n)`` of the ``n``
    turns (:func:`turn_band`: at least :data:`TURN_BAND` of the span, and
    :data:`NOISE_REACH` times the input's noise; the extreme is the fit's last sample);
    a fraction of 1 at the record's end. With fewer than :data:`MIN_TURNS` turns, or where a
    part would hold fewer than 2 samples, the fractions are of the samples. A measured
    voltage's noise does not turn: on what ``piezohyst excite`` writes, 87 turns with 0 to
    0.5 % RMS noise, the folds on the same tops (with the span's band alone, 302 turns at
    0.2 %); at 1 % 85-87, loops smaller than ten times the noise no longer counting.

    Parameters
    ----------
    x : ndarray, shape (N,)
        The input.

    Returns
    -------
    list of (int, int)
        (fit stop, score stop) per fold.
    """
    return _bounds(x.size, _turns(x))


def _bounds(size: int, turns: np.ndarray) -> list[tuple[int, int]]:
    """:func:`fold_bounds` of a record of ``size`` samples whose turns are ``turns``."""
    by_samples = [(round(a * size), round(b * size)) for a, b in FOLDS]
    n = turns.size
    if n < MIN_TURNS:
        return by_samples

    def stop(f: float) -> int:
        return size if f >= 1.0 else int(turns[max(round(f * n), 1) - 1]) + 1

    bounds = [(stop(a), stop(b)) for a, b in FOLDS]
    if any(a < 2 or b - a < 2 for a, b in bounds):
        return by_samples
    return bounds


def _part(residual: FloatArray, starts: np.ndarray, span: float) -> Part:
    squares = np.add.reduceat(residual * residual, starts)
    counts = np.diff(np.append(starts, residual.size)).astype(np.float64)
    return Part(squares, counts, span)


def jackknife(parts: Sequence[Part], other: Sequence[Part] = ()) -> float:
    r"""The block-jackknife standard error of a score (:data:`WEIGHTS` over its parts' NRMSE),
    or of its difference from ``other``'s on the same blocks (paired).

    Each block of each part is left out in turn (of both scores, when paired) and the score
    recomputed; :math:`\mathrm{se}^2 = \frac{J-1}{J}\sum_j (\theta_{(j)} - \bar\theta)^2`
    over the :math:`J` blocks. Blocks are half-cycles of the input, so an error that
    repeats with the drive counts once per block, not once per sample.

    Parameters
    ----------
    parts : sequence of Part
        One per fold.
    other : sequence of Part, optional
        Another candidate's parts on the same blocks.

    Returns
    -------
    float
        NaN where a part has fewer than two blocks.
    """
    if any(p.squares.size < 2 for p in parts):
        return math.nan

    def left_out(ps: Sequence[Part]) -> FloatArray:
        whole = [p.nrmse for p in ps]
        runs = []
        for f, p in enumerate(ps):
            rest = sum(w * v for k, (w, v) in enumerate(zip(WEIGHTS, whole, strict=True)) if k != f)
            runs.append(WEIGHTS[f] * p.left_out() + rest)
        return np.concatenate(runs)

    theta = left_out(parts) - (left_out(other) if other else 0.0)
    j = theta.size
    return math.sqrt((j - 1) / j * float(np.sum((theta - theta.mean()) ** 2)))


def with_margins(rows: Sequence[SelectionRow], winner: SelectionRow) -> list[SelectionRow]:
    """The rows with each one's margin over ``winner`` and its paired standard error.

    Parameters
    ----------
    rows : sequence of SelectionRow
        Every candidate's scores (its parts: the folds' half-cycle errors).
    winner : SelectionRow
        The chosen candidate's row.

    Returns
    -------
    list of SelectionRow
        The rows in their order, each with ``margin`` (score minus the winner's) and
        ``margin_stderr`` (a paired jackknife over the record's half-cycles).
    """
    out = []
    for r in rows:
        if r.name == winner.name:
            out.append(replace(r, margin=0.0, margin_stderr=0.0))
        elif r.parts and winner.parts:
            se = jackknife(r.parts, winner.parts)
            out.append(replace(r, margin=r.score - winner.score, margin_stderr=se))
        else:
            out.append(r)
    return out


def undecided(rows: Sequence[SelectionRow], name: str) -> tuple[str, ...]:
    """The rows' candidates not told apart from ``name`` (see :attr:`Selection.undecided`).

    Parameters
    ----------
    rows : sequence of SelectionRow
        The rows with margins (:func:`with_margins`).
    name : str
        The chosen candidate.

    Returns
    -------
    tuple of str
        The other candidates whose margin is within :data:`SURE` standard errors, in the
        rows' order.
    """
    return tuple(
        r.name for r in rows if r.name != name and math.isfinite(r.score) and not r.decided
    )


def verdict(rows: Sequence[SelectionRow], name: str, notes: Sequence[str]) -> tuple[str, ...]:
    """How sure the choice of ``name`` is, in sentences.

    Parameters
    ----------
    rows, name
        As for :func:`undecided`.
    notes : sequence of str
        What the record cannot test (:func:`record_notes`).

    Returns
    -------
    tuple of str
        The candidates the record does not tell apart from ``name`` (one sentence, if any),
        then ``notes``.
    """
    close = undecided(sorted(rows, key=lambda r: r.score), name)
    if not close:
        return tuple(notes)
    head = (
        f"Not told apart from {name} by this record (within {SURE:g} standard errors): "
        f"{', '.join(close)}."
    )
    return (head, *notes)


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
    return _forward(models, x, y, t, initial_state, _turns(x))


def _forward(
    models: dict[str, HysteresisModel],
    x: FloatArray,
    y: FloatArray,
    t: FloatArray | None,
    initial_state: InitialState,
    turns: np.ndarray,
) -> list[SelectionRow]:
    """:func:`forward_scores` on a record whose turns are ``turns`` (:func:`_turns`)."""
    scores: dict[str, list[float]] = {n: [] for n in models}
    parts: dict[str, list[Part]] = {n: [] for n in models}
    errors: dict[str, str] = {}
    for fit_stop, stop in _bounds(x.size, turns):
        starts = block_starts(turns, fit_stop, stop)
        span = float(np.ptp(y[fit_stop:stop]))
        with warnings.catch_warnings():  # a scored part may leave the fitted region
            warnings.simplefilter("ignore", ExtrapolationWarning)
            result = compare_models(
                models, x[:stop], y[:stop], None if t is None else t[:stop],
                train=fit_stop / stop, initial_state=initial_state,
            )  # fmt: skip
        for row in result.rows:
            scores[row.name].append(math.nan if row.error else row.test_nrmse)
            if row.error:
                errors.setdefault(row.name, row.error)
            elif row.test_residual is not None and span > 0.0:
                parts[row.name].append(_part(row.test_residual, starts, span))
    rows = []
    for n in models:
        folds = tuple(scores[n])
        finite = all(math.isfinite(f) for f in folds)
        why = errors.get(n, "" if finite else "non-finite prediction")
        score = float(np.dot(WEIGHTS, folds)) if finite else math.inf
        kept = tuple(parts[n]) if finite and len(parts[n]) == len(folds) else ()
        se = jackknife(kept) if kept else math.nan
        rows.append(SelectionRow(n, folds, score, why, stderr=se, parts=kept))
    return rows


def chosen(rows: Sequence[SelectionRow]) -> SelectionRow:
    """The first row (the simplest, in candidate order) within ``TIE`` of the best.

    Parameters
    ----------
    rows : sequence of SelectionRow
        Every candidate's row, in candidate order (simplest first).

    Returns
    -------
    SelectionRow
    """
    best = min(r.score for r in rows)
    return next(r for r in rows if r.score <= best * (1 + TIE))


def latest_of_close(rows: Sequence[SelectionRow], first: SelectionRow) -> SelectionRow:
    """Among ``first`` and the candidates the record does not tell from it, the one that
    forecast the record's latest part best (the simplest within ``TIE`` of it).

    The rule for a record too thin to choose from (issue 55): over the two parts the scores
    are within their noise, and the fit on the most of the record, scored on its latest
    part, is the one most like the final model's use. Chosen on 20 plants drawn at random
    from six families (``benchmarks/selection_random.py``, ``docs/selection-study.md``):
    within 1.25x of the best candidate's held-out error on 13 of 20 plants, the worst
    2.08x, where the plain mean's choice was within on 11 and its worst 4.94x; scored once
    on 40 more drawn the same way: 34 within 1.25x, against 32.

    Parameters
    ----------
    rows : sequence of SelectionRow
        Every candidate's row, in candidate order, with margins over ``first``
        (:func:`with_margins`).
    first : SelectionRow
        What :func:`chosen` took by the score.

    Returns
    -------
    SelectionRow
        A row of ``rows`` (``first``'s, where no undecided candidate did better).
    """
    near = {first.name, *undecided(rows, first.name)}
    latest = [r for r in rows if r.name in near and math.isfinite(r.folds[-1])]
    if len(latest) < 2:
        return next(r for r in rows if r.name == first.name)
    best = min(r.folds[-1] for r in latest)
    return next(r for r in latest if r.folds[-1] <= best * (1 + TIE))


def decide(rows: Sequence[SelectionRow]) -> tuple[SelectionRow, SelectionRow]:
    """The choice among scored rows: the simplest near the best score (:func:`chosen`),
    then, among it and what the record does not tell from it, the best on the latest part
    (:func:`latest_of_close`). What ``select_model`` and ``compare``'s recommendation take.

    Parameters
    ----------
    rows : sequence of SelectionRow
        Every candidate's row, in candidate order (at least one with a finite score).

    Returns
    -------
    (SelectionRow, SelectionRow)
        The choice by the score alone, and the one taken (the same row where the latest
        part did not move it).
    """
    first = chosen([r for r in rows if math.isfinite(r.score)])
    return first, latest_of_close(with_margins(rows, first), first)


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
    input_dynamics: str = "none",
    growth_terms: str = "default",
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
        CLI model names (:func:`~piezohyst.model.persistence.model_names`).
    operators : int, default 10
        Play operators of the candidates that have them.
    initial_state : {"rest", "periodic"} or History
        Where the record starts (a History: the input before it).
    input_unit, output_unit : str
        The models' units.
    input_dynamics : str, default "none"
        The amplifier's or sensor's lag every candidate identifies with its hysteresis
        (``"auto"``, ``"first-order"``...; see :class:`~piezohyst.HysteresisModel`): on a
        record of several drive frequencies, the candidates are then scored on their
        hysteresis, not on how much of the lag each absorbs.
    growth_terms : {"default", "auto"}, default "default"
        ``"default"``: each candidate its own growth terms; ``"auto"``: every candidate
        that has growth terms chooses them by forward-chaining cross-validation of its
        Prandtl-Ishlinskii proxy (``growth_terms="auto"``: an op-amp's bias current, a
        conductance that rises with the voltage), the others as they are.

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
    unknown = [n for n in names if not is_candidate(n)]
    if unknown or not names:
        msg = (
            f"candidates must be model names from {model_names()} (a name{CREEP}: with creep). "
            f"Got {candidates!r}."
        )
        raise ParameterError(msg)
    xs, ys = as_signal(x, "x"), as_signal(y, "y")
    same_length(xs, ys, "x", "y")
    ts = as_time(t, xs.size, required=False, owner="select_model")
    if ts is None:  # creep operators need times: those candidates wait for a timed record
        names = [n for n in names if not n.endswith(CREEP)] or names
    units = (input_unit, output_unit)
    # the record's outliers and holes said once, here, not by each candidate's fits (a gap
    # was said 17 times); the candidates fit the cleaned record
    xs, ys = screened(xs, ys, ts, False, input_unit, output_unit)
    turns = _turns(xs)
    if growth_terms not in ("default", "auto"):
        msg = f"'growth_terms' must be 'default' or 'auto'. Got {growth_terms!r}."
        raise ParameterError(msg)
    dyn: dict[str, Any] = {} if input_dynamics == "none" else {"input_dynamics": input_dynamics}
    if growth_terms == "auto":
        dyn["growth_terms"] = "auto"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordWarning)
        # what a candidate's lag cannot be told from is said of the chosen one alone (below)
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        rows = _forward(
            {n: candidate_model(n, operators, units, ts, **dyn) for n in names},
            xs,
            ys,
            ts,
            initial_state,
            turns,
        )
    ranked = sorted(rows, key=lambda r: r.score)
    if not math.isfinite(ranked[0].score):
        msg = f"no candidate could be fitted: {ranked[0].name}: {ranked[0].error}"
        raise InsufficientDataError(msg)
    first, winner = decide(rows)

    said: dict[str, list[warnings.WarningMessage]] = {}

    def fitted(name: str) -> HysteresisModel:
        """A candidate fitted on the whole record, what its fit warned kept (said of the
        chosen one alone)."""
        m = candidate_model(name, operators, units, ts, **dyn)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warnings.simplefilter("ignore", RecordWarning)  # said above
            m.fit(xs, ys, t=ts, initial_state=initial_state)
        said[name] = caught
        return m

    notes = _record_notes(xs, turns)
    if winner.name != first.name:
        notes = (
            f"{first.name} scored best over both parts, within the noise of {winner.name}, "
            f"which forecast the record's latest part better ({100 * winner.folds[-1]:.3g} % "
            f"against {100 * first.folds[-1]:.3g} %): {winner.name} chosen.",
            *notes,
        )
    near = median_choice(rows, xs, ts, fitted, turns)
    if near is not None and near[0].name != winner.name:
        notes = (median_said(near[0].name, winner.name, xs, turns), *notes)
    close = (first.name, *undecided(with_margins(rows, first), first.name))
    creep, creep_said = creep_where_undecided(
        (near[0] if near is not None else winner).name, close, [r.name for r in rows]
    )
    if creep_said:  # the creep variant of what was chosen, which the record cannot tell from it
        notes, near = (*creep_said, *notes), None
        winner = next(r for r in rows if r.name == creep)
    if near is not None:
        winner, model = near
        for w in said.get(winner.name, []):  # what the chosen one's fit warned
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RecordWarning)  # said above
            model = candidate_model(winner.name, operators, units, ts, **dyn)
            model.fit(xs, ys, t=ts, initial_state=initial_state)
    notes = (*notes, *rise_not_held(model, winner.name, xs, ys, ts))
    ranked = sorted(with_margins(rows, winner), key=lambda r: r.score)
    return Selection(model, winner.name, tuple(ranked), notes)
