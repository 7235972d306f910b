r"""A structure moved by several actuators, identified as one system: the coupled linear
dynamics in state space (an order chosen from the data), each actuator's hysteresis inside
the loop.

.. math::

    x_{k+1} = A x_k + B u_k + E\,p_k, \qquad y_k = C x_k + D u_k + c, \qquad
    p_k = \bigl[\Gamma_{r_j}(s_{q,k}) - s_{q,k}\bigr]_{q,j}, \quad s_k = T y_k

:math:`u` the actuators' voltages, :math:`y` the outputs read (any number of them),
:math:`s = T y` each actuator's stroke (the outputs mapped back by the inverse of the static
gain), :math:`\Gamma_r` a play operator of width :math:`r`. The play operators' lag behind
each stroke acts on the structure's modes through :math:`E`: a piezo stack's stiffness and
damping that depend on how far it moved, which shifts the modes with the drive level (what
the measured fine-steering mirror shows: ``docs/validation.md``). At low frequency it is a
Prandtl-Ishlinskii hysteresis in each actuator's loop; without operators the model is the
coupled linear dynamics alone.

Beside :class:`~piezohyst.CoupledModel`: that one is a hysteresis model per actuator and a
static coupling (each actuator's lag and mode its own), and the compensator and the
exports invert it. This one identifies the structure's own shared modes and the coupling
in one state space; :class:`~piezohyst.StructureCompensator` inverts it (the tracker with
preview).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Self

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import ModelFileError, NotFittedError, ParameterError, PiezohystError, ShapeError
from ..io import JsonFile
from . import structure_fit as sf
from .coupled import columns
from .estimator import SeveralChannels
from .persistence import checked, signed

__all__ = ["STRUCTURE_FORMAT", "StructureModel"]

STRUCTURE_FORMAT = "piezohyst-structure-model"
STRUCTURE_VERSION = 1
#: The orders ``order="auto"`` scores (those within ``max_order`` and the records' reach)
ORDERS = (2, 4, 6, 8, 12, 16, 20, 24, 32, 40, 48, 56, 64, 80, 96, 128)
#: A record from rest scores the orders on its last part
TAIL = 0.7
#: The smallest order within this factor of the best held-out score is chosen, and the
#: loop's operators kept only where they beat the linear dynamics by more ...
PARSIMONY = 1.02
#: ... or within this NRMSE (%) of it: a difference below any sensor's resolution
RESOLUTION = 1e-3


def _array(a: ArrayLike, name: str) -> FloatArray:
    return columns(a, name, 8)


def _listed(a: Any) -> list[Any]:
    """Several records (a list or tuple of arrays) or one."""
    return list(a) if isinstance(a, (list, tuple)) else [a]


def _rate(t: Any, sample_rate: float | None, lengths: list[int]) -> float:
    """The records' one sample rate, from ``sample_rate`` or their uniform time stamps."""
    if sample_rate is not None:
        if not (np.isfinite(sample_rate) and sample_rate > 0):
            msg = f"'sample_rate' must be a positive number (Hz). Got {sample_rate!r}."
            raise ParameterError(msg)
        return float(sample_rate)
    if t is None:
        msg = "give the records' time stamps 't' or their 'sample_rate' (Hz)"
        raise ParameterError(msg)
    ts = _listed(t)
    if len(ts) != len(lengths):
        msg = f"'t' holds {len(ts)} time vectors for {len(lengths)} records"
        raise ShapeError(msg)
    rates = []
    for k, (tk, n) in enumerate(zip(ts, lengths, strict=True)):
        tk = np.asarray(tk, dtype=np.float64)
        if tk.shape != (n,):
            msg = f"record {k}: 't' must have {n} samples. Got shape {tk.shape}."
            raise ShapeError(msg)
        dt = np.diff(tk)
        step = float(np.median(dt))
        if not step > 0 or np.max(np.abs(dt - step)) > 1e-6 * step:
            msg = f"record {k}: the structure's dynamics need uniform sampling ('t' is not)"
            raise ShapeError(msg)
        rates.append(1.0 / step)
    if max(rates) - min(rates) > 1e-6 * max(rates):
        msg = f"the records were sampled at different rates ({min(rates):.6g}-{max(rates):.6g} Hz)"
        raise ShapeError(msg)
    return float(np.mean(rates))


