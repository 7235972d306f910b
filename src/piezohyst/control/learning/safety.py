"""When a trial's error says to undo learning: against the last good trial (the error
grew beyond the noise) and against the best since the last rollback (it crept up, by less
than the noise each trial); the warning that says it (docs/realtime.md, "Safety")."""

from __future__ import annotations

import math

import numpy as np

FloatArray = np.ndarray

__all__ = ["CREEP", "GAIN_FLOOR", "GROWTH_SIGMAS", "rollback", "rolled_said"]

#: a trial's error counts as grown beyond this many standard errors of its estimate
GROWTH_SIGMAS = 3.0
#: learning stops halving its gain below the first gain over this
GAIN_FLOOR = 64.0
#: a trial whose error has crept above the best trial's by this many times the growth
#: threshold is rolled back to the best: a slow divergence, within the noise each trial
CREEP = 2.0


def rollback(
    good: tuple[FloatArray, float] | None,
    best: tuple[FloatArray, float] | None,
    error: float,
    floor: float,
    learned: int,
) -> tuple[tuple[FloatArray, float], bool] | None:
    """Where a trial's error says to roll back to: the last good trial (the error grew
    beyond :data:`GROWTH_SIGMAS` standard errors over it), or the best trial (it crept
    beyond :data:`CREEP` times that over the best since, by less each trial: a mode the
    model misplaces, learned a little wrong every trial); None: learn from it. The flag
    says which.

    Parameters
    ----------
    good, best : (ndarray, float) or None
        The last good trial's correction and error; the best's since the last rollback.
    error : float
        This trial's error.
    floor : float
        The error the noise alone leaves (errors below it are not compared).
    learned : int
        Samples learned from (the growth threshold falls as their square root grows).

    Returns
    -------
    ((ndarray, float), bool) or None
        The trial to roll back to and whether it is the best (a creep); None: none.
    """
    step = GROWTH_SIGMAS / math.sqrt(learned)
    if good is not None and error > max(good[1], floor) * (1 + step):
        return good, False
    if best is not None and error > max(best[1], floor) * (1 + CREEP * step):
        return best, True
    return None


def rolled_said(index: int, was: float, error: float, gain: float, crept: bool) -> str:
    """The warning of a trial rolled back (:func:`rollback`).

    Parameters
    ----------
    index : int
        The trial.
    was, error : float
        The error rolled back to, and this trial's.
    gain : float
        The learning gain now (halved).
    crept : bool
        Rolled back to the best trial (a creep) rather than the last good one.

    Returns
    -------
    str
    """
    if crept:
        return (
            f"trial {index}: the error crept up from {was:.3%} (the best trial's) to "
            f"{error:.3%} over the trials since: their updates are undone (the best trial's "
            f"correction is sent again) and the learning gain halved to {gain:.3g}"
        )
    return (
        f"trial {index}: the error grew from {was:.3%} to {error:.3%}: the last update is "
        f"undone (its correction is sent again) and the learning gain halved to {gain:.3g}"
    )
