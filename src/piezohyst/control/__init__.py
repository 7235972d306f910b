"""Control: the inverse engines, the compensator, the self-sensing controller,
learning from repetition, channel banks and the C export.
May import: the foundation, ``_kernels``, ``io``, ``model`` (never ``analysis``).
"""

from .._lazy import attach

# each module loaded at first use: piezohyst.control.NAME after import piezohyst
__getattr__, __dir__ = attach(__name__, {})
