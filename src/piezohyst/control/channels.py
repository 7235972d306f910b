"""Banks of channels: one live compensator or controller per channel of a ModelBank.

:class:`ChannelBank` is what a bank's feedforward compensator and its
self-sensing controller share: per-channel settings (one value, or one per
channel), errors that name their channel, one live object per channel
(:meth:`~ChannelBank.channel`), the counters as arrays, shape checks, and the
stacked arrays of the one parallel kernel when every channel runs play
operators. :class:`BankCompensator` and :class:`BankController` add their
step.
"""

from __future__ import annotations

import math
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import Any, Generic, Literal, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._kernels import play as K
from .._kernels import signal as S
from .._validation import FloatArray
from ..errors import ExtrapolationWarning, LimitWarning, ParameterError, ShapeError, warn
from ..model.bank import ModelBank
from ..model.calibrations.leakage import Leakage
from ..model.calibrations.output_map import OutputMap, monotone_charges
from ..model.model import HysteresisModel
from .arguments import Domain
from .compensator import Compensator
from .selfsensing import SelfSensingController
from .tally import LIMIT_CHECK_FIRST, LIMIT_SHARE

__all__ = ["BankCompensator", "BankController", "ChannelBank", "per_channel"]

#: Steps of a fused bank whose commands are counted together (the slew-limit tally)
TALLY_ROWS = 64


#: A bank's channels: compensators, or self-sensing controllers
C = TypeVar("C", Compensator, SelfSensingController)


def per_channel(value: object, c: int, name: str) -> list[Any]:
    """A setting for each of ``c`` channels: a scalar (or None) repeated, or ``c`` values.

    Parameters
    ----------
    value : float, None or array_like
    c : int
        Channels.
    name : str
        The setting, named in the error.

    Returns
    -------
    list
        ``c`` values.
    """
    if value is None or isinstance(value, str | int | float | np.integer | np.floating):
        return [value] * c
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size != c:
        msg = f"'{name}' must be a number or one value per channel ({c}). Got {arr.size} values."
        raise ShapeError(msg)
    return [float(a) for a in arr]


