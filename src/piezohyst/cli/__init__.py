"""The ``piezohyst`` command: a thin shell over the library.

Every command is one call of a library function; errors a user can cause
print one line on stderr and exit 1 (usage errors exit 2), with the
traceback only under ``--debug``.

This package defines nothing itself: :func:`main` is the click group (``_main``), and each
command group has its module:

===============  ======================================================================
module           commands
===============  ======================================================================
``_records``     ``simulate``, ``excite``
``_models``      ``fit`` (``--model auto``: ``_support``), ``compare``, ``predict``, ``fit-many``
``_compensate``  ``compensate``
``_report``      ``report``
``_loop``        ``simulate-loop``
``_calibrate``   ``calibrate-leakage``, ``calibrate-gain``, ``calibrate-stage``
``_export``      ``export-c``, ``export-fmu``
``_learn``       ``learn``
``_demo``        ``demo``
``_support``     the options every command shares, the run wrapper and its one-line errors
===============  ======================================================================
"""

from ._main import main

__all__ = ["main"]
