r"""Several actuators moving one structure: a hysteresis model per input, then the coupling.

.. math::

    y(t) = C\,\bigl[h_1(u_1)(t), \dots, h_n(u_n)(t)\bigr]^\top + c

with :math:`h_i` any single-channel model of this library (its core, growth or creep terms,
input dynamics) fitted to what actuator :math:`i` alone would move, :math:`C` the static
coupling (a flexure that moves y by a few per cent when x moves; the diagonal 1: each
actuator's model is in its own axis's units) and :math:`c` the offsets. Identified by
alternation: the coupling from a linear fit of the outputs on the inputs, each actuator's
model on the virtual output :math:`C^{-1}(y - c)` that is its own, the coupling again on
the models' outputs, a few rounds.

Each actuator's model may hold its amplifier's lag and the mode its axis moves through
(``input_dynamics``, ``output_dynamics="second-order"``): identified with its hysteresis on
a record of several rates per axis, they are the dynamics a fast raster's corners excite,
and the compensator inverts them with one sample of preview (a flexure whose coupling is
kinematic: y's sensor sees x's motion, mode and all; ``simulation.XY_DYNAMIC``). Modes
*after* the coupling (a structure's own modes shared by the axes) and modes that move with
the drive level (the measured fine-steering mirror: hysteresis inside the dynamics' loop,
``docs/validation.md``) are :class:`~piezohyst.StructureModel`'s, which predicts them
(:class:`~piezohyst.StructureCompensator` inverts it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Self

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import (
    IdentifiabilityWarning,
    ModelFileError,
    NotFittedError,
    ParameterError,
    PiezohystError,
    ShapeError,
    warn,
)
from ..io import JsonFile
from .estimator import SeveralChannels
from .model import HysteresisModel, is_model
from .persistence import checked, model_from_dict, model_to_dict, signed
from .presets import ClassicalPI

__all__ = ["COUPLED_FORMAT", "TOGETHER", "CoupledModel", "columns", "warn_together"]

#: Inputs whose changes correlate beyond this move together: the record cannot tell which
#: of them moved an output (the coupling between their axes is not determined)
TOGETHER = 0.9

COUPLED_FORMAT = "piezohyst-coupled-model"
COUPLED_VERSION = 1


def columns(a: ArrayLike, name: str, rows: int = 1) -> FloatArray:
    """``a`` as (samples, channels) of at least ``rows`` rows, every value finite, or a
    one-line error naming the row and column (also :mod:`~piezohyst.model.structure`'s)."""
    x = np.asarray(a, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] < rows:
        least = f" with {rows} samples or more" if rows > 1 else ""
        msg = f"'{name}' must be (samples, channels){least}. Got shape {x.shape}."
        raise ShapeError(msg)
    if not np.all(np.isfinite(x)):
        row, col = np.argwhere(~np.isfinite(x))[0]
        msg = f"'{name}' holds a non-finite value at row {row}, column {col}."
        raise ShapeError(msg)
    return x


#: A coupling whose condition number reaches this is not inverted (singular up to rounding)
COND_LIMIT = 1e8


def warn_together(u: FloatArray) -> None:
    """Warn where two inputs' changes correlate beyond :data:`TOGETHER` (named)."""
    du = np.diff(u, axis=0)
    if du.shape[0] < 2 or np.any(np.std(du, axis=0) == 0):
        return
    corr = np.atleast_2d(np.asarray(np.corrcoef(du.T), dtype=np.float64))
    for i in range(u.shape[1]):
        for j in range(i + 1, u.shape[1]):
            if abs(corr[i, j]) > TOGETHER:
                warn(
                    f"inputs {i} and {j} move together (their changes correlate at "
                    f"{corr[i, j]:.2f}): the record cannot tell which moved an output, so the "
                    "coupling between their axes is not determined; excite each actuator with "
                    "its own signal at its own rate",
                    IdentifiabilityWarning,
                )


class CoupledModel(JsonFile, SeveralChannels):
    """A hysteresis model per input and the static coupling between the outputs.

    Parameters
    ----------
    channel : HysteresisModel or sequence of HysteresisModel, optional
        The template each input's model is fitted from (a fresh copy per input), or one
        template per input (actuators of different physics: choose each with
        :func:`~piezohyst.select_model` on a record of that actuator alone); default
        ``ClassicalPI(10, output_unit="m")``, for stage positions.
    rounds : int, default 3
        Alternation rounds (each: every input's model, then the coupling).

    Attributes
    ----------
    channels_ : list of HysteresisModel
        One fitted model per input, in its own axis's units.
    coupling_ : ndarray, shape (outputs, inputs)
        The static coupling, about 1 on the diagonal (each model in its own axis's units;
        the last round's least squares, not forced). Output ``i`` is actuator ``i``'s own
        axis; outputs beyond the actuators (a third sensor on a two-actuator stage) are
        further readings of the same motion, and the actuators' parts are then a least
        squares over all of them.
    offset_ : ndarray, shape (outputs,)
    output_nrmse_ : ndarray, shape (outputs,)
        The fit's error per output, over its span.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> from piezohyst.simulation import make_signal, simulate_stage
    >>> t, a = make_signal("decaying", duration=8.0)           # each axis its own signal
    >>> _, b = make_signal("triangle", duration=8.0, frequency=1.3)
    >>> rec = simulate_stage(np.column_stack([np.clip(2 * a, 0, 140), b]), t)
    >>> model = ph.CoupledModel().fit(rec.voltage, rec.position, t=rec.t)
    >>> np.round(model.coupling_, 2).tolist()                 # x moves y by 4 %, y x by -3 %
    [[1.0, -0.03], [0.04, 1.0]]
    """

    file_kind = "a coupled model file"
    _fitted = "coupling_"

    def __init__(
        self, channel: HysteresisModel | Sequence[HysteresisModel] | None = None, rounds: int = 3
    ) -> None:
        self.channel = channel
        self.rounds = rounds

    def _templates(self, n: int) -> list[HysteresisModel]:
        """One template per input, checked."""
        given = self.channel if self.channel is not None else ClassicalPI(10, output_unit="m")
        templates = list(given) if isinstance(given, Sequence) else [given] * n
        if len(templates) != n:
            msg = f"CoupledModel's 'channel' holds {len(templates)} models for {n} inputs."
            raise ParameterError(msg)
        for template in templates:
            if not is_model(template):
                msg = (
                    "CoupledModel's 'channel' must be a piezohyst model such as "
                    f"ph.ClassicalPI(10, output_unit='m'), or one per input. Got "
                    f"{type(template).__name__}."
                )
                raise ParameterError(msg)
        if not isinstance(self.rounds, int) or not 1 <= self.rounds <= 20:
            msg = f"CoupledModel's 'rounds' must be an integer in [1, 20]. Got {self.rounds!r}."
            raise ParameterError(msg)
        return templates

    # -------------------------------------------------------------------- fit
    def fit(self, u: ArrayLike, y: ArrayLike, t: ArrayLike | None = None) -> Self:
        """Identify every input's model and the coupling from one record.

        Parameters
        ----------
        u : array_like, shape (N, inputs)
            The actuators' voltages (V).
        y : array_like, shape (N, outputs)
            The positions read (as many outputs as inputs: one per actuator's axis).
        t : array_like, shape (N,), optional
            Sample times (s), for models with rate-dependent terms.

        Returns
        -------
        CoupledModel
            ``self``, fitted.

        Raises
        ------
        ShapeError
            Not (samples, channels), a non-finite value (named by row and column), or a
            different number of outputs than inputs.
        """
        us, ys = columns(u, "u", 2), columns(y, "y", 2)
        if us.shape[0] != ys.shape[0]:
            msg = f"'u' and 'y' must have as many rows. Got {us.shape[0]} and {ys.shape[0]}."
            raise ShapeError(msg)
        n, m = us.shape[1], ys.shape[1]
        if m < n:
            msg = (
                f"CoupledModel pairs each actuator with one output, its own axis: {n} inputs, "
                f"{m} outputs (fewer outputs than actuators cannot tell them apart)"
            )
            raise ShapeError(msg)
        templates = self._templates(n)
        warn_together(us)
        ts = None if t is None else np.asarray(t, dtype=np.float64)
        # the start: the linear voltage map, each column scaled to its own axis
        a = np.column_stack([us, np.ones(us.shape[0])])
        lin = np.linalg.lstsq(a, ys, rcond=None)[0]  # (n + 1, m)
        coupling = (lin[:n] / np.diag(lin[:n, :n])[:, None]).T  # C[:, i]: column i of the map
        offset = np.zeros(m)
        channels: list[HysteresisModel] = []
        for k in range(self.rounds):
            cond = float(np.linalg.cond(coupling))
            if not cond < COND_LIMIT:  # inputs that move together leave it singular
                msg = (
                    "the record cannot separate the actuators: the coupling it gives cannot "
                    f"be inverted (condition number {cond:.3g}); drive each actuator with "
                    "its own signal (inputs that move together are named in the warning)"
                )
                raise ParameterError(msg)
            # each actuator's own part (with more outputs than actuators, in least squares)
            virtual = (
                np.linalg.solve(coupling, (ys - offset).T).T
                if m == n
                else np.linalg.lstsq(coupling, (ys - offset).T, rcond=None)[0].T
            )
            channels = [
                type(tp)(**tp.get_params()).fit(us[:, i], virtual[:, i], t=ts)
                for i, tp in enumerate(templates)
            ]
            h = np.column_stack([ch.predict(us[:, i], t=ts) for i, ch in enumerate(channels)])
            sol = np.linalg.lstsq(np.column_stack([h, np.ones(h.shape[0])]), ys, rcond=None)[0]
            coupling, offset = (
                np.asarray(sol[:n].T, dtype=np.float64),
                np.asarray(sol[n], dtype=np.float64),
            )
            if k < self.rounds - 1:  # the next round's models take the diagonal's scale
                coupling = coupling / np.diag(coupling)[None, :]
        self.channels_, self.coupling_, self.offset_ = channels, coupling, offset
        resid = self.predict(us, t=ts) - ys
        span = np.maximum(np.ptp(ys, axis=0), 1e-300)
        self.output_nrmse_ = np.sqrt(np.mean(resid**2, axis=0)) / span
        return self

    # ---------------------------------------------------------------- predict
    def _check_fitted(self) -> None:
        if not hasattr(self, "coupling_"):
            msg = "This CoupledModel is not fitted yet: call fit(u, y) first."
            raise NotFittedError(msg)

    def hysteresis(self, u: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """Each actuator's own output (its model's, in its axis's units), before the coupling.

        Parameters
        ----------
        u : array_like, shape (N, inputs)
        t : array_like, shape (N,), optional

        Returns
        -------
        ndarray, shape (N, inputs)
        """
        self._check_fitted()
        us = columns(u, "u")
        if us.shape[1] != len(self.channels_):
            msg = f"'u' must have {len(self.channels_)} columns. Got {us.shape[1]}."
            raise ShapeError(msg)
        return np.column_stack([ch.predict(us[:, i], t=t) for i, ch in enumerate(self.channels_)])

    def predict(self, u: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """The outputs for the actuators' voltages.

        Parameters
        ----------
        u, t
            As for :meth:`hysteresis`.

        Returns
        -------
        ndarray, shape (N, outputs)
        """
        return np.asarray(self.hysteresis(u, t) @ self.coupling_.T + self.offset_)

    def describe(self) -> str:
        """The coupling and each actuator's model, one paragraph.

        Returns
        -------
        str
        """
        self._check_fitted()
        rows = "; ".join("[" + ", ".join(f"{x:.4g}" for x in row) + "]" for row in self.coupling_)
        fit = ", ".join(f"{100 * e:.3g} %" for e in self.output_nrmse_)
        kinds = ", ".join(type(ch).__name__ for ch in self.channels_)
        worst = max(abs(x) for i, row in enumerate(self.coupling_) for j, x in
                    enumerate(row) if i != j) if len(self.channels_) > 1 else math.nan  # fmt: skip
        dynamics = []
        for k, ch in enumerate(self.channels_):
            held = []
            lag, mode = ch.input_dynamics_, ch.output_dynamics_
            if lag.active:
                held.append(f"a lag of {1e3 * (lag.tau + lag.delay):.3g} ms")
            if mode.active:
                held.append(f"a mode at {mode.f0:.4g} Hz (damping {mode.zeta:.3g})")
            if held:
                dynamics.append(f"actuator {k} {' and '.join(held)}")
        said = f"; {'; '.join(dynamics)}" if dynamics else ""
        return (
            f"CoupledModel: {len(self.channels_)} actuators ({kinds}), static coupling "
            f"[{rows}] (largest cross term {100 * worst:.3g} %), NRMSE per output {fit}{said}"
        )

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """The fitted model as JSON data: the coupling, the offsets, each actuator's model
        file, the fit's error; with a format, a version and a checksum.

        Returns
        -------
        dict
        """
        self._check_fitted()
        body: dict[str, Any] = {
            "format": COUPLED_FORMAT,
            "version": COUPLED_VERSION,
            "rounds": self.rounds,
            "coupling": self.coupling_.tolist(),
            "offset": self.offset_.tolist(),
            "output_nrmse": self.output_nrmse_.tolist(),
            "channels": [model_to_dict(ch) for ch in self.channels_],
        }
        return signed(body)

    @classmethod
    def from_dict(cls, data: Any, where: str = "coupled model") -> CoupledModel:
        """Rebuild a fitted model from :meth:`to_dict` data; a bad field is named.

        Parameters
        ----------
        data : dict
        where : str
            Named in errors (a file's path).

        Returns
        -------
        CoupledModel

        Raises
        ------
        ModelFileError
            Not a coupled model file, a checksum that does not match, or a damaged field.
        """
        data = checked(data, COUPLED_FORMAT, where, "coupled model")
        try:
            channels = [model_from_dict(d) for d in data["channels"]]
            coupling = np.array(data["coupling"], dtype=np.float64)
            offset = np.array(data["offset"], dtype=np.float64)
            nrmse = np.array(data["output_nrmse"], dtype=np.float64)
            n = len(channels)
            m = coupling.shape[0] if coupling.ndim == 2 else 0
            if coupling.shape != (m, n) or m < n or offset.shape != (m,) or nrmse.shape != (m,):
                raise ValueError(f"a coupling for {n} channels must be (outputs >= {n}) x {n}")
        except (KeyError, TypeError, ValueError, PiezohystError) as exc:
            msg = f"{where}: a damaged coupled model ({exc})"
            raise ModelFileError(msg) from None
        model = cls([type(ch)(**ch.get_params()) for ch in channels], int(data["rounds"]))
        model.channels_, model.coupling_, model.offset_ = channels, coupling, offset
        model.output_nrmse_ = nrmse
        return model
