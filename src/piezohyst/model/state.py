"""A model's state between blocks of samples, where a run starts, and the run itself.

:class:`ModelState` names every part of it (the core's state, one array per
term, the last time, the input dynamics' and the output mode's states);
:func:`start_state` checks a given state against a model, and
:func:`named_start` builds one from ``"rest"``, ``"periodic"`` or a
:class:`History`; :func:`run_model` runs a model from one (its core, its
terms block by block, the input dynamics before, the output mode after).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, as_time, same_length
from ..errors import ExtrapolationWarning, ParameterError, ShapeError, TimeAxisError, warn
from ..io.blocks import BLOCK, block_dt
from .cores.base import Propagation
from .terms import term_columns

__all__ = [
    "History",
    "InitialState",
    "ModelState",
    "model_table",
    "named_start",
    "predict_record",
    "remove_growth",
    "rest_state",
    "run_model",
    "start_state",
]


@dataclass(frozen=True)
class History:
    """The input an actuator saw before a record: its operators start where it left them.

    Attributes
    ----------
    input : ndarray
        The earlier input (V), from rest at its first sample.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> before = np.array([0.0, 100.0, 40.0])
    >>> h = ph.PIHysteresis([0.0, 20.0], [1e-8, 5e-9])
    >>> model = ph.ClassicalPI.from_operator(h)
    >>> x = np.array([40.0, 60.0])
    >>> model.predict(x, state=ph.History(before)).tolist() == h.predict(
    ...     np.concatenate([before, x]))[3:].tolist()
    True
    """

    input: FloatArray

    def __post_init__(self) -> None:
        object.__setattr__(self, "input", as_signal(self.input, "History.input"))


#: What a fit or a prediction may start from: "rest" (None), "periodic", a History, or states
InitialState = str | History | ArrayLike | None


@dataclass(frozen=True)
class ModelState:
    """The state of a model between two blocks of samples.

    Attributes
    ----------
    operators : ndarray, shape (n,)
        Play-operator states (input units, e.g. V).
    terms : tuple of ndarray
        One state per term of the fitted model (see the model's
        :meth:`~HysteresisModel.state_names`): integrals in input unit x s,
        elapsed time in s, creep lags in input units.
    t_last : float or None
        Time (s) of the last sample run, None before any (or for a
        rate-independent model run without times).
    input : ndarray
        The input dynamics' state (delay buffer and lag; empty without them).
    output : ndarray
        The output mode's state (position, velocity; empty without it).
    """

    operators: FloatArray
    terms: tuple[FloatArray, ...] = ()
    t_last: float | None = None
    input: FloatArray = field(default_factory=lambda: np.zeros(0))
    output: FloatArray = field(default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data.

        Returns
        -------
        dict
        """
        return {
            "operators": self.operators.tolist(),
            "terms": [s.tolist() for s in self.terms],
            "t_last": self.t_last,
            "input": self.input.tolist(),
            "output": self.output.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelState:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict

        Returns
        -------
        ModelState
        """
        t_last = data.get("t_last")
        return cls(
            as_signal(data["operators"], "operators").copy(),
            tuple(as_signal(s, "terms", allow_empty=True).copy() for s in data.get("terms", [])),
            None if t_last is None else float(t_last),
            as_signal(data.get("input", []), "input", allow_empty=True).copy(),
            as_signal(data.get("output", []), "output", allow_empty=True).copy(),
        )


def named_start(
    model: Any, state: str | History, xs: FloatArray, ts: FloatArray | None
) -> ModelState | None:
    """ "rest", "periodic" or a History as a start state for the input ``xs``.

    Growth terms start at rest (their integrals count from the record's
    start); input dynamics, when the model has them, settle over the same
    passes as the operators.
    """
    x0 = float(xs[0])
    dyn = model.input_dynamics_
    if isinstance(state, History):
        z = model.operator_.history_state(as_signal(state.input, "history"))
    elif state == "rest":
        return None
    elif state == "periodic":
        if dyn.active:
            assert ts is not None
            dt = block_dt(ts, 0, ts.size, None)
            assert dt is not None
            dt[0] = float(np.median(np.diff(ts))) if ts.size > 1 else 0.0  # the wrap
            inner = dyn.rest_state(x0)
            u = xs
            for _ in range(2):  # the lag settles into the period, then the operators
                u, inner = dyn.apply(xs, dt, inner)
            z = model.operator_.periodic_state(u)
            terms = tuple(term.rest_state(x0) for term in model.terms_)
            out = np.full(2, np.nan) if model.output_dynamics_.active else np.zeros(0)
            return ModelState(z, terms, None, inner, out)
        z = model.operator_.periodic_state(xs)
    else:
        msg = (
            "'state' must be a ModelState, operator states, 'rest', 'periodic' or a "
            f"History. Got {state!r}."
        )
        raise ParameterError(msg)
    return start_state(model, z, x0)


def start_state(model: Any, state: ModelState | ArrayLike | None, x0: float) -> ModelState:
    n = model.operator_.initial_state.size
    dyn = model.input_dynamics_
    if state is None:
        return ModelState(
            model.operator_.initial_state.copy(),
            tuple(term.rest_state(x0) for term in model.terms_),
            None,
            dyn.rest_state(x0) if dyn.active else np.zeros(0),
            np.full(2, np.nan) if model.output_dynamics_.active else np.zeros(0),
        )
    if not isinstance(state, ModelState):  # operator states only
        z = as_signal(state, "state").copy()
        if z.size != n:
            msg = f"'state' must be a ModelState or {n} operator states (V). Got {z.size} values."
            raise ShapeError(msg)
        rest = dyn.rest_state(x0) if dyn.active else np.zeros(0)
        out = np.full(2, np.nan) if model.output_dynamics_.active else np.zeros(0)
        return ModelState(z, tuple(term.rest_state(x0) for term in model.terms_), None, rest, out)
    z = as_signal(state.operators, "state.operators").copy()
    if z.size != n or len(state.terms) != len(model.terms_):
        msg = (
            f"'state' does not match this model: {n} operators and {len(model.terms_)} "
            f"term states expected, got {z.size} and {len(state.terms)}."
        )
        raise ShapeError(msg)
    terms = []
    for term, s in zip(model.terms_, state.terms, strict=True):
        arr = as_signal(s, "state.terms", allow_empty=True).copy()
        if arr.size != len(term.state_names):
            msg = f"the state of term {term.kind!r} needs {len(term.state_names)} values."
            raise ShapeError(msg)
        terms.append(arr)
    inp = np.array(state.input, dtype=np.float64)
    expected = dyn.rest_state(x0).size if dyn.active else 0
    if inp.size != expected:
        msg = f"the input dynamics state needs {expected} values. Got {inp.size}."
        raise ShapeError(msg)
    outp = np.array(state.output, dtype=np.float64)
    if outp.size != (2 if model.output_dynamics_.active else 0):
        msg = f"the output mode's state needs 2 values. Got {outp.size}."
        raise ShapeError(msg)
    return ModelState(z, tuple(terms), state.t_last, inp, outp)


def run_model(
    model: Any,
    x: ArrayLike,
    t: ArrayLike | None,
    state: ModelState | InitialState,
    *,
    removed_only: bool,
) -> Propagation[ModelState]:
    """Run ``model`` over ``x`` from ``state``: the core and every term, or (``removed_only``)
    the growth terms alone; the input dynamics before, the output mode after."""
    model._check_fitted()
    xs = as_signal(x, "x", allow_empty=True)
    rate = model.rate_dependent_
    ts = as_time(t, xs.size, required=rate and xs.size > 0, owner=type(model).__name__)
    start: ModelState | ArrayLike | None
    if isinstance(state, History | str):
        start = named_start(model, state, xs, ts) if xs.size else None
    else:
        start = state
    st = start_state(model, start, float(xs[0]) if xs.size else 0.0)
    if xs.size == 0:
        return Propagation(xs.copy(), st)
    if rate and ts is not None and st.t_last is not None and ts[0] <= st.t_last:
        msg = (
            f"'t' must continue after the state's last time {st.t_last!r}. "
            f"Got t[0]={float(ts[0])!r}."
        )
        raise TimeAxisError(msg)
    if model.input_dynamics_.active:  # the command becomes the voltage on the piezo
        assert ts is not None
        xs, _ = model.input_dynamics_.apply(xs, block_dt(ts, 0, ts.size, st.t_last), st.input)
    if removed_only:
        out = np.zeros_like(xs)
        z = st.operators
    else:
        out, z = model.operator_.propagate(xs, st.operators)
        region_warning(model, xs, out)
    use = [j for j, term in enumerate(model.terms_) if term.removed or not removed_only]
    terms = [model.terms_[j] for j in use]
    states = [st.terms[j] for j in use]
    if terms:
        coef = np.concatenate([model.coefs_[j] for j in use])
        t_run = ts if rate else None
        cols = np.empty((min(BLOCK, xs.size), coef.size))
        for start in range(0, xs.size, BLOCK):
            stop = min(start + BLOCK, xs.size)
            block = cols[: stop - start]
            dt = block_dt(t_run, start, stop, st.t_last)
            ts_b = None if t_run is None else t_run[start:stop]
            term_columns(terms, xs[start:stop], ts_b, dt, states, block)
            out[start:stop] += block @ coef
    t_last = float(ts[-1]) if (rate and ts is not None) else st.t_last
    mode = model.output_dynamics_
    if mode.active:  # the mechanical mode between the hysteresis and the displacement
        if removed_only:  # the growth alone, through the mode from rest at its start
            out = mode.apply(out)[0]
        else:
            ms = st.output.reshape(2, 1)
            if np.isnan(ms).any():  # not started yet: at rest at the first output
                ms[:] = mode.rest_state([out[0]])
            out = mode.apply(out, ms)[0]
    return Propagation(out, ModelState(z, st.terms, t_last, st.input, st.output))


def rest_state(model: Any, x0: float) -> ModelState:
    """A fitted model's actuator resting at ``x0``: its core, creep lags and input dynamics
    settled there, growth integrals at 0, no time run yet."""
    dyn = model.input_dynamics_
    return ModelState(
        model.operator_.rest_state(x0),
        tuple(term.rest_state(x0) for term in model.terms_),
        None,
        dyn.rest_state(x0) if dyn.active else np.zeros(0),
        np.full(2, np.nan) if model.output_dynamics_.active else np.zeros(0),
    )


def region_warning(model: Any, x: FloatArray, core_output: FloatArray) -> None:
    """Warn when a run leaves the (voltage, output) region the core was identified on."""
    region = model.operator_.region
    if x.size == 0:
        return
    if region is None:  # a core without a region: the input range it was identified on
        range_warning(model, x)
        return
    d = region.distance(x, core_output)
    outside = d > float(getattr(model, "region_tolerance", 0.05)) * region.span
    if outside.any():
        k = int(np.argmax(outside))
        warn(
            f"{int(outside.sum())} of {x.size} samples (first: sample {k}, "
            f"{x[k]:.4g} {model.input_unit}) lie outside the (voltage, output) region the "
            f"{type(model).__name__} was identified on, by up to {float(d.max()):.3g} "
            f"{model.output_unit}: the model extrapolates there",
            ExtrapolationWarning,
        )


def range_warning(model: Any, x: FloatArray) -> None:
    """Warn when a run's input leaves the range the model was identified on by more than
    its ``region_tolerance`` (5 %) of that range."""
    lo, hi = getattr(model, "input_range_", (math.nan, math.nan))
    if not (math.isfinite(lo) and math.isfinite(hi)) or not hi > lo:
        return
    reach = float(getattr(model, "region_tolerance", 0.05)) * (hi - lo)
    outside = (x < lo - reach) | (x > hi + reach)
    if outside.any():
        k = int(np.argmax(outside))
        warn(
            f"{int(outside.sum())} of {x.size} samples (first: sample {k}, {x[k]:.4g} "
            f"{model.input_unit}) lie outside the input range [{lo:.4g}, {hi:.4g}] "
            f"{model.input_unit} the {type(model).__name__} was identified on: the model "
            "extrapolates there",
            ExtrapolationWarning,
        )


def predict_record(model: Any, x: FloatArray, t: FloatArray | None) -> FloatArray:
    """A fitted model over a whole record it may have been identified on a window of.

    From the model's training window's start (``train_window_``) the model runs from its
    own initial state, where its fit started (the history's state, the growth at rest),
    so that window's numbers equal the fit's and a later window continues it; samples
    before the training window run from rest at the record's start.

    Parameters
    ----------
    model : HysteresisModel
    x : ndarray
        Input (V).
    t : ndarray or None
        Times (s).

    Returns
    -------
    ndarray
    """
    t_w = float(model.train_window_[0])
    if t is None or not np.isfinite(t_w) or t[0] >= t_w:
        return np.asarray(model.predict(x, t))
    k = int(np.searchsorted(t, t_w, "left"))
    with warnings.catch_warnings():  # the input before the training window: it may lie
        warnings.simplefilter("ignore", ExtrapolationWarning)  # outside the window's range
        before = model.predict(x[:k], t[:k], state=model.rest_state(float(x[0])))
    return np.concatenate([before, model.predict(x[k:], t[k:])])


def model_table(model: Any) -> str:
    """A model as an HTML table (its ``_repr_html_``): kind, settings, fit quality, training
    range and window, coefficients with units, input dynamics."""
    from html import escape

    rows = [("model", type(model).__name__)]
    rows += [(f"setting {k}", repr(v)) for k, v in model.params_to_json().items()]
    if model.is_fitted:
        (lo, hi), (t0, t1) = model.input_range_, model.train_window_
        rows += [("core", model.operator_.summary),
                 ("fit NRMSE", f"{100 * model.nrmse_:.4g} %"),
                 ("fit RMSE", f"{model.rmse_:.4g} {model.output_unit}"),
                 ("training input", f"{lo:.6g} to {hi:.6g} {model.input_unit}"),
                 ("training window", f"{t0:.6g} to {t1:.6g} s")]  # fmt: skip
        rows += [(k, f"{v:.6g} {u}") for k, (v, u) in model.coefficients().items()]
        dyn = model.input_dynamics_
        if dyn.active:
            rows.append(
                ("input dynamics", f"lag {dyn.tau * 1e3:.4g} ms, delay {dyn.delay * 1e3:.4g} ms")
            )
    else:
        rows.append(("fitted", "no"))
    body = "".join(f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td></tr>"
                   for k, v in rows)  # fmt: skip
    return f"<table>{body}</table>"


def remove_growth(
    model: Any, x: ArrayLike, y: ArrayLike, t: ArrayLike | None, leakage: Any
) -> FloatArray:
    """Eq. 19 (``model.remove_growth``): the output minus the model's growth, or minus a
    calibrated leakage's charge."""
    ys = as_signal(y, "y")
    if leakage is not None:
        if t is None:
            msg = "remove_growth with a leakage needs the sample times t (s). Got t=None."
            raise TimeAxisError(msg)
        g = leakage.charge(x, t, ys if leakage.discharge else None)
    else:
        g = model.growth(x, t)
    same_length(g, ys, "x", "y")
    return np.asarray(ys - g)
