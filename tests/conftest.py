"""Hypothesis profiles.

``ci`` (the default, and what ``make test`` runs): derandomized, so every run of the suite
tries the same examples on every machine, and no example database, so nothing a previous
run found changes what this one tries. ``dev`` (``HYPOTHESIS_PROFILE=dev``): random,
five times the examples, with the database, for a longer hunt before a change lands.
A ``--hypothesis-seed`` on the command line picks the examples of either.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

# Kernels compile on first call (numba): no per-example deadline.
_COMMON = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow]}
settings.register_profile("ci", max_examples=60, derandomize=True, database=None, **_COMMON)
settings.register_profile("dev", max_examples=300, **_COMMON)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
