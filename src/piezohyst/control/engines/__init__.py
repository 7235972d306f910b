"""The inverse engines: how the compensator inverts each family of cores, one sample at a
time.

A core's :meth:`~piezohyst.model.cores.base.Core.inverse_plan` names its engine;
:class:`~piezohyst.Compensator` looks it up in :data:`INVERSES` and builds one
from the model's :class:`~piezohyst.model.model.InverseSpec` and its
:class:`EngineSettings`. The engine owns its kernel arrays (the tables, the
config and the state the compiled step updates in place): it runs the step
(``inner_step``, ``inner_process``, and the self-sensing loop's
``controller_step``, which takes the loop's own arrays and returns the
command), and reads, resets and advances its state. The compensator and the
controller hold an engine; an engine knows neither.

* ``"play"``: eq. 18 on play operators (Newton beside kept static or creep
  terms), the play kernels of :mod:`piezohyst._kernels`;
* ``"packed"``: the Preisach, Duhem and Bouc-Wen cores' bracketed Newton step
  (:mod:`piezohyst._kernels.packed`), with creep lags and a relaxing core;
* ``"python"``: any core, by a bracketed root search on
  :meth:`~piezohyst.model.cores.base.Core.propagate` (a core defined outside the
  library: no compiled step, no C).

==========  =======================================================================
module      what it holds
==========  =======================================================================
``base``    the contract, :class:`~.base.Inverse`; :class:`~.base.EngineSettings`,
            :class:`~.base.CompensatorState`
``play``    :class:`~.play.PlayInverse`
``packed``  :class:`~.packed.PackedInverse`
``python``  :class:`~.python.PythonInverse`
==========  =======================================================================

:data:`INVERSES` maps each engine's name to it (a core's ``inverse_plan().engine``).
"""

from .base import CompensatorState, EngineSettings, Inverse, finite_number
from .packed import PackedInverse
from .play import PlayInverse
from .python import PythonInverse

#: The compensator's engine for each inverse plan (a core's ``inverse_plan().engine``)
INVERSES: dict[str, type[Inverse]] = {
    PlayInverse.name: PlayInverse,
    PackedInverse.name: PackedInverse,
    PythonInverse.name: PythonInverse,
}

__all__ = [
    "INVERSES",
    "CompensatorState",
    "EngineSettings",
    "Inverse",
    "PackedInverse",
    "PlayInverse",
    "PythonInverse",
    "finite_number",
]
