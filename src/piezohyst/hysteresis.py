"""Immutable Prandtl-Ishlinskii hysteresis operators and their analytic inverse.

:class:`PIHysteresis` is the *model* layer: identified parameters, checked once
when built, with :meth:`~PIHysteresis.propagate` (explicit state in, final state
out), :meth:`~PIHysteresis.predict` and :meth:`~PIHysteresis.inverse`. The
estimators in :mod:`piezohyst.models` produce these.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Generic, NamedTuple, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ._lazy import LazyModule
from ._validation import FloatArray, as_signal
from .errors import NotInvertibleError, ParameterError, ShapeError

if TYPE_CHECKING:
    from . import _kernels
else:  # numba loads when a model first runs (see _lazy)
    _kernels = LazyModule("piezohyst._kernels", globals(), "_kernels")

__all__ = ["PIHysteresis", "Propagation"]


S = TypeVar("S")


class Propagation(NamedTuple, Generic[S]):
    """Result of running a stateful operator or model over a block of samples.

    Attributes
    ----------
    output : ndarray
        One output sample per input sample.
    state : ndarray or ModelState
        The state after the last sample (operator states for
        :class:`PIHysteresis`, a :class:`~piezohyst.models.ModelState` for a
        model); pass it back to continue.
    """

    output: FloatArray
    state: S


def _frozen(values: ArrayLike, name: str) -> FloatArray:
    arr = as_signal(values, name).copy()
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class PIHysteresis:
    r"""Classical Prandtl-Ishlinskii operator (paper eq. 9-12) with an output offset.

    .. math::

        y(t) = c + \sum_{i=0}^{n-1} w_i\, z_i(t), \qquad
        z_i(t) = \max\bigl(x(t) - r_i,\ \min\{x(t) + r_i,\ z_i(t - T)\}\bigr)

    The recursion runs on the unweighted operator state :math:`z_i` (the paper's
    eq. 13-14 write it on :math:`w_i z_i`, a slip).

    Parameters
    ----------
    thresholds : array_like, shape (n,)
        Play thresholds :math:`r_i` in input units (V), strictly increasing and
        starting at 0 (the linear part).
    weights : array_like, shape (n,)
        Weights :math:`w_i` in output units per input unit (e.g. C/V).
    offset : float
        Output offset :math:`c` in output units.
    initial_state : array_like, shape (n,), optional
        Operator states *before* the first sample, in input units. The first
        sample is clamped into ``[x0 - r_i, x0 + r_i]`` (eq. 10). Default: all 0,
        the paper's :math:`y_0 = 0`.

    Examples
    --------
    >>> import numpy as np
    >>> h = PIHysteresis([0.0, 1.0], [1.0, 0.5])
    >>> h.predict([0.0, 2.0, 0.0]).tolist()
    [0.0, 2.5, 0.5]
    >>> bool(np.allclose(h.inverse().predict(h.predict([0.0, 2.0, 0.0])), [0.0, 2.0, 0.0]))
    True
    """

    thresholds: FloatArray
    weights: FloatArray
    offset: float = 0.0
    initial_state: FloatArray = field(default=None)  # type: ignore[arg-type]
    kind: ClassVar[str] = "play"  # the core's name in model files

    def __post_init__(self) -> None:
        r = _frozen(self.thresholds, "thresholds")
        w = _frozen(self.weights, "weights")
        if r.size != w.size:
            msg = (
                f"'thresholds' and 'weights' must have the same length. Got {r.size} and {w.size}."
            )
            raise ShapeError(msg)
        if r[0] != 0.0:
            msg = f"'thresholds' must start at 0 (the linear operator). Got {r[0]!r}."
            raise ParameterError(msg)
        if r.size > 1 and np.any(np.diff(r) <= 0):
            msg = f"'thresholds' must be strictly increasing. Got {r.tolist()}."
            raise ParameterError(msg)
        if not np.isfinite(self.offset):
            msg = f"'offset' must be finite. Got {self.offset!r}."
            raise ParameterError(msg)
        if self.initial_state is None:
            z0 = np.zeros_like(r)
            z0.flags.writeable = False
        else:
            z0 = _frozen(self.initial_state, "initial_state")
            if z0.size != r.size:
                msg = f"'initial_state' must hold one state per operator ({r.size}). Got {z0.size}."
                raise ShapeError(msg)
        object.__setattr__(self, "thresholds", r)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "offset", float(self.offset))
        object.__setattr__(self, "initial_state", z0)

    # ------------------------------------------------------------------ basics
    @property
    def n_operators(self) -> int:
        """Number of play operators, the linear one included."""
        return int(self.thresholds.size)

    @property
    def loading_slopes(self) -> FloatArray:
        r"""Slopes of the initial loading curve, :math:`\sum_{j \le i} w_j` (output/input)."""
        return np.cumsum(self.weights)

    @property
    def is_invertible(self) -> bool:
        """True when the first weight and every partial sum of weights are positive."""
        return bool(np.all(self.loading_slopes > 0.0))

    def rest_state(self, x0: float) -> FloatArray:
        """Operator states of an actuator resting at input ``x0`` with its memory wiped.

        Parameters
        ----------
        x0 : float
            Input (V).

        Returns
        -------
        ndarray, shape (n,)
        """
        return np.full(self.n_operators, float(x0))

    def loading_curve(self, s: ArrayLike) -> FloatArray:
        r"""Initial loading curve :math:`\varphi(s) = \sum_i w_i \max(s - r_i, 0)`, s >= 0.

        Parameters
        ----------
        s : array_like
            Input excursions from rest (input units), >= 0.

        Returns
        -------
        ndarray
            Output change along the first loading (output units).
        """
        s_arr = np.asarray(s, dtype=np.float64)
        return np.asarray(np.maximum(s_arr[..., None] - self.thresholds, 0.0) @ self.weights)

    # ------------------------------------------------------------- evaluation
    def propagate(self, x: ArrayLike, state: ArrayLike | None = None) -> Propagation[FloatArray]:
        """Run the operator over ``x`` from ``state`` (default :attr:`initial_state`).

        Parameters
        ----------
        x : array_like, shape (N,)
            Input samples (V).
        state : array_like, shape (n,), optional
            Operator states before the first sample.

        Returns
        -------
        Propagation
            ``output`` (N,) and the final ``state``; running a signal in chunks,
            passing each final state on, equals one call.
        """
        xs = as_signal(x, "x", allow_empty=True)
        z = self._state(state)
        y = np.empty_like(xs)
        _kernels.pi_forward(xs, self.thresholds, self.weights, z, y)
        if self.offset != 0.0:
            y += self.offset
        return Propagation(y, z)

    def predict(self, x: ArrayLike, state: ArrayLike | None = None) -> FloatArray:
        """See :meth:`propagate`, which this calls: the output alone."""
        return self.propagate(x, state).output

    def _state(self, state: ArrayLike | None) -> FloatArray:
        if state is None:
            return np.array(self.initial_state, dtype=np.float64)
        z = as_signal(state, "state").copy()
        if z.size != self.n_operators:
            msg = f"'state' must hold {self.n_operators} operator states. Got {z.size}."
            raise ShapeError(msg)
        return z

    # ---------------------------------------------------------------- inverse
    def inverse(self) -> PIHysteresis:
        r"""Analytic inverse (paper eq. 18, with the inverse weights :math:`w'`).

        With loading slopes :math:`S_i = \sum_{j \le i} w_j` (all > 0):

        .. math::

            r'_i = \sum_{j \le i} w_j (r_i - r_j), \quad
            w'_0 = 1/w_0, \quad w'_i = \frac{-w_i}{S_i S_{i-1}}, \quad
            c' = -c / S_{n-1}

        and the inverse operators start from
        :math:`z'_i = c + \sum_{j \le i} w_j z_i + \sum_{j > i} w_j z_j`
        (:meth:`inverse_state`). The inverse of the inverse is the original.

        Returns
        -------
        PIHysteresis
            Output units in, input units out.

        Raises
        ------
        NotInvertibleError
            If the first weight or any partial sum of weights is not positive.
        """
        slopes = self.loading_slopes
        if not np.all(slopes > 0.0):
            bad = int(np.argmax(slopes <= 0.0))
            msg = (
                "The hysteresis model has no analytic inverse: every partial sum of weights "
                f"must be > 0, but the sum up to operator {bad} is {slopes[bad]:.6g}."
            )
            raise NotInvertibleError(msg)
        r, w = self.thresholds, self.weights
        r_inv = np.array([np.dot(w[: i + 1], r[i] - r[: i + 1]) for i in range(r.size)])
        w_inv = np.empty_like(w)
        w_inv[0] = 1.0 / w[0]
        w_inv[1:] = -w[1:] / (slopes[1:] * slopes[:-1])
        return PIHysteresis(
            thresholds=r_inv,
            weights=w_inv,
            offset=-self.offset / slopes[-1],
            initial_state=self.inverse_state(self.initial_state),
        )

    def inverse_state(self, state: ArrayLike) -> FloatArray:
        r"""States of the inverse operators matching forward states ``state`` (eq. 18).

        :math:`z'_i = c + z_i \sum_{j \le i} w_j + \sum_{j > i} w_j z_j`.

        Parameters
        ----------
        state : array_like, shape (n,)
            Forward operator states (input units).

        Returns
        -------
        ndarray, shape (n,)
            Inverse operator states (output units).
        """
        z = self._state(state)
        w = self.weights
        tail = np.concatenate([np.cumsum((w * z)[::-1])[::-1][1:], [0.0]])
        return np.asarray(self.offset + np.cumsum(w) * z + tail, dtype=np.float64)

    @property
    def summary(self) -> str:
        """A few words on the core, for one-line descriptions."""
        return f"{self.n_operators} operators"

    def describe(self, input_unit: str, output_unit: str) -> list[tuple[str, str]]:
        """Labelled parameters with units, for reports.

        Parameters
        ----------
        input_unit, output_unit : str

        Returns
        -------
        list of (str, str)
        """
        fmt = ", ".join
        return [
            ("core", f"Prandtl-Ishlinskii, {self.n_operators} play operators"),
            ("thresholds", f"{fmt(f'{r:.4g}' for r in self.thresholds)} {input_unit}"),
            ("weights", f"{fmt(f'{w:.4g}' for w in self.weights)} {output_unit}/{input_unit}"),
        ]

    # ------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON parameters (lists of floats).

        Returns
        -------
        dict
            ``thresholds``, ``weights``, ``offset``, ``initial_state``.
        """
        return {
            "thresholds": self.thresholds.tolist(),
            "weights": self.weights.tolist(),
            "offset": self.offset,
            "initial_state": self.initial_state.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PIHysteresis:
        """Inverse of :meth:`to_dict`; raises on missing or malformed fields.

        Parameters
        ----------
        data : dict

        Returns
        -------
        PIHysteresis
        """
        return cls(
            thresholds=data["thresholds"],
            weights=data["weights"],
            offset=data["offset"],
            initial_state=data["initial_state"],
        )
