"""Models: terms, dynamics, the cores (``cores/``, one module per core), the estimator
contract, state, the fit, the model class and its presets, files and banks, and the
capacitor's leakage measured on holds (``leakage``).
May import: the foundation, ``_kernels``, ``io``.
"""

from .._lazy import attach

# each module loaded at first use: piezohyst.model.NAME after import piezohyst
__getattr__, __dir__ = attach(__name__, {})
