"""What the limits did to the commands: counted and said.

:class:`Tallied` is the part of :class:`~piezohyst.Compensator` (and so of the controllers
built on it) that counts the commands the voltage limits, the slew limit and the identified
region held, and warns once per limit (a :class:`~piezohyst.errors.LimitWarning` naming each
limit that held more than :data:`LIMIT_SHARE` of the commands, with its count). The counts
are kept by the kernel (``_kernels.play.tally_*``) in one array.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._kernels import play as K
from .._validation import FloatArray
from ..errors import LimitWarning, warn

__all__ = ["LIMIT_CHECK_FIRST", "LIMIT_SHARE", "Tallied", "approach_message", "limit_parts"]

#: The share of commands held by a limit above which a compensator or controller warns
LIMIT_SHARE = 0.01
#: Commands given before the first check (then at every doubling, and after each block)
LIMIT_CHECK_FIRST = 100


class Tallied:
    """The counts of what the limits held, and the one warning per limit (mixed into the
    compensator, whose limits, engine and output map it reads)."""

    #: Who the limits' warnings name (a coupled stage names the actuator)
    owner: str = "Compensator"

    inverse: Any
    charges: Any
    v_min: float
    v_max: float
    sample_rate: float | None
    allow_extrapolation: bool
    _max_step: float
    _tally: FloatArray
    _until_check: int
    _limits_warned: set[str]
    _approach_warned: bool

    @property
    def max_step(self) -> float:
        """The largest command change per sample (V; inf: no slew limit)."""
        return self._max_step

    @property
    def last_command(self) -> float:
        """The command sent last (V): where the actuator sits now."""
        return float(self.inverse.last_command())

    @property
    def nonfinite_count(self) -> int:
        """Desired values that were NaN or infinite (the last command was held)."""
        return int(self.inverse.nonfinite_count())

    @property
    def saturated_count(self) -> int:
        """Samples whose command was sent at ``v_min`` or ``v_max`` because the target was
        beyond it (out of reach); a command the slew limit held before it reached a limit
        counts in :attr:`slew_limited_count` (on the trajectory) or not at all (the approach)."""
        return int(self.inverse.saturated_count())

    @property
    def outside_count(self) -> int:
        """Commands that would have left the identified region (held unless extrapolating)."""
        return int(self.inverse.outside_count())

    @property
    def extrapolated_count(self) -> int:
        """Desired displacements beyond the output map's calibrated range since the last reset
        (the map is extended linearly from its edge there; 0 without a map). The C export's
        fourth count is the same."""
        return 0 if self.charges is None else self.charges.outside

    def tally_one(self, command: float, owner: str | None = None) -> None:
        """:meth:`tally` for one command (a loop's step).

        Parameters
        ----------
        command : float
            The command sent (V).
        owner : str, optional
            Who sent them, for the message (default :attr:`owner`).
        """
        K.tally_command(float(command), self._tally)
        self._until_check -= 1
        if not self._until_check:
            self._check_limits(owner or self.owner)

    def tally(self, commands: FloatArray, owner: str | None = None) -> None:
        """Count the commands the voltage and slew limits held, and warn once (a
        :class:`~piezohyst.errors.LimitWarning`) when they hold more than
        :data:`LIMIT_SHARE` of them. :meth:`step` and :meth:`process` call it; a loop
        built on this compensator's kernel (the self-sensing controller) calls it with
        the commands it sent.

        Parameters
        ----------
        commands : ndarray
            The commands sent since the last call, in order (V).
        owner : str, optional
            Who sent them, for the message (default :attr:`owner`).
        """
        if not commands.size:
            return
        K.tally_block(np.ascontiguousarray(commands, dtype=np.float64), self._tally)
        self._check_limits(owner or self.owner)

    @property
    def slew_limited_count(self) -> int:
        """Commands held back by the slew limit (moved by exactly :attr:`max_step`), from
        the first command that reached the trajectory on (the approach from rest or from a
        precondition cycle's end is the limit doing its job: not counted)."""
        return int(self._tally[K.TALLY_HELD])

    @property
    def approach_count(self) -> int:
        """Commands the slew limit held before they reached the trajectory (since the reset
        or the precondition cycle; warned of from :data:`LIMIT_CHECK_FIRST` on, not arrived)."""
        return int(self._tally[K.TALLY_APPROACH])

    @property
    def command_count(self) -> int:
        """Commands given by :meth:`step` and :meth:`process` since the last reset, from the
        first that reached the trajectory on (see :attr:`slew_limited_count`)."""
        return int(self._tally[K.TALLY_GIVEN])

    @property
    def sent_count(self) -> int:
        """Every command given since the last reset, the approach included: what
        :attr:`saturated_count`'s share is of (the voltage limits bite on the approach too)."""
        return int(self._tally[K.TALLY_ALL])

    def _count_reset(self) -> None:
        """The counters of commands held by the limits, from zero."""
        tol = self._max_step * (1.0 - 1e-9) if math.isfinite(self._max_step) else math.inf
        self._tally = np.zeros(K.TALLY_SIZE)
        self._tally[[K.TALLY_PREV, K.TALLY_TOL]] = self.last_command, tol
        self._tally[[K.TALLY_LOW, K.TALLY_HIGH]] = self.v_min, self.v_max
        self._until_check = LIMIT_CHECK_FIRST  # steps until the next look at the counts
        self._limits_warned: set[str] = set()  # the limits said ("slew", "voltage", "region")
        self._approach_warned = False

    def _check_limits(self, owner: str) -> None:
        """Warn once when the limits held more than :data:`LIMIT_SHARE` of the commands, and
        once when :data:`LIMIT_CHECK_FIRST` held ones have not reached the trajectory."""
        given = self.sent_count
        self._until_check = max(given, LIMIT_CHECK_FIRST)  # again when they have doubled
        late = not (self._approach_warned or self._tally[K.TALLY_ARRIVED])
        if late and self.approach_count >= LIMIT_CHECK_FIRST:
            self._approach_warned = True
            warn(approach_message(owner, self), LimitWarning)
        if len(self._limits_warned) == 3 or given < LIMIT_CHECK_FIRST:
            return
        sides = int(self._tally[K.TALLY_AT_LOW]), int(self._tally[K.TALLY_AT_HIGH])
        parts = limit_parts(
            self.command_count, self.saturated_count, self.slew_limited_count,
            (self.v_min, self.v_max), self._max_step, self.sample_rate,
            given=given, sides=sides,
            outside=0 if self.allow_extrapolation else self.outside_count,
        )  # fmt: skip
        # each limit is said once, when it first holds more than the share: a slew limit
        # said early does not silence the voltage limits later (nor the other way round)
        new = {k: v for k, v in parts.items() if k not in self._limits_warned}
        if new:
            self._limits_warned.update(new)
            warn(f"{owner}: {'; '.join(new.values())}", LimitWarning)


def approach_message(owner: str, comp: Tallied) -> str:
    """The warning when the slew limit has held every command since the start (or the last
    precondition cycle), :data:`LIMIT_CHECK_FIRST` or more, and they have not reached the
    trajectory: the target runs ahead of them (a ramp from rest that arrives is not counted).

    Parameters
    ----------
    owner : str
    comp : Compensator or the counts of one
        Its approach so far (:attr:`Compensator.approach_count`, the last command, the limit).

    Returns
    -------
    str
    """
    step, rate = comp.max_step, comp.sample_rate
    per_s = f"{step * rate:.4g} V/s" if rate else f"{step:.4g} V/sample"
    return (
        f"{owner}: the slew limit ({per_s}) has held all {comp.approach_count} commands since "
        f"the start and they have not reached the trajectory (now at {comp.last_command:.4g} "
        "V): the target runs ahead of what the limit lets them follow; set slew_rate "
        "(--slew-rate) to what the amplifier allows, start nearer the trajectory "
        "(precondition), or slow the target"
    )


def limit_parts(
    issued: int,
    saturated: int,
    slewed: int,
    limits: tuple[float, float],
    max_step: float,
    sample_rate: float | None,
    *,
    given: int | None = None,
    sides: tuple[int, int] | None = None,
    outside: int = 0,
    trained: bool = True,
) -> dict[str, str]:
    """What each limit that held over :data:`LIMIT_SHARE` of the commands did: ``"slew"``,
    ``"voltage"`` and ``"region"`` keys, each a sentence with its count and the setting to
    change.

    Parameters
    ----------
    issued, saturated, slewed : int
        Commands given on the trajectory (the slew limit's count is of these); held by the
        voltage limits; held by the slew limit.
    given : int, optional
        Every command given, the approach to the trajectory too (the voltage limits' count
        is of these); default ``issued``.
    sides : (int, int), optional
        Of those, the commands at ``v_min`` and at ``v_max``: the message names the side
        a target out of reach is on (the one with more).
    limits : (float, float)
        ``v_min, v_max`` (V).
    max_step : float
        The slew limit per sample (V).
    sample_rate : float or None
        Hz, for the message.
    outside : int, default 0
        Commands held back because they would have left the (voltage, output) region the
        model was identified on (a compensator that does not extrapolate).
    trained : bool, default True
        The slew limit's default is the training record's fastest change (said); False
        for a compensator whose slew limit is only what the user set.

    Returns
    -------
    dict
    """
    parts = {}
    if slewed > LIMIT_SHARE * issued:
        per_s = f"{max_step * sample_rate:.4g} V/s" if sample_rate else f"{max_step:.4g} V/sample"
        parts["slew"] = (
            f"the slew limit ({per_s}) held {slewed} of {issued} commands "
            f"({100 * slewed / issued:.1f} %): the trajectory is faster than the limit"
            + (" (by default the training record's fastest change)" if trained else "")
            + "; set slew_rate (--slew-rate) to what the amplifier allows, "
            + ("or identify on faster loops" if trained else "or slow the target")
        )
    total = max(issued, saturated if given is None else given)
    if saturated > LIMIT_SHARE * total:
        reach, change = "the target is out of reach there", "v_min/v_max (--v-min/--v-max)"
        if sides is not None and max(sides) > 0:
            low = sides[0] >= sides[1]
            reach = (f"{sides[0]} at v_min, {sides[1]} at v_max: the target is "
                     + ("below what v_min reaches" if low else "beyond what v_max reaches")
                     + " there")  # fmt: skip
            change = "v_min (--v-min)" if low else "v_max (--v-max)"
        parts["voltage"] = (
            f"the voltage limits [{limits[0]:g}, {limits[1]:g}] V held {saturated} of {total} "
            f"commands ({100 * saturated / total:.1f} %; {reach}); widen {change} if the "
            "actuator allows, or bring the target within reach"
        )
    if outside > LIMIT_SHARE * total:
        parts["region"] = (
            f"the identified region held {outside} of {total} commands "
            f"({100 * outside / total:.1f} %: they would have taken the actuator out of the "
            "(voltage, output) region the model was identified on); allow extrapolation "
            "(allow_extrapolation=True, --allow-extrapolation) to send them, identify on a "
            "record that covers the target, or bring the target within it"
        )
    return parts
