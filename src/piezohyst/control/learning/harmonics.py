r"""The loop's response at each harmonic of the trial, measured between trials, and learned
through where the model's makes a harmonic of the error grow.

The learning laws step through the model: at harmonic :math:`f` the error after an update
is, to first order, :math:`E(f) - r(f)\,\Delta\hat Y(f)`, where :math:`\Delta\hat Y` is the
change the model predicts for the new commands and :math:`r(f)` what the loop does over what
the model says it does. The design (:mod:`.design`) allows for a timing and a slope the model
has wrong, not for a misplaced mode: around a lightly damped mode the model puts 15 Hz off,
:math:`r` turns by up to 180 degrees and those harmonics grow a little every trial (a coupled
stage's actuator of other physics: ``docs/validation.md``).

Two trials that ran different commands measure :math:`r` wherever the model's change
between them stands clear of the noise (:data:`SIGMAS`; with a standard error of
:math:`\sqrt{2N}\,\sigma / |\Delta\hat Y|` for white noise of RMS :math:`\sigma` over
:math:`N` samples) and of the rest of the trial's change (:data:`RELATIVE`): the measured
change over the model's, :math:`\hat r = \Delta Y / \Delta\hat Y`. A harmonic is taken over
where the evidence says learning there goes wrong, all of: two successive measurements of its
response agree (:data:`AGREE`), the response is turned beyond :data:`TURN` and passes at
least :data:`FLOOR` of the model's, and the error there grew over the last :data:`GROWN`
trials. From then on the law learns that harmonic through the measured response: the error
there times :math:`\bar{\hat r} / (|\hat r|^2 + \epsilon^2)` (:data:`FLOOR`), a regularized
inverse, so that the step's effect there is what the law meant. Elsewhere nothing changes.
A harmonic whose later measurements agree on a response that is no longer turned is given
back to the model.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

FloatArray = np.ndarray

__all__ = [
    "AGREE",
    "FLOOR",
    "GROWN",
    "RELATIVE",
    "SIGMAS",
    "TURN",
    "Harmonics",
    "band",
    "told_the_others",
]

#: A harmonic's response is measured where the model's change there is at least this many
#: standard errors of the measured change's noise (the estimate then within 1/SIGMAS of it)
SIGMAS = 5.0
#: ... and at least this share of the largest change (a harmonic the scan barely moves is
#: moved most by the others through the hysteresis, which the model holds only roughly)
RELATIVE = 0.01
#: Two successive measurements of a harmonic's response agree within this share of the larger
#: before it is used (a change the commands did not cause rarely measures the same twice)
AGREE = 0.3
#: A harmonic is learned through its measured response only where that turns the phase
#: beyond this (rad, 60 degrees): a gain the model has wrong alone is the rollbacks' to catch
TURN = math.radians(60.0)
#: ... where the error there grew over this many successive trials (beyond the noise)
GROWN = 2
#: The measured response's regularized inverse, :math:`\bar r / (|r|^2 + FLOOR^2)`: a
#: harmonic the loop barely passes is not driven without bound (and one it passes at under
#: this share of the model's is left to the law as it is)
FLOOR = 0.3


class Harmonics:
    """What the last learned-from trial ran and measured, each harmonic's measured response
    (1 where not measured), and the harmonics learned through it.

    Parameters
    ----------
    samples : int
        Samples per trial (0 before the trajectory is known).
    """

    def __init__(self, samples: int = 0) -> None:
        bins = samples // 2 + 1
        self.commands = np.zeros(0)
        self.error = np.zeros(0)
        self.predicted = np.zeros(0)  # the model's output for ``commands`` (once each)
        self.response = np.ones(bins, dtype=complex)
        self.last = np.full(bins, np.nan, dtype=complex)  # the last measurement
        self.grown: np.ndarray = np.zeros(bins, dtype=np.int64)  # trials the error grew in a row
        self.taken = np.zeros(bins, dtype=bool)  # learned through the measured response
        self.said = False
        #: On a coupled stage, per harmonic, the largest change the other actuators' commands
        #: made (their model's, in this one's units; set before each trial is learned from):
        #: it reaches this actuator's readings through the coupling's error, so a harmonic
        #: is measured only where this actuator's own change is the larger
        self.others = np.zeros(0)
        self._next: tuple[FloatArray, FloatArray] = (np.zeros(0), np.zeros(0))

    def observe(
        self,
        commands: FloatArray,
        error: FloatArray,
        noise: float,
        respond: Callable[[FloatArray], FloatArray],
        band: Any = True,
    ) -> None:
        """Measure each harmonic's response from this trial and the one before it (their
        commands differing), decide which harmonics are learned through it, then keep this
        trial's for the next.

        Parameters
        ----------
        commands : ndarray
            The trial's voltages.
        error : ndarray
            Desired minus measured over the trial, gaps filled (before any limit's anti-windup).
        noise : float
            The measurement noise's RMS (the desired's units; NaN: taken as 0).
        respond : callable
            Commands -> the model's output in the desired's units (the trial after itself).
        band : bool or ndarray of bool
            The harmonics measured (:func:`band`): elsewhere a change is a by-product.
        """
        sigma = noise if math.isfinite(noise) else 0.0
        per_bin = math.sqrt(2 * commands.size) * sigma  # the noise of a difference, per bin
        if self.error.size == error.size:
            grew = np.abs(np.fft.rfft(error)) > np.abs(np.fft.rfft(self.error)) + per_bin
            self.grown = np.where(grew, self.grown + 1, 0)
        predicted = self._predicted(commands, respond)
        if self.commands.size == commands.size and not np.array_equal(self.commands, commands):
            model = np.fft.rfft(predicted - self._predicted(self.commands, respond))
            seen = -np.fft.rfft(error - self.error)  # the error falls as the output rises
            size = np.abs(model)
            clear = size >= np.maximum(SIGMAS * per_bin, RELATIVE * float(size.max()))
            if self.others.size == size.size:
                clear &= size > self.others
            clear &= band
            clear[0] = False  # the mean: a charge's is not learned, a sensor's offset is
            clear &= size > 0
            now = np.full(clear.size, np.nan, dtype=complex)
            now[clear] = seen[clear] / model[clear]
            big = np.maximum(np.abs(now), np.abs(self.last))
            agree = clear & (np.abs(now - self.last) <= AGREE * big)  # NaN: False
            self.response[agree] = 0.5 * (now[agree] + self.last[agree])
            self.last = now
            r = self.response
            wrong = (np.abs(np.angle(r)) > TURN) & (np.abs(r) >= FLOOR)
            self.taken |= agree & wrong & (self.grown >= GROWN) & _smooth(r, agree)
            self.taken &= ~(agree & ~wrong)  # measured right again: the model's
        self.commands, self.error, self.predicted = commands.copy(), error.copy(), predicted

    def _predicted(self, commands: FloatArray, respond: Callable[[FloatArray], FloatArray]) -> Any:
        """The model's output for ``commands``: kept for the last trial's and the next's."""
        for known, out in (self._next, (self.commands, self.predicted)):
            if known.size == commands.size and out.size and np.array_equal(known, commands):
                return out
        out = respond(commands)
        self._next = (commands.copy(), out)
        return out

    def steering(self, own: Any = 1.0) -> FloatArray:
        """Per harmonic, the factor the error is learned through: where :meth:`observe` took
        the harmonic over, the regularized inverse of :math:`L r` (:math:`L` the law's own
        factor there); else 1.

        Parameters
        ----------
        own : complex or ndarray of complex
            The law's own factor at each harmonic (the harmonic law's lag inverse; 1).

        Returns
        -------
        ndarray of complex
        """
        lr = own * self.response
        out = np.ones_like(lr)
        t = self.taken
        out[t] = np.conj(lr[t]) / (np.abs(lr[t]) ** 2 + FLOOR**2)
        return np.asarray(out)

    def steered(self) -> np.ndarray:
        """The harmonics learned through their measured response.

        Returns
        -------
        ndarray of int
        """
        return np.flatnonzero(self.taken)

    def said_once(self, index: int, sample_rate: float) -> str | None:
        """The warning, once per learner, where the measured response first takes over a
        harmonic (None: nothing to say).

        Parameters
        ----------
        index : int
            The trial.
        sample_rate : float
            Hz.

        Returns
        -------
        str or None
        """
        bins = self.steered()
        if self.said or not bins.size:
            return None
        self.said = True
        step = sample_rate / max(self.commands.size, 1)
        turn = float(np.degrees(np.max(np.abs(np.angle(self.response[bins])))))
        return (
            f"trial {index}: at {bins.size} harmonic{'s' if bins.size > 1 else ''} "
            f"({bins[0] * step:.4g}-{bins[-1] * step:.4g} Hz) the error grew while the loop "
            f"responds unlike the model (turned by up to {turn:.0f} degrees: a mode or timing "
            "it misplaces): learned there through the response measured between trials"
        )

    def change(self, commands: FloatArray, respond: Callable[[FloatArray], FloatArray]) -> Any:
        """The magnitude of the model's change at each harmonic from the trial before to
        ``commands`` (0 where there is no trial before).

        Parameters
        ----------
        commands : ndarray
        respond : callable

        Returns
        -------
        ndarray
        """
        if self.commands.size != commands.size:
            return np.zeros(commands.size // 2 + 1)
        now = self._predicted(commands, respond)
        return np.abs(np.fft.rfft(now - self._predicted(self.commands, respond)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (see :meth:`from_dict`).

        Returns
        -------
        dict
        """

        def nulled(values: FloatArray) -> list[float | None]:
            return [None if math.isnan(v) else v for v in values.tolist()]

        return {
            "commands": self.commands.tolist(),
            "error": self.error.tolist(),
            "response": [self.response.real.tolist(), self.response.imag.tolist()],
            "last": [nulled(self.last.real), nulled(self.last.imag)],
            "grown": self.grown.tolist(),
            "taken": np.flatnonzero(self.taken).tolist(),
            "said": self.said,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None, samples: int) -> Harmonics:
        """From :meth:`to_dict` (None: a state saved before it, nothing measured).

        Parameters
        ----------
        data : dict or None
        samples : int

        Returns
        -------
        Harmonics

        Raises
        ------
        ValueError
            Arrays that do not fit a trajectory of ``samples`` samples.
        """
        out = cls(samples)
        if data is None:
            return out
        out.commands = np.array(data["commands"], dtype=np.float64)
        out.error = np.array(data["error"], dtype=np.float64)
        parts = [np.array(data["response"][0], dtype=np.float64),
                 np.array(data["response"][1], dtype=np.float64),
                 *(np.array([math.nan if v is None else v for v in p], dtype=np.float64)
                   for p in data["last"]),
                 np.array(data["grown"], dtype=np.int64)]  # fmt: skip
        if any(p.shape != out.response.shape for p in parts):
            raise ValueError("the measured response does not fit the trajectory")
        out.response = parts[0] + 1j * parts[1]
        out.last = parts[2] + 1j * parts[3]
        out.grown = parts[4]
        out.taken[np.array(data["taken"], dtype=int)] = True
        out.said = bool(data["said"])
        return out


def _smooth(r: FloatArray, agree: np.ndarray) -> np.ndarray:
    """Where a harmonic's response agrees with a neighbour's measured on the same pair (a
    structure's response is smooth in frequency; a ratio measured by chance is not)."""
    out = np.zeros(r.size, dtype=bool)
    for shift in (-1, 1):
        a = slice(max(shift, 0), r.size + min(shift, 0))
        b = slice(max(-shift, 0), r.size + min(-shift, 0))
        big = np.maximum(np.abs(r[a]), np.abs(r[b]))
        out[a] |= agree[a] & agree[b] & (np.abs(r[a] - r[b]) <= AGREE * big)
    return out


def band(q: FloatArray) -> Any:
    """The harmonics whose response is measured: those the law's filter passes at least
    half of (beyond it the law learns nothing, and a change there is a by-product).

    Parameters
    ----------
    q : ndarray
        The learning filter at each harmonic.

    Returns
    -------
    ndarray of bool
    """
    return q >= 0.5


def told_the_others(harmonics: list[Harmonics], changes: list[Any]) -> None:
    """Tell each actuator's :class:`Harmonics` the largest change the others made at each
    harmonic (:attr:`Harmonics.others`), from each one's :meth:`Harmonics.change`.

    Parameters
    ----------
    harmonics : list of Harmonics
    changes : list of ndarray
        Each actuator's change, in the same units (the stage's actuator coordinates).
    """
    for i, h in enumerate(harmonics):
        rest = [c for j, c in enumerate(changes) if j != i]
        h.others = np.max(rest, axis=0) if rest else np.zeros(0)