class ChannelBank(ABC, Generic[C]):
    """One live object per channel of a fitted bank (see the module documentation)."""

    def __init__(self, bank: ModelBank, build: Callable[[int, HysteresisModel], C]) -> None:
        channels: list[C] = []
        for i, m in enumerate(self._models(bank)):
            try:
                channels.append(build(i, m))
            except (ParameterError, ShapeError) as exc:
                raise type(exc)(f"channel {i}: {exc}") from None
        self.bank = bank
        self._channels: list[C] = channels
        #: True when all channels run in the one parallel kernel (set by the subclass)
        self.fused = False

    def __len__(self) -> int:
        return len(self._channels)

    def step(
        self, desired: ArrayLike, measured: ArrayLike | None = None, *,
        out: FloatArray | None = None,
    ) -> FloatArray:  # fmt: skip
        """One command per channel.

        Parameters
        ----------
        desired : array_like, shape (C,)
            Desired output per channel; NaN or infinity holds that channel's
            last command (counted).
        measured : array_like, shape (C,), optional
            The charge read at this sample, per channel: a bank of controllers feeds it
            back (NaN for a channel, or None for all: feedforward alone), a bank of
            compensators ignores it (the controllers' one contract,
            :mod:`~piezohyst.control.contract`).
        out : ndarray, shape (C,), optional
            Written in place (a float64 array): nothing is allocated.

        Returns
        -------
        ndarray, shape (C,)
            Commands (V), each inside its channel's limits.
        """
        return self._step(desired, measured, out)

    def process(self, desired: ArrayLike, measured: ArrayLike | None = None) -> FloatArray:
        """Commands for a block: equal to :meth:`step` on each row.

        Parameters
        ----------
        desired, measured : array_like, shape (samples, C)
            As :meth:`step` takes them, a row per sample.

        Returns
        -------
        ndarray, shape (samples, C)
        """
        return self._process(desired, measured)

    @abstractmethod
    def _step(
        self, desired: ArrayLike, measured: ArrayLike | None, out: FloatArray | None
    ) -> FloatArray:
        """Each bank's :meth:`step`."""

    @abstractmethod
    def _process(self, desired: ArrayLike, measured: ArrayLike | None) -> FloatArray:
        """Each bank's :meth:`process`."""

    # -------------------------------------------------------------- limits that bite
    def _tally_reset(self) -> None:
        """The fused kernels' counts of commands held by the slew limit, from zero."""
        comps = [getattr(ch, "compensator", ch) for ch in self._channels]  # a controller's
        steps = np.array([getattr(cp, "max_step", math.inf) for cp in comps])
        self._tol = np.where(np.isfinite(steps), steps * (1.0 - 1e-9), np.inf)
        self._prev = self.last_command
        self._held = np.zeros(len(self._channels), dtype=np.int64)
        self._given = np.zeros(len(self._channels), dtype=np.int64)
        self._arrived = np.zeros(len(self._channels), dtype=np.bool_)  # on the trajectory
        self._approach = np.zeros(len(self._channels), dtype=np.int64)  # held before it
        self._approach_warned = False
        self._recent = np.empty((TALLY_ROWS, len(self._channels)))  # steps not yet counted
        self._pending = 0
        self._sent = 0  # every step's commands since the reset, the approach too
        self._check_at = LIMIT_CHECK_FIRST
        self._limits_warned: set[str] = set()  # the limits warned of, each once

    @property
    def slew_limited_count(self) -> NDArray[np.int64]:
        """Per channel: commands held back by the slew limit."""
        if self.fused:
            self._flush()
            return self._held.copy()
        return np.array([getattr(ch, "slew_limited_count", 0) for ch in self._channels],
                        dtype=np.int64)  # fmt: skip

    def _tally_step(self, commands: FloatArray) -> None:
        """:meth:`_tally` for one step's commands (C,), counted :data:`TALLY_ROWS` at a time
        (one kernel call per step would cost a third of the step)."""
        self._recent[self._pending] = commands
        self._pending += 1
        if self._pending == TALLY_ROWS:
            self._flush()

    def _flush(self) -> None:
        if self._pending:
            rows, self._pending = self._recent[: self._pending], 0
            self._tally(rows)

    def _tally(self, commands: FloatArray) -> None:
        """Count what the limits held in a block of fused commands (samples, C); warn once
        when on some channel they held more than :data:`LIMIT_SHARE` of its commands."""
        if self._pending and commands is not self._recent:
            self._flush()
        S.count_held(commands, self._prev, self._tol, self._held, self._given, self._arrived,
                     self._approach)  # fmt: skip
        self._sent += commands.shape[0]
        away = np.empty(0, dtype=np.int64)
        if not self._approach_warned:  # a ramp that arrives is not counted
            away = np.flatnonzero(~self._arrived & (self._approach >= LIMIT_CHECK_FIRST))
        if away.size:
            self._approach_warned = True
            worst = int(away[np.argmax(self._approach[away])])
            warn(
                f"{type(self).__name__}: the slew limit has held every command of {away.size} "
                f"of {len(self)} channels since the start ({int(self._approach[worst])} on "
                f"channel {worst}) and they have not reached the trajectory: the target runs "
                "ahead of what the limit lets them follow; set slew_rate to what the "
                "amplifiers allow, start nearer the trajectory (precondition), or slow the "
                "target",
                LimitWarning,
            )
        if len(self._limits_warned) == 2 or self._sent < self._check_at:
            return
        self._check_at = 2 * self._sent
        # the slew limit's share is of the commands on the trajectory; the voltage limits'
        # of every command, the approach too (they bite there: as Compensator's tally)
        sent = np.full(len(self._channels), self._sent, dtype=np.int64)
        held = {"slew limit": (self._held, self._given),
                "voltage limits": (self.saturated_count, sent)}  # fmt: skip
        parts = []
        for what, (counts, given) in held.items():
            over = np.flatnonzero((counts > LIMIT_SHARE * given) & (given >= LIMIT_CHECK_FIRST))
            if over.size and what not in self._limits_warned:  # each limit said once
                self._limits_warned.add(what)
                worst = int(over[np.argmax(counts[over])])
                parts.append(
                    f"the {what} held more than {100 * LIMIT_SHARE:g} % of the commands on "
                    f"{over.size} of {len(self)} channels (worst: channel {worst}, "
                    f"{int(counts[worst])} of {int(given[worst])})"
                )
        if parts:
            setting = "set slew_rate to what the amplifiers allow, or widen v_min/v_max"
            warn(f"{type(self).__name__}: {'; '.join(parts)}: {setting}",
                          LimitWarning)  # fmt: skip

    @classmethod
    def _models(cls, bank: ModelBank) -> list[HysteresisModel]:
        """The bank's models, one per channel (every channel fitted)."""
        if not isinstance(bank, ModelBank):
            msg = f"{cls.__name__} needs a fitted ModelBank. Got {type(bank).__name__}."
            raise ParameterError(msg)
        return bank.complete_models()

    def channel(self, index: int) -> C:
        """Channel ``index``'s object: live, sharing the bank's state.

        Parameters
        ----------
        index : int

        Returns
        -------
        Compensator or SelfSensingController
        """
        return self._channels[index]

    @property
    def v_min(self) -> FloatArray:
        """Lower limits in force, per channel (V)."""
        return np.array([ch.v_min for ch in self._channels])

    @property
    def v_max(self) -> FloatArray:
        """Upper limits in force, per channel (V)."""
        return np.array([ch.v_max for ch in self._channels])

    @property
    def last_command(self) -> FloatArray:
        """The last command of every channel (V)."""
        return np.array([ch.last_command for ch in self._channels])

    @property
    def nonfinite_count(self) -> NDArray[np.int64]:
        """Per channel: desired values that were NaN or infinite (the last command held)."""
        return np.array([ch.nonfinite_count for ch in self._channels], dtype=np.int64)

    @property
    def saturated_count(self) -> NDArray[np.int64]:
        """Per channel: commands clipped to the limits."""
        return np.array([ch.saturated_count for ch in self._channels], dtype=np.int64)

    @property
    def extrapolated_count(self) -> NDArray[np.int64]:
        """Per channel: desired displacements beyond its output map's calibrated range (see
        :attr:`Compensator.extrapolated_count`)."""
        return np.array([ch.extrapolated_count for ch in self._channels], dtype=np.int64)

    def _rows(self, arrays: Sequence[ArrayLike], names: str, ndim: int) -> list[FloatArray]:
        """The per-channel inputs as float arrays of one shape, ``(C,)`` or ``(samples, C)``."""
        out = [np.ascontiguousarray(a, dtype=np.float64) for a in arrays]
        c = len(self._channels)
        first = out[0]
        if first.ndim != ndim or first.shape[-1] != c or any(a.shape != first.shape for a in out):
            want = f"({c},)" if ndim == 1 else f"(samples, {c})"
            shapes = " and ".join(str(a.shape) for a in out)
            msg = f"{names} must have shape {want}, one value per channel. Got {shapes}."
            raise ShapeError(msg)
        return out

    @staticmethod
    def _out(out: FloatArray | None, shape: tuple[int, ...]) -> FloatArray:
        if out is None:
            return np.empty(shape)
        if out.shape != shape or out.dtype != np.float64:
            msg = f"'out' must be a float64 array of shape {shape}. Got {out.dtype} {out.shape}."
            raise ShapeError(msg)
        return out

    @staticmethod
    def _stack(rows: Sequence[FloatArray]) -> FloatArray:
        return np.ascontiguousarray(np.stack(list(rows)))


