"""Beyond the record: what a choice made inside a record cannot rank, and what is done or
said there (for :func:`~piezohyst.analysis.selection.select_model`).

* Where a record never comes back to an end of its range after its first turn (decaying
  loops that reach 0 V on their first rise only), the scores inside it cannot rank how the
  candidates predict loops from there. :func:`median_choice` takes, among the candidates
  scoring near the best, the one whose loops from that end lie nearest the candidates'
  median (no truth read there: the candidates compared with one another), as
  ``select_model`` and ``compare``'s recommendation do. Chosen on plants drawn at random
  (``docs/selection-study.md``).
* Where the chosen candidate's variant with creep operators is among the candidates the
  record does not tell from the score's choice, :func:`creep_where_undecided` takes that
  variant: a record that cannot tell them apart cannot show the rates where creep matters,
  and a creep term the actuator does not need fits small. Chosen on plants drawn at random
  (``docs/selection-study.md``).
* Where a charge record's holds show the leak rising with the voltage and the chosen model
  holds no term for it, :func:`rise_not_held` says so.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import ExtrapolationWarning, PiezohystError
from ..io.blocks import Summary, array_blocks
from ..model.fit_record import holds_show_rise
from ..model.model import HysteresisModel
from ..units import is_length
from .turns import _turns, unseen_ends

__all__ = [
    "MEDIAN_WITHIN",
    "creep_where_undecided",
    "median_choice",
    "median_said",
    "probe_loops",
    "rise_not_held",
]

#: Where a record never comes back to an end of its range, the candidates scoring within this
#: factor of the best are compared on loops from that end (:func:`_nearest_median`)
MEDIAN_WITHIN = 1.5


def probe_loops(x: FloatArray, end: str, dt: float) -> FloatArray:
    """Loops from an end of the input's range to all, 3/4, 1/2 and 1/4 of it (1 s each, at
    the step ``dt``): what a record that never comes back to that end does not show.

    Parameters
    ----------
    x : ndarray
        The record's input.
    end : {"lowest", "highest"}
    dt : float
        s.

    Returns
    -------
    ndarray
    """
    lo, hi = float(np.min(x)), float(np.max(x))
    per = max(round(1.0 / dt), 8)
    k = np.arange(per) / per
    tri = 1.0 - np.abs(2.0 * k - 1.0)  # 0 -> 1 -> 0
    start, toward = (lo, hi - lo) if end == "lowest" else (hi, lo - hi)
    return np.concatenate([start + toward * a * tri for a in (1.0, 0.75, 0.5, 0.25)])


def median_said(name: str, instead: str, x: FloatArray, turns: np.ndarray | None = None) -> str:
    """The note when :func:`median_choice` moved the choice from ``instead`` to ``name``.

    Parameters
    ----------
    name, instead : str
    x : ndarray
        The record's input.
    turns : ndarray, optional
        Its turns (found if not given).

    Returns
    -------
    str
    """
    end = unseen_ends(x, _turns(x) if turns is None else turns)[0]
    return (
        f"The record never comes back to its {end} values, where the scores cannot rank the "
        f"candidates: among those scoring within {MEDIAN_WITHIN:g}x of the best, {name}'s "
        f"loops from there lie nearest the candidates' median: {name} chosen (rather than "
        f"{instead})."
    )


def median_choice(
    rows: Sequence[Any], x: FloatArray, t: FloatArray | None, fitted: Any,
    turns: np.ndarray | None = None,
) -> tuple[Any, HysteresisModel] | None:  # fmt: skip
    """Where the record never comes back to an end of its range (:func:`unseen_ends`): the
    candidate (among those scoring within :data:`MEDIAN_WITHIN` of the best) whose
    prediction of loops from that end (:func:`probe_loops`) lies nearest the candidates'
    median, and its model; None elsewhere, or where fewer than three are compared (no
    median to speak of). No truth is read on the loops: the candidates are compared with
    one another. Chosen on plants drawn at random (``docs/selection-study.md``).

    Parameters
    ----------
    rows : sequence of SelectionRow
        The candidates' scores (each with ``name`` and ``score``).
    x : ndarray
        The record's input (what the candidates are fitted on).
    t : ndarray or None
        Its times.
    fitted : callable
        ``fitted(name)``: the candidate fitted on the record.
    turns : ndarray, optional
        The input's turns (found if not given).

    Returns
    -------
    (SelectionRow, HysteresisModel) or None
    """
    ends = unseen_ends(x, _turns(x) if turns is None else turns)
    if not ends or not rows:
        return None
    end = ends[0]
    best = min(r.score for r in rows)
    close = [r for r in rows if math.isfinite(r.score) and r.score <= MEDIAN_WITHIN * best]
    if len(close) < 3:
        return None
    dt = float(np.median(np.diff(t))) if t is not None else 1e-3
    loops = probe_loops(x, end, dt)
    tl = np.arange(loops.size) * dt if t is not None else None
    models, preds = {}, {}
    for row in close:
        try:
            models[row.name] = fitted(row.name)
            with warnings.catch_warnings():  # the loops leave the record's region: the point
                warnings.simplefilter("ignore", ExtrapolationWarning)
                pred = np.asarray(models[row.name].predict(loops, t=tl))
        except PiezohystError:
            continue
        if np.all(np.isfinite(pred)):
            preds[row.name] = pred
    if len(preds) < 3:
        return None
    median = np.median(np.array(list(preds.values())), axis=0)
    far = {n: float(np.sqrt(np.mean((p - median) ** 2))) for n, p in preds.items()}
    name = min(far, key=lambda n: far[n])
    return next(r for r in rows if r.name == name), models[name]


def creep_where_undecided(
    name: str, close: Sequence[str], names: Sequence[str]
) -> tuple[str, tuple[str, ...]]:
    """The candidate to take instead of ``name`` where its variant with creep operators is
    among ``close`` (the score's choice and what the record does not tell from it), and the
    note that says so; ``name`` and no note elsewhere. Chosen on development plants drawn
    at random (60: within 1.25x of the best default on 51 against 47, the worst unchanged)
    and scored once on 30 fresh ones (23 against 22), ``docs/selection-study.md``.

    Parameters
    ----------
    name : str
        The candidate chosen so far.
    close : sequence of str
        The score's choice and the candidates the record does not tell from it.
    names : sequence of str
        The candidates scored.

    Returns
    -------
    (str, tuple of str)
    """
    variant = f"{name}+creep"
    if name.endswith("+creep") or variant not in close or variant not in names:
        return name, ()
    return variant, (
        f"{name} and {variant} are within the record's noise of each other: {variant} "
        "chosen (the record cannot show the rates where creep operators matter; where the "
        "actuator has no creep they fit small).",
    )


def rise_not_held(
    model: HysteresisModel, name: str, x: FloatArray, y: FloatArray, t: FloatArray | None
) -> tuple[str, ...]:
    """A sentence where a charge record's holds show the leak rising with the voltage and the
    chosen model holds no term for it (``abs_integral``): its prediction at another mean
    voltage than the record's drifts. Seen on a plant drawn at random whose leak rose 142 %
    to 140 V: ActivePI, chosen, drifted 6.2 % of the span over the test, where the Preisach
    model, which takes the rise, left 0.96 % (``docs/selection-study.md``).

    Parameters
    ----------
    model : HysteresisModel
        The chosen model, fitted.
    name : str
        Its candidate name.
    x, y : ndarray
        The record.
    t : ndarray or None
        Its times (none: nothing to say).

    Returns
    -------
    tuple of str
        The sentence, or nothing.
    """
    if t is None or is_length(model.output_unit):
        return ()
    if any(term.kind == "abs_integral" for term in model.terms_):
        return ()
    blocks = array_blocks(x, y, t)
    if not holds_show_rise(blocks, Summary.of(blocks)):
        return ()
    return (
        f"The record's holds show the leak rising with the voltage, which {name} holds no "
        "term for: where a use's mean voltage is not the record's, its prediction drifts "
        "(the Preisach, Duhem and Bouc-Wen defaults take the rise where holds show it).",
    )
