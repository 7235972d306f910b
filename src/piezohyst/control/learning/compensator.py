r"""Learning from repetition: iterative learning control on the measured charge.

A scan repeats, and so does what a model gets wrong about it. After each trial (one period
of the trajectory, sent without a pause) the error measured over it corrects the reference
the next trial's compensator inverts:

.. math::

    r_j = d + c_j, \qquad c_{j+1} = Q\,(c_j + \gamma\,L\,e_j),

with :math:`e_j` the desired trajectory minus what was measured: the charge with the
calibrated leakage removed (sensorless), or a sensor's displacement. The inverse model is
the learning law's plant inverse (a change :math:`\delta r` of the reference becomes
:math:`\delta r / (dq/dv)` volts: the model's local slope), :math:`L` inverts a lag the
model does not hold, :math:`Q` is a zero-phase low-pass over the periodic trial, and
:math:`\gamma` is the learning gain. :class:`LearningDesign` holds the choices and the
condition under which the error shrinks from trial to trial; ``docs/realtime.md``
("Learning from repetition") derives them.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import check_float
from ...errors import (
    LearningWarning,
    ParameterError,
    ShapeError,
    warn,
)
from ...metrics import hysteresis_width
from ...model.calibrations.leakage import Leakage
from ...model.calibrations.output_map import OutputMap
from ..arguments import Domain
from ..compensator import Compensator
from .design import LearningDesign, design_learning
from .harmonics import Harmonics, band
from .jacobian import MAX_SAMPLES
from .laws import LAWS, Evidence, Law
from .probe import Response, probe_bins, probe_signal, response
from .safety import GAIN_FLOOR, rollback, rolled_said
from .saving import Saving, digest
from .stepping import Stepping
from .timing import TrialLag, timed, trial_lag
from .trial import (
    Trial,
    anti_windup,
    centred_slew,
    count_saturated,
    limits_said,
    periodic_fill,
    ramp_in,
    trajectory,
)

FloatArray = np.ndarray


__all__ = ["LearningCompensator", "resolved_law"]

#: the share of a trial's commands at a limit beyond which it is out of the actuator's reach
SATURATED = 0.02


def _flag(value: object, name: str) -> bool:
    if not isinstance(value, bool):
        msg = f"'{name}' must be True or False. Got {value!r}."
        raise ParameterError(msg)
    return value


def _readings(
    charge: ArrayLike | None, displacement: ArrayLike | None, sent: int
) -> tuple[FloatArray, bool]:
    """A trial's readings as floats, one per command sent, and whether a sensor's."""
    if (charge is None) == (displacement is None):
        msg = "learn() takes the measured charge or a sensor's displacement (one of them)"
        raise ParameterError(msg)
    try:
        y = np.array(charge if charge is not None else displacement, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        msg = f"the readings must be numbers ({exc})."
        raise ShapeError(msg) from None
    if y.size != sent:
        msg = f"one reading per command: the trial sent {sent}, got {y.size} readings"
        raise ShapeError(msg)
    return y.reshape(-1), displacement is not None


#: The most a noise gate can ask (``noise_gate``): a bin learned only above 100 times the
#: noise's power (10 times its amplitude)
GATE_MAX = 100.0


def _lead_probe(d: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """The harmonics of the lead-in's probe and its sines (:mod:`.probe`)."""
    bins = probe_bins(d)
    return bins, probe_signal(bins, d.size, float(np.ptp(d)))


def _probed(
    lead: tuple[FloatArray, FloatArray] | None, measured: FloatArray, ok: FloatArray,
    bins: np.ndarray, d: FloatArray,
) -> Response | None:  # fmt: skip
    """The loop's response to the lead-in's probe (None without one)."""
    return None if lead is None else response(lead[0], measured, lead[1] & ok, bins, d)


def _desired_gain(settings: dict[str, Any], om: OutputMap | None) -> tuple[float | None, bool]:
    """Desired units per model output unit (an output map's at its center), and whether the
    desired values are a displacement."""
    if om is not None:
        return om.gain, True
    return settings["gain"], settings["domain"] == "displacement"