class BankCompensator(ChannelBank[Compensator]):
    r"""Feedforward compensation of every channel of a :class:`~piezohyst.ModelBank`.

    Channel ``c`` is exactly the :class:`Compensator` of ``bank[c]`` (same
    inverse, limits, slew limit, NaN handling and counters; :meth:`channel`
    returns it, live): :meth:`step` takes one desired value per channel and
    returns one command per channel. When every channel inverts analytically
    without input dynamics (play operators and removed growth terms), all
    channels run in one numba kernel, in parallel across cores, allocating
    nothing; otherwise the channels' own compensators run one after another.

    Built as ``ph.BankCompensator(bank, v_min=..., v_max=...)``.

    Parameters
    ----------
    bank : ModelBank
        A fitted bank (every channel fitted).
    v_min, v_max : float or array_like of C
        Voltage limits (V), shared or one per channel.
    slew_rate, gain : float or array_like of C, optional
        As for :class:`Compensator`, shared or per channel (the slew limit's
        default, "trained": each channel's training record's fastest change).
    sample_rate : float, optional
        The loop rate (Hz), shared.
    domain : {"charge", "displacement"}
    allow_extrapolation : bool, default False
        Limits beyond a channel's identified range are narrowed to it, with
        one warning naming how many channels were narrowed.
    output_maps : sequence of OutputMap, optional
        One charge -> displacement map per channel (:func:`~piezohyst.calibrate_gain`):
        desired values in metres, through each channel's map, instead of ``gain``. The maps
        run before the fused kernel: the linear ones in one pass over the channels.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> units = [ph.PIHysteresis([0.0, 20.0], [g * 1e-8, 5e-9]) for g in (1.0, 2.0)]
    >>> bank = ph.ModelBank.from_models([ph.ClassicalPI.from_operator(u) for u in units])
    >>> comp = ph.BankCompensator(bank, v_min=0.0, v_max=140.0)
    >>> desired = np.array([units[0].predict([50.0])[0], units[1].predict([80.0])[0]])
    >>> np.round(comp.step(desired), 9).tolist()
    [50.0, 80.0]
    """

    #: False: the commands do not depend on readings (the controllers' one contract,
    #: :mod:`~piezohyst.control.contract`)
    reads = False

    def __init__(
        self,
        bank: ModelBank,
        *,
        v_min: float | ArrayLike,
        v_max: float | ArrayLike,
        slew_rate: float | ArrayLike | Literal["trained"] | None = "trained",
        sample_rate: float | None = None,
        domain: Domain = "charge",
        gain: float | ArrayLike | None = None,
        allow_extrapolation: bool = False,
        output_maps: Sequence[OutputMap] | None = None,
    ) -> None:
        c = len(self._models(bank))
        lows, highs = per_channel(v_min, c, "v_min"), per_channel(v_max, c, "v_max")
        slews, gains = per_channel(slew_rate, c, "slew_rate"), per_channel(gain, c, "gain")
        maps: list[OutputMap | None] = [None] * c
        if output_maps is not None:
            maps = list(output_maps)
            if len(maps) != c:
                msg = f"'output_maps' must hold one map per channel ({c}). Got {len(maps)}."
                raise ShapeError(msg)

        def build(i: int, m: HysteresisModel) -> Compensator:
            return Compensator(m, v_min=lows[i], v_max=highs[i], slew_rate=slews[i],
                               sample_rate=sample_rate, domain=domain, gain=gains[i],
                               allow_extrapolation=allow_extrapolation,
                               output_map=maps[i])  # fmt: skip

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            super().__init__(bank, build)
        narrowed = sum(ch.requested_limits is not None for ch in self._channels)
        if narrowed:
            warn(
                f"Compensator limits narrowed on {narrowed} of {c} channels to the voltages "
                "each was identified on (pass allow_extrapolation=True to keep them; "
                "v_min/v_max show the limits in force).",
                UserWarning,
            )
        channels = self._channels
        #: the output maps' inverse before the kernel (None without maps)
        self._front = None if output_maps is None else _MapFront(channels)
        #: True when all channels run in the one parallel kernel
        self.fused = all(ch.inverse.plain for ch in channels)
        if self.fused:
            # one array per quantity; each channel's compensator keeps views of its row,
            # so channel(i) stays live and identical to the bank's state
            self.tables = self._stack([ch.inverse.tables for ch in channels])
            self.config = self._stack([ch.inverse.config for ch in channels])
            self._state = self._stack([ch.kernel_state for ch in channels])
            for i, ch in enumerate(channels):
                ch.share(self.tables[i], self.config[i], self._state[i])
        self._tally_reset()

    def reset(self, *, voltage: float | ArrayLike | None = None) -> None:
        """Every channel back to its model's initial state, or settled at ``voltage`` (per channel).

        Parameters
        ----------
        voltage : float or array_like of C, optional
        """
        volts = per_channel(voltage, len(self), "voltage")
        for ch, v in zip(self._channels, volts, strict=True):
            ch.reset(voltage=v)
        self._tally_reset()

    def precondition(self, samples: int = 1000) -> FloatArray:
        """Every channel's preconditioning cycle (see :meth:`Compensator.precondition`).

        Parameters
        ----------
        samples : int, default 1000
            Samples in each channel's cycle (more where a slew limit needs them).

        Returns
        -------
        ndarray, shape (samples', C)
            Commands to send first; a channel whose cycle is shorter (wider
            slew limit) holds its last command to the end.
        """
        cycles = [ch.precondition(samples) for ch in self._channels]
        m = max(cy.size for cy in cycles)
        out = np.empty((m, len(cycles)))
        for c, cy in enumerate(cycles):
            out[: cy.size, c] = cy
            out[cy.size :, c] = cy[-1]
        self._flush()
        self._prev = self.last_command  # a cycle at the slew limit by design: not counted,
        self._arrived[:] = False  # nor the ramp from its end to the trajectory
        self._approach[:] = 0  # (unless it is long)
        self._approach_warned = False
        return out

    def _step(
        self, desired: ArrayLike, measured: ArrayLike | None, out: FloatArray | None
    ) -> FloatArray:
        (d,) = self._rows([desired], "'desired'", 1)
        out = self._out(out, d.shape)
        if self.fused:
            if self._front is not None:
                d = self._front(d)
            K.bank_step(d, self.tables, self.config, self._state, out)
            self._tally_step(out)
        else:
            for i, ch in enumerate(self._channels):
                out[i] = ch.step(float(d[i]))
        return out

    def _process(self, desired: ArrayLike, measured: ArrayLike | None) -> FloatArray:
        (d,) = self._rows([desired], "'desired'", 2)
        out = np.empty_like(d)
        if self.fused:
            if self._front is not None:
                d = np.ascontiguousarray(self._front(d))
            K.bank_process(d, self.tables, self.config, self._state, out)
            self._tally(out)
        else:
            for i, ch in enumerate(self._channels):
                out[:, i] = ch.process(np.ascontiguousarray(d[:, i]))
        return out


