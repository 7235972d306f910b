from __future__ import annotations

from hypothesis import HealthCheck, settings

# Kernels compile on first call (numba): no per-example deadline.
settings.register_profile(
    "piezohyst", deadline=None, suppress_health_check=[HealthCheck.too_slow], max_examples=60
)
settings.load_profile("piezohyst")