def _measured(
    y: FloatArray, u: FloatArray, sensor: bool, d: FloatArray, leaked: float,
    learner: LearningCompensator,
) -> tuple[FloatArray, float, float]:  # fmt: skip
    """The readings in the desired's units (leakage removed from a charge), the leakage's 95 %
    bound over the trial (fraction of the span), and the charge leaked by the trial's end."""
    g, as_displacement = _desired_gain(learner.settings, learner.output_map)
    span = float(np.ptp(d))
    if sensor:
        if g is None and learner.model.output_unit == "m":  # the model's output is the sensor's
            return y, 0.0, leaked
        if g is None:
            msg = "learning from a displacement needs the gain (m per model output unit)"
            raise ParameterError(msg)
        return (y if as_displacement else y / g), 0.0, leaked
    ok = np.isfinite(y)
    q = periodic_fill(np.where(ok, y, 0.0), ok) if ok.any() else np.zeros_like(y)
    dt = 1.0 / learner.sample_rate
    leak = leaked + np.cumsum(learner.leakage.current(u, q) * dt)
    sigma = learner.leakage.current_stderr(u, q)
    scale = abs(g) if as_displacement and g is not None else 1.0
    bound = 2.0 * float(np.mean(sigma)) * u.size * dt * scale / span
    return _in_desired(learner, np.where(ok, y, np.nan) - leak), bound, float(leak[-1])


def _in_desired(learner: LearningCompensator, q: FloatArray) -> FloatArray:
    """The model's output (a capacitor charge) in the desired's units: through the output
    map (curvature included), or the gain, or as it is."""
    if learner.output_map is not None:
        return np.asarray(learner.output_map.predict(q))
    g, as_displacement = _desired_gain(learner.settings, None)
    return q * g if as_displacement and g is not None else q


def resolved_law(law: str, lag: float, samples: int) -> str:
    """The law ``law="auto"`` learns with: ``"jacobian"`` for a trial of up to
    :data:`~.jacobian.MAX_SAMPLES` samples without a stated lag, else ``"harmonic"``
    (any other law as it is).

    Parameters
    ----------
    law : str
    lag : float
        s, a stated lag (0: none).
    samples : int
        Of one trial.

    Returns
    -------
    str
    """
    if law != "auto":
        return law
    return "jacobian" if lag <= 0 and 0 < samples <= MAX_SAMPLES else "harmonic"


def _other_law(law: str, lag: float, samples: int) -> bool:
    """Whether the Jacobian law could learn where the harmonic law learns (not through a lag
    stated or measured: ``lag``, s)."""
    return law == "harmonic" and resolved_law("auto", lag, samples) == "jacobian"


def _design_args(s: dict[str, Any], samples: int) -> dict[str, Any]:
    """:func:`design_learning`'s arguments from a learner's settings, for a trial."""
    keys = ("sample_rate", "cutoff", "lag", "lag_tolerance", "slope_error")
    return {**{k: s[k] for k in keys}, "gain": s["learning_gain"], "samples": samples}


def _fingerprint(model: Any, settings: dict[str, Any], leakage: Leakage) -> str:
    """What a saved state must have been made with: the model, the settings, the leakage."""
    text = json.dumps(model.to_dict(), sort_keys=True, default=str).encode()
    rest = json.dumps([settings, leakage.to_dict()], sort_keys=True, default=str).encode()
    return digest(text + rest)


def _first_design(
    learner: LearningCompensator, measured: FloatArray, ok: FloatArray, e: FloatArray, index: int
) -> LearningDesign:
    """The law chosen from the first trial learned from, with the lead-in probe's response;
    warns where that response is beyond every timing the law allows for."""
    d = learner.desired
    loop = _probed(learner._lead, measured, ok, learner._bins, d)
    args = _design_args(learner.settings, d.size)
    design = design_learning(learner._model, **args, first_error=e, measured=loop)
    if design.probe_phase:
        s = learner.settings  # the default would have measured it: no lag stated, none held
        off = not s.get("measure_lag", True) and s["lag"] <= 0 and not design.model_timed
        default = ("; by default the trial after the lead-in measures the loop's lag and the "
                   "model holds it from then on: this run was told not to (measure_lag=False, "
                   "--no-lag-measurement)") if off else ""  # fmt: skip
        warn(f"trial {index}: {design.beyond()}{default}", LearningWarning)
    return design


