r"""The core contract: what every hysteresis core is and does.

A *core* is the hysteresis part of a model: play operators (PI), a Preisach
density, Duhem slopes, a Bouc-Wen equation. A fitted core is one immutable
object that follows :class:`Core`:

* its **registry name** (``kind``), which model files and the C export use;
* its **state**: at rest (:meth:`Core.rest_state`), after a history
  (:meth:`Core.history_state`), periodic (:meth:`Core.periodic_state`);
* **propagation** (:meth:`Core.propagate`), chunks equal to one call;
* its **identification step** (:meth:`Core.identify`): a :class:`FitJob` in
  (the record, the terms beside the core, the model's settings), a
  :class:`CoreFit` out (the core and every term's coefficients);
* its **inverse plan** (:meth:`Core.inverse_plan`): how the one
  :class:`~piezohyst.Compensator` inverts it sample by sample;
* its **C source** (:attr:`Core.c_source`): a file shipped beside the module;
* its **file form** (:meth:`Core.to_dict` / :meth:`Core.from_dict`).

Subclassing :class:`Core` with a ``kind`` registers the class, so a core
defined outside the library loads from files like the built-in ones. The
built-in cores live one per module, :mod:`~piezohyst.model.cores.play`,
:mod:`~piezohyst.model.cores.preisach`, :mod:`~piezohyst.model.cores.duhem` and
:mod:`~piezohyst.model.cores.boucwen`, imported when first named.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Generic, NamedTuple, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ..._kernels import packed as P
from ..._validation import FloatArray, as_signal, frozen
from ...errors import NotInvertibleError, NumericRangeError, ParameterError, ShapeError
from ...io.blocks import Blocks, Summary

__all__ = [
    "CORES",
    "Core",
    "CoreFit",
    "FitJob",
    "InversePlan",
    "PackedCore",
    "Propagation",
    "Region",
    "core_class",
]

S = TypeVar("S")

#: At most this many passes of a record for its periodic state, for every core: play
#: operators repeat within two passes once the period reaches its extremes (the loop stops
#: there); creep and relaxation lags settle by their time constants, which may take more
PERIODIC_PASSES = 200

#: Every registered core class by its ``kind`` (a file's ``core.kind``)
CORES: dict[str, type[Core]] = {}
#: The built-in cores' modules, imported when a file or a name first asks for them
BUILTIN = {"play": "play", "duhem": "duhem", "preisach": "preisach", "bouc-wen": "boucwen"}


def core_class(kind: str) -> type[Core] | None:
    """The core class registered under ``kind`` (a built-in one is imported first), or None.

    Parameters
    ----------
    kind : str

    Returns
    -------
    type or None
    """
    if kind not in CORES and kind in BUILTIN:
        importlib.import_module(f"{__package__}.{BUILTIN[kind]}")
    return CORES.get(kind)


class Propagation(NamedTuple, Generic[S]):
    """Result of running a stateful operator or model over a block of samples.

    Attributes
    ----------
    output : ndarray
        One output sample per input sample.
    state : ndarray or ModelState
        The state after the last sample (operator states for
        :class:`PIHysteresis`, a :class:`~piezohyst.model.presets.ModelState` for a
        model); pass it back to continue.
    """

    output: FloatArray
    state: S


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
            ``v_lo``, ``v_hi`` (the voltage grid's edges) and ``q_lo``, ``q_hi`` (the output
            band over it), as :meth:`to_dict` wrote them.

        Returns
        -------
        Region
        """
        return cls(data["v_lo"], data["v_hi"], data["q_lo"], data["q_hi"])


@dataclass
class FitJob:
    """What the model hands a core's identification step.

    Attributes
    ----------
    blocks : callable
        Returns the record's ``(x, y, t)`` blocks from its start, each call.
    summary : io.blocks.Summary
        The record's extremes, length and times.
    terms : list of Term
        Bound terms beside the core: kept ones (creep, asymmetry) first, then
        the growth terms.
    subsets : list of tuple of int, or None
        For a growth selection: the candidate subsets of ``terms``.
    initial_state : "rest", "periodic", History, array or None
        Where the record starts.
    params : dict
        The model's checked settings (``min_slope``, the core's own settings).
    owner, input_unit, output_unit : str
        For messages.
    output : OutputDynamics or None
        A mechanical mode the regressor columns pass through.
    """

    blocks: Blocks
    summary: Any
    terms: list[Any]
    subsets: list[tuple[int, ...]] | None
    initial_state: Any
    params: dict[str, Any]
    owner: str
    input_unit: str = "V"
    output_unit: str = "C"
    output: Any = None


@dataclass
class CoreFit:
    """What a core's identification step returns.

    Attributes
    ----------
    core : Core
        The fitted core.
    terms : tuple of Term
        The terms kept by the fit (a selection may drop growth terms).
    coefs : tuple of ndarray
        One coefficient array per kept term.
    selection : (dict, dict, list) or None
        A growth selection's held-out scores by subset label, its per-fold
        scores and the fold splits.
    """

    core: Core
    terms: tuple[Any, ...]
    coefs: tuple[FloatArray, ...]
    selection: tuple[dict[str, float], dict[str, list[float]], list[int]] | None = None


