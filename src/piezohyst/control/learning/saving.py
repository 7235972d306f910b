"""A learner's state as a file: :class:`Saving`, the part of
:class:`~piezohyst.control.learning.compensator.LearningCompensator` that writes what it has
learned and resumes from it exactly (the same commands next trial), made with the same model,
leakage and settings (a fingerprint of them is checked).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import ModelFileError
from ...io import atomic_write_text
from .design import LearningDesign
from .harmonics import Harmonics
from .timing import TrialLag
from .trial import Trial

FloatArray = np.ndarray

__all__ = ["FORMAT", "Saving", "StateFile", "digest"]

FORMAT = "piezohyst-learning"


def digest(values: Any) -> str:
    """The first 16 hex digits of the SHA-256 of ``values`` (bytes).

    Parameters
    ----------
    values : bytes-like

    Returns
    -------
    str
    """
    return hashlib.sha256(values).hexdigest()[:16]


def _lead(data: Any, n: int) -> tuple[FloatArray, FloatArray] | None:
    """The lead-in's readings and usable mask from a saved state (None: none kept)."""
    if data is None:
        return None
    seen = np.array([math.nan if v is None else v for v in data[0]], dtype=np.float64)
    usable = np.zeros(n, dtype=bool)
    usable[np.array(data[1], dtype=int)] = True
    return seen, usable


def _lead_data(lead: tuple[FloatArray, FloatArray] | None) -> list[Any] | None:
    """The lead-in's readings (NaN as null) and usable indices, JSON-ready."""
    if lead is None:
        return None
    seen = [float(v) if math.isfinite(v) else None for v in lead[0]]
    return [seen, np.flatnonzero(lead[1]).tolist()]


