"""Checks for people who write their own core: the core contract as a function to run.

:func:`check_core` runs a fitted :class:`~piezohyst.Core` through what the library asks of
every core (as scikit-learn's ``check_estimator`` does for estimators) and raises
:class:`CoreContractError` naming the first rule it breaks. Run it in your own tests::

    from piezohyst.testing import check_core

    def test_my_core_follows_the_contract():
        check_core(MyCore.from_dict(saved))  # or a core fitted with ph.HysteresisModel
"""

from __future__ import annotations

import json
import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray
from .errors import ExtrapolationWarning, LimitWarning, PiezohystError, RecordWarning
from .model.cores.base import CORES, Core, InversePlan, Propagation

__all__ = ["CoreContractError", "check_core"]


class CoreContractError(PiezohystError, AssertionError):
    """A core breaks the core contract (the message names the rule)."""


def _fail(core: Core, rule: str) -> CoreContractError:
    return CoreContractError(f"{type(core).__name__} (kind {core.kind!r}): {rule}")


def _probe(x_range: tuple[float, float]) -> FloatArray:
    """Loops of several sizes inside ``x_range`` (V): rises, reversals and minor loops."""
    lo, hi = x_range
    t = np.linspace(0.0, 1.0, 1200)
    shape = 0.5 - 0.5 * np.cos(2 * np.pi * 4 * t) * (1.0 - 0.8 * t)
    return lo + (hi - lo) * (0.05 + 0.9 * shape)


def check_core(core: Core, x: ArrayLike | None = None) -> None:
    """Check that a fitted core follows the core contract; raise naming what it breaks.

    The rules: ``kind`` names it in the core registry; :meth:`~Core.rest_state`
    and :meth:`~Core.propagate` give finite arrays of consistent shapes; a run
    split into chunks, each from the state the last one left, equals one run (to
    1e-12 of the output's span); :meth:`~Core.predict` is ``propagate``'s output;
    its file form survives JSON and predicts bit for bit what it did; ``describe``
    labels its parameters; ``min_slope`` is positive and no slope on the probe
    falls below it; its ``inverse_plan`` names an engine; ``identify``, handed
    the core's own output through :class:`~piezohyst.HysteresisModel`, returns
    a core of the same kind; and the :class:`~piezohyst.Compensator` built on it
    brings its own output back to the voltages that made it.

    Parameters
    ----------
    core : Core
        A fitted core (for example ``model.operator_``).
    x : array_like, optional
        The input (V) to probe it with; default: loops of several sizes over
        0-140 V.

    Raises
    ------
    CoreContractError
        The first rule it breaks (an ``AssertionError`` and a ``PiezohystError``).

    Examples
    --------
    >>> import piezohyst as ph
    >>> v = 70 - 70 * np.cos(np.linspace(0, 6 * np.pi, 900))
    >>> model = ph.ClassicalPI(6).fit(v, 1e-8 * v + 1e-10 * v**1.5)
    >>> check_core(model.operator_)  # silent: it follows the contract
    """
    if not isinstance(core, Core):
        msg = f"check_core needs a piezohyst Core instance. Got {type(core).__name__}."
        raise CoreContractError(msg)
    if not core.kind or CORES.get(core.kind) is not type(core):
        raise _fail(core, "its 'kind' must name it in the core registry (set kind = '...')")
    xs = _probe((0.0, 140.0)) if x is None else np.asarray(x, dtype=np.float64).reshape(-1)
    if xs.size < 10 or not np.all(np.isfinite(xs)):
        raise _fail(core, "the probe input must hold at least 10 finite samples")
    with warnings.catch_warnings():  # a probe may leave the region it was identified on
        warnings.simplefilter("ignore", ExtrapolationWarning)
        y = _runs(core, xs)
        _file_form(core, xs, y)
    _describes(core)
    _slopes(core, xs, y)
    _identifies(core, xs, y)


def _runs(core: Core, xs: FloatArray) -> FloatArray:
    """rest_state, propagate and predict agree, and chunks equal one call."""
    z0 = np.asarray(core.rest_state(float(xs[0])), dtype=np.float64)
    if z0.ndim != 1 or not np.all(np.isfinite(z0)):
        raise _fail(core, f"rest_state(x0) must be a finite 1-D array. Got shape {z0.shape}")
    run = core.propagate(xs, z0)
    if not isinstance(run, Propagation):
        raise _fail(core, "propagate must return a Propagation (output, state)")
    y = np.asarray(run.output, dtype=np.float64)
    if y.shape != xs.shape or not np.all(np.isfinite(y)):
        raise _fail(core, f"propagate's output must be finite, one value per input sample "
                          f"(shape {xs.shape}). Got shape {y.shape}")  # fmt: skip
    if np.asarray(run.state).shape != z0.shape:
        raise _fail(core, "propagate's final state must have rest_state's shape")
    span = max(float(np.ptp(y)), 1e-300)
    state: Any = z0
    parts = []
    for piece in np.array_split(xs, [7, 100, 101, 513]):
        part = core.propagate(piece, state)
        parts.append(np.asarray(part.output, dtype=np.float64))
        state = part.state
    # tol: the same recursion in pieces; 1e-12 of the span allows a kernel's reordered sums
    if np.max(np.abs(np.concatenate(parts) - y)) > 1e-12 * span:
        raise _fail(core, "a run split into chunks, each from the state the last left, must "
                          "equal one run (carry every state in the returned state)")  # fmt: skip
    if not np.array_equal(np.asarray(core.predict(xs, z0), dtype=np.float64), y):
        raise _fail(core, "predict(x, state) must be propagate(x, state).output")
    return y


