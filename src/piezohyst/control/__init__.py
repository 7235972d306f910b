"""Control: the inverse engines, the compensator, the self-sensing controller,
learning from repetition, channel banks and the C export.
May import: the foundation, ``_kernels``, ``io``, ``model`` (never ``analysis``).
"""
