"""Controllers run against the simulated bench, sample by sample."""

from __future__ import annotations

from typing import TypeGuard

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_signal
from ..control.compensator import Compensator
from ..control.selfsensing import SelfSensingController
from .bench import Bench, BenchRecord

__all__ = ["feedforward", "run_loop"]


def feedforward(controller: SelfSensingController | Compensator) -> TypeGuard[Compensator]:
    """True for a feedforward compensator (a whole trajectory at once, no reading), False
    for a controller that takes the reading after each command.

    Parameters
    ----------
    controller : SelfSensingController or Compensator

    Returns
    -------
    bool
    """
    return isinstance(controller, Compensator)


def run_loop(
    controller: SelfSensingController | Compensator, desired: ArrayLike, bench: Bench
) -> BenchRecord:
    """Drive ``bench`` with ``controller`` over a desired trajectory, one sample at a time.

    A :class:`~piezohyst.control.selfsensing.SelfSensingController` gets, each sample,
    the charge the bench read after the previous command (as on a rig: read
    the ADC, compute, write the DAC); a
    :class:`~piezohyst.control.compensator.Compensator` (feedforward) needs no
    reading. Sample ``k`` of the result is what the bench read after command
    ``k``, so ``displacement[k]`` is the response to ``desired[k]``.

    Parameters
    ----------
    controller : SelfSensingController or Compensator
        Reset to the bench's voltage before the run, or as the caller left it.
    desired : array_like, shape (N,)
        Desired values (the controller's units); NaN holds the last command.
    bench : Bench
        The plant, continuing from its present state.

    Returns
    -------
    BenchRecord
        Commands, readings and the hidden truth, one row per sample.
    """
    d = np.ascontiguousarray(desired, dtype=np.float64)
    as_signal(np.nan_to_num(d), "desired")  # 1-D and not empty
    if feedforward(controller):
        return bench.run(controller.process(d))
    rows = np.empty((d.size, 7))
    for k in range(d.size):
        r = bench.apply(controller.step(float(d[k]), bench.reading.charge))
        rows[k] = (
            r.t,
            r.voltage,
            r.charge,
            r.displacement,
            r.capacitor_charge,
            r.leak_charge,
            r.true_displacement,
        )
    p = bench.preset
    t, v, q, s, q_c, q_r, s_true = (np.ascontiguousarray(c) for c in rows.T)
    return BenchRecord(t, v, q, s, q_c, q_r, s_true, true_growth_rate=p.g_leak, preset=p)
