r"""Learning a repeated scan on a coupled stage: the coupling's inverse, one learner per
actuator.

A :class:`~piezohyst.model.coupled.CoupledModel` says ``y = C h(u) + c``: each actuator's
own motion ``h_i``, then the static coupling. The stage's sensors read ``y``; through the
identified coupling's inverse they say what each actuator moved, ``C^-1 (y - c)``, and the
desired positions say what each must move. Between the two, each actuator is a single
channel again, and its own :class:`~piezohyst.control.learning.LearningCompensator` learns
its share of the scan from trial to trial (decoupling, then single-channel iterative
learning: the scheme of the piezo-scanner learning literature for coupled axes). What the
identified coupling gets wrong (a few tenths of a per cent of a cross term) moves each
actuator's measured motion by that much of the other's error, which the learning then takes
out as the error shrinks.

An actuator whose own share does not move over the trial (a held axis with no coupling to
undo) has nothing to learn: it is held by its feedforward compensator, and
:meth:`CoupledLearningCompensator.describe` says so.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from ...errors import LearningWarning, ParameterError, ShapeError, warn
from ...metrics import hysteresis_width
from ..coupled import CoupledCompensator, _per_actuator
from .compensator import LearningCompensator, _responder
from .coupled_saving import FORMAT, CoupledSaving
from .harmonics import told_the_others
from .trial import CoupledTrial, Trial

FloatArray = np.ndarray

__all__ = ["FORMAT", "CoupledLearningCompensator", "CoupledTrial"]

#: The learning options passed on to each actuator's learner (as LearningCompensator takes
#: them); the limits, the rate and the domain are the stage's
OPTIONS = frozenset({"learning_gain", "cutoff", "lag_tolerance", "slope_error", "lead_in",
                     "probe", "noise_gate", "law", "measure_lag", "lag"})  # fmt: skip
#: An actuator's share whose span over the trial is below this share of its reach is held
HELD = 1e-9
#: An actuator whose share spans less than this share of its reach (what undoing the coupling
#: asks of a held axis: a few per cent of the other's scan) learns without the lead-in's
#: probe and without measuring the loop's lag: both are scaled to its own span, and there
#: they sink below a sensor's noise (on the simulated stage a 1.6 % share's probe "measured"
#: a 20 ms delay)
SMALL_SHARE = 0.1


def _crosstalk(learners: list[LearningCompensator | None]) -> None:
    """Each learner told the others' change at each harmonic since their trial before (their
    model's), which reaches its readings through the coupling's error
    (:func:`~.harmonics.told_the_others`)."""
    live, changes = [], []
    for lrn in learners:
        if lrn is not None and lrn._pending is not None:
            live.append(lrn._harmonics)
            changes.append(live[-1].change(lrn._pending, _responder(lrn)))
    told_the_others(live, changes)


def _relayed(i: int, call: Any) -> Any:
    """Run ``call`` and say its warnings again, each naming actuator ``i``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = call()
    for w in caught:
        warn(f"actuator {i}: {str(w.message).removeprefix('Compensator: ')}", w.category)
    return out