def _file_form(core: Core, xs: FloatArray, y: FloatArray) -> None:
    data = core.to_dict()
    try:
        text = json.dumps(data)
    except (TypeError, ValueError) as exc:
        raise _fail(core, f"to_dict() must give plain JSON data ({exc})") from None
    again = type(core).from_dict(json.loads(text))
    if type(again) is not type(core):
        raise _fail(core, "from_dict(to_dict()) must give a core of the same class")
    z0 = core.rest_state(float(xs[0]))
    if not np.array_equal(np.asarray(again.predict(xs, z0), dtype=np.float64), y):
        raise _fail(core, "a core read back from its file form must predict bit for bit what "
                          "it did (write every parameter, at full precision)")  # fmt: skip


def _describes(core: Core) -> None:
    rows = core.describe("V", "C")
    if not isinstance(rows, list) or not all(
        isinstance(r, tuple) and len(r) == 2 and all(isinstance(s, str) for s in r) for r in rows
    ):
        raise _fail(core, "describe(input_unit, output_unit) must give (label, text) pairs")


def _slopes(core: Core, xs: FloatArray, y: FloatArray) -> None:
    slope = float(core.min_slope)
    if not (math.isfinite(slope) and slope > 0.0):
        raise _fail(core, f"min_slope must be a finite number > 0. Got {slope!r}")
    dx = np.diff(xs)
    moving = np.abs(dx) > 1e-9 * max(float(np.ptp(xs)), 1e-300)
    observed = np.diff(y)[moving] / dx[moving]
    # tol: a secant over one sample of a curve whose slope never falls below min_slope stays
    # above it; 1e-6 of it for the rounding of two outputs' difference
    if observed.size and float(observed.min()) < slope * (1.0 - 1e-6):
        raise _fail(core, f"min_slope {slope:.6g} must bound its slopes from below; the "
                          f"probe shows {float(observed.min()):.6g}")  # fmt: skip
    plan = core.inverse_plan()
    if not isinstance(plan, InversePlan):
        raise _fail(core, "inverse_plan() must return an InversePlan")


def _estimator(core: Core) -> Any:
    """The model that fits this core: the first registered preset built on its class that
    adds no growth term (its settings' defaults; as many operators as the core has), else a
    plain HysteresisModel on it (a core from outside the library)."""
    from .model.model import HysteresisModel
    from .model.persistence import model_class, model_names

    for name in model_names():  # the registry lists the plainest preset of a core first
        cls = model_class(name)
        params = cls().get_params()
        if cls().core_class is not type(core):
            continue
        kw: dict[str, Any] = {"growth_terms": ()} if "growth_terms" in params else {}
        n = getattr(core, "n_operators", None)
        if n is not None and "n_operators" in params:
            kw["n_operators"] = int(n)
        return cls(**kw)
    return HysteresisModel(type(core), terms=())


def _identifies(core: Core, xs: FloatArray, y: FloatArray) -> None:
    """identify through the model and the one Compensator back to the probe's voltages."""
    from .control.compensator import Compensator

    t = np.arange(xs.size) * 1e-3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordWarning)  # a probe of steps is no DAQ record
        try:
            model = _estimator(core).fit(xs, y, t=t)
        except PiezohystError as exc:
            raise _fail(core, f"identify failed on the core's own output: {exc}") from None
    fitted = model.operator_
    if type(fitted) is not type(core):
        raise _fail(core, "identify must return a CoreFit whose core is of its own class")
    if not math.isfinite(model.nrmse_):
        raise _fail(core, "the identified core must predict the record (finite error)")
    lo, hi = float(xs.min()), float(xs.max())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LimitWarning)  # the first samples may step in
        warnings.simplefilter("ignore", ExtrapolationWarning)
        comp = Compensator(model, v_min=lo, v_max=hi, slew_rate=None,
                           allow_extrapolation=True)  # fmt: skip
        target = model.predict(xs, t=t)
        back = comp.process(target)
        achieved = model.predict(back, t=t)
    # tol: a per-sample inverse (eq. 18, or a root search to 1e-12 of its interval) from the
    # same state; 1e-6 of the span allows a core whose slope is small at a reversal
    if np.max(np.abs(achieved - target)) > 1e-6 * max(float(np.ptp(target)), 1e-300):
        raise _fail(core, "the Compensator on it must bring its own output back (its "
                          "inverse plan, or propagate near a command, is off)")  # fmt: skip