class _MapFront:
    """Desired displacements as charges before a fused bank's kernel: each channel's output
    map, the linear ones in one pass over the channels (the arithmetic of
    :meth:`OutputMap.inverse`), a curved one through its channel's own front end."""

    def __init__(self, channels: Sequence[Compensator]) -> None:
        maps = [ch.output_map for ch in channels]
        lin = [i for i, m in enumerate(maps) if m is not None and m.order == 1]
        self.linear = np.array(lin, dtype=np.intp)
        self.curved = [(i, ch.charges) for i, ch in enumerate(channels)
                       if ch.output_map is not None and ch.output_map.order != 1]  # fmt: skip
        chosen = [m for m in maps if m is not None and m.order == 1]
        self.counted = [channels[i].charges for i in lin]  # each linear channel's count
        self.center = np.array([m.center for m in chosen])
        self.scale = np.array([m.scale for m in chosen])
        self.c0 = np.array([m.coefficients[0] for m in chosen])
        self.c1 = np.array([m.coefficients[1] for m in chosen])
        self.edges = tuple(np.array(col) for col in zip(*(m.edges() for m in chosen), strict=True))

    def __call__(self, desired: FloatArray) -> FloatArray:
        out = desired.copy()
        if self.linear.size:
            q, beyond = monotone_charges(desired[..., self.linear], self.center, self.scale,
                                         self.c0, self.c1, self.edges)  # fmt: skip
            out[..., self.linear] = q
            if beyond.any():
                per = beyond.reshape(-1, self.linear.size).sum(axis=0)
                for charges, n in zip(self.counted, per, strict=True):  # each channel's count
                    assert charges is not None
                    charges.outside += int(n)
                warn(
                    "BankCompensator: desired displacements lie outside their channels' "
                    "calibrated ranges; each map is extended linearly from its edge there "
                    "(calibrate over the full drive to hold it)",
                    ExtrapolationWarning,
                )
        for i, charges in self.curved:  # counted by the channel's own front end
            assert charges is not None
            column = np.ascontiguousarray(desired[..., i]).reshape(-1)
            out[..., i] = charges.block(column).reshape(desired[..., i].shape)
        return out


