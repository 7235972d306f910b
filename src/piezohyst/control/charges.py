"""A compensator's front end for desired displacements: :class:`Charges` turns them into
capacitor charges through an :class:`~piezohyst.model.calibrations.output_map.OutputMap`, one
sample or block after another (on a map that turns, each on the branch of the charge before
it), (the arithmetic, for one map or a bank's at once:
:func:`~piezohyst.model.calibrations.output_map.monotone_charges`)."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import (
    ExtrapolationWarning,
    ParameterError,
)
from ..model.calibrations.output_map import OutputMap

__all__ = ["Charges"]


class Charges:
    """Desired displacements turned into capacitor charges through an :class:`OutputMap`,
    one sample or block after another: on a map that turns, each on the branch of the
    charge before it (a compensator's and a controller's front end).

    Parameters
    ----------
    output_map : OutputMap
    """

    def __init__(self, output_map: OutputMap) -> None:
        self.output_map = output_map
        self.last: float | None = None
        #: desired displacements beyond the calibrated ones since the last reset (the map
        #: extended linearly from its edge there, or out of reach on a map that turns)
        self.outside = 0
        self._said = False  # the first of them since the last reset was warned about
        lo_s, hi_s = (output_map.edges()[2:4] if output_map.monotone
                      else output_map.displacement_range())  # fmt: skip
        self._reach = (min(lo_s, hi_s), max(lo_s, hi_s))
        #: a linear monotone map: one sample inverted in floats (:meth:`one`), the same
        #: arithmetic as the block's, without arrays (a loop calls it every sample)
        self._linear = output_map.monotone and output_map.order == 1

    @classmethod
    def of(cls, output_map: Any, gain: float | None, model: Any = None) -> Charges | None:
        """The front end for a compensator's ``output_map`` argument (None without one).

        Parameters
        ----------
        output_map : OutputMap or None
        gain : float or None
            The compensator's ``gain`` argument: the map replaces it.
        model : HysteresisModel, optional
            The model the compensator inverts: said where the map was calibrated through
            another (:meth:`OutputMap.check_model`).

        Returns
        -------
        Charges or None

        Raises
        ------
        ParameterError
            Not an OutputMap, or given with a gain.
        """
        if output_map is None:
            return None
        if not isinstance(output_map, OutputMap):
            msg = (
                "'output_map' must be an OutputMap (see calibrate_gain). "
                f"Got {type(output_map).__name__}."
            )
            raise ParameterError(msg)
        if gain is not None:
            msg = "give the output_map or a gain, not both (the map holds the gain)"
            raise ParameterError(msg)
        if model is not None:
            output_map.check_model(model)
        return cls(output_map)

    def reset(self) -> None:
        """Forget the branch and the count (a compensator's reset)."""
        self.last = None
        self.outside = 0
        self._said = False

    def block(self, desired: FloatArray) -> FloatArray:
        """The charges for a block of desired displacements (NaN stays NaN).

        Parameters
        ----------
        desired : ndarray

        Returns
        -------
        ndarray
        """
        with warnings.catch_warnings():  # said here, once a run (a loop steps sample by sample)
            warnings.simplefilter("ignore", ExtrapolationWarning)
            q = self.output_map.inverse(desired, near=self.last)
        low, high = self._reach
        beyond = np.isfinite(desired) & ((desired < low) | (desired > high))  # NaN, inf: held
        self.outside += int(np.count_nonzero(beyond))
        if beyond.any() and not self._said:
            self._said = True
            far = desired[beyond]
            self.output_map._warn_outside(
                f"desired displacements from {far.min():.4g} to {far.max():.4g} "
                f"{self.output_map.output_unit} (the first since the start: later ones are "
                "counted, extrapolated_count, not said again)"
            )
        done = q[np.isfinite(q)]
        if done.size:
            self.last = float(done[-1])
        return np.ascontiguousarray(q)

    def one(self, desired: float, preview: ArrayLike | None) -> tuple[float, FloatArray | None]:
        """The charge for one desired displacement, and for its preview (on the same branch).

        Parameters
        ----------
        desired : float
        preview : array_like or None

        Returns
        -------
        (float, ndarray or None)
        """
        ahead = None
        if self._linear:  # floats: a loop calls this every sample, often with a preview
            if preview is not None:
                ahead = np.array([self._charge_linear(float(p)) for p in np.ravel(preview)])
            return self._one_linear(float(desired)), ahead
        if preview is not None:
            with warnings.catch_warnings():  # each is said and counted when its sample comes
                warnings.simplefilter("ignore", ExtrapolationWarning)
                ahead = self.output_map.inverse(np.asarray(preview, dtype=np.float64), self.last)
        return float(self.block(np.array([float(desired)]))[0]), ahead

    def _charge_linear(self, s: float) -> float:
        """The charge for one displacement on a linear monotone map, in floats: the same
        operations in the same order as :func:`monotone_charges`; nothing counted or said."""
        if not math.isfinite(s):
            return math.nan
        om = self.output_map
        lo, hi, s_lo, s_hi, d_lo, d_hi = om.edges()
        c0, c1 = om.coefficients
        rising = s_hi > s_lo
        low_end, high_end = (s_lo, s_hi) if rising else (s_hi, s_lo)
        if s < low_end:
            return lo + (s - s_lo) / d_lo if rising else hi + (s - s_hi) / d_hi
        if s > high_end:
            return hi + (s - s_hi) / d_hi if rising else lo + (s - s_lo) / d_lo
        return om.center + om.scale * (s - c0) / c1

    def _one_linear(self, s: float) -> float:
        """:meth:`block` of one displacement on a linear monotone map, in floats: the same
        operations in the same order as :func:`monotone_charges` (so a loop's ``step``
        equals its ``process`` to the bit), the same count and warning."""
        if not math.isfinite(s):
            return math.nan
        q = self._charge_linear(s)
        om = self.output_map
        low, high = self._reach
        if s < low or s > high:
            self.outside += 1
            if not self._said:
                self._said = True
                om._warn_outside(
                    f"desired displacements from {s:.4g} to {s:.4g} {om.output_unit} (the "
                    "first since the start: later ones are counted, extrapolated_count, not "
                    "said again)"
                )
        self.last = q
        return q
