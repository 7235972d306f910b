r"""Differential hysteresis cores: a data-driven Duhem model and the Bouc-Wen model.

Where the Prandtl-Ishlinskii operators (:mod:`piezohyst.hysteresis`) fix every
minor loop by the major loop (congruent minor loops), these cores describe the
hysteresis by its slope, which depends on where the actuator stands:

* :class:`DuhemHysteresis` — :math:`dq/dv = f_\pm(v, q)`, rising (+) or
  falling (−), each slope a non-negative bilinear surface on a grid over the
  (voltage, output) region the training data covered. Linear in its
  coefficients, so identified by one bounded least squares; rate independent;
  inverted explicitly, one sample at a time.
* :class:`BoucWenHysteresis` — :math:`y = c_0 v + \alpha h + c`,
  :math:`dh/dv = 1 - |h|^n (\beta\,\mathrm{sign}(h\,dv) + \gamma)`: five
  physical parameters, the model most papers on piezo stacks fit; inverted by
  a safeguarded Newton solve per sample.

Both carry a two-value state ``[v, x]`` (the last input, and the output
``q`` for Duhem or :math:`h` for Bouc-Wen), run in numba kernels
(:mod:`piezohyst._diffkernels`), and record the :class:`Region` of
(voltage, output) their training data covered: outside it, the model
extrapolates.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._lazy import LazyModule
from ._validation import FloatArray, as_signal
from .errors import NumericRangeError, ParameterError, ShapeError
from .hysteresis import Propagation

if TYPE_CHECKING:
    from . import _diffkernels as D
else:  # numba loads when a model first runs (see _lazy)
    D = LazyModule("piezohyst._diffkernels", globals(), "D")

__all__ = [
    "BoucWenHysteresis",
    "DifferentialCore",
    "DuhemHysteresis",
    "PreisachHysteresis",
    "Region",
    "everett_map",
    "everett_nodes",
]

PERIODIC_PASSES = 200  # at most this many passes of a record for its periodic state


def _frozen(values: ArrayLike, name: str, *, allow_empty: bool = False) -> FloatArray:
    arr = as_signal(values, name, allow_empty=allow_empty).copy()
    arr.flags.writeable = False
    return arr


def _finite(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        msg = f"'{name}' must be a number. Got {value!r}."
        raise ParameterError(msg)
    v = float(value)
    if not math.isfinite(v):
        msg = f"'{name}' must be finite. Got {value!r}."
        raise ParameterError(msg)
    return v


@dataclass(frozen=True, eq=False)
class Region:
    """The (input, output) band a model's training data covered.

    The input range ``[v_lo, v_hi]`` is cut into ``len(q_lo)`` equal bins; in
    each, the output of the pure hysteresis stayed within ``[q_lo, q_hi]``
    (bins the data never entered take their nearest neighbour's band).

    Parameters
    ----------
    v_lo, v_hi : float
        Input range (V).
    q_lo, q_hi : array_like, shape (M,)
        Output band per bin (output units).
    """

    v_lo: float
    v_hi: float
    q_lo: FloatArray
    q_hi: FloatArray

    def __post_init__(self) -> None:
        lo, hi = _finite(self.v_lo, "v_lo"), _finite(self.v_hi, "v_hi")
        if not lo < hi:
            msg = f"a region needs v_lo < v_hi. Got {lo!r}, {hi!r}."
            raise ParameterError(msg)
        a, b = _frozen(self.q_lo, "q_lo"), _frozen(self.q_hi, "q_hi")
        if a.size != b.size or np.any(a > b):
            msg = "a region's q_lo and q_hi must have one value per bin, q_lo <= q_hi"
            raise ShapeError(msg)
        object.__setattr__(self, "v_lo", lo)
        object.__setattr__(self, "v_hi", hi)
        object.__setattr__(self, "q_lo", a)
        object.__setattr__(self, "q_hi", b)

    @classmethod
    def of(cls, v: FloatArray, q: FloatArray, bins: int = 40) -> Region:
        """The band of samples ``(v, q)``.

        Parameters
        ----------
        v, q : ndarray, shape (N,)
            Input and pure-hysteresis output of the training record.
        bins : int, default 40

        Returns
        -------
        Region
        """
        lo, hi = float(v.min()), float(v.max())
        if not hi > lo:
            hi = lo + 1.0
        b = np.clip(((v - lo) / (hi - lo) * bins).astype(np.int64), 0, bins - 1)
        q_lo = np.full(bins, np.inf)
        q_hi = np.full(bins, -np.inf)
        np.minimum.at(q_lo, b, q)
        np.maximum.at(q_hi, b, q)
        seen = np.flatnonzero(np.isfinite(q_lo))
        if seen.size < bins:  # empty bins: the nearest visited bin's band
            near = seen[np.abs(np.arange(bins)[:, None] - seen[None, :]).argmin(axis=1)]
            q_lo, q_hi = q_lo[near], q_hi[near]
        return cls(lo, hi, q_lo, q_hi)

    @property
    def span(self) -> float:
        """The output span the region covers."""
        return float(self.q_hi.max() - self.q_lo.min())

    @property
    def array(self) -> FloatArray:
        """``[q_lo; q_hi]``, shape (2, M), as the compensator kernel reads it."""
        return np.ascontiguousarray(np.vstack([self.q_lo, self.q_hi]))

    def distance(self, v: ArrayLike, y: ArrayLike) -> FloatArray:
        """How far each output lies outside the band at its input (0 inside), output units.

        Inputs beyond ``[v_lo, v_hi]`` count by the voltage they exceed it by,
        times the band's mean slope.

        Parameters
        ----------
        v, y : array_like, shape (N,)

        Returns
        -------
        ndarray, shape (N,)
        """
        va = np.asarray(v, dtype=np.float64)
        ya = np.asarray(y, dtype=np.float64)
        m = self.q_lo.size
        b = np.clip(((va - self.v_lo) / (self.v_hi - self.v_lo) * m).astype(np.int64), 0, m - 1)
        d = np.maximum(np.maximum(self.q_lo[b] - ya, ya - self.q_hi[b]), 0.0)
        slope = self.span / (self.v_hi - self.v_lo)
        beyond = np.maximum(np.maximum(self.v_lo - va, va - self.v_hi), 0.0)
        return np.asarray(np.maximum(d, beyond * slope))

    def middle(self, v: float) -> float:
        """The middle of the band at input ``v`` (the output an actuator at rest there has).

        Parameters
        ----------
        v : float

        Returns
        -------
        float
        """
        m = self.q_lo.size
        centres = self.v_lo + (np.arange(m) + 0.5) * (self.v_hi - self.v_lo) / m
        mid = 0.5 * (self.q_lo + self.q_hi)
        return float(np.interp(v, centres, mid))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data.

        Returns
        -------
        dict
        """
        return {
            "v_lo": self.v_lo,
            "v_hi": self.v_hi,
            "q_lo": self.q_lo.tolist(),
            "q_hi": self.q_hi.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Region:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict

        Returns
        -------
        Region
        """
        return cls(data["v_lo"], data["v_hi"], data["q_lo"], data["q_hi"])


class DifferentialCore:
    """What the Duhem and Bouc-Wen cores share: a packed parameter array and a [v, x] state.

    Subclasses set ``kind`` and build ``packed`` (the kernels' layout).
    """

    kind: ClassVar[str] = ""
    packed: FloatArray
    initial_state: FloatArray
    region: Region | None

    @property
    def n_states(self) -> int:
        """Values in the state: the last input, the internal variable (and, for a Duhem
        core on reversal memory, the direction and the stack of reversal points)."""
        return int(D.state_size(self.packed))

    @property
    def is_invertible(self) -> bool:
        """True: the identification keeps every branch strictly increasing."""
        return True

    @property
    def summary(self) -> str:
        """A few words on the core, for one-line descriptions."""
        raise NotImplementedError

    def _state(self, state: ArrayLike | None) -> FloatArray:
        if state is None:
            return np.array(self.initial_state, dtype=np.float64)
        z = as_signal(state, "state").copy()
        if z.size != self.n_states:
            msg = (
                f"'state' of this {type(self).__name__} must hold {self.n_states} values "
                f"([input, {self.inner}, ...]). Got {z.size}."
            )
            raise ShapeError(msg)
        return z

    inner: ClassVar[str] = "x"

    def propagate(self, x: ArrayLike, state: ArrayLike | None = None) -> Propagation[FloatArray]:
        """Run the core over ``x`` from ``state`` (default :attr:`initial_state`).

        Parameters
        ----------
        x : array_like, shape (N,)
            Input (V).
        state : array_like, shape (2,), optional
            ``[last input, internal variable]``.

        Returns
        -------
        Propagation
            ``output`` (N,) and the final state; chunks equal one call.
        """
        xs = as_signal(x, "x", allow_empty=True)
        z = self._state(state)
        y = np.empty_like(xs)
        D.core_propagate(self.packed, xs, z, y)
        return Propagation(y, z)

    def predict(self, x: ArrayLike, state: ArrayLike | None = None) -> FloatArray:
        """See :meth:`propagate`: the output alone.

        Parameters
        ----------
        x : array_like
        state : array_like, optional

        Returns
        -------
        ndarray
        """
        return self.propagate(x, state).output

    def output(self, state: ArrayLike) -> float:
        """The output at a state (no input applied).

        Parameters
        ----------
        state : array_like, shape (2,)

        Returns
        -------
        float
        """
        z = self._state(state)
        return float(D.core_output(self.packed, z))

    def rest_state(self, x0: float) -> FloatArray:
        """The state of an actuator resting at input ``x0`` with no memory of its history.

        Parameters
        ----------
        x0 : float

        Returns
        -------
        ndarray, shape (2,)
        """
        raise NotImplementedError

    def history_state(self, history: ArrayLike) -> FloatArray:
        """The state after the input ``history``, starting at rest at its first sample.

        Parameters
        ----------
        history : array_like

        Returns
        -------
        ndarray, shape (2,)
        """
        h = as_signal(history, "history")
        return self.propagate(h, self.rest_state(float(h[0]))).state

    def periodic_state(self, x: ArrayLike) -> FloatArray:
        """The state before ``x`` when ``x`` is one period of a drive that has been running.

        The record is run again and again from rest at its first sample until
        the state after it repeats (to 1e-12 of the output span). Bouc-Wen and
        Preisach always settle (Preisach in two passes: its loops close);
        a Duhem model's loop can drift on an input unlike its training.

        Parameters
        ----------
        x : array_like

        Returns
        -------
        ndarray

        Raises
        ------
        NumericRangeError
            If the state has not settled after ``PERIODIC_PASSES`` passes and
            the output still moves by more than 1e-6 of its span per pass.
        """
        xs = as_signal(x, "x")
        z = self.rest_state(float(xs[0]))
        y = np.empty_like(xs)
        span = 0.0
        moved = 0.0
        for _ in range(PERIODIC_PASSES):
            before = z.copy()
            D.core_propagate(self.packed, xs, z, y)
            span = max(span, float(np.ptp(y)), 1e-300)
            moved = abs(self.output(z) - self.output(before))  # in output units, like span
            if z[0] == before[0] and np.array_equal(z[2:], before[2:]) and moved <= 1e-12 * span:
                return z
        if not moved <= 1e-6 * span:  # (NaN too)
            msg = (
                f"no periodic steady state: on this input the {type(self).__name__}'s loop "
                f"still moves by {moved / span:.2g} of its span per period after "
                f"{PERIODIC_PASSES} periods; start from 'rest' or a History instead"
            )
            raise NumericRangeError(msg)
        return z

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """Labelled parameters with units, for reports.

        Parameters
        ----------
        input_unit, output_unit : str

        Returns
        -------
        list of (str, str)
        """
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (its ``from_dict`` reads it back).

        Returns
        -------
        dict
        """
        raise NotImplementedError


def _region_dict(region: Region | None) -> dict[str, Any] | None:
    return None if region is None else region.to_dict()


def _region_from(data: Any) -> Region | None:
    return None if data is None else Region.from_dict(dict(data))


@dataclass(frozen=True, eq=False)
class DuhemHysteresis(DifferentialCore):
    r"""Rate-independent Duhem hysteresis: :math:`dq/dv = f_\pm(v, q)` on a grid.

    ``f+`` while the input rises, ``f-`` while it falls, each bilinear between
    the nodes of a (voltage, output) grid and constant beyond its edges.
    Explicit Euler, ``q[k+1] = q[k] + f±(v[k], q[k]) (v[k+1] - v[k])``, in steps
    of at most ``dv_max`` (then the rest): a sampled trajectory's step is one
    Euler step, inverted explicitly.

    Parameters
    ----------
    v_nodes : array_like, shape (nv,)
        Equally spaced voltages (V), at least 2.
    q_nodes : array_like, shape (nq,)
        Equally spaced outputs (output units), at least 2.
    up, down : array_like, shape (nv, nq)
        Slopes (output per V) at the nodes, all > 0.
    initial_state : array_like, shape (2,)
        ``[v, q]`` before the first sample.
    region : Region, optional
        Where the training data lay.
    dv_max : float, optional
        Largest Euler step (V); default a quarter of the voltage grid's spacing.
    """

    v_nodes: FloatArray
    q_nodes: FloatArray
    up: FloatArray
    down: FloatArray
    initial_state: FloatArray
    region: Region | None = None
    dv_max: float | None = None
    packed: FloatArray = field(init=False, repr=False)
    kind: ClassVar[str] = "duhem"
    inner: ClassVar[str] = "output"

    def __post_init__(self) -> None:
        vn = _nodes(self.v_nodes, "v_nodes")
        qn = _nodes(self.q_nodes, "q_nodes")
        shape = (vn.size, qn.size)
        up = _slopes(self.up, "up", shape)
        down = _slopes(self.down, "down", shape)
        z0 = _frozen(self.initial_state, "initial_state")
        if z0.size != 2:
            msg = f"'initial_state' must be [v, q]. Got {z0.size} values."
            raise ShapeError(msg)
        v_step = (vn[-1] - vn[0]) / (vn.size - 1)
        dv = _finite(0.25 * v_step if self.dv_max is None else self.dv_max, "dv_max")
        if not dv > 0:
            msg = f"'dv_max' must be > 0. Got {dv!r}."
            raise ParameterError(msg)
        for name, value in (("v_nodes", vn), ("q_nodes", qn), ("up", up), ("down", down),
                            ("initial_state", z0), ("dv_max", dv)):  # fmt: skip
            object.__setattr__(self, name, value)
        f_min = min(float(up.min()), float(down.min()))
        head = [D.KIND_DUHEM, vn.size, qn.size, vn[0], v_step, qn[0],
                (qn[-1] - qn[0]) / (qn.size - 1), dv, f_min]  # fmt: skip
        packed = np.concatenate([head, up.ravel(), down.ravel()])
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

    @classmethod
    def from_packed(
        cls, packed: FloatArray, initial_state: ArrayLike, region: Region | None = None
    ) -> DuhemHysteresis:
        """A core from the kernels' parameter layout (the identification's solution).

        Parameters
        ----------
        packed : ndarray
        initial_state : array_like, shape (2,)
        region : Region, optional

        Returns
        -------
        DuhemHysteresis
        """
        nv, nq = int(packed[D.DU_NV]), int(packed[D.DU_NQ])
        vn = packed[D.DU_V_LO] + packed[D.DU_V_STEP] * np.arange(nv)
        qn = packed[D.DU_Q_LO] + packed[D.DU_Q_STEP] * np.arange(nq)
        cells = nv * nq
        up = packed[D.DU_UP : D.DU_UP + cells].reshape(nv, nq)
        down = packed[D.DU_UP + cells : D.DU_UP + 2 * cells].reshape(nv, nq)
        z0 = np.asarray(initial_state, dtype=np.float64)
        return cls(vn, qn, up, down, z0, region, float(packed[D.DU_DV_MAX]))

    @property
    def summary(self) -> str:
        """See :attr:`DifferentialCore.summary`."""
        return f"Duhem, {self.v_nodes.size} × {self.q_nodes.size} grid"

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`DifferentialCore.rest_state`: the middle of the recorded band at ``x0``.

        Without a region: the initial state's output, moved to ``x0``.
        """
        q = self.region.middle(x0) if self.region is not None else float(self.initial_state[1])
        return np.array([float(x0), q])

    def slopes(self, v: ArrayLike, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``f+`` and ``f-`` at points (v, q).

        Parameters
        ----------
        v, q : array_like, shape (N,)

        Returns
        -------
        (ndarray, ndarray)
        """
        va = np.asarray(v, dtype=np.float64).reshape(-1)
        qa = np.asarray(q, dtype=np.float64).reshape(-1)
        pairs = list(zip(va, qa, strict=True))
        up = np.array([D.duhem_slope(self.packed, a, b, True)[0] for a, b in pairs])
        down = np.array([D.duhem_slope(self.packed, a, b, False)[0] for a, b in pairs])
        return up, down

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """See :meth:`DifferentialCore.describe`."""
        slope = f"{output_unit}/{input_unit}"
        return [
            ("core", "Duhem, dq/dv = f±(v, q), bilinear"),
            ("grid", f"{self.v_nodes.size} × {self.q_nodes.size} nodes over "
                     f"[{self.v_nodes[0]:.6g}, {self.v_nodes[-1]:.6g}] {input_unit} × "
                     f"[{self.q_nodes[0]:.6g}, {self.q_nodes[-1]:.6g}] {output_unit}"),
            ("rising slopes f+", f"{self.up.min():.4g} to {self.up.max():.4g} {slope}"),
            ("falling slopes f-", f"{self.down.min():.4g} to {self.down.max():.4g} {slope}"),
        ]  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """See :meth:`DifferentialCore.to_dict`."""
        return {
            "v_nodes": self.v_nodes.tolist(),
            "q_nodes": self.q_nodes.tolist(),
            "up": self.up.tolist(),
            "down": self.down.tolist(),
            "initial_state": self.initial_state.tolist(),
            "dv_max": self.dv_max,
            "region": _region_dict(self.region),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DuhemHysteresis:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict

        Returns
        -------
        DuhemHysteresis
        """
        return cls(
            data["v_nodes"],
            data["q_nodes"],
            data["up"],
            data["down"],
            data["initial_state"],
            _region_from(data.get("region")),
            data.get("dv_max"),
        )


#: Reversal points of a Preisach core's rest state (a demagnetising staircase), of
#: the stack's ``_diffkernels.STACK``; the rest holds the reversals of the drive
DEMAG_POINTS = 20
#: Ratio of successive amplitudes of that staircase (the last is 1e-3 of the first)
DEMAG_RATIO = 0.7


@dataclass(frozen=True, eq=False)
class PreisachHysteresis(DifferentialCore):
    r"""The Preisach model, by its Everett function on a grid of reversal points.

    Rising from a minimum :math:`a`: :math:`q(v) = q(a) + E(a, v)`; falling
    from a maximum :math:`b`: :math:`q(v) = q(b) - E(v, b)`. The reversal
    points form a stack with the wiping-out rule (passing the previous
    extremum of the same direction closes the inner loop and resumes the
    outer branch), so every minor loop closes and returns to its starting
    point (return-point memory), and minor loops have the shape their place
    in the major loop gives them — not PI's congruent copies. :math:`E` is
    bilinear between the nodes, built from a Preisach density
    :math:`\mu \ge 0` on the grid's cells,
    :math:`E(a_i, b_j) = \sum_{i \le k \le l < j} \mu_{kl}`, so every branch
    is increasing; beyond the grid it continues with the smallest slope.

    Parameters
    ----------
    nodes : array_like, shape (n,)
        Equally spaced voltages (V), at least 2.
    density : array_like, shape (n - 1, n - 1)
        :math:`\mu_{kl}` (output units) for cells ``k <= l``; ``>= 0``, the
        diagonal ``> 0``; the lower half is ignored.
    initial_state : array_like
        ``[v, q, direction, k, R[0..STACK-1]]`` (see ``_diffkernels``).
    region : Region, optional
    virgin : bool, default False
        What "at rest" means (:meth:`rest_state`): True, a demagnetised state,
        from which the first move follows the initial loading curve (as play
        operators from zero state); False, no reversal yet, the first move
        follows a branch from the rest point (as from an extremum).
    """

    nodes: FloatArray
    density: FloatArray
    initial_state: FloatArray
    region: Region | None = None
    virgin: bool = False
    packed: FloatArray = field(init=False, repr=False)
    kind: ClassVar[str] = "preisach"
    inner: ClassVar[str] = "output"

    def __post_init__(self) -> None:
        nodes = _nodes(self.nodes, "nodes")
        n = nodes.size
        mu = np.triu(np.array(self.density, dtype=np.float64))
        if mu.shape != (n - 1, n - 1):
            msg = f"'density' must have shape {(n - 1, n - 1)} (cells). Got {mu.shape}."
            raise ShapeError(msg)
        if not np.all(np.isfinite(mu)) or np.any(mu < 0) or np.any(np.diag(mu) <= 0):
            msg = "the Preisach density must be finite and >= 0, its diagonal > 0"
            raise ParameterError(msg)
        mu.flags.writeable = False
        z0 = _frozen(self.initial_state, "initial_state")
        if z0.size != D.RV_SIZE:
            msg = f"'initial_state' of a Preisach core holds {D.RV_SIZE} values. Got {z0.size}."
            raise ShapeError(msg)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "density", mu)
        object.__setattr__(self, "initial_state", z0)
        h = (nodes[-1] - nodes[0]) / (n - 1)
        s_min = float(np.diag(mu).min()) / h
        head = [D.KIND_PREISACH, n, n, nodes[0], h, 0.0, 0.0, 0.0, s_min]
        packed = np.concatenate([head, everett_nodes(mu).ravel()])
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

    @property
    def summary(self) -> str:
        """See :attr:`DifferentialCore.summary`."""
        n = self.nodes.size
        if self.region is None:
            return f"Preisach, {n} nodes"
        tol = 1e-9 * float(self.nodes[1] - self.nodes[0])
        lo, hi = self.region.v_lo - tol, self.region.v_hi + tol
        inside = int(np.count_nonzero((self.nodes >= lo) & (self.nodes <= hi)))
        if not self.virgin:
            return f"Preisach, {inside} nodes"
        beyond = f" (+{n - inside} nodes beyond the range)" if n > inside else ""
        return f"Preisach, {inside} nodes, initial loading curve from rest{beyond}"

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`DifferentialCore.rest_state`: at ``x0``, mid-band.

        Without :attr:`virgin`, no reversal yet: the first move follows a
        branch from ``x0``. With it, the actuator has forgotten its extremes:
        the state an AC drive decaying to ``x0`` leaves, a staircase of
        :data:`DEMAG_POINTS` reversal points shrinking towards ``x0`` by
        :data:`DEMAG_RATIO`, as wide as the grid allows on both sides; the
        first rise (or fall) then follows the initial loading curve, as a play
        operator from zero state does (a fit from rest extends the grid to the
        rest point's mirror image to learn it). At the grid's edge (no room
        below or above) the first move follows a branch from ``x0`` either way.
        """
        q = self.region.middle(x0) if self.region is not None else float(self.initial_state[1])
        z = np.zeros(D.RV_SIZE)
        x0 = float(x0)
        z[0], z[1], z[D.RV_K], z[D.RV_R] = x0, q, 1.0, x0
        amp = min(x0 - float(self.nodes[0]), float(self.nodes[-1]) - x0)
        if self.virgin and amp > 0:
            points = x0 - amp * (-DEMAG_RATIO) ** np.arange(DEMAG_POINTS)
            z[D.RV_R : D.RV_R + DEMAG_POINTS] = points
            z[D.RV_K] = DEMAG_POINTS
            z[D.RV_DIR] = -1.0 if points[-1] > x0 else 1.0
        return z

    def everett(self, a: ArrayLike, b: ArrayLike) -> FloatArray:
        """The Everett function :math:`E(a, b)` (output units).

        Parameters
        ----------
        a, b : array_like
            Lower and upper reversal points (V).

        Returns
        -------
        ndarray
        """
        aa, bb = np.broadcast_arrays(
            np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        )
        out = np.array(
            [D.everett(self.packed, x, y)[0] for x, y in zip(aa.ravel(), bb.ravel(), strict=True)]
        )
        return out.reshape(aa.shape)

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """See :meth:`DifferentialCore.describe`."""
        mu = self.density
        return [
            ("core", "Preisach, Everett function on a grid, wiping-out memory"),
            ("grid", f"{self.nodes.size} nodes over [{self.nodes[0]:.6g}, "
                     f"{self.nodes[-1]:.6g}] {input_unit}"),
            ("density", f"{mu.sum():.4g} {output_unit} in all, "
                        f"{np.trace(mu) / mu.sum():.1%} on the diagonal (reversible)"),
            ("smallest slope", f"{self.packed[D.DU_F_MIN]:.4g} {output_unit}/{input_unit}"),
        ]  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """See :meth:`DifferentialCore.to_dict`."""
        return {
            "nodes": self.nodes.tolist(),
            "density": self.density.tolist(),
            "initial_state": self.initial_state.tolist(),
            "region": _region_dict(self.region),
            "rest": "virgin" if self.virgin else "branch",
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PreisachHysteresis:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict

        Returns
        -------
        PreisachHysteresis
        """
        rest = data.get("rest", "branch")  # files before the virgin rest state: a branch
        if rest not in ("virgin", "branch"):
            msg = f"the Preisach core's 'rest' must be 'virgin' or 'branch'. Got {rest!r}."
            raise ParameterError(msg)
        return cls(
            data["nodes"],
            data["density"],
            data["initial_state"],
            _region_from(data.get("region")),
            virgin=rest == "virgin",
        )


def everett_nodes(density: FloatArray) -> FloatArray:
    """Everett values at the nodes from a density on the cells: E[i, j] = sum of mu[k, l]
    over i <= k <= l < j (0 on and below the diagonal).

    Parameters
    ----------
    density : ndarray, shape (n - 1, n - 1)

    Returns
    -------
    ndarray, shape (n, n)
    """
    mu = np.triu(density)
    m = mu.shape[0]
    e = np.zeros((m + 1, m + 1))
    # E[i, j] = sum over k >= i, l < j of mu[k, l] (mu is upper triangular)
    tail = np.cumsum(mu[::-1], axis=0)[::-1]  # rows k >= i
    e[:m, 1:] = np.cumsum(tail, axis=1)
    return np.triu(e, 1)


def everett_map(n: int) -> FloatArray:
    """The matrix T with E.ravel() = T @ mu.ravel() (n nodes, (n-1)^2 cells).

    Parameters
    ----------
    n : int

    Returns
    -------
    ndarray, shape (n * n, (n - 1) ** 2)
        Read-only (one copy per grid size is kept).
    """
    return _everett_map(int(n))


@functools.lru_cache(maxsize=8)
def _everett_map(n: int) -> FloatArray:
    m = n - 1
    t = np.zeros((n * n, m * m))
    for k in range(m):
        for c in range(k, m):
            unit = np.zeros((m, m))
            unit[k, c] = 1.0
            t[:, k * m + c] = everett_nodes(unit).ravel()
    t.flags.writeable = False
    return t


def _nodes(values: ArrayLike, name: str) -> FloatArray:
    nodes = _frozen(values, name)
    steps = np.diff(nodes)
    if nodes.size < 2 or np.any(steps <= 0) or np.ptp(steps) > 1e-9 * abs(steps[0]):
        msg = f"'{name}' must hold at least 2 equally spaced, increasing values."
        raise ParameterError(msg)
    return nodes


def _slopes(values: ArrayLike, name: str, shape: tuple[int, int]) -> FloatArray:
    c = np.array(values, dtype=np.float64)
    if c.shape != shape:
        msg = f"'{name}' must have shape {shape} (voltage, output nodes). Got {c.shape}."
        raise ShapeError(msg)
    if not np.all(np.isfinite(c)) or np.any(c <= 0):
        msg = f"every '{name}' slope must be finite and > 0 (strictly increasing branches)."
        raise ParameterError(msg)
    c.flags.writeable = False
    return c


@dataclass(frozen=True, eq=False)
class BoucWenHysteresis(DifferentialCore):
    r"""The Bouc-Wen model: :math:`y = c_0 v + \alpha h + c`.

    .. math::

        \frac{dh}{dv} = 1 - |h|^n \bigl(\beta\,\mathrm{sign}(h\,\dot v) + \gamma\bigr)

    (the usual form with :math:`A = 1`, so :math:`h` is in volts), integrated
    in the voltage by classical Runge-Kutta with sub-steps of at most
    ``dv_max`` V: rate independent. :math:`h` saturates at
    :math:`(\beta + \gamma)^{-1/n}` on a long rise.

    Parameters
    ----------
    c0 : float
        Linear slope (output per V), > 0.
    alpha : float
        Weight of the hysteretic variable (output per V), of either sign (the
        sign sets the loop's orientation) with ``c0 + alpha g_max > 0``,
        :math:`g_{max} = 2\beta / (\beta + \gamma)` the largest ``dh/dv``.
    beta, gamma : float
        Shape: ``beta > 0``, ``|gamma| <= beta`` (stable loops, increasing branches).
    n : float
        Smoothness of the transition, in [1, 6].
    offset : float
        Output at v = 0, h = 0.
    initial_state : array_like, shape (2,)
        ``[v, h]`` before the first sample.
    dv_max : float, optional
        Largest integration sub-step (V); default a tenth of the saturation value of h.
    region : Region, optional
    """

    c0: float
    alpha: float
    beta: float
    gamma: float
    n: float
    offset: float
    initial_state: FloatArray
    dv_max: float | None = None
    region: Region | None = None
    packed: FloatArray = field(init=False, repr=False)
    kind: ClassVar[str] = "bouc_wen"
    inner: ClassVar[str] = "h"

    def __post_init__(self) -> None:
        names = ("c0", "alpha", "beta", "gamma", "n", "offset")
        vals = {k: _finite(getattr(self, k), k) for k in names}
        if not vals["beta"] > 0 or abs(vals["gamma"]) > vals["beta"] * (1 + 1e-12):
            msg = "Bouc-Wen needs beta > 0 and |gamma| <= beta (bounded, stable loops)."
            raise ParameterError(msg)
        g_max = (
            2.0 * vals["beta"] / (vals["beta"] + vals["gamma"])
            if vals["beta"] + vals["gamma"] > 0
            else 2.0
        )
        s_min = vals["c0"] + min(vals["alpha"], 0.0) * g_max
        if not vals["c0"] > 0 or not s_min > 0:
            msg = (
                "Bouc-Wen needs c0 > 0 and c0 + alpha * g_max > 0 (strictly increasing "
                f"branches; g_max = {g_max:.6g})."
            )
            raise ParameterError(msg)
        if not 1.0 <= vals["n"] <= 6.0:
            msg = f"Bouc-Wen's exponent n must lie in [1, 6]. Got {vals['n']!r}."
            raise ParameterError(msg)
        for k, v in vals.items():
            object.__setattr__(self, k, v)
        z0 = _frozen(self.initial_state, "initial_state")
        if z0.size != 2:
            msg = f"'initial_state' must be [v, h]. Got {z0.size} values."
            raise ShapeError(msg)
        object.__setattr__(self, "initial_state", z0)
        dv = self.dv_max
        if dv is None:
            dv = 0.1 * self.h_max if math.isfinite(self.h_max) else 1.0
        dv = _finite(dv, "dv_max")
        if not dv > 0:
            msg = f"'dv_max' must be > 0. Got {dv!r}."
            raise ParameterError(msg)
        object.__setattr__(self, "dv_max", dv)
        packed = np.array([D.KIND_BOUC_WEN, vals["c0"], vals["alpha"], vals["beta"],
                           vals["gamma"], vals["n"], vals["offset"], dv, g_max, s_min])  # fmt: skip
        packed.flags.writeable = False
        object.__setattr__(self, "packed", packed)

    @property
    def h_max(self) -> float:
        """The value h saturates at on a long rise, :math:`(\\beta + \\gamma)^{-1/n}` (V)."""
        s = self.beta + self.gamma
        return float(s ** (-1.0 / self.n)) if s > 0 else math.inf

    @property
    def summary(self) -> str:
        """See :attr:`DifferentialCore.summary`."""
        return f"Bouc-Wen, n = {self.n:.3g}"

    def rest_state(self, x0: float) -> FloatArray:
        """See :meth:`DifferentialCore.rest_state`: h = 0 at ``x0``."""
        return np.array([float(x0), 0.0])

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """See :meth:`DifferentialCore.describe`."""
        slope = f"{output_unit}/{input_unit}"
        return [
            ("core", "Bouc-Wen, y = c0 v + alpha h + offset"),
            ("c0", f"{self.c0:.6g} {slope}"),
            ("alpha", f"{self.alpha:.6g} {slope}"),
            ("beta, gamma", f"{self.beta:.6g}, {self.gamma:.6g} {input_unit}^-{self.n:.4g}"),
            ("n", f"{self.n:.4g}"),
            ("h saturates at", f"{self.h_max:.6g} {input_unit}"),
            ("offset", f"{self.offset:.6g} {output_unit}"),
        ]

    def to_dict(self) -> dict[str, Any]:
        """See :meth:`DifferentialCore.to_dict`."""
        return {
            "c0": self.c0,
            "alpha": self.alpha,
            "beta": self.beta,
            "gamma": self.gamma,
            "n": self.n,
            "offset": self.offset,
            "dv_max": self.dv_max,
            "initial_state": self.initial_state.tolist(),
            "region": _region_dict(self.region),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BoucWenHysteresis:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict

        Returns
        -------
        BoucWenHysteresis
        """
        return cls(
            data["c0"],
            data["alpha"],
            data["beta"],
            data["gamma"],
            data["n"],
            data["offset"],
            data["initial_state"],
            data.get("dv_max"),
            _region_from(data.get("region")),
        )


CORES: dict[str, type[DifferentialCore]] = {
    DuhemHysteresis.kind: DuhemHysteresis,
    PreisachHysteresis.kind: PreisachHysteresis,
    BoucWenHysteresis.kind: BoucWenHysteresis,
}
