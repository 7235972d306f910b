"""A record's own frequency response from several inputs to several outputs, estimated
without a model: what a structure's identified response is checked against.

Welch's averaged spectra (Hann-windowed segments, half overlapping, each segment's mean
taken out) give, at every frequency bin, the inputs' cross-spectral matrix ``Suu`` and the
outputs' with the inputs ``Syu``; the response is ``H = Syu Suu^-1`` (the H1 estimate: an
output's noise, or the part of it the inputs do not explain linearly, such as an
actuator's hysteresis, averages out of it). At a bin the inputs do not excite, or where
they move together (``Suu`` near singular: a single frequency's inputs always do, so the
segments must each span several of a multisine's lines), the response is not estimated.
The multiple coherence says, per output and bin, the share of the output's power the
inputs explain linearly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import ParameterError

__all__ = ["MeasuredResponse", "measured_response"]

#: Segments the record is cut into, at least (the averages' variance falls as one over it)
SEGMENTS = 8
#: The longest segment (samples)
MAX_SEGMENT = 8192
#: Bins whose inputs' power is below this share of the strongest bin's are not excited
EXCITED = 1e-4
#: A bin whose inputs' cross-spectral matrix is this ill-conditioned cannot separate them
#: (independent noises over 8 segments: mostly below 10) ...
SEPARABLE = 30.0
#: ... and segments are shortened until this share of the excited bins can
SEPARATED = 0.8


@dataclass(frozen=True)
class MeasuredResponse:
    """A record's response estimate.

    Attributes
    ----------
    frequency : ndarray, shape (F,)
        Hz, the estimated bins only.
    response : ndarray of complex, shape (F, outputs, inputs)
    coherence : ndarray, shape (F, outputs)
        Each output's multiple coherence with the inputs (0 to 1).
    segment : int
        Samples per segment (the resolution is the sample rate over it).
    """

    frequency: FloatArray
    response: np.ndarray
    coherence: FloatArray
    segment: int


def measured_response(u: ArrayLike, y: ArrayLike, sample_rate: float) -> MeasuredResponse:
    """The H1 estimate of the response from the inputs ``u`` to the outputs ``y``.

    Parameters
    ----------
    u : array_like, shape (N, inputs)
    y : array_like, shape (N, outputs)
    sample_rate : float
        Hz.

    Returns
    -------
    MeasuredResponse
        Empty (no bins) where the record is too short for :data:`SEGMENTS` segments of 64
        samples or excites no bin the inputs can be told apart at.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((20000, 2))
    >>> y = np.column_stack([lfilter([0.5], [1, -0.5], u[:, 0]) + 0.1 * u[:, 1], u[:, 1]])
    >>> est = measured_response(u, y, 1000.0)
    >>> float(round(abs(est.response[0, 0, 0]), 2)), float(round(abs(est.response[0, 0, 1]), 2))
    (1.0, 0.1)
    """
    ua = np.asarray(u, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    if ua.ndim != 2 or ya.ndim != 2 or ua.shape[0] != ya.shape[0]:
        msg = f"'u' and 'y' must be (samples, channels) of one length: {ua.shape}, {ya.shape}"
        raise ParameterError(msg)
    n_samples = ua.shape[0]
    longest = min(MAX_SEGMENT, n_samples * 2 // (SEGMENTS + 1))
    empty = MeasuredResponse(np.zeros(0), np.zeros((0, ya.shape[1], ua.shape[1]), complex),
                             np.zeros((0, ya.shape[1])), 0)  # fmt: skip
    segment = 2 ** int(np.floor(np.log2(max(longest, 1))))
    while segment >= 64:  # the longest segments whose bins can tell the inputs apart
        found = _welch(ua, ya, segment, sample_rate)
        if found is not None:
            return found
        segment //= 2
    return empty


def _welch(u: FloatArray, y: FloatArray, segment: int, rate: float) -> MeasuredResponse | None:
    """The estimate from segments of ``segment`` samples, or None where fewer than
    :data:`SEPARATED` of the excited bins can tell the inputs apart."""
    window = np.hanning(segment)
    starts = range(0, u.shape[0] - segment + 1, segment // 2)

    def spectra(x: FloatArray) -> np.ndarray:
        seg = np.stack([x[s : s + segment] for s in starts])  # (K, L, channels)
        seg = seg - seg.mean(axis=1, keepdims=True)
        return np.fft.rfft(seg * window[None, :, None], axis=1)  # (K, F, channels)

    uf, yf = spectra(u), spectra(y)
    suu = np.einsum("kfi,kfj->fij", uf.conj(), uf)  # Suu[i, j] = sum conj(U_i) U_j
    syu = np.einsum("kfo,kfi->foi", yf, uf.conj())  # Syu[o, i] = sum Y_o conj(U_i)
    syy = np.einsum("kfo,kfo->fo", yf.conj(), yf).real
    power = np.real(np.einsum("fii->f", suu))
    power[0] = 0.0  # each segment's mean is taken out
    if not power.max() > 0:
        return None
    excited = np.flatnonzero(power > EXCITED * power.max())
    bins = excited[np.linalg.cond(suu[excited]) < SEPARABLE]
    if bins.size < max(SEPARATED * excited.size, 1):
        return None
    # Y = H U: Syu = H Suu^T, so H^T = Suu^-1 Syu^T, bin by bin
    h = np.linalg.solve(suu[bins], syu[bins].transpose(0, 2, 1)).transpose(0, 2, 1)
    explained = np.einsum("foi,foi->fo", syu[bins], h.conj()).real  # H Suu^T H^H, per output
    coherence = np.clip(explained / np.maximum(syy[bins], 1e-300), 0.0, 1.0)
    freq = bins * rate / segment
    return MeasuredResponse(np.asarray(freq, dtype=np.float64), h, coherence, segment)
