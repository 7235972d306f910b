"""A coupled stage's learning state as a file: :class:`CoupledSaving`, the part of
:class:`~piezohyst.control.learning.coupled.CoupledLearningCompensator` that writes what its
actuators' learners have learned and resumes from it exactly (each learner's own state,
:class:`~piezohyst.control.learning.saving.Saving`; a held actuator's compensator replayed).
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ...errors import ModelFileError
from .saving import StateFile
from .trial import CoupledTrial

if TYPE_CHECKING:
    from ..coupled import CoupledCompensator
    from .compensator import LearningCompensator

FloatArray = np.ndarray

__all__ = ["FORMAT", "CoupledSaving"]

FORMAT = "piezohyst-coupled-learning"


class CoupledSaving(StateFile):
    """Writes a coupled stage's learner's state and resumes from it (mixed into the coupled
    learning compensator, whose attributes it reads and sets)."""

    feedforward: CoupledCompensator
    learners: list[LearningCompensator | None]
    history: list[CoupledTrial]
    _desired: FloatArray | None
    _pending: FloatArray | None
    _own: FloatArray
    _held: FloatArray
    _cursor: int
    _awaiting: int | None
    _seen: FloatArray

    if TYPE_CHECKING:

        def reset(self) -> None: ...

        def _scan(self, desired: ArrayLike) -> FloatArray: ...

    def to_dict(self) -> dict[str, Any]:
        """The stage's learning state, JSON-ready: the scan, each actuator's learner's own
        state (:meth:`~piezohyst.LearningCompensator.to_dict`; None for a held actuator),
        the trial waiting for its readings and the record of the trials.

        Returns
        -------
        dict
        """

        def nulled(a: FloatArray) -> list[float | None]:
            return [float(v) if math.isfinite(v) else None for v in a]

        return {
            "format": FORMAT,
            "version": 1,
            "desired": None if self._desired is None else self._desired.tolist(),
            "pending": None if self._pending is None else self._pending.tolist(),
            "held": self._held.tolist(),
            "stepping": None
            if self._pending is None or (self._cursor == 0 and self._awaiting is None)
            else {
                "cursor": self._cursor,
                "awaiting": self._awaiting,
                "seen": [nulled(row) for row in self._seen],
            },
            "learners": [None if lrn is None else lrn.to_dict() for lrn in self.learners],
            "history": [
                {
                    "error": nulled(t.error),
                    "width": nulled(t.width),
                    "saturated": t.saturated.tolist(),
                    "skipped": t.skipped,
                }
                for t in self.history
            ],
        }

    def restore(self, data: dict[str, Any], where: str = "coupled learning state") -> None:
        """Continue from :meth:`to_dict`'s contents, made with the same model and settings:
        the next :meth:`command` (or :meth:`learn`) is the one the saved learner would have
        given.

        Parameters
        ----------
        data : dict
            What :meth:`to_dict` gave (read back from JSON).
        where : str
            What the errors name: the file's path.

        Raises
        ------
        ModelFileError
            Not a coupled learning state, a damaged one, or one of another model or settings.
        """
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            msg = f"{where}: not a piezohyst coupled learning state"
            raise ModelFileError(msg)
        try:
            self.reset()
            if data["desired"] is None:
                return
            with warnings.catch_warnings():  # said when the run sent them; not again
                warnings.simplefilter("ignore")
                self._scan(np.array(data["desired"], dtype=np.float64))
                saved = data["learners"]
                if len(saved) != len(self.learners) or any(
                    (s is None) != (lrn is None)
                    for s, lrn in zip(saved, self.learners, strict=True)
                ):
                    raise ValueError("its actuators are not this scan's")
                sent = len(data["history"]) + (data["pending"] is not None)
                for i, lrn in enumerate(self.learners):
                    if lrn is None:  # a held actuator's compensator: its trials again
                        comp = self.feedforward.compensators[i]
                        for _ in range(sent):
                            comp.process(self._own[:, i].copy())
                    else:
                        lrn.restore(saved[i], f"{where}, actuator {i}")
            self._held = np.array(data["held"], dtype=np.int64)
            self._pending = (
                None if data["pending"] is None else np.array(data["pending"], dtype=np.float64)
            )
            if self._pending is not None:
                m = self._desired.shape[1] if self._desired is not None else 0
                self._seen = np.full((self._pending.shape[0], m), np.nan)
                stepping = data.get("stepping")
                if stepping is not None:  # a loop stepping the trial, saved mid-trial
                    self._cursor = int(stepping["cursor"])
                    awaiting = stepping["awaiting"]
                    self._awaiting = None if awaiting is None else int(awaiting)
                    rows = [[math.nan if v is None else v for v in row] for row in stepping["seen"]]
                    self._seen = np.array(rows, dtype=np.float64).reshape(self._seen.shape)
            self.history = [
                CoupledTrial(
                    k,
                    np.array([math.nan if v is None else v for v in t["error"]]),
                    np.array([math.nan if v is None else v for v in t["width"]]),
                    tuple(None if lrn is None else lrn.history[k] for lrn in self.learners),
                    np.array(t["saturated"], dtype=np.int64),
                    bool(t["skipped"]),
                )
                for k, t in enumerate(data["history"])
            ]
        except ModelFileError:  # an actuator's own state refused: said as it is
            self.reset()
            raise
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            self.reset()
            msg = f"{where}: a damaged coupled learning state ({exc})"
            raise ModelFileError(msg) from None