def _lag_measured(
    learner: LearningCompensator, measured: FloatArray, ok: FloatArray, index: int
) -> TrialLag | None:
    """The loop's lag measured on the first trial after the lead-in (:mod:`.timing`), where
    the model holds no input dynamics, no lag was stated and ``measure_lag`` is on."""
    s = learner.settings
    if s["lag"] > 0 or not s.get("measure_lag", True) or learner.timing is not None:
        return None
    if learner.model.input_dynamics_.active or learner._pending is None:
        return None
    found = trial_lag(_responder(learner), learner._pending, measured, ok, s["sample_rate"])
    return None if found is None else replace(found, trial=index)


def _update(
    learner: LearningCompensator, e: FloatArray, sensor: bool, u: FloatArray, index: int
) -> FloatArray:
    """The law's next correction from a good trial's error ``e``, each harmonic through the
    model's response or, where that made the error grow, the measured one (said once)."""
    design, s, gain = learner.design, learner.settings, learner._gain
    assert design is not None
    law = learner._law()
    said = learner._harmonics.said_once(index, learner.sample_rate)
    if said is not None:
        warn(said, LearningWarning)
    steer = learner._harmonics.steering(law.own(design))
    return law.update(
        Evidence(design, gain, learner._correction, e, sensor, s.get("noise_gate", 0.0), u,
                 _responder(learner), s["v_max"] - s["v_min"], steer)
    )  # fmt: skip


def _described(learner: LearningCompensator) -> str:
    """:meth:`LearningCompensator.describe`'s paragraph."""
    design = learner.design
    if design is None:
        return f"law {learner.law!r}: chosen with the trajectory (the first command())"
    if learner.timing is not None and learner._first:
        return f"{learner.timing.describe()}; the law is chosen from the next trial"
    law = learner._law()
    said = law.said(design)
    if learner.timing is not None:
        said = f"{learner.timing.describe()}; {said}"
    bins = learner._harmonics.steered()
    if bins.size:
        step = learner.sample_rate / design.samples
        said += (
            f"; {bins.size} harmonic{'s' if bins.size > 1 else ''} ({bins[0] * step:.4g}-"
            f"{bins[-1] * step:.4g} Hz) learned through the loop's response measured between "
            "trials, where the model's made the error grow"
        )
    return said


def _responder(learner: LearningCompensator) -> Any:
    """Commands -> the model's output in the desired's units, the trial run after itself (its
    input dynamics, the gain or map included)."""
    n = learner.desired.size
    t = np.arange(2 * n) / learner.settings["sample_rate"]
    model = learner._model.hysteresis_

    def respond(v: FloatArray) -> FloatArray:
        with warnings.catch_warnings():  # the limits were checked where the commands were made
            warnings.simplefilter("ignore")
            q = np.asarray(model.predict(np.tile(v, 2), t))[n:]
        return _in_desired(learner, q)

    return respond


