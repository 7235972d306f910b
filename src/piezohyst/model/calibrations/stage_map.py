r"""A coupled stage's positions from its actuators' charges: :class:`StageMap`, calibrated
once with the stage's sensors by :func:`calibrate_stage`, then used without them.

Each actuator's charge is its own (the coupling of a flexure stage is mechanical: the
Sawyer-Tower circuit of actuator *i* reads actuator *i*), and each actuator's displacement
follows its capacitor's charge (eq. 6-7). So the stage's positions are

.. math::

    y = C\,\bigl[g_1(q_1), \dots, g_n(q_n)\bigr]^\top + c

with :math:`q_i` actuator *i*'s capacitor charge (its measured charge less the leakage its
model's growth terms hold, eq. 19), :math:`g_i` its :class:`~.output_map.OutputMap` (what
it moves along its own axis, through its mode where the stage rings) and :math:`C` the
coupling (about 1 on the diagonal), as :class:`~piezohyst.CoupledModel` has it for voltages.
Identified by alternation: each actuator's map from what it alone moved,
:math:`C^{-1}(y - c)`, by :func:`~.from_sensor.calibrate_gain` (its delay, curvature and
mode by evidence); the coupling and offsets by least squares on the maps' outputs; three
rounds. What the map does not hold: a charge that the flexure's load on a stack moves (the
direct effect under stress; eq. 6-7 are at zero stress), and modes of the structure after
the coupling (one mode shared by the axes), which each actuator's own mode only
approximates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import FloatArray, as_time
from ...errors import InsufficientDataError, ModelFileError, ParameterError, ShapeError
from ...io import JsonFile
from ..coupled import columns, warn_together
from ..persistence import checked, signed
from .from_sensor import calibrate_gain
from .output_map import OutputMap

__all__ = ["STAGE_MAP_FORMAT", "StageMap", "calibrate_stage"]

STAGE_MAP_FORMAT = "piezohyst-stage-map"
STAGE_MAP_VERSION = 1
#: Alternation rounds (each: every actuator's map, then the coupling)
ROUNDS = 3
#: A coupling whose condition number reaches this is refused (its inverse would amplify
#: the charges' noise a millionfold)
COND_LIMIT = 1e6


@dataclass(frozen=True)
class StageMap(JsonFile):
    """What a coupled stage's sensors would read, from its actuators' capacitor charges.

    Attributes
    ----------
    maps : tuple of OutputMap
        Per actuator: its capacitor charge to what it alone moves along its own axis.
    coupling : ndarray, shape (outputs, actuators)
        What each actuator's motion moves each output (about 1 on the diagonal).
    offset : ndarray, shape (outputs,)
        The outputs' offsets (their units).
    residual : ndarray, shape (outputs,)
        RMS misfit of the calibration per output (its units).
    output_unit : str
    """

    file_kind: ClassVar[str] = "a stage map"

    maps: tuple[OutputMap, ...]
    coupling: FloatArray
    offset: FloatArray
    residual: FloatArray
    output_unit: str = "m"

    def __post_init__(self) -> None:
        c = np.asarray(self.coupling, dtype=np.float64)
        n = len(self.maps)
        if c.ndim != 2 or c.shape[1] != n or c.shape[0] < n or not np.all(np.isfinite(c)):
            msg = (
                f"a StageMap needs a finite coupling of (outputs >= {n}, {n}) for its {n} "
                f"maps. Got shape {c.shape}."
            )
            raise ParameterError(msg)
        cond = float(np.linalg.cond(c))
        if not cond < COND_LIMIT:
            msg = f"a StageMap's coupling cannot be inverted (condition number {cond:.3g})"
            raise ParameterError(msg)
        off = np.asarray(self.offset, dtype=np.float64).reshape(-1)
        res = np.asarray(self.residual, dtype=np.float64).reshape(-1)
        if off.size != c.shape[0] or res.size != c.shape[0] or not np.all(np.isfinite(off)):
            msg = f"a StageMap needs one finite offset and residual per output ({c.shape[0]})"
            raise ParameterError(msg)
        object.__setattr__(self, "coupling", c)
        object.__setattr__(self, "offset", off)
        object.__setattr__(self, "residual", res)

    @property
    def inverse(self) -> FloatArray:
        """What each actuator moved: ``inverse @ (y - offset)`` (least squares with more
        outputs than actuators).

        Returns
        -------
        ndarray, shape (actuators, outputs)
        """
        c = self.coupling
        return np.asarray(
            np.linalg.inv(c) if c.shape[0] == c.shape[1] else np.linalg.pinv(c), dtype=np.float64
        )

    def predict(self, charge: ArrayLike) -> FloatArray:
        """The stage's positions for the actuators' capacitor charges.

        Parameters
        ----------
        charge : array_like, shape (samples, actuators)
            Each actuator's capacitor charge (its model's output: growth removed).

        Returns
        -------
        ndarray, shape (samples, outputs)
        """
        q = columns(charge, "charge")
        if q.shape[1] != len(self.maps):
            msg = f"'charge' must hold {len(self.maps)} columns. Got {q.shape[1]}."
            raise ShapeError(msg)
        own = np.column_stack([m.predict(q[:, i]) for i, m in enumerate(self.maps)])
        return np.asarray(own @ self.coupling.T + self.offset)

    def describe(self) -> str:
        """The coupling, each actuator's gain with its standard error, and the misfit.

        Returns
        -------
        str
        """
        rows = "; ".join("[" + ", ".join(f"{v:.4g}" for v in row) + "]" for row in self.coupling)
        lines = [f"coupling {rows} (outputs x actuators)"]
        lines += [f"actuator {i}: {m.summary()}" for i, m in enumerate(self.maps)]
        lines.append(
            "RMS misfit per output: "
            + ", ".join(f"{v:.3g} {self.output_unit}" for v in self.residual)
        )
        return "\n".join(lines)

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """The map as a file holds it.

        Returns
        -------
        dict
            Its format and schema version, each actuator's map, the coupling, offsets and
            misfit, and the checksum over them.
        """
        body: dict[str, Any] = {
            "format": STAGE_MAP_FORMAT,
            "schema_version": STAGE_MAP_VERSION,
            "maps": [m.to_dict() for m in self.maps],
            "coupling": self.coupling.tolist(),
            "offset": self.offset.tolist(),
            "residual": [None if math.isnan(v) else float(v) for v in self.residual],
            "output_unit": self.output_unit,
        }
        return signed(body)

    @classmethod
    def from_dict(cls, data: Any, where: str = "stage map") -> StageMap:
        """Rebuild from :meth:`to_dict` output; a bad field is named in one line.

        Parameters
        ----------
        data : dict
        where : str
            Named in errors (a file name).

        Returns
        -------
        StageMap

        Raises
        ------
        ModelFileError
        """
        data = checked(data, STAGE_MAP_FORMAT, where, "stage map")
        if data.get("schema_version") != STAGE_MAP_VERSION:
            msg = f"{where}: schema_version {data.get('schema_version')!r} is not 1"
            raise ModelFileError(msg)
        try:
            maps = tuple(
                OutputMap.from_dict(m, f"{where}, actuator {i}") for i, m in enumerate(data["maps"])
            )
            return cls(
                maps=maps,
                coupling=np.array(data["coupling"], dtype=np.float64),
                offset=np.array(data["offset"], dtype=np.float64),
                residual=np.array(
                    [math.nan if v is None else v for v in data["residual"]], dtype=np.float64
                ),
                output_unit=str(data.get("output_unit", "m")),
            )
        except (KeyError, TypeError, ValueError, IndexError, ParameterError) as exc:
            missing = isinstance(exc, KeyError)
            said = f"field {exc.args[0]!r} is missing" if missing else str(exc).splitlines()[0]
            raise ModelFileError(f"{where}: {said}") from None


def _delayed(s: FloatArray, samples: int) -> FloatArray:
    """``s`` as a sensor ``samples`` behind it reads it (its first value before)."""
    if samples <= 0:
        return s
    return np.concatenate([np.full(samples, s[0]), s[:-samples]])


def calibrate_stage(
    models: Sequence[Any],
    voltage: ArrayLike,
    charge: ArrayLike,
    position: ArrayLike,
    t: ArrayLike,
    *,
    output_unit: str = "m",
    output_dynamics: str = "auto",
) -> StageMap:
    """Calibrate a coupled stage's positions from its actuators' charges, with its sensors
    once (the one step that needs them; :class:`StageMap` says what it holds).

    Parameters
    ----------
    models : sequence of HysteresisModel
        One per actuator, each fitted on its own voltage -> charge (its growth terms are
        removed from the charge, eq. 19).
    voltage, charge : array_like, shape (samples, actuators)
        The commands (V) and each actuator's measured charge (its models' units).
    position : array_like, shape (samples, outputs)
        The stage's sensors (``output_unit``), outputs >= actuators; output ``i`` is
        actuator ``i``'s own axis.
    t : array_like, shape (samples,)
        s.
    output_unit : str, default "m"
    output_dynamics : {"auto", "none", "second-order"}, default "auto"
        Each actuator's mode between its charge and what it moves (as
        :func:`calibrate_gain`): where the stage rings.

    Returns
    -------
    StageMap

    Raises
    ------
    ShapeError
        Columns that do not match the models, or a non-finite value (named by row and
        column).
    InsufficientDataError
        A sensor that does not follow an actuator's charge (as :func:`calibrate_gain`).
    """
    u = columns(voltage, "voltage", rows=2)
    q = columns(charge, "charge", rows=2)
    y = columns(position, "position", rows=2)
    n = len(models)
    if n == 0 or u.shape[1] != n or q.shape[1] != n:
        msg = (
            f"one model per actuator: {n} models, {u.shape[1]} voltage and {q.shape[1]} "
            "charge columns"
        )
        raise ShapeError(msg)
    if not (u.shape[0] == q.shape[0] == y.shape[0]):
        msg = f"voltage, charge and position must have the same rows. Got {u.shape[0]}, " \
              f"{q.shape[0]} and {y.shape[0]}."  # fmt: skip
        raise ShapeError(msg)
    if y.shape[1] < n:
        msg = f"'position' needs a sensor per actuator at least ({n}). Got {y.shape[1]}."
        raise ShapeError(msg)
    ts = as_time(t, u.shape[0], required=True, owner="calibrate_stage")
    assert ts is not None
    warn_together(u)
    qc = np.column_stack(
        [np.asarray(m.remove_growth(u[:, i], q[:, i], t=ts)) for i, m in enumerate(models)]
    )
    # the first round's coupling: the positions against the charges, scaled per actuator
    design = np.column_stack([qc, np.ones(u.shape[0])])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    raw = coef[:n].T  # (outputs, actuators), per C
    gains = np.diag(raw[:n, :n]).copy()
    if np.any(gains == 0) or not np.all(np.isfinite(gains)):
        msg = "an actuator's own axis does not move with its charge: is output i actuator i's?"
        raise InsufficientDataError(msg)
    c, off = raw / gains, coef[n]
    dt = float(np.median(np.diff(ts)))
    maps: list[OutputMap] = []
    for _ in range(ROUNDS):
        own = (y - off) @ np.linalg.pinv(c).T
        maps = [
            calibrate_gain(
                m,
                u[:, i],
                q[:, i],
                own[:, i],
                ts,
                output_unit=output_unit,
                output_dynamics=output_dynamics,
            )
            for i, m in enumerate(models)
        ]
        moved = np.column_stack(
            [_delayed(mp.respond(qc[:, i]), round(mp.delay / dt)) for i, mp in enumerate(maps)]
        )
        coef, *_ = np.linalg.lstsq(np.column_stack([moved, np.ones(u.shape[0])]), y, rcond=None)
        c, off = coef[:n].T, coef[n]
    resid = y - (moved @ c.T + off)
    return StageMap(
        maps=tuple(maps),
        coupling=c,
        offset=off,
        residual=np.sqrt(np.mean(resid**2, axis=0)),
        output_unit=output_unit,
    )