@dataclass(frozen=True)
class InversePlan:
    """How the compensator inverts a core, sample by sample.

    Attributes
    ----------
    engine : {"play", "packed", "python"}
        ``"play"``: eq. 18 and the play kernels (PI); ``"packed"``: the packed
        cores' compiled bracketed Newton (Preisach, Duhem, Bouc-Wen);
        ``"python"``: a bracketed Newton solve on :meth:`Core.propagate`, for
        any core (a core defined outside the library).
    min_slope : float
        The core's smallest slope (output per V): it brackets the root.
    """

    engine: str
    min_slope: float = 0.0


class Core:
    """The contract of a fitted hysteresis core (see the module documentation).

    Subclasses set ``kind`` (which registers them) and implement
    :meth:`propagate`, :meth:`rest_state`, :meth:`identify`,
    :meth:`to_dict` / :meth:`from_dict` and :meth:`describe`; the rest has
    defaults that follow from those.
    """

    #: registry name (in files and messages); set by every concrete core
    kind: ClassVar[str] = ""
    #: the C file of its compensator step in ``cores/c`` (None: no C export)
    c_source: ClassVar[str | None] = None
    #: the growth terms come from a play-operator proxy first (cores whose loops need not close)
    growth_from_proxy: ClassVar[bool] = False
    #: its identification passes its regressors through the fit's mechanical mode
    #: (``FitJob.output``); a core without it is fitted to the output with the mode taken out
    #: (:func:`~piezohyst.model.dynamics.OutputDynamics.unapply`)
    takes_mode: ClassVar[bool] = False
    #: Settings that make the repeated fits of the input-dynamics profile cheaper (see
    #: :func:`~piezohyst.model.fit_dynamics.profile_dynamics`); the final fit uses the model's own
    profile_settings: ClassVar[dict[str, Any]] = {}
    #: fields of its file form a reader checks by name first: "number" or "numbers" (a list)
    file_fields: ClassVar[dict[str, str]] = {}
    initial_state: FloatArray
    region: Region | None = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("kind"):
            CORES[cls.kind] = cls

    # ------------------------------------------------------------ running
    def propagate(self, x: ArrayLike, state: ArrayLike | None = None) -> Propagation[FloatArray]:
        """Run the core over ``x`` from ``state`` (default :attr:`initial_state`).

        Parameters
        ----------
        x : array_like, shape (N,)
            Input (V).
        state : array_like, optional
            The core's state.

        Returns
        -------
        Propagation
            ``output`` (N,) and the final state; chunks equal one call.
        """
        raise NotImplementedError

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

    # -------------------------------------------------------------- state
    def rest_state(self, x0: float) -> FloatArray:
        """The state of an actuator resting at input ``x0`` with no memory of its history.

        Parameters
        ----------
        x0 : float
            The input it rests at (V).

        Returns
        -------
        ndarray
            The core's state vector (its layout is the core's).
        """
        raise NotImplementedError

    def history_state(self, history: ArrayLike) -> FloatArray:
        """The state after the input ``history``, starting at rest at its first sample.

        Parameters
        ----------
        history : array_like

        Returns
        -------
        ndarray
        """
        h = as_signal(history, "history")
        return np.asarray(self.propagate(h, self.rest_state(float(h[0]))).state)

    def periodic_state(self, x: ArrayLike) -> FloatArray:
        """The state before ``x`` when ``x`` is one period of a drive that has been running.

        The record is run again and again from rest at its first sample until
        the state after it repeats (to 1e-12 of the output span).

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
        span = 0.0
        moved = 0.0
        end = math.nan  # the output at the end of the previous pass
        for _ in range(PERIODIC_PASSES):
            before = z.copy()
            y, z = self.propagate(xs, z)
            span = max(span, float(np.ptp(y)), 1e-300)
            moved, end = abs(float(y[-1]) - end), float(y[-1])  # in output units, like span
            if self._repeats(z, before) and moved <= 1e-12 * span:
                return z
        if not moved <= 1e-6 * span:  # (NaN too)
            msg = (
                f"no periodic steady state: on this input the {type(self).__name__}'s loop "
                f"still moves by {moved / span:.2g} of its span per period after "
                f"{PERIODIC_PASSES} periods; start from 'rest' or a History instead"
            )
            raise NumericRangeError(msg)
        return z

    def _repeats(self, z: FloatArray, before: FloatArray) -> bool:
        """Whether a state after one more period is the same as before (up to its output)."""
        return bool(np.array_equal(z, before))

    def output(self, state: ArrayLike) -> float:
        """The output at a state (no input applied).

        Parameters
        ----------
        state : array_like

        Returns
        -------
        float
        """
        z = np.asarray(state, dtype=np.float64)
        return float(self.propagate(z[:1], z).output[0])

    # ----------------------------------------------------- the model's view
    def fitted_attributes(self) -> dict[str, Any]:
        """The model attributes (names ending in ``_``) that describe this core.

        Returns
        -------
        dict
        """
        return {"region_": self.region}

    def fast_plan(
        self, terms: tuple[Any, ...], coefs: tuple[FloatArray, ...]
    ) -> Callable[[FloatArray, Any], FloatArray | None] | None:
        """A one-call compiled prediction of the core with these terms, or None.

        Parameters
        ----------
        terms : tuple of Term
        coefs : tuple of ndarray

        Returns
        -------
        callable or None
            ``plan(x, t)``: the output from the initial state (None: take the
            general path for these arguments).
        """
        return None

    def inverse(self) -> Core:
        """The core's closed-form inverse (a core from output to input).

        Returns
        -------
        Core

        Raises
        ------
        NotInvertibleError
            If the core has none (the compensator inverts it per sample).
        """
        msg = (
            f"a {type(self).__name__} has no closed-form inverse; ph.Compensator inverts it "
            "exactly, one sample at a time"
        )
        raise NotInvertibleError(msg)

    def inverse_plan(self) -> InversePlan:
        """How the compensator inverts this core (default: Newton on :meth:`propagate`).

        Returns
        -------
        InversePlan
        """
        return InversePlan("python", self.min_slope)

    @property
    def min_slope(self) -> float:
        """The smallest slope of the output in the input (output per V), > 0."""
        raise NotImplementedError

    @classmethod
    def states_before_fit(
        cls, settings: dict[str, Any], window: Summary
    ) -> tuple[dict[str, Any], Core] | None:
        """For a fit on a window of a longer record: the settings the fit fixes from the
        window, and a core the input before the window can run through first, when its
        state does not depend on what the fit identifies (play operators: their thresholds
        alone). None (the default) when it does: the fit runs the history itself (a
        ``History`` start), and a file's history is read into memory for it.

        Parameters
        ----------
        settings : dict
            The model's settings.
        window : Summary
            The window's summary (its input range).

        Returns
        -------
        tuple of (dict, Core), or None
        """
        return None

    @classmethod
    def identify(cls, job: FitJob) -> CoreFit:
        """The core's identification step: the core and the terms' coefficients from a record.

        Parameters
        ----------
        job : FitJob

        Returns
        -------
        CoreFit
        """
        raise NotImplementedError

    # ------------------------------------------------------------ files
    @property
    def summary(self) -> str:
        """A few words on the core, for one-line descriptions."""
        return self.kind

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

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Core:
        """The core from :meth:`to_dict` data.

        Parameters
        ----------
        data : dict

        Returns
        -------
        Core
        """
        raise NotImplementedError


class PackedCore(Core):
    """A core whose parameters are one packed array run by the compiled kernels
    (``_kernels.packed``): Preisach, Duhem and Bouc-Wen; the first slot names its kernel.

    Subclasses build ``packed`` (the kernels' layout) and set ``kind``.
    """

    packed: FloatArray
    inner: ClassVar[str] = "x"
    c_source: ClassVar[str | None] = "packed.c"

    @property
    def n_states(self) -> int:
        """Values in the state: the last input, the internal variable (and, for a Preisach
        core, the direction and the stack of reversal points)."""
        return int(P.state_size(frozen(self.packed)))

    @property
    def is_invertible(self) -> bool:
        """True: the identification keeps every branch strictly increasing."""
        return True

    @property
    def min_slope(self) -> float:
        """The smallest slope of every step (output per V), which brackets the inverse."""
        return float(self.packed[P.DU_F_MIN])  # Bouc-Wen keeps its own slot

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

    def propagate(self, x: ArrayLike, state: ArrayLike | None = None) -> Propagation[FloatArray]:
        """See :meth:`~piezohyst.model.cores.base.Core.propagate`."""
        xs = as_signal(x, "x", allow_empty=True)
        z = self._state(state)
        y = np.empty_like(xs)
        P.core_propagate(frozen(self.packed), frozen(xs), z, y)
        return Propagation(y, z)

    def output(self, state: ArrayLike) -> float:
        """See :meth:`~piezohyst.model.cores.base.Core.output`."""
        z = self._state(state)
        return float(P.core_output(self.packed, z))

    def _repeats(self, z: FloatArray, before: FloatArray) -> bool:
        # the voltage and the memory repeat; the output is compared in output units
        return bool(z[0] == before[0] and np.array_equal(z[2:], before[2:]))

    def region_json(self) -> dict[str, Any] | None:
        """The region in a file (None: none recorded)."""
        return None if self.region is None else self.region.to_dict()

    @staticmethod
    def region_from(data: Any) -> Region | None:
        """The region a file records (None: none)."""
        return None if data is None else Region.from_dict(dict(data))

    def inverse_plan(self) -> InversePlan:
        """See :meth:`~piezohyst.model.cores.base.Core.inverse_plan`."""
        return InversePlan("packed", self.min_slope)