class BankController(ChannelBank[SelfSensingController]):
    """The self-sensing controller of every channel of a :class:`~piezohyst.ModelBank`.

    Channel ``c`` is exactly the :class:`SelfSensingController` of ``bank[c]``
    (:meth:`channel` returns it, live); :meth:`step` takes one desired value
    and one measured charge per channel, and all channels run in one numba
    kernel across cores. Usually built as
    ``ph.BankController(bank, v_min=..., v_max=..., sample_rate=...)``.

    Parameters
    ----------
    bank : ModelBank
        A fitted bank (every channel fitted). Play-operator channels run in one
        parallel kernel; Preisach, Duhem or Bouc-Wen channels one after another.
    v_min, v_max : float or array_like of C
        Voltage limits (V).
    sample_rate : float
        The loop rate (Hz), shared.
    leakage : Leakage or sequence of Leakage, optional
        One calibration for all channels, or one per channel (default: each
        channel's identified leakage).
    **settings
        The other settings of :class:`SelfSensingController` (``ki``, ``kp``,
        ``slew_rate``, ``domain``, ``gain``...), shared; ``slew_rate`` and
        ``gain`` may be one per channel.

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> units = [ph.PIHysteresis([0.0, 20.0], [g * 1e-8, 5e-9]) for g in (1.0, 2.0)]
    >>> bank = ph.ModelBank.from_models([ph.ClassicalPI.from_operator(u) for u in units])
    >>> ctl = ph.BankController(bank, v_min=0.0, v_max=140.0, sample_rate=1000.0)
    >>> ctl.step(np.array([2e-7, 4e-7]), np.array([0.0, 0.0])).shape
    (2,)
    """

    #: True: each command depends on the reading before it (the controllers' one contract,
    #: :mod:`~piezohyst.control.contract`)
    reads = True

    def __init__(
        self,
        bank: ModelBank,
        *,
        v_min: float | ArrayLike,
        v_max: float | ArrayLike,
        sample_rate: float,
        leakage: Leakage | list[Leakage] | tuple[Leakage, ...] | None = None,
        **settings: Any,
    ) -> None:
        c = len(self._models(bank))
        lows, highs = per_channel(v_min, c, "v_min"), per_channel(v_max, c, "v_max")
        per = {
            k: per_channel(settings.pop(k, default), c, k)
            for k, default in (("slew_rate", "trained"), ("gain", None))
        }
        if leakage is None or isinstance(leakage, Leakage):
            leaks: list[Leakage | None] = [leakage] * c
        else:
            leaks = list(leakage)
            if len(leaks) != c:
                msg = f"'leakage' must be one Leakage or one per channel ({c}). Got {len(leaks)}."
                raise ShapeError(msg)

        def build(i: int, m: HysteresisModel) -> SelfSensingController:
            return SelfSensingController(m, v_min=lows[i], v_max=highs[i],
                                         sample_rate=sample_rate, leakage=leaks[i],
                                         slew_rate=per["slew_rate"][i], gain=per["gain"][i],
                                         **settings)  # fmt: skip

        super().__init__(bank, build)
        channels = self._channels
        #: True when all channels run in the one parallel kernel (play operators); a bank
        #: of Preisach, Duhem or Bouc-Wen models runs its channels' controllers in turn
        self.fused = all(ch.compensator.plain for ch in channels)
        self._tally_reset()
        if not self.fused:
            return
        comps = [ch.compensator for ch in channels]
        self.tables = self._stack([cp.inverse.tables for cp in comps])
        comp_config = self._stack([cp.inverse.config for cp in comps])
        self.state_array = self._stack([cp.kernel_state for cp in comps])
        self.config = self._stack([ch.config for ch in channels])
        self.ctl = self._stack([ch.ctl for ch in channels])
        self.feedback = self._stack([ch.feedback for ch in channels])
        for i, ch in enumerate(channels):  # each channel keeps views of its rows: live
            ch.compensator.share(self.tables[i], comp_config[i], self.state_array[i])
            ch.config, ch.ctl, ch.feedback = self.config[i], self.ctl[i], self.feedback[i]

    @property
    def measurement_faults(self) -> NDArray[np.int64]:
        """Per channel: non-finite measurements (feedforward used)."""
        return np.array([ch.measurement_faults for ch in self._channels], dtype=np.int64)

    def reset(self) -> None:
        """Every channel back to its initial state, feedback cleared."""
        for ch in self._channels:
            ch.reset()
        self._tally_reset()

    def _step(
        self, desired: ArrayLike, measured: ArrayLike | None, out: FloatArray | None
    ) -> FloatArray:
        if measured is None:
            measured = np.full(np.shape(desired), np.nan)
        d, m = self._rows([desired, measured], "'desired' and 'measured'", 1)
        out = self._out(out, d.shape)
        if not self.fused:
            for i, ch in enumerate(self._channels):
                out[i] = ch.step(float(d[i]), float(m[i]))
            return out
        K.bank_controller_step(
            d, m, self.tables, self.config, self.state_array, self.ctl, self.feedback, out
        )
        self._tally_step(out)
        return out

    def _process(self, desired: ArrayLike, measured: ArrayLike | None) -> FloatArray:
        if measured is None:
            measured = np.full(np.shape(desired), np.nan)
        d, m = self._rows([desired, measured], "'desired' and 'measured'", 2)
        out = np.empty_like(d)
        if not self.fused:
            for i, ch in enumerate(self._channels):
                out[:, i] = ch.process(np.ascontiguousarray(d[:, i]), np.ascontiguousarray(m[:, i]))
            return out
        K.bank_controller_process(
            d, m, self.tables, self.config, self.state_array, self.ctl, self.feedback, out
        )
        self._tally(out)
        return out