class StateFile:
    """A learner's state as a JSON file, written atomically and read back: ``save``,
    ``save_dict`` and ``load`` around a ``to_dict`` and a ``restore`` (the single learner's
    :class:`Saving`, the coupled stage's
    :class:`~piezohyst.control.learning.coupled_saving.CoupledSaving`)."""

    if TYPE_CHECKING:

        def to_dict(self) -> dict[str, Any]: ...

        def restore(self, data: dict[str, Any], where: str = ...) -> None: ...

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`to_dict` as JSON, atomically (a reader sees the old file or the new).

        Parameters
        ----------
        path : path

        Returns
        -------
        Path
        """
        return self.save_dict(path, self.to_dict())

    def save_dict(self, path: str | os.PathLike[str], data: dict[str, Any]) -> Path:
        """Write ``data`` (:meth:`to_dict`'s, perhaps with keys added) as JSON, atomically.

        Parameters
        ----------
        path : path
        data : dict

        Returns
        -------
        Path
        """
        return atomic_write_text(Path(path), json.dumps(data))

    def load(self, path: str | os.PathLike[str]) -> None:
        """Continue from a file :meth:`save` wrote (see :meth:`restore`).

        Parameters
        ----------
        path : path
        """
        p = Path(path)
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            msg = f"{p}: cannot read the learning state ({exc})"
            raise ModelFileError(msg) from None
        self.restore(data, str(p))


class Saving(StateFile):
    """Writes a learner's state and resumes from it (mixed into the learning compensator,
    whose attributes it reads and sets)."""

    _fingerprint: str
    _desired: FloatArray | None
    _correction: FloatArray
    _previous: FloatArray
    _good: tuple[FloatArray, float] | None
    _best: tuple[FloatArray, float] | None
    _pending: FloatArray | None
    _clamped: FloatArray
    _last: float
    _leaked: float
    _gain: float
    _first: bool
    _resend: bool
    _lead: tuple[FloatArray, FloatArray] | None
    _cursor: int
    _seen: FloatArray
    _awaiting: int | None
    _harmonics: Harmonics
    design: LearningDesign | None
    timing: TrialLag | None
    history: list[Trial]

    if TYPE_CHECKING:

        def reset(self, *, voltage: float | None = None) -> None: ...

        def _set_trajectory(self, desired: Any) -> FloatArray: ...

        def _time(self, found: TrialLag) -> None: ...

    def to_dict(self) -> dict[str, Any]:
        """The learner's state, JSON-ready (see :meth:`from_dict`).

        Returns
        -------
        dict
        """
        good = best = None
        if self._good is not None:
            good = {"correction": self._good[0].tolist(), "metric": self._good[1]}
        if self._best is not None:
            best = {"correction": self._best[0].tolist(), "metric": self._best[1]}
        return {
            "format": FORMAT,
            "version": 1,
            "fingerprint": self._fingerprint,
            "trajectory": None if self._desired is None else digest(self._desired.tobytes()),
            "desired": None if self._desired is None else self._desired.tolist(),
            "correction": self._correction.tolist(),
            "previous": self._previous.tolist(),
            "good": good,
            "best": best,
            "pending": None if self._pending is None else self._pending.tolist(),
            "clamped": np.flatnonzero(self._clamped).tolist(),
            "last_command": self._last,
            "leaked": self._leaked,
            "gain": self._gain,
            "first": self._first,
            "resend": self._resend,
            "lead": _lead_data(self._lead),
            "design": None if self.design is None else asdict(self.design),
            "timing": None if self.timing is None else asdict(self.timing),
            "history": [asdict(t) for t in self.history],
            "stepping": self._stepping(),
            "harmonics": self._harmonics.to_dict(),
        }

    def _stepping(self) -> dict[str, Any] | None:
        """Where a loop stepping the trial stands (None: not stepping): the next sample, the
        readings so far (NaN as null), the sample whose reading comes next."""
        if self._pending is None or (self._cursor == 0 and self._awaiting is None):
            return None
        seen = [float(v) if math.isfinite(v) else None for v in self._seen]
        return {"cursor": self._cursor, "seen": seen, "awaiting": self._awaiting}

    def restore(self, data: dict[str, Any], where: str = "learning state") -> None:
        """Continue from :meth:`to_dict`'s contents, made with the same model and settings.

        Parameters
        ----------
        data : dict
        where : str
            Named in errors (a file's path).

        Raises
        ------
        ModelFileError
            Another model, other settings, or not a learning state.
        """
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            msg = f"{where}: not a piezohyst learning state"
            raise ModelFileError(msg)
        if data.get("fingerprint") != self._fingerprint:
            msg = (
                f"{where}: made with another model, leakage or settings (law= too: 'auto' is the "
                "default, a run saved before it was 'harmonic'); a state continues only its run"
            )
            raise ModelFileError(msg)
        try:
            self.reset()
            if data["desired"] is not None:
                self._set_trajectory(data["desired"])
                if data["trajectory"] != digest(self._desired.tobytes()):  # type: ignore[union-attr]
                    raise ValueError("the trajectory's digest does not match its values")
            self._correction = np.array(data["correction"], dtype=np.float64)
            self._previous = np.array(data["previous"], dtype=np.float64)
            good = data["good"]
            if good is not None:
                self._good = (np.array(good["correction"], dtype=np.float64), float(good["metric"]))
            best = data.get("best", good)  # a state saved before it: the last good
            if best is not None:
                self._best = (np.array(best["correction"], dtype=np.float64), float(best["metric"]))
            pending = data["pending"]
            self._pending = None if pending is None else np.array(pending, dtype=np.float64)
            n = 0 if self._desired is None else self._desired.size
            self._clamped = np.zeros(n, dtype=bool)
            self._clamped[np.array(data["clamped"], dtype=int)] = True
            self._last = float(data["last_command"])
            self._leaked = float(data["leaked"])
            self._gain = float(data["gain"])
            self._first = bool(data["first"])
            self._resend = bool(data["resend"])
            self._lead = _lead(data.get("lead"), n)
            self.design = None if data["design"] is None else LearningDesign(**data["design"])
            if data.get("timing") is not None:  # the lag measured (not in states before it)
                self._time(TrialLag(**data["timing"]))
            self.history = [Trial(**t) for t in data["history"]]
            self._harmonics = Harmonics.from_dict(data.get("harmonics"), n)  # None: older
            if self._pending is not None:  # a loop may step the pending trial from its start
                self._seen = np.full(self._pending.size, np.nan)
            stepping = data.get("stepping")  # a state saved mid-trial by a stepping loop
            if stepping is not None and self._pending is not None:
                self._cursor = int(stepping["cursor"])
                seen = [math.nan if v is None else v for v in stepping["seen"]]
                self._seen = np.array(seen, dtype=np.float64)
                awaiting = stepping["awaiting"]
                self._awaiting = None if awaiting is None else int(awaiting)
                if not (0 <= self._cursor <= self._pending.size == self._seen.size):
                    raise ValueError("the stepping loop's place is outside its trial")
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            self.reset()
            msg = f"{where}: a damaged learning state ({exc})"
            raise ModelFileError(msg) from None