class StructureModel(JsonFile, SeveralChannels):
    """Coupled linear dynamics of an order chosen from the data, with each actuator's
    hysteresis in the loop (the module's equations).

    Parameters
    ----------
    order : int or "auto", default "auto"
        The state's dimension; ``"auto"`` scores :data:`ORDERS` up to ``max_order`` on
        records the fit did not see (every fourth record from the last, or a single record
        from rest's last 30 %) and keeps the best.
    operators : int, default 6
        Play operators per actuator in the loop; 0 for the linear dynamics alone. Kept only
        where they predict the held-out records at least 2 % (and 0.001 % of the outputs'
        spread) better than the linear dynamics, and the loop stays stable with every
        operator stuck (a small drive's linear end: ``modes(strokes="small")``; the
        refinement keeps it there, a penalty on the poles past
        :data:`~piezohyst.model.structure_fit.STUCK_RADIUS`); said in ``describe``.
    widths : (float, float), default (0.003, 0.3)
        The smallest and largest operator width, as shares of each stroke's half-range
        (spaced geometrically).
    max_order : int, default 64
    refine : bool, default True
        Refine every matrix, the poles too, by output error (the simulated outputs' error;
        its gradient by the adjoint of the recursion, L-BFGS) from the least squares'
        solution, which reads the measured outputs in the loop (equation error) and is biased
        where the loop matters. Kept where stable and lower (``refinement_``).

    Attributes
    ----------
    order_ : int
    orders_ : dict
        Each order scored and its held-out NRMSE (%) (empty for a stated order).
    operators_ : int
        Operators per actuator kept (0: the feedback did not predict better).
    sample_rate_ : float
    output_nrmse_ : float
        The fit's own NRMSE (%), mean over records and outputs.
    refinement_ : Refinement or None
        The output-error refinement's weighted squared error before and after, its
        iterations, and whether it was kept (None: not asked).
    schedule_refinement_ : Refinement or None
        The scheduled refinement (None: not tried, the records at one level); the schedule
        itself is ``structure_.schedule`` (None: not kept).
    unstable_stuck_ : float or None
        Where the operators predicted better but their loop, with every operator stuck (a
        small drive), had a pole of this modulus (>= 1): the model is the linear dynamics
        instead (said in ``describe``).

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> rng = np.random.default_rng(0)
    >>> u = [rng.standard_normal((400, 2)) for _ in range(3)]      # two actuators
    >>> a = np.array([[1.6, -0.8], [1.0, 0.0]])                     # one shared mode
    >>> def structure(v):
    ...     x, y = np.zeros(2), []
    ...     for vk in v:
    ...         y.append([x[0], 0.5 * x[0] + 0.1 * vk[1]])
    ...         x = a @ x + np.array([1.0, 0.0]) * (vk[0] + 0.3 * vk[1])
    ...     return np.array(y)
    >>> model = ph.StructureModel(order="auto", operators=0).fit(
    ...     u, [structure(v) for v in u], sample_rate=1000.0)
    >>> model.order_, bool(model.output_nrmse_ < 0.01)            # NRMSE in %
    (2, True)
    """

    file_kind = "a structure model file"
    _fitted = "structure_"

    def __init__(
        self,
        order: int | str = "auto",
        operators: int = 6,
        widths: tuple[float, float] = (0.003, 0.3),
        max_order: int = 64,
        refine: bool = True,
        scheduled: bool = True,
    ) -> None:
        self.order = order
        self.operators = operators
        self.widths = widths
        self.max_order = max_order
        self.refine = refine
        self.scheduled = scheduled

    def _check_params(self) -> None:
        if not (self.order == "auto" or (isinstance(self.order, int) and self.order >= 1)):
            msg = (
                "StructureModel's 'order' must be a positive integer or 'auto'. "
                f"Got {self.order!r}."
            )
            raise ParameterError(msg)
        if not isinstance(self.operators, int) or not 0 <= self.operators <= 32:
            msg = (
                "StructureModel's 'operators' must be an integer in [0, 32]. "
                f"Got {self.operators!r}."
            )
            raise ParameterError(msg)
        lo_hi = tuple(self.widths) if isinstance(self.widths, Sequence) else ()
        if len(lo_hi) != 2 or not 0 < lo_hi[0] <= lo_hi[1] <= 1:
            msg = (
                "StructureModel's 'widths' must be (smallest, largest) in (0, 1]. "
                f"Got {self.widths!r}."
            )
            raise ParameterError(msg)
        if not isinstance(self.scheduled, bool) or not isinstance(self.refine, bool):
            msg = (
                "StructureModel's 'refine' and 'scheduled' must be True or False. "
                f"Got {self.refine!r} and {self.scheduled!r}."
            )
            raise ParameterError(msg)
        if not isinstance(self.max_order, int) or self.max_order < 1:
            msg = (
                f"StructureModel's 'max_order' must be a positive integer. Got {self.max_order!r}."
            )
            raise ParameterError(msg)

    # -------------------------------------------------------------------- fit
    def fit(
        self,
        u: ArrayLike | Sequence[ArrayLike],
        y: ArrayLike | Sequence[ArrayLike],
        t: ArrayLike | Sequence[ArrayLike] | None = None,
        *,
        sample_rate: float | None = None,
        initial_state: str = "rest",
    ) -> Self:
        """Identify the structure from one record or several (realizations).

        Parameters
        ----------
        u : array_like (N, inputs), or a list of them
            The actuators' voltages.
        y : array_like (N, outputs), or a list of them
            The outputs read, as many records as ``u``.
        t : array_like (N,), or a list of them, optional
            Uniform sample times (s); or give ``sample_rate``.
        sample_rate : float, optional
            Hz, for every record.
        initial_state : {"rest", "periodic"}
            Each record starts at rest, or is one period of a periodic steady state (a
            multisine's period after the transient: the benchmark's records).

        Returns
        -------
        StructureModel
            ``self``, fitted.

        Raises
        ------
        ShapeError
            Not (samples, channels), a non-finite value (named by record, row and column),
            records of different widths, or time stamps that are not uniform.
        ParameterError
            A bad parameter, or records that cannot separate the inputs.
        """
        self._check_params()
        if initial_state not in ("rest", "periodic"):
            msg = f"'initial_state' must be 'rest' or 'periodic'. Got {initial_state!r}."
            raise ParameterError(msg)
        us, ys = _listed(u), _listed(y)
        if len(us) != len(ys):
            msg = f"'u' holds {len(us)} records and 'y' {len(ys)}"
            raise ShapeError(msg)
        records = []
        for k, (uk, yk) in enumerate(zip(us, ys, strict=True)):
            where = f"record {k}: " if len(us) > 1 else ""
            try:
                ua, ya = _array(uk, "u"), _array(yk, "y")
            except ShapeError as exc:
                raise ShapeError(f"{where}{exc}") from None
            if ua.shape[0] != ya.shape[0]:
                msg = f"{where}'u' and 'y' must have as many rows ({ua.shape[0]} and {ya.shape[0]})"
                raise ShapeError(msg)
            records.append(sf.Record(ua, ya, initial_state == "periodic"))
        shapes = {(r.u.shape[1], r.y.shape[1]) for r in records}
        if len(shapes) > 1:
            msg = f"the records hold different numbers of inputs or outputs: {sorted(shapes)}"
            raise ShapeError(msg)
        rate = _rate(t, sample_rate, [r.u.shape[0] for r in records])
        fit_on, held, tail = self._split(records)
        if self.order == "auto" and not held:
            msg = (
                "order='auto' scores the orders on records the fit did not see: give two or "
                "more periodic records (realizations), or a record from rest, or state the order"
            )
            raise ParameterError(msg)
        h_fit = sf.impulse_response(fit_on) if held else None  # once, for every candidate
        h_all = sf.impulse_response(records)
        self.orders_: dict[int, float] = {}
        found: dict[int, tuple[sf.Structure, sf.Structure]] = {}  # order: (linear, asked)
        if self.order == "auto":
            for order in (o for o in ORDERS if o <= self.max_order):
                try:
                    found[order] = self._identify(fit_on, h_fit, order, self.operators)
                except ParameterError:
                    break  # the records hold no more
                self.orders_[order] = sf.nrmse(found[order][1], held, tail)
            if not self.orders_:
                msg = "no order could be realized from these records (too short?)"
                raise ParameterError(msg)
            best = min(self.orders_.values())
            order = min(o for o, e in self.orders_.items() if e <= PARSIMONY * best + RESOLUTION)
        else:
            order = int(self.order)
        operators = self.operators
        if operators and held:  # the loop's operators kept where they predict
            pair = found.get(order) or self._identify(fit_on, h_fit, order, operators)
            linear, looped = (sf.nrmse(st, held, tail) for st in pair)
            self.held_nrmse_ = {"linear": linear, "operators": looped}
            operators = operators if looped * PARSIMONY + RESOLUTION < linear else 0
        linear_all, self.structure_ = self._identify(records, h_all, order, operators)
        if operators and not np.isfinite(sf.nrmse(self.structure_, records)):
            self.structure_, operators = linear_all, 0
        self.refinement_: sf.Refinement | None = None
        if self.refine:
            self.structure_, self.refinement_ = sf.refine(records, self.structure_)
        self.unstable_stuck_: float | None = None
        if operators and self.structure_.radius() >= 1.0:
            # a loop that rings up once every operator sticks (small drives) is not a model
            # of a structure at every amplitude: the linear dynamics instead, said
            self.unstable_stuck_ = self.structure_.radius()
            self.structure_, operators = linear_all, 0
            if self.refine:
                self.structure_, self.refinement_ = sf.refine(records, self.structure_)
        self.schedule_refinement_: sf.Refinement | None = None
        if self.scheduled and self.refine:
            self._schedule(records, rate)
        self.order_, self.operators_, self.sample_rate_ = order, operators, rate
        self.n_inputs_, self.n_outputs_ = records[0].u.shape[1], records[0].y.shape[1]
        self.output_nrmse_ = sf.nrmse(self.structure_, records)
        return self

    def _schedule(self, records: list[sf.Record], rate: float) -> None:
        """The dynamics scheduled by the drive's level, where the records hold several
        levels, refined from the structure fitted; kept where stable and clearly lower."""
        rms = np.array([np.sqrt(np.mean(np.sum(r.u**2, axis=1))) for r in records])
        if not rms.min() > 0 or rms.max() < sf.LEVEL_SPREAD * rms.min():
            return
        ref, tau = float(np.mean(rms)), sf.LEVEL_TIME * rate
        seen = np.concatenate([sf.levels(r.u, r.periodic, ref, tau) for r in records])
        st = self.structure_
        n, nf = st.order, st.e.shape[1]
        start = sf.Schedule(np.zeros((n, n)), np.zeros_like(st.b), np.zeros((n, nf)), ref, tau,
                            float(seen.min()), float(seen.max()))  # fmt: skip
        scheduled, info = sf.refine(records, st, schedule=start)
        self.schedule_refinement_ = info
        if info.kept and info.after <= (1.0 - sf.LEVEL_GAIN) * info.before:
            self.structure_ = scheduled

    @staticmethod
    def _split(records: list[sf.Record]) -> tuple[list[sf.Record], list[sf.Record], float]:
        """Records to fit on and to score on: every fourth from the last held out; one
        record from rest: its first 70 % to fit on and its last 30 % scored."""
        if len(records) >= 2:
            held_idx = set(range(len(records) - 1, -1, -4))
            return (
                [r for k, r in enumerate(records) if k not in held_idx],
                [r for k, r in enumerate(records) if k in held_idx],
                0.0,
            )
        rec = records[0]
        if rec.periodic:
            return records, [], 0.0
        cut = int(TAIL * rec.u.shape[0])
        return [sf.Record(rec.u[:cut], rec.y[:cut], False)], records, TAIL

    def _identify(
        self, records: list[sf.Record], h: FloatArray | None, order: int, operators: int
    ) -> tuple[sf.Structure, sf.Structure]:
        """The linear structure of this order, and the one asked (the same without
        operators; with them, their stroke map from the linear one's static gain)."""
        assert h is not None  # held-out records come with their own impulse response
        a, c = sf.realize(h, order)
        n, m = records[0].u.shape[1], records[0].y.shape[1]
        empty = np.zeros((n, 0))
        linear = sf.least_squares(records, a, c, np.zeros((n, m)), empty)
        if not operators:
            return linear, linear
        stroke = np.asarray(np.linalg.pinv(linear.dc_gain()), dtype=np.float64)  # y -> strokes
        s = np.concatenate([r.y for r in records]) @ stroke.T
        half = np.maximum(np.ptp(s, axis=0) / 2, 1e-300)
        lo, hi = self.widths
        r = np.asarray(half[:, None] * np.geomspace(lo, hi, operators)[None, :], dtype=np.float64)
        return linear, sf.least_squares(records, a, c, stroke, r)

    # ---------------------------------------------------------------- predict
    def predict(
        self, u: ArrayLike, t: ArrayLike | None = None, *, state: str = "rest"
    ) -> FloatArray:
        """The outputs for the actuators' voltages.

        Parameters
        ----------
        u : array_like, shape (N, inputs)
        t : array_like, shape (N,), optional
            Checked against the fit's sample rate.
        state : {"rest", "periodic"}
            Start at rest, or in the periodic steady state of ``u`` taken as one period.

        Returns
        -------
        ndarray, shape (N, outputs)
        """
        if not hasattr(self, "structure_"):
            msg = "This StructureModel is not fitted yet: call fit(u, y, sample_rate=...) first."
            raise NotFittedError(msg)
        ua = _array(u, "u")
        if ua.shape[1] != self.n_inputs_:
            msg = f"'u' must have {self.n_inputs_} columns. Got {ua.shape[1]}."
            raise ShapeError(msg)
        if state not in ("rest", "periodic"):
            msg = f"'state' must be 'rest' or 'periodic'. Got {state!r}."
            raise ParameterError(msg)
        if t is not None:
            rate = _rate(t, None, [ua.shape[0]])
            if abs(rate - self.sample_rate_) > 1e-6 * self.sample_rate_:
                msg = (
                    f"the model was identified at {self.sample_rate_:.6g} Hz and 't' is "
                    f"sampled at {rate:.6g} Hz: its dynamics hold at that rate only"
                )
                raise ShapeError(msg)
        return self.structure_.run(ua, state == "periodic")

    def _linear(self, strokes: str) -> tuple[FloatArray, FloatArray]:
        """``A`` and ``B`` of the linear structure for ``strokes``: "large" (the operators
        slide: their lag is their width, a constant, and the loop is open) or "small" (all
        stuck: each one's output constant, so its lag ``-s`` feeds each stroke back through
        the sum of its actuator's columns of ``E``)."""
        if not hasattr(self, "structure_"):
            msg = "This StructureModel is not fitted yet: call fit(u, y, sample_rate=...) first."
            raise NotFittedError(msg)
        if strokes not in ("large", "small"):
            msg = f"'strokes' must be 'large' or 'small'. Got {strokes!r}."
            raise ParameterError(msg)
        return self.structure_.linear(stuck=strokes == "small")

    def frequency_response(self, frequencies: ArrayLike, *, strokes: str = "large") -> np.ndarray:
        """The structure's linear frequency response from each actuator to each output.

        With play operators in the loop the structure is linear in two limits: large
        strokes, where every operator slides, and small strokes, where every one sticks; a
        drive between them moves between the two (what shifts a mirror's modes with its
        drive level).

        Parameters
        ----------
        frequencies : array_like
            Hz, below half the sample rate.
        strokes : {"large", "small"}

        Returns
        -------
        ndarray of complex, shape (frequencies, outputs, inputs)
            In output units per volt.
        """
        a, b = self._linear(strokes)
        st = self.structure_
        f = np.atleast_1d(np.asarray(frequencies, dtype=np.float64))
        if f.ndim != 1 or not np.all((f >= 0) & (f <= self.sample_rate_ / 2)):
            msg = (
                "'frequencies' must be a list of frequencies from 0 to half the sample rate "
                f"({self.sample_rate_ / 2:.6g} Hz)"
            )
            raise ParameterError(msg)
        eye = np.eye(st.order)
        z = np.exp(2j * np.pi * f / self.sample_rate_)
        return np.array([st.d + st.c @ np.linalg.solve(zk * eye - a, b) for zk in z])

    def modes(self, *, strokes: str = "large") -> list[tuple[float, float]]:
        """Each lightly or heavily damped mode (a complex pole pair): its frequency (Hz) and
        damping ratio, the lowest frequency first.

        Parameters
        ----------
        strokes : {"large", "small"}
            The loop's linear end, as :meth:`frequency_response` takes it.

        Returns
        -------
        list of (float, float)
        """
        s = np.log(np.linalg.eigvals(self._linear(strokes)[0]).astype(complex))
        s = s * self.sample_rate_
        return sorted((float(abs(sk)) / (2 * np.pi), float(-sk.real / max(abs(sk), 1e-300)))
                      for sk in s if sk.imag > 0)  # fmt: skip

    def describe(self) -> str:
        """The order, its modes, the loop's operators and the fit, one paragraph.

        Returns
        -------
        str
        """
        return _described(self)

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """The fitted model as JSON data, with a format, a version and a checksum.

        Returns
        -------
        dict
        """
        if not hasattr(self, "structure_"):
            msg = "This StructureModel is not fitted yet: nothing to save."
            raise NotFittedError(msg)
        st = self.structure_
        return signed(
            {
                "format": STRUCTURE_FORMAT,
                "version": STRUCTURE_VERSION,
                "params": {**self.get_params(), "widths": list(self.widths)},
                "sample_rate": self.sample_rate_,
                "orders": {str(k): v for k, v in self.orders_.items()},
                "operators_kept": self.operators_,
                "held_nrmse": getattr(self, "held_nrmse_", None),
                "unstable_stuck": getattr(self, "unstable_stuck_", None),
                "output_nrmse": self.output_nrmse_,
                "refinement": None
                if self.refinement_ is None
                else list(vars(self.refinement_).values()),
                **{
                    name: getattr(st, name).tolist()
                    for name in ("a", "b", "c", "d", "e", "t", "r", "off")
                },
                "schedule": None if st.schedule is None else {
                    k: v.tolist() if isinstance(v, np.ndarray) else v
                    for k, v in vars(st.schedule).items()
                },
                "schedule_refinement": None if self.schedule_refinement_ is None
                else list(vars(self.schedule_refinement_).values()),
            }
        )  # fmt: skip

    @classmethod
    def from_dict(cls, data: Any, where: str = "structure model") -> StructureModel:
        """The fitted structure a :meth:`to_dict` body holds, its matrices' shapes checked.

        Parameters
        ----------
        data : dict
            The body (a file's contents).
        where : str
            The file's path, for the errors' one line.

        Returns
        -------
        StructureModel

        Raises
        ------
        ModelFileError
            Another kind of file, a checksum that does not match, or a damaged field.
        """
        data = checked(data, STRUCTURE_FORMAT, where, "structure model")
        try:
            arrays = {
                name: np.array(data[name], dtype=np.float64, ndmin=2 if name != "off" else 1)
                for name in ("a", "b", "c", "d", "e", "t", "r", "off")
            }
            sched = data.get("schedule")  # None: unscheduled, or a file saved before it
            if sched is not None:
                m1 = [np.array(sched[k], dtype=np.float64, ndmin=2) for k in ("a1", "b1", "e1")]
                lv = [float(sched[k]) for k in ("ref", "tau", "lo", "hi")]
                sched = sf.Schedule(m1[0], m1[1], m1[2], lv[0], lv[1], lv[2], lv[3])
            st = sf.Structure(**arrays, schedule=sched)
            n, m = st.b.shape[1], st.c.shape[0]
            if st.a.shape != (st.order, st.order) or st.d.shape != (m, n) or st.off.shape != (m,):
                raise ValueError("the matrices' shapes do not agree")
            if sched is not None and (sched.a1.shape, sched.b1.shape, sched.e1.shape) != (
                st.a.shape,
                st.b.shape,
                st.e.shape,
            ):
                raise ValueError("the scheduled matrices' shapes do not agree")
            params = dict(data["params"])
            params["widths"] = tuple(params["widths"])
            model = cls(**params)
            model.structure_ = st
            model.sample_rate_ = float(data["sample_rate"])
            model.orders_ = {int(k): float(v) for k, v in data["orders"].items()}
            model.order_, model.operators_ = st.order, int(data["operators_kept"])
            model.n_inputs_, model.n_outputs_ = n, m
            model.output_nrmse_ = float(data["output_nrmse"])
            stuck = data.get("unstable_stuck")
            model.unstable_stuck_ = None if stuck is None else float(stuck)
            if data.get("held_nrmse") is not None:
                model.held_nrmse_ = {k: float(v) for k, v in data["held_nrmse"].items()}
            ref = data.get("refinement")
            model.refinement_ = None if ref is None else sf.Refinement(
                float(ref[0]), float(ref[1]), int(ref[2]), bool(ref[3]))  # fmt: skip
            ref = data.get("schedule_refinement")
            model.schedule_refinement_ = None if ref is None else sf.Refinement(
                float(ref[0]), float(ref[1]), int(ref[2]), bool(ref[3]))  # fmt: skip
        except (KeyError, TypeError, ValueError, PiezohystError) as exc:
            msg = f"{where}: a damaged structure model ({exc})"
            raise ModelFileError(msg) from None
        return model


