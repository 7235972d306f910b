"""Analysis: comparing models, choosing one, reports.
May import: the foundation, ``_kernels``, ``io``, ``model`` (never ``control``).
"""
