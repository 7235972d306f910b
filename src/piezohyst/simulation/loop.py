"""Controllers run against the simulated bench, sample by sample."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_signal
from ..control.contract import Controller
from .bench import Bench, BenchRecord

__all__ = ["run_loop"]


def run_loop(controller: Controller, desired: ArrayLike, bench: Bench) -> BenchRecord:
    """Drive ``bench`` with ``controller`` over a desired trajectory, one sample at a time.

    Any controller of the one contract (:mod:`~piezohyst.control.contract`): one that
    reads (``reads``: the self-sensing controller, the learning compensator) gets,
    each sample, the charge the bench read after the previous command (as on a rig: read
    the ADC, compute, write the DAC), and the trajectory's next values where it takes them
    (``previews``: an output map's mode, a delay); a feedforward one (the compensator) is sent the
    whole trajectory at once. Sample ``k`` of the result is what the bench read after
    command ``k``, so ``displacement[k]`` is the response to ``desired[k]``.

    Parameters
    ----------
    controller : Controller
        A compensator, self-sensing controller or learning compensator (with its
        trajectory: the first ``command``), as the caller left it.
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
    if not controller.reads:
        return bench.run(controller.process(d))
    rows = np.empty((d.size, 7))
    ahead = int(getattr(controller, "previews", 0))  # a planned trajectory's next values
    previewed: Any = controller  # one that says ``previews`` takes them (beyond the contract)
    for k in range(d.size):
        if ahead:
            c = previewed.step(float(d[k]), bench.reading.charge, d[k + 1 : k + 1 + ahead])
        else:
            c = controller.step(float(d[k]), bench.reading.charge)
        r = bench.apply(c)
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
