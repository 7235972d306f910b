"""Models: terms, dynamics, the cores (``cores/``, one module per core), the estimator
contract, state, the fit, the model class and its presets, files and banks, and the
capacitor's leakage measured on holds (``leakage``).
May import: the foundation, ``_kernels``, ``io``.
"""
