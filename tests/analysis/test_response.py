"""A record's own frequency response (Welch's H1) for several inputs and outputs: against a
known system's, and what it refuses to estimate."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from piezohyst.analysis.response import measured_response
from piezohyst.errors import ParameterError
from piezohyst.workflows.excitation import excitation

FS = 1000.0
#: Each path's short impulse response (outputs, inputs, lags)
H = np.array([[[1.0, 0.5, -0.2], [0.05, 0.03, 0.0]],
              [[-0.04, 0.0, 0.02], [0.8, -0.3, 0.1]],
              [[0.3, 0.3, 0.3], [0.2, -0.2, 0.0]]])  # fmt: skip


def _through(u: np.ndarray) -> np.ndarray:
    return np.column_stack([sum(lfilter(H[o, i], [1.0], u[:, i]) for i in range(2))
                            for o in range(3)])  # fmt: skip


def _truth(f: np.ndarray) -> np.ndarray:
    z = np.exp(-2j * np.pi * np.outer(f / FS, np.arange(3)))  # (F, lags)
    return np.einsum("oil,fl->foi", H, z)


def test_white_inputs_give_the_system_s_response() -> None:
    rng = np.random.default_rng(0)
    u = rng.standard_normal((40000, 2))
    y = _through(u) + 0.01 * rng.standard_normal((40000, 3))
    est = measured_response(u, y, FS)
    assert est.segment == 8192 and est.frequency.size > 3000
    err = np.abs(est.response - _truth(est.frequency))
    # tol: H1's scatter with output noise 1 % of the inputs' over 9 half-overlapping
    # segments: per value about 0.01 / sqrt(9) (RMS 0.004 here, the inputs' sample
    # covariance inflating it); the largest of 25000 values (0.026 here) within 12 times
    # that; the 3-lag paths' leakage across 8192-sample segments is far below it
    assert np.sqrt(np.mean(err**2)) < 0.01 and err.max() < 0.05
    assert np.all(est.coherence > 0.99)  # the outputs are the inputs', but for 1 % of noise


def test_a_multisine_on_interleaved_lines_is_separated() -> None:
    """excite's multisine for two actuators: the longest segments' bins (half the lines'
    spacing) each hold a single actuator's line; the estimate shortens its segments until a
    window's main lobe (two bins either side) holds both actuators' lines."""
    exc = excitation("multisine", v_min=-1, v_max=1, sample_rate=FS, band=300, actuators=2,
                     periods=16)  # fmt: skip
    a, b = exc.steady
    u = exc.voltage[a:b]
    est = measured_response(u, _through(u), FS)
    assert est.segment == 1024  # not 2048, the longest 16 periods allow
    inside = est.frequency <= 290  # the band's edge: bins that reach past it hold one line
    # tol: noise-free; the periodic signal's windowed segments leak between the lines, a
    # bias smaller than 1 % of the largest path (0.0036 here)
    np.testing.assert_allclose(est.response[inside], _truth(est.frequency[inside]), atol=0.01)


def test_what_cannot_be_estimated_is_empty() -> None:
    rng = np.random.default_rng(1)
    v = rng.standard_normal(5000)
    u = np.column_stack([v, 2 * v])  # the inputs move together at every frequency
    est = measured_response(u, _through(u), FS)
    assert est.frequency.size == 0 and est.response.shape == (0, 3, 2)
    short = measured_response(rng.standard_normal((200, 2)), np.zeros((200, 3)), FS)
    assert short.frequency.size == 0  # fewer than 8 segments of 64 samples
    with pytest.raises(ParameterError, match="one length"):
        measured_response(np.zeros((10, 2)), np.zeros((9, 3)), FS)