class CoupledLearningCompensator(CoupledSaving):
    """Iterative learning control of a repeated scan on a coupled stage.

    Each trial is one period of the scan, sent right after the one before:
    :meth:`command` gives every actuator's voltages for it, :meth:`learn` takes the stage's
    positions measured over it (one row per command, reading *i* taken at the end of sample
    *i*). The positions are turned into what each actuator moved through the coupling's
    inverse, and each actuator's :class:`~piezohyst.LearningCompensator` learns from its
    own (with its offset: a sensor). Every command is finite and inside its actuator's limits
    and slew limit, across trials too; a desired position outside what the stage reaches is
    named and counted (:attr:`outside_count`), as :class:`~piezohyst.CoupledCompensator`
    does.

    Parameters
    ----------
    model : CoupledModel
        Fitted (with more outputs than actuators, what each moved is the least squares'
        over every reading, as :class:`~piezohyst.CoupledCompensator`'s).
    v_min, v_max : float or array_like
        Each actuator's voltage limits (V): one number for all, or one per actuator.
    sample_rate : float
        Hz, of the trials.
    slew_rate : float, "trained" or None, default "trained"
        Per actuator, as for :class:`~piezohyst.Compensator`.
    allow_extrapolation : bool, default False
    voltage : float or array_like, optional
        Where the actuators sit now (V): the first trial ramps in from there.
    **options
        The learning options of :class:`~piezohyst.LearningCompensator`, the same for every
        actuator: ``learning_gain``, ``cutoff``, ``law``, ``noise_gate``, ``lead_in``,
        ``probe``, ``measure_lag``, ``lag``, ``lag_tolerance``, ``slope_error``.

    Attributes
    ----------
    feedforward : CoupledCompensator
        The coupling's inverse and each actuator's plain compensator (its reach; it holds an
        actuator with nothing to learn).
    learners : list of (LearningCompensator or None)
        One per actuator once the scan is known (None: held by the feedforward).
    history : list of CoupledTrial

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> from piezohyst.simulation import Bench, XY_COUPLING, make_signal, simulate_stage
    >>> t, a = make_signal("decaying", duration=8.0)
    >>> _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    >>> rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t)
    >>> stage = ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)
    >>> ilc = ph.CoupledLearningCompensator(stage, v_min=0.0, v_max=140.0,
    ...                                     sample_rate=1000.0, slew_rate=None)
    >>> (x0, x1), (y0, y1) = ilc.feedforward.reach
    >>> k = np.arange(500)                                 # a trial: a 4 Hz raster line
    >>> tri = np.abs((k / 1000 * 4) % 1 * 2 - 1)
    >>> scan = np.column_stack([x0 + (x1 - x0) * (0.3 + 0.4 * tri), np.full(500, (y0 + y1) / 2)])
    >>> benches = [Bench(seed=i, voltage=v) for i, v in enumerate(ilc.last_command)]
    >>> for _ in range(4):                                 # the lead-in, then three learned
    ...     u = ilc.command(scan)
    ...     moved = np.column_stack([b.run(u[:, i]).displacement for i, b in enumerate(benches)])
    ...     trial = ilc.learn(moved @ XY_COUPLING.T)
    >>> first, last = ilc.history[1].error, ilc.history[-1].error
    >>> bool(np.all(last < 0.5 * first))                   # x 0.90 -> 0.12 %, y 0.84 -> 0.40 %
    True
    """

    def __init__(
        self,
        model: Any,
        *,
        v_min: float | ArrayLike,
        v_max: float | ArrayLike,
        sample_rate: float,
        slew_rate: float | Literal["trained"] | None = "trained",
        allow_extrapolation: bool = False,
        voltage: float | ArrayLike | None = None,
        **options: Any,
    ) -> None:
        unknown = sorted(set(options) - OPTIONS)
        if unknown:
            msg = (
                f"CoupledLearningCompensator does not take {', '.join(map(repr, unknown))}; "
                f"its learning options are {', '.join(sorted(OPTIONS))}"
            )
            raise ParameterError(msg)
        self.feedforward = CoupledCompensator(
            model, v_min=v_min, v_max=v_max, sample_rate=sample_rate, slew_rate=slew_rate,
            allow_extrapolation=allow_extrapolation,
        )  # fmt: skip
        self.feedforward.owner = "CoupledLearningCompensator"
        for i, comp in enumerate(self.feedforward.compensators):  # a held actuator's warnings
            comp.owner = f"CoupledLearningCompensator, actuator {i}"
        self.model = model
        n = len(model.channels_)
        self._voltage = None if voltage is None else _per_actuator(voltage, n, "voltage")
        self._kept: dict[str, Any] = {
            "sample_rate": sample_rate, "slew_rate": slew_rate,
            "allow_extrapolation": allow_extrapolation, **options,
        }  # fmt: skip
        self.reset()  # every option checked now, on a learner per actuator

    def _learner(self, i: int, small: bool = False) -> LearningCompensator:
        """Actuator ``i``'s learner (``small``: a share too small to probe or time)."""
        comp = self.feedforward.compensators[i]
        v = None if self._voltage is None else float(self._voltage[i])
        quiet = {"probe": False, "measure_lag": False} if small else {}
        return LearningCompensator(self.model.channels_[i], v_min=comp.v_min, v_max=comp.v_max,
                                   domain="displacement", gain=1.0, voltage=v,
                                   **{**self._kept, **quiet})  # fmt: skip

    def reset(self) -> None:
        """Forget the scan and what was learned; the actuators back where they sat."""
        self.feedforward.reset(voltage=self._voltage)
        self.learners: list[LearningCompensator | None] = [
            self._learner(i) for i in range(len(self.model.channels_))
        ]
        self._small = np.zeros(len(self.learners), dtype=bool)
        self.history: list[CoupledTrial] = []
        self._desired: FloatArray | None = None
        self._pending: FloatArray | None = None
        self._held = np.zeros(len(self.learners), dtype=np.int64)
        self._cursor = 0  # a stepping loop's place in the trial, and the reading it awaits
        self._awaiting: int | None = None
        self._seen = np.empty((0, self.model.coupling_.shape[0]))

    # ---------------------------------------------------------------- state
    @property
    def outside_count(self) -> int:
        """Desired positions of the scan outside what the stage reaches."""
        return self.feedforward.outside_count

    @property
    def last_command(self) -> FloatArray:
        """The last commands sent, one per actuator (V): where the actuators sit."""
        return np.array([
            (lrn.last_command if lrn is not None else comp.last_command)
            for lrn, comp in zip(self.learners, self.feedforward.compensators, strict=True)
        ])  # fmt: skip

    @property
    def pending(self) -> FloatArray | None:
        """The commands of the trial waiting for its readings (None: none waits)."""
        return None if self._pending is None else self._pending.copy()

    @property
    def desired(self) -> FloatArray | None:
        """The scan, one period (None until the first :meth:`command`)."""
        return None if self._desired is None else self._desired.copy()

    @property
    def trials(self) -> int:
        """Trials learned from (or skipped) so far."""
        return len(self.history)

    def describe(self) -> str:
        """One line per actuator: what its learner learns with (or that it is held).

        Returns
        -------
        str
        """
        lines = []
        for i, lrn in enumerate(self.learners):
            said = ("held by its compensator: its share of the scan does not move"
                    if lrn is None else lrn.describe())  # fmt: skip
            if self._small[i]:
                said = (
                    f"its share of the scan moves under {100 * SMALL_SHARE:g} % of its reach (no "
                    f"lead-in probe, no lag measured: below the noise); {said}"
                )
            lines.append(f"actuator {i}: {said}")
        return "\n".join(lines)

    # ------------------------------------------------------------- trials
    def _scan(self, desired: ArrayLike) -> FloatArray:
        m = self.model.coupling_.shape[0]
        d = np.asarray(desired, dtype=np.float64)
        if d.ndim != 2 or d.shape[1] != m:
            msg = f"'desired' must be (samples, {m}) positions. Got shape {d.shape}."
            raise ShapeError(msg)
        if not np.all(np.isfinite(d)):
            row = int(np.flatnonzero(~np.isfinite(d).all(axis=1))[0])
            msg = f"'desired' must be finite: a scan to learn holds no gaps (row {row})"
            raise ParameterError(msg)
        if self._desired is None:
            own = self.feedforward.actuator_targets(d)
            span = self.feedforward.reach[:, 1] - self.feedforward.reach[:, 0]
            share = np.ptp(own, axis=0) / span
            if not np.any(share > HELD):
                msg = "'desired' must move: a constant scan has nothing to learn."
                raise ParameterError(msg)
            self._small = (share > HELD) & (share < SMALL_SHARE)
            self.learners = [
                None if share[i] <= HELD else self._learner(i, True) if self._small[i] else lrn
                for i, lrn in enumerate(self.learners)
            ]
            self._desired, self._own = d.copy(), own
        elif d.shape != self._desired.shape or not np.array_equal(d, self._desired):
            msg = (
                "this learner belongs to another scan: every trial repeats the first "
                "(reset() to learn a new one)"
            )
            raise ParameterError(msg)
        return self._desired

    def command(self, desired: ArrayLike | None = None) -> FloatArray:
        """Every actuator's voltages for the next trial.

        Parameters
        ----------
        desired : array_like, shape (samples, outputs), optional
            One period of the scan (the model's output units), the same every trial; needed
            the first time. It must end where it begins (checked per actuator).

        Returns
        -------
        ndarray, shape (samples, actuators)
            Commands (V): finite, each inside its actuator's limits and slew limit.

        Raises
        ------
        ParameterError
            A trial still waits for its readings, another scan, or none given yet.
        """
        if self._pending is not None:
            msg = (
                f"trial {self.trials} still waits for its readings: call learn() with the "
                "positions measured over it before the next command()"
            )
            raise ParameterError(msg)
        if desired is None and self._desired is None:
            msg = "the first command() needs the desired scan"
            raise ParameterError(msg)
        if desired is not None:
            self._scan(desired)
        own = self._own
        cols = []
        for i, lrn in enumerate(self.learners):
            if lrn is None:
                comp = self.feedforward.compensators[i]
                before = comp.saturated_count + comp.slew_limited_count
                cols.append(comp.process(own[:, i].copy()))
                self._held[i] = comp.saturated_count + comp.slew_limited_count - before
            else:
                zero = lrn.compensator.reference  # its displacement 0, in the model's units
                cols.append(_relayed(i, lambda lrn=lrn, i=i, z=zero: lrn.command(own[:, i] - z)))
        u = np.column_stack(cols)
        self._pending = u
        self._cursor, self._awaiting = 0, None
        self._seen = np.full((u.shape[0], self.model.coupling_.shape[0]), np.nan)
        return u

    # ------------------------------------------------------- a stepping loop
    #: True: the trial's readings are learned from (the controllers' one contract)
    reads = True

    def step(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """One sample of the repeated scan, for a loop that reads after each command.

        Each call sends the next of the trial's commands and keeps ``measured``, the
        positions read after the command before, as that sample's; the readings of a trial's
        last sample arrive with the next trial's first call, which learns from the trial
        (:meth:`learn`) and begins the next. Equal to :meth:`command` and :meth:`learn` on
        whole trials.

        Parameters
        ----------
        desired : array_like, shape (outputs,)
            The scan's positions at this sample (checked against the scan given to the
            first :meth:`command`).
        measured : array_like, shape (outputs,), optional
            The positions read after the command before; None or NaN: none.

        Returns
        -------
        ndarray, shape (actuators,)
            The commands (V).

        Raises
        ------
        ParameterError
            No scan yet, or ``desired`` is not the scan's row at this point of the trial.
        """
        if self._desired is None:
            msg = (
                "step() repeats a known scan: give it once with command(desired), whose "
                "commands are the first trial's, which step() then sends"
            )
            raise ParameterError(msg)
        m = self._desired.shape[1]
        if self._awaiting is not None:
            seen = np.full(m, np.nan) if measured is None else np.asarray(measured, np.float64)
            if seen.shape != (m,):
                msg = f"'measured' must hold {m} positions. Got shape {seen.shape}."
                raise ShapeError(msg)
            self._seen[self._awaiting] = seen
            self._awaiting = None
        if self._pending is not None and self._cursor == self._pending.shape[0]:
            self.learn(self._seen.copy())
        if self._pending is None:
            self.command()
        assert self._pending is not None
        k, d = self._cursor, self._desired
        want = np.asarray(desired, dtype=np.float64).reshape(-1)
        if want.shape != (m,) or not np.all(np.abs(want - d[k]) <= 1e-9 * np.ptp(d, axis=0)):
            msg = (
                f"step(): desired {want.tolist()} at sample {k} of the trial, where the scan "
                f"is {d[k].tolist()}: the learner repeats one scan (reset() for another)"
            )
            raise ParameterError(msg)
        self._cursor, self._awaiting = k + 1, k
        return np.array(self._pending[k])

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """:meth:`step` on each row of a block (readings known beforehand: a playback).

        Parameters
        ----------
        desired, measured : array_like, shape (N, outputs)

        Returns
        -------
        ndarray, shape (N, actuators)
        """
        d = np.asarray(desired, dtype=np.float64)
        r = np.full(d.shape, np.nan) if measured is None else np.asarray(measured, np.float64)
        if d.ndim != 2 or r.shape != d.shape:
            msg = f"'desired' and 'measured' must be (samples, outputs), alike. Got {d.shape}."
            raise ShapeError(msg)
        return np.array([self.step(a, b) for a, b in zip(d, r, strict=True)])

    def learn(self, positions: ArrayLike) -> CoupledTrial:
        """Learn from the stage's positions measured over the trial just sent.

        Parameters
        ----------
        positions : array_like, shape (samples, outputs)
            One row per command (the model's output units); NaN where a reading is missing
            (a row with a missing output is not learned from by any actuator: what each
            moved needs every output).

        Returns
        -------
        CoupledTrial
            Also appended to :attr:`history`.

        Warns
        -----
        LearningWarning
            An actuator's learner undid an update, or had too few readings; each message
            names the actuator.
        """
        if self._pending is None:
            msg = "learn() needs a trial: call command() and send its voltages first"
            raise ParameterError(msg)
        d = self._desired
        assert d is not None
        y = np.asarray(positions, dtype=np.float64)
        if y.shape != d.shape:
            msg = f"'positions' must be {d.shape} (one row per command). Got shape {y.shape}."
            raise ShapeError(msg)
        moved = (y - self.model.offset_) @ self.feedforward.inverse.T
        _crosstalk(self.learners)  # before they learn
        records: list[Trial | None] = []
        for i, lrn in enumerate(self.learners):
            if lrn is None:
                records.append(None)
                continue
            zero = lrn.compensator.reference
            records.append(
                _relayed(i, lambda lrn=lrn, i=i, z=zero: lrn.learn(displacement=moved[:, i] - z))
            )
        self._pending = None
        trial = self._record(d, y, tuple(records))
        self.history.append(trial)
        return trial

    def _record(
        self, d: FloatArray, y: FloatArray, records: tuple[Trial | None, ...]
    ) -> CoupledTrial:
        ok = np.isfinite(y).all(axis=1)
        reach = self.output_reach()
        error = np.full(d.shape[1], math.nan)
        width = np.full(d.shape[1], math.nan)
        if ok.any():
            error = np.sqrt(np.mean((d[ok] - y[ok]) ** 2, axis=0)) / (reach[:, 1] - reach[:, 0])
        for j in range(d.shape[1]):
            if ok.sum() > 2 and np.ptp(d[:, j]) > HELD * (reach[j, 1] - reach[j, 0]):
                width[j] = hysteresis_width(d[ok, j], y[ok, j])
        saturated = np.array([r.saturated if r is not None else self._held[i]
                              for i, r in enumerate(records)], dtype=np.int64)  # fmt: skip
        skipped = all(r is None or r.skipped for r in records)
        if not any(r is not None for r in records):
            warn("every actuator is held: nothing learned", LearningWarning)
        return CoupledTrial(self.trials, error, width, records, saturated, skipped)

    def output_reach(self) -> FloatArray:
        """What the stage reaches along each output: its extent over every actuator's range
        through the coupling (the parallelogram's bounding box).

        Returns
        -------
        ndarray, shape (outputs, 2)
            The lowest and highest position along each output (its units).
        """
        c = self.model.coupling_
        lo, hi = self.feedforward.reach[:, 0], self.feedforward.reach[:, 1]
        a, b = c * lo, c * hi
        off = self.model.offset_
        return np.column_stack([off + np.minimum(a, b).sum(axis=1),
                                off + np.maximum(a, b).sum(axis=1)])  # fmt: skip
