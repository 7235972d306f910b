"""File-to-file workflows: what each ``piezohyst`` command does, callable from Python.

Each function reads its inputs, calls the library, and writes its outputs
atomically (a failure leaves no output file). The CLI is a thin shell over
these; from Python they are one call each too::

    import piezohyst.workflows as wf
    model = wf.fit_file("run.csv", "model.json", model="active-pi", operators=20)

This package defines nothing itself; each command family has its module:

=======================  ==========================================================
module                   commands (functions)
=======================  ==========================================================
``record_files``         ``simulate``, ``excite`` (:func:`simulate_file`, :func:`excite_file`)
``model_files``          ``fit``, ``select``/``fit --model auto``, ``compare``, ``predict``
                         (:func:`fit_file`, :func:`select_file`, :func:`compare_file`,
                         :func:`predict_file`, :class:`Prediction`)
``stage_files``          ``fit``, ``predict``, ``compensate``, ``export-c`` with several columns: a
                         coupled stage or a structure (``fit_stage_file``, ``fit_structure_file``)
``stage_report``         ``report`` of a stage or a structure (``stage_report``)
``stage_loop_files``     ``calibrate-stage``, and ``export-c``/``export-fmu`` of a stage map: a
                         stage on its actuators' charges (``calibrate_stage_file``,
                         ``export_stage_loop_file``)
``compensate``           ``compensate`` (:func:`compensate_file`, :class:`Compensation`)
``calibrate_files``      ``calibrate-leakage``, ``calibrate-gain`` (:func:`calibrate_leakage_file`,
                         :func:`calibrate_gain_file`)
``export_files``         ``export-c``, ``export-fmu`` (:func:`export_file`: C, a shared library, a
                         MEX gateway or an FMU, by the output file)
``loop_files``           ``simulate-loop`` (:func:`simulate_loop_file`, :class:`LoopRun`)
``report_files``         ``report`` (:func:`model_report`)
``learning_files``       ``learn`` (``learn_file``)
``fleet``                ``fit-many``: a fleet of records on Dask (``fit_many``)
``excitation``           the voltages ``excite`` plays (``excitation``, ``Excitation``)
``demo``                 ``demo``: the paper's experiment on the simulated bench
``_base``                what every workflow shares: loading, output guards, units
=======================  ==========================================================
"""

from __future__ import annotations

from ._base import guard_outputs
from .calibrate_files import calibrate_gain_file, calibrate_leakage_file
from .compensate import Compensation, compensate_file
from .export_files import export_file
from .loop_files import LoopRun, simulate_loop_file
from .model_files import Prediction, compare_file, fit_file, predict_file, select_file
from .record_files import excite_file, simulate_file
from .report_files import model_report

__all__ = [
    "Compensation",
    "LoopRun",
    "Prediction",
    "calibrate_gain_file",
    "calibrate_leakage_file",
    "compare_file",
    "compensate_file",
    "excite_file",
    "export_file",
    "fit_file",
    "guard_outputs",
    "model_report",
    "predict_file",
    "select_file",
    "simulate_file",
    "simulate_loop_file",
]
