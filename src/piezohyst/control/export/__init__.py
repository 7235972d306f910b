"""The compensator (or the self-sensing controller) outside Python: its step as C, and the
hosts a lab runs that C in.

=================  =========================================================================
module             what it holds
=================  =========================================================================
``c_code``         :func:`export_c`, :func:`write_c`, :class:`CCode`, :func:`c_paths`: the
                   step as one C file and its header (double or float), from each core's C
                   in ``piezohyst/model/cores/c/``
``shared``         :func:`write_shared` (a shared library with an opaque-handle API, for
                   ctypes, LabVIEW or Simulink), :func:`write_mex` (a MEX gateway for MATLAB
                   and Octave), :data:`STATUS`, :func:`compiler`, :func:`library_path`
``fmu``            :func:`write_fmu`: an FMI 2.0 co-simulation FMU, :func:`fmu_platform`
``stage_c``        :func:`export_stage_c`, :func:`write_stage_c`, :func:`write_stage_shared`,
                   :func:`write_stage_fmu`, :func:`write_stage_mex`, :class:`StageCode`: a
                   coupled stage's compensator, each actuator's step and the coupling's
                   inverse around them, its library, FMU and MEX gateway (a stage's
                   self-sensing loop: its C and library)
``structure_c``    :func:`~.structure_c.write_structure_c`,
                   :func:`~.structure_c.write_structure_shared`,
                   :func:`~.structure_c.write_structure_mex`,
                   :func:`~.structure_c.write_structure_fmu`: a structure's compensator (the
                   tracker with preview of a ``StructureModel``), its library, MEX and FMU
``c/``             the hosts' C templates (the shared API, the MEX gateway, the FMI functions)
=================  =========================================================================
"""

from .c_code import CCode, c_paths, export_c, write_c
from .fmu import fmu_platform, write_fmu
from .shared import STATUS, compiler, library_path, write_mex, write_shared
from .stage_c import (
    StageCode,
    export_stage_c,
    write_stage_c,
    write_stage_fmu,
    write_stage_mex,
    write_stage_shared,
)

__all__ = [
    "STATUS",
    "CCode",
    "StageCode",
    "c_paths",
    "compiler",
    "export_c",
    "export_stage_c",
    "fmu_platform",
    "library_path",
    "write_c",
    "write_fmu",
    "write_mex",
    "write_shared",
    "write_stage_c",
    "write_stage_fmu",
    "write_stage_mex",
    "write_stage_shared",
]