def _described(model: StructureModel) -> str:
    """:meth:`StructureModel.describe`'s paragraph."""
    if not hasattr(model, "structure_"):
        return "StructureModel (not fitted)"
    modes = model.modes()
    said = ", ".join(f"{fk:.4g} Hz ({zk:.2g})" for fk, zk in modes[:6])
    more = f" and {len(modes) - 6} more" if len(modes) > 6 else ""
    chosen = f"chosen from {len(model.orders_)} on held-out records" if model.orders_ else "stated"
    loop = (
        f"{model.operators_} play operators per actuator in the loop"
        if model.operators_
        else "no operators in the loop (linear dynamics)"
    )
    if model.operators and not model.operators_ and getattr(model, "unstable_stuck_", None):
        loop += (
            ": with them the loop was unstable where every operator sticks (small "
            f"strokes; a pole of modulus {model.unstable_stuck_:.4g})"
        )
    elif model.operators and not model.operators_ and hasattr(model, "held_nrmse_"):
        h = model.held_nrmse_
        loop += (
            f": the operators did not predict the held-out records better "
            f"({h['operators']:.3g} % against {h['linear']:.3g} %)"
        )
    ref = model.refinement_
    refined = ""
    if ref is not None:
        change = 100 * (1 - ref.after / ref.before) if ref.before > 0 else 0.0
        error = (
            f"{change:.0f} % less squared error"
            if change >= 0
            else f"{-change:.0f} % more squared error than the least squares' loop, "
            "which was unstable where every operator sticks"
        )
        refined = (
            f"; refined by output error ({error}, {ref.iterations} iterations)"
            if ref.kept
            else "; the output-error refinement was not kept (not stable or not lower)"
        )
    return (
        f"StructureModel: {model.n_inputs_} inputs, {model.n_outputs_} outputs at "
        f"{model.sample_rate_:.6g} Hz; order {model.order_} ({chosen}); modes (damping) "
        f"{said or 'none'}{more}; {loop}{refined}{_scheduled_said(model)}; fit NRMSE "
        f"{model.output_nrmse_:.3g} %"
    )


def _scheduled_said(model: StructureModel) -> str:
    """What :meth:`describe` says of the schedule by the drive's level."""
    sc, info = model.structure_.schedule, getattr(model, "schedule_refinement_", None)
    if sc is not None and info is not None:
        lo, hi = (sc.ref * (1 + x) for x in (sc.lo, sc.hi))
        return (
            f"; its dynamics scheduled by the drive's level (the inputs' RMS over "
            f"{sc.tau / model.sample_rate_:.3g} s, {lo:.3g}-{hi:.3g} seen: "
            f"{100 * (1 - info.after / info.before):.0f} % less squared error)"
        )
    if info is not None:
        return "; not scheduled by the drive's level (not stable, or not 5 % lower)"
    return ""
