"""Analysis: comparing models, choosing one, reports.
May import: the foundation, ``_kernels``, ``io``, ``model`` (never ``control``).
"""

from .._lazy import attach

# each module loaded at first use: piezohyst.analysis.NAME after import piezohyst
__getattr__, __dir__ = attach(__name__, {})
