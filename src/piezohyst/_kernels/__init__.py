"""The numba kernels: plain functions over arrays and explicit state; no classes, no I/O.

``play`` (play operators, their compensator, controller and bank steps), ``packed`` (the
Preisach, Duhem and Bouc-Wen cores' steps and inverse), ``signal`` (running integral, lags,
input and mode filters, turns), ``structure`` (coupled state-space dynamics with each
actuator's hysteresis in the loop). A module imports them as usual
(``from .._kernels import play as K``); numba loads when a kernel is first looked up, not
when piezohyst is imported (see :mod:`piezohyst._lazy`).
May import: the foundation (errors, _validation) only.
"""

from typing import TYPE_CHECKING

from .._lazy import LazyModule

if TYPE_CHECKING:
    from . import packed, play, signal, structure
else:  # stand-ins, each replaced by its module at first use (see _lazy)
    packed = LazyModule("piezohyst._kernels.packed", globals(), "packed")
    play = LazyModule("piezohyst._kernels.play", globals(), "play")
    signal = LazyModule("piezohyst._kernels.signal", globals(), "signal")
    structure = LazyModule("piezohyst._kernels.structure", globals(), "structure")

__all__ = ["packed", "play", "signal", "structure"]