class LearningCompensator(Saving, Stepping):
    r"""A feedforward compensator that learns from repetition (iterative learning control).

    Each trial is one period of a repeated trajectory, sent right after the
    one before (the actuator's hysteresis and the leakage carry over):
    :meth:`command` gives the trial's voltages, :meth:`learn` takes what was
    measured over it (reading *i* taken at the end of sample *i*, as the
    models are identified) and updates the correction for the next. Learning
    from the charge needs no position sensor: the leakage (calibrated from
    holds, :func:`~piezohyst.calibrate_leakage`) is removed and its zero,
    which the leakage leaves unknown, is not learned. A sensor's
    displacement (``learn(displacement=...)``) is learned with its offset.

    The commands of a trial are the compensator's (:class:`~piezohyst.Compensator`)
    for the reference ``desired + correction``, continuing from the previous
    trial's reference (one period of it, at least 1 s, run first from the
    model's initial state: the same history the actuator has, so a trial's
    commands depend on the correction alone and a saved learner resumes
    exactly). Every command is finite, inside ``[v_min, v_max]`` and within
    the slew limit of the command before it, across trials too.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model; its inverse drives the actuator.
    v_min, v_max : float
        The actuator's limits (V).
    sample_rate : float
        Hz, of the trials.
    leakage : Leakage, optional
        Removed from the measured charge; default the model's growth terms.
    slew_rate, domain, gain, allow_extrapolation
        As for :class:`~piezohyst.Compensator` (``gain``, m per model output
        unit, also turns a sensor's displacement into the model's units).
    lag : float, default 0
        s: a lag the model does not hold, inverted by the learning filter
        (see :func:`design_learning`, with ``lag_tolerance``, ``slope_error``). 0 with
        a model that holds no input dynamics: see ``measure_lag``.
    learning_gain, cutoff : float or "auto", default "auto"
        The fraction of the error learned per trial, and the robustness filter's
        cutoff (Hz); ``"auto"`` chooses them from the first trial's error
        (:func:`design_learning`).
    lag_tolerance, slope_error : float
        What the convergence condition allows for (defaults 0.25 and 0.5).
    voltage : float, optional
        Where the actuator sits now (V; default the model's initial state): the
        first trial ramps in from there at the slew limit.
    lead_in : bool, default True
        The first trial brings the actuator from where it sat into the scan and
        is not learned from: its response is the arrival's, not the scan's (on the
        plants, an error of 11 % where the scan's own was 0.75 %; learned from, it
        cost a trial to undo). False learns from it too (the actuator already runs
        the scan).
    probe : bool, default True
        The lead-in carries eight small sines (0.2 % of the span each, between
        the scan's harmonics; :mod:`~piezohyst.control.learning.probe`): the next
        trial's readings without them give the loop's phase there, and the law then
        allows only for the timings that agree with it (``design.probed``).
    output_map : OutputMap, optional
        Desired values in metres through this map (instead of ``gain``): the charge
        readings are turned into displacement with it, curvature included.
    noise_gate : float, default 0
        Learn a frequency of the error only where its power is above this many times
        the measurement noise's (9: three times its amplitude). 0 learns the noise too,
        and the commands carry it, which dithers the loop narrower; 9 lowered the NRMSE
        on 19 of 20 plant rows and widened the loop on 13 (``docs/realtime.md``).
    measure_lag : bool, default True
        Where the model holds no input dynamics and no ``lag`` is stated, the first
        trial after the lead-in measures the loop's lag
        (:mod:`~piezohyst.control.learning.timing`): where the lag explains at least
        half of that trial's misfit, it is not learned from, the commands invert a
        copy of the model that holds the lag from the next trial on, the law is
        chosen on that trial, and :meth:`describe` says so (:attr:`timing`).
        Behind a 4 ms amplifier, fitted without dynamics: 40 Hz scans to 0.2-0.7 %
        width after 10 trials where the law that assumed no lag left 0.5-5.7 %
        (docs/benchmarks.md). False: that trial is learned from.
    law : {"auto", "harmonic", "jacobian"}
        How the error is learned: ``"harmonic"`` corrects the reference, each harmonic
        through the model's inverse; ``"jacobian"`` moves the commands through the model's
        Jacobian along them (:mod:`~piezohyst.control.learning.jacobian`: an actuator whose
        output runs on past its reversals too; up to 4000 samples, 0.2-0.7 s per 1000; no
        ``lag``: a lag the model holds, as a measured one, it learns through).
        ``"auto"``: the Jacobian law where it can (:func:`resolved_law`), the harmonic
        law where a lag was stated.

    Attributes
    ----------
    timing : TrialLag or None
        The lag measured (``measure_lag``), where one was: from the next trial on, the
        commands invert a copy of the model that holds it (the model is not changed).
    design : LearningDesign
        The law in use, chosen when the first trial is learned from (before it: a
        provisional one, gain 0.5 and the widest band that converges).
    history : list of Trial

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> from piezohyst.simulation import Bench
    >>> rec = ph.simulate(duration=10.0)
    >>> model = ph.ActivePI(n_operators=8).fit(rec.voltage, rec.charge, t=rec.t)
    >>> top, bottom = model.hysteresis_.predict(np.array([140.0, 0.0]))
    >>> k = np.arange(200)                                   # a trial: four 20 Hz scans
    >>> desired = bottom + (top - bottom) * (0.4 + 0.1 * np.sin(2 * np.pi * 4 * k / 200))
    >>> ilc = ph.LearningCompensator(model, v_min=0.0, v_max=140.0, sample_rate=1000.0,
    ...                              slew_rate=30e3)
    >>> bench = Bench(seed=1, voltage=ilc.last_command)
    >>> for _ in range(8):
    ...     trial = ilc.learn(bench.run(ilc.command(desired)).charge)
    >>> ilc.history[-1].error < 0.6 * ilc.history[0].error   # 0.51 % -> 0.25 %: the noise
    True
    """

    def __init__(
        self,
        model: Any,
        *,
        v_min: float,
        v_max: float,
        sample_rate: float,
        leakage: Leakage | None = None,
        slew_rate: float | Literal["trained"] | None = "trained",
        domain: Domain = "charge",
        gain: float | None = None,
        allow_extrapolation: bool = False,
        lag: float = 0.0,
        learning_gain: float | Literal["auto"] = "auto",
        cutoff: float | Literal["auto"] = "auto",
        lag_tolerance: float = 0.25,
        slope_error: float = 0.5,
        voltage: float | None = None,
        lead_in: bool = True,
        output_map: OutputMap | None = None,
        probe: bool = True,
        noise_gate: float = 0.0,
        law: Literal["auto", "harmonic", "jacobian"] = "auto",
        measure_lag: bool = True,
    ) -> None:
        kept: dict[str, Any] = {"v_min": v_min, "v_max": v_max, "sample_rate": sample_rate,
                                "domain": domain, "gain": gain, "output_map": output_map,
                                "allow_extrapolation": allow_extrapolation}  # fmt: skip
        self.model = model
        self._kept = {**kept, "slew_rate": slew_rate}
        self._build(model)
        #: The charge -> displacement map of the desired values (None: a gain or charge)
        self.output_map = output_map
        if leakage is None:
            leakage = Leakage.from_model(model)
        if not isinstance(leakage, Leakage):
            msg = f"'leakage' must be a Leakage (see calibrate_leakage). Got {leakage!r}."
            raise ParameterError(msg)
        self.leakage = leakage
        self.sample_rate = float(sample_rate)
        self.settings: dict[str, Any] = {
            "v_min": float(v_min),
            "v_max": float(v_max),
            "sample_rate": self.sample_rate,
            "slew_rate": slew_rate,
            "domain": domain,
            "gain": gain,
            "allow_extrapolation": bool(allow_extrapolation),
            "lag": float(lag),
            "learning_gain": learning_gain,
            "cutoff": cutoff,
            "lag_tolerance": float(lag_tolerance),
            "slope_error": float(slope_error),
            "lead_in": _flag(lead_in, "lead_in"),
            "probe": _flag(probe, "probe"),
        }
        gate = check_float(noise_gate, "noise_gate", "LearningCompensator", 0.0, GATE_MAX)
        if gate > 0:  # only when set: the states saved before it existed resume
            self.settings["noise_gate"] = gate
        if law != "auto" and law not in LAWS:
            *some, last = (repr(n) for n in ("auto", *LAWS))
            msg = f"'law' must be {', '.join(some)} or {last}. Got {law!r}."
            raise ParameterError(msg)
        if law in LAWS:
            LAWS[law].check_lag(float(lag))
        if law != "harmonic":  # the same: the states saved before it existed resume
            self.settings["law"] = law
        if not _flag(measure_lag, "measure_lag"):  # the same
            self.settings["measure_lag"] = False
        # checks every design setting now (a one-sample trial stands in for the trajectory)
        design_learning(model, **_design_args(self.settings, 2))
        self._fingerprint = _fingerprint(model, self.settings, self.leakage)
        self.reset(voltage=voltage)

    def _build(self, model: Any) -> None:
        """The model the commands invert (the one given, or a copy holding a measured lag),
        and its compensators."""
        kept = dict(self._kept)
        self._model = model
        self.compensator = Compensator(model, **kept)
        # the trial's commands before the slew limit, which the whole trial then meets at once
        # (centred_slew); the compensator above holds the limit
        self._free = Compensator(model, **{**kept, "slew_rate": None})

    def _time(self, found: TrialLag) -> None:
        """Run a copy of the model given that holds the lag measured (:mod:`.timing`)."""
        self.timing = found
        self._build(timed(self.model, found.lag, self.sample_rate))

    # ------------------------------------------------------------------ state
    def reset(self, *, voltage: float | None = None) -> None:
        """Forget the trajectory and what was learned.

        Parameters
        ----------
        voltage : float, optional
            Where the actuator sits now (V); default the model's initial state.
            The first trial ramps in from there.
        """
        if self._model is not self.model:
            self._build(self.model)
        self.timing: TrialLag | None = None
        self.compensator.reset()
        self._desired: FloatArray | None = None
        self._correction = np.zeros(0)
        self._previous = np.zeros(0)  # the reference correction of the trial before
        self._good: tuple[FloatArray, float] | None = None  # the last good correction, error
        self._best: tuple[FloatArray, float] | None = None  # the best since the last rollback
        self._resend = False  # the correction now is the last good one, sent again
        self._pending: FloatArray | None = None
        self._clamped = np.zeros(0, dtype=bool)
        self._last = float(self.compensator.last_command)
        if voltage is not None:
            v = float(voltage)
            if not (math.isfinite(v) and self.compensator.v_min <= v <= self.compensator.v_max):
                msg = (
                    f"'voltage' must lie inside the limits [{self.compensator.v_min:g}, "
                    f"{self.compensator.v_max:g}] V. Got {voltage!r}."
                )
                raise ParameterError(msg)
            self._last = v
        self._leaked = 0.0
        self._probe, self._bins = np.zeros(0), np.zeros(0, dtype=int)  # the lead-in's sines
        self._lead: tuple[FloatArray, FloatArray] | None = None  # its readings, and usable
        self._gain = 0.5
        self._first = True  # the law is chosen from the first trial learned from
        self.history: list[Trial] = []
        self.design: LearningDesign | None = None
        self._cursor = 0  # step(): the next sample of the pending trial
        self._seen = np.zeros(0)  # step(): the pending trial's readings so far
        self._awaiting: int | None = None  # step(): the sample whose reading comes next
        self._harmonics = Harmonics()  # each harmonic's response, measured between trials

    @property
    def law(self) -> str:
        """The law learning: ``"harmonic"`` or ``"jacobian"``; ``law="auto"`` chooses once the
        trajectory is known (:func:`resolved_law`; before it, ``"auto"``)."""
        law, d = self.settings.get("law", "harmonic"), self._desired
        return law if d is None else resolved_law(law, self.settings["lag"], d.size)

    def _law(self) -> Law:
        """The law learning (:mod:`.laws`), once the trajectory is known."""
        return LAWS[self.law]

    def describe(self) -> str:
        """One paragraph: the lag measured (if one was), the law learning, its gain, filter.

        Returns
        -------
        str
        """
        return _described(self)

    @property
    def trials(self) -> int:
        """Trials learned from (or skipped) so far."""
        return len(self.history)

    @property
    def rollbacks(self) -> int:
        """Trials whose update was undone because the error grew."""
        return sum(t.rolled_back for t in self.history)

    @property
    def skipped(self) -> int:
        """Trials not learned from (the lead-in, the trial that measured the loop's lag, or
        under half their readings usable)."""
        return sum(t.skipped for t in self.history)

    @property
    def correction(self) -> FloatArray:
        """The correction added to the desired trajectory next trial (a copy; desired units)."""
        return self._correction.copy()

    @property
    def pending(self) -> FloatArray | None:
        """The commands of the trial sent and not yet learned from (a copy), or None."""
        return None if self._pending is None else self._pending.copy()

    @property
    def desired(self) -> FloatArray:
        """The trajectory every trial repeats (a copy; empty before the first command)."""
        return np.zeros(0) if self._desired is None else self._desired.copy()

    @property
    def last_command(self) -> float:
        """The last voltage sent (V)."""
        return self._last

    # --------------------------------------------------------------- commands
    def _set_trajectory(self, desired: ArrayLike) -> FloatArray:
        d = trajectory(desired)
        asked = self.settings.get("law", "harmonic")
        if asked in LAWS:  # "auto" chooses a law that can learn it
            LAWS[asked].check_samples(d.size)
        if self._desired is None:
            self._desired = d.copy()
            self._correction = np.zeros(d.size)
            self._previous = np.zeros(d.size)
            self._harmonics = Harmonics(d.size)
            self.design = design_learning(self._model, **_design_args(self.settings, d.size))
            if self.settings["probe"] and self.settings["lead_in"]:
                self._bins, self._probe = _lead_probe(d)
        elif d.size != self._desired.size or not np.array_equal(d, self._desired):
            msg = (
                "this learner belongs to another trajectory: every trial repeats the first "
                "(reset() to learn a new one)"
            )
            raise ParameterError(msg)
        return self._desired

    def _commands(
        self, previous: FloatArray, correction: Any, volts: FloatArray | None = None
    ) -> FloatArray:
        """The compensator's commands for ``desired + correction`` after the history of
        ``desired + previous`` (at least 1 s of it, from the model's initial state), within
        the slew limit over the whole trial (:func:`centred_slew`)."""
        assert self._desired is not None
        d = self._desired
        comp = self._free
        comp.reset()
        reps = max(1, math.ceil(self.sample_rate / d.size))
        comp.process(np.tile(d + previous, reps))
        u = comp.process(d + correction)
        if volts is not None:  # the Jacobian law's correction, inside the limits
            u = np.clip(u + volts, self.compensator.v_min, self.compensator.v_max)
        step = self.compensator.max_step
        if math.isfinite(step):  # a hair inside, so that rounding never steps over it; the
            u = centred_slew(u, step * (1.0 - 1e-9))  # hulls stay inside the commands' range
        return u

    def command(self, desired: ArrayLike | None = None) -> FloatArray:
        """The voltages of the next trial.

        Parameters
        ----------
        desired : array_like, optional
            One period of the trajectory (model output units, or m with
            ``domain="displacement"``), the same every trial; needed the first
            time. It must end where it begins (checked).

        Returns
        -------
        ndarray
            Commands (V): finite, inside the limits, within the slew limit of
            the last command sent.

        Raises
        ------
        ParameterError
            A trial still waits for its readings (:meth:`learn`), or another trajectory.
        """
        if self._pending is not None:
            msg = (
                f"trial {self.trials} still waits for its readings: call learn() with what was "
                "measured over it before the next command()"
            )
            raise ParameterError(msg)
        if desired is None and self._desired is None:
            msg = "the first command() needs the desired trajectory"
            raise ParameterError(msg)
        if desired is not None:
            self._set_trajectory(desired)
        probing = self._probe.size and self.trials == 0  # the lead-in carries the probe
        probe = self._probe if probing else 0.0
        assert self._desired is not None
        u = self._commands(*self._law().reference(self._correction, self._previous, probe))
        clamped = ramp_in(u, self._last, self.compensator.max_step, self._desired)
        self._pending, self._clamped = u.copy(), clamped
        self._last = float(u[-1])
        self._cursor, self._seen, self._awaiting = 0, np.full(u.size, np.nan), None
        return u

    # ----------------------------------------------------------------- learning
    def learn(
        self, charge: ArrayLike | None = None, *, displacement: ArrayLike | None = None
    ) -> Trial:
        """Learn from what was measured over the trial just sent.

        Parameters
        ----------
        charge : array_like, optional
            The measured charge (model output units), one reading per command;
            NaN where a reading is missing.
        displacement : array_like, optional
            Instead: a displacement sensor's reading (m; needs ``gain``), learned
            with its offset (its zero: the actuator at rest, as the compensator's).

        Returns
        -------
        Trial
            Also appended to :attr:`history`.

        Warns
        -----
        LearningWarning
            The error grew (the update is undone and the gain halved), or too
            few readings to learn from.
        """
        if self._pending is None:
            msg = "learn() needs a trial: call command() and send its voltages first"
            raise ParameterError(msg)
        u, d = self._pending, self._desired
        assert d is not None
        y, sensor = _readings(charge, displacement, u.size)
        if not sensor and self.output_map is not None and self.output_map.mode.active:
            msg = (
                "learn() from the charge reads it through the output map as it stands, and this "
                f"map holds a mode ({self.output_map.mode_f0:.4g} Hz) that the charge does not "
                "show: learn from the sensor (displacement=), or calibrate the map without the "
                "mode (output_dynamics='none')"
            )
            raise ParameterError(msg)
        ok = np.isfinite(y) & ~self._clamped
        measured, bound, self._leaked = _measured(y, u, sensor, d, self._leaked, self)
        e = d - measured
        if not sensor:
            e = e - (e[ok].mean() if ok.any() else 0.0)
        index = self.trials
        span = float(np.ptp(d))
        learned = int(ok.sum())
        saturated = count_saturated(u, self.compensator)
        self._previous = self._correction  # what this trial sent: the next trial's history
        lead_in = self.settings["lead_in"] and index == 0  # the arrival, not the scan's response
        if lead_in and self._probe.size:
            self._previous = self._correction + self._probe
            self._lead = (measured.copy(), ok.copy())
        if lead_in or learned < d.size // 2:
            if not lead_in:
                warn(
                    f"trial {index}: {learned} of {d.size} readings to learn from (NaN or "
                    "slew-limited into the trajectory): nothing learned",
                    LearningWarning,
                )
            seen = float(np.sqrt(np.mean(e[ok] ** 2))) / span if lead_in and ok.any() else math.nan
            trial = Trial(index, seen, math.nan, 0 if lead_in else learned, self._gain, False,
                          True, bound, saturated)  # fmt: skip
            self._close(trial)
            return trial
        error = float(np.sqrt(np.mean(e[ok] ** 2))) / span
        width = hysteresis_width(d[ok], measured[ok]) if learned > 2 else math.nan
        e = periodic_fill(e, ok)
        filled = e
        g, as_displacement = _desired_gain(self.settings, self.output_map)
        flipped = as_displacement and g is not None and g < 0
        e = anti_windup(e, u, self.compensator, -1.0 if flipped else 1.0)
        if saturated > SATURATED * u.size:
            other = _other_law(self.law, self.settings["lag"], u.size)
            warn(limits_said(index, u, self.compensator, other), LearningWarning)  # fmt: skip
        rolled = False
        found = _lag_measured(self, measured, ok, index) if self._first else None
        if found is not None:  # a second lead-in: the law is chosen on the next trial
            self._time(found)
            self._lead = None  # the probe measured the loop the lag's inverse now changes
            trial = Trial(index, error, width, 0, self._gain, False, True, bound, saturated)
            self._close(trial)
            return trial
        if self._first:  # the law, chosen from the first trial learned from
            self.design = _first_design(self, measured, ok, e, index)
            self._lead, self._gain, self._first = None, self.design.gain, False
        assert self.design is not None
        q = band(self.design.q())
        self._harmonics.observe(u, filled, self.design.noise, _responder(self), q)
        floor = self.design.noise * math.sqrt(1.0 + self.design.noise_gain**2) / span
        back = None if self._resend else rollback(self._good, self._best, error, floor, learned)
        if back is not None:
            (kept, was), crept = back
            rolled = True
            self._gain = max(self._gain / 2, self.design.gain / GAIN_FLOOR)
            warn(rolled_said(index, was, error, self._gain, crept), LearningWarning)
            self._correction, self._resend = kept.copy(), True
        else:  # a good trial, or a correction rolled back to measured again: learn from it
            self._good = (self._correction.copy(), error)
            if self._best is None or self._resend or error < self._best[1]:
                self._best = self._good
            self._resend = False
            self._correction = _update(self, e, sensor, u, index)
        steered = int(self._harmonics.steered().size)
        trial = Trial(index, error, width, learned, self._gain, rolled, False, bound, saturated,
                      steered)  # fmt: skip
        self._close(trial)
        return trial

    def _close(self, trial: Trial) -> None:
        self.history.append(trial)
        self._pending = None

    # -------------------------------------------------------------------- files
