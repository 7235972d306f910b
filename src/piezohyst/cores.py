r"""Hysteresis cores: the operator family a model is built on.

A core supplies the regressor columns of its operators (block by block, with
carried state), the constraint that keeps the identified hysteresis
invertible, and builds the immutable fitted operator from the solved
parameters. Today's core is :class:`PlayCore`, the Prandtl-Ishlinskii play
operators of eq. 9-12 with an output offset.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ._lazy import LazyModule
from ._validation import FloatArray
from .hysteresis import PIHysteresis

if TYPE_CHECKING:
    from . import _kernels
else:  # numba loads when a model first runs (see _lazy)
    _kernels = LazyModule("piezohyst._kernels", globals(), "_kernels")

__all__ = ["PlayCore"]


class PlayCore:
    r"""Play operators with thresholds :math:`r_i` (:math:`r_0 = 0`) and an offset.

    Columns: the operator states :math:`z_i` (input units), then a constant 1
    (the offset). The weights are solved in loading-curve slopes
    :math:`S_i = \sum_{j \le i} w_j \ge \epsilon`, which guarantees the
    analytic inverse (eq. 18) while allowing the negative weights of a
    saturating curve.

    Parameters
    ----------
    thresholds : ndarray, shape (n,)
        Strictly increasing from 0 (input units).
    """

    input_degree = 1

    def __init__(self, thresholds: FloatArray) -> None:
        self.thresholds = np.asarray(thresholds, dtype=np.float64)

    @property
    def n_operators(self) -> int:
        """Number of play operators (the linear one included)."""
        return int(self.thresholds.size)

    @property
    def width(self) -> int:
        """Operator columns plus the offset column."""
        return self.n_operators + 1

    def rest_state(self, x0: float) -> FloatArray:
        """Every operator at rest at input ``x0`` (memory wiped).

        Parameters
        ----------
        x0 : float
            The input the actuator rests at.

        Returns
        -------
        ndarray, shape (n,)
        """
        return np.full(self.n_operators, float(x0))

    def scaled(self, scale: float) -> PlayCore:
        """The same core for an input divided by ``scale`` (a power of two: exact).

        Parameters
        ----------
        scale : float

        Returns
        -------
        PlayCore
        """
        return PlayCore(self.thresholds / scale)

    def fill(self, x: FloatArray, state: FloatArray, block: FloatArray) -> None:
        """Write the core's operator columns for ``x`` into ``block[:len(x), :n]``.

        Parameters
        ----------
        x : ndarray, shape (N,)
            Input samples (input units).
        state : ndarray, shape (n,)
            Operator states, updated in place.
        block : ndarray, shape (M, p), M >= N
            Destination; its offset column (``n``) must already hold 1.
        """
        _kernels.play_states(x, self.thresholds, state, block)

    def fill_rows(
        self, x: FloatArray, state: FloatArray, rows: npt.NDArray[np.intp], block: FloatArray
    ) -> None:
        """:meth:`fill` for the rows ``rows`` of ``x`` only (the states run through all).

        Parameters
        ----------
        x : ndarray, shape (N,)
        state : ndarray, shape (n,)
            Updated in place.
        rows : ndarray of int, sorted
        block : ndarray, shape (len(rows), p)
        """
        _kernels.play_states_rows(x, self.thresholds, state, rows, block)

    def slope_map(self, p: int) -> FloatArray:
        """Matrix M with ``parameters = M @ (slopes, other parameters)``.

        Parameters
        ----------
        p : int
            Total parameter count (core and terms).

        Returns
        -------
        ndarray, shape (p, p)
        """
        n = self.n_operators
        m = np.eye(p)
        m[np.arange(1, n), np.arange(0, n - 1)] = -1.0
        return m

    def build(self, params: FloatArray, initial_state: FloatArray) -> PIHysteresis:
        """The fitted operator from solved weights and offset.

        Parameters
        ----------
        params : ndarray, shape (n + 1,)
            Weights (output per input unit) then the offset (output units).
        initial_state : ndarray, shape (n,)
            Operator states before the first training sample (input units).

        Returns
        -------
        PIHysteresis
        """
        n = self.n_operators
        return PIHysteresis(self.thresholds, params[:n], float(params[n]), initial_state)
