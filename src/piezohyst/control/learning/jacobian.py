r"""The Jacobian learning law (``LearningCompensator(law="jacobian")``).

The harmonic law (:mod:`piezohyst.control.learning.design`) learns a correction of the
reference: each harmonic of the error, turned into volts by the model's inverse, that is
by its local slope. It converges while the actuator's slope over the model's stays near 1
(:attr:`~piezohyst.control.learning.design.LearningDesign.slope_error`). An actuator whose
output runs on past a reversal (``metrics.run_on``: the charge still rises while the
voltage already falls) has a negative slope there over every model that can be inverted,
and the inverse of a model whose branch is flat just past a reversal turns a small
reference change into a large voltage step, which the slew limit then cuts.

This law learns the commands themselves. After each trial it takes the model's Jacobian
along the trial's commands, :math:`J_{kj} = \partial y_k / \partial u_j` (the trial run
after itself, the model's input dynamics included: a command moves the output at its own
sample, through the lag at the next ones, and through the memory of a reversal it sets over
the rest of the trial; a lag the model does not hold is refused, identify it with the model),
and moves the commands by the damped
least-squares step

.. math:: \delta u = \gamma\,(J^\top J + \lambda I)^{-1} J^\top Q e,

with :math:`\gamma` and :math:`Q` from the same design as the harmonic law and
:math:`\lambda` = :data:`DAMPING` times :math:`J`'s largest singular value squared; the
commands then meet the voltage and slew limits. Each singular direction of the output moves
by :math:`\gamma\,\sigma^2/(\sigma^2 + \lambda) \le \gamma` of its error, so the step never
amplifies the measurement noise in the output, and where the model is flat the damping
keeps the voltage from jumping.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

FloatArray = np.ndarray

__all__ = ["DAMPING", "MAX_SAMPLES", "damped_step", "trial_jacobian", "uniform_shift"]

#: :math:`\lambda` over the Jacobian's largest singular value squared: among 1e-4, 1e-3 and
#: 1e-2, on the bench behind its 4 ms amplifier (seed 0, ActivePI with identified dynamics, 10
#: and 40 Hz scans: 1e-2 left the widest loops there), the one with the smaller step where the
#: model is flat of the two that tied (``docs/benchmarks.md`` says what else was seen first)
DAMPING = 1e-3
#: the longest trial this law learns: its Jacobian is a dense n x n matrix (4000: 128 MB)
MAX_SAMPLES = 4000
#: the finite-difference step, V per V of the commands' range (at least 1 mV)
STEP = 1e-5
#: the largest eigenvalue of :math:`J^\top J` to this relative accuracy (it only scales
#: :math:`\lambda`): at full precision Lanczos did not converge on a model without input
#: dynamics whose Jacobian's largest value repeats (``tests/fixtures/jacobian``)
TOP_TOL = 1e-9
#: below this many commands every eigenvalue is computed (exact, and cheap)
EXACT_BELOW = 64


def trial_jacobian(
    respond: Callable[[FloatArray], FloatArray], u: FloatArray, span: float
) -> FloatArray:
    """The Jacobian of ``respond`` at ``u`` by forward differences, one column per command.

    Parameters
    ----------
    respond : callable
        Commands (one trial) -> outputs (one per command).
    u : ndarray
        The trial's commands (V).
    span : float
        V, the commands' range: the step is ``STEP`` of it, at least 1 mV.

    Returns
    -------
    ndarray, shape (n, n)
    """
    n = u.size
    h = max(STEP * span, 1e-3)
    y0 = respond(u)
    jac = np.empty((n, n))
    moved = u.copy()
    for j in range(n):
        moved[j] = u[j] + h
        jac[:, j] = respond(moved) - y0
        moved[j] = u[j]
    return jac / h


def damped_step(jac: FloatArray, e: FloatArray, damping: float = DAMPING) -> FloatArray:
    r""":math:`(J^\top J + \lambda I)^{-1} J^\top e`, :math:`\lambda` = ``damping`` times
    :math:`J`'s largest singular value squared (zero where ``J`` is).

    The normal equations by Cholesky: with :math:`\lambda` at least ``damping`` of the largest
    eigenvalue, their condition number is at most ``1 + 1 / damping``; the largest eigenvalue
    of :math:`J^\top J` by Lanczos (``scipy.sparse.linalg.eigsh``, to :data:`TOP_TOL`; all of
    them below :data:`EXACT_BELOW` commands, or where Lanczos does not converge).

    Parameters
    ----------
    jac : ndarray, shape (m, n)
    e : ndarray, shape (m,)
    damping : float

    Returns
    -------
    ndarray, shape (n,)
    """
    from scipy.linalg import cho_factor, cho_solve  # here: import piezohyst stays light
    from scipy.sparse.linalg import ArpackNoConvergence, eigsh

    n = jac.shape[1]
    gram = jac.T @ jac
    top = float(np.linalg.eigvalsh(gram)[-1]) if n and n < EXACT_BELOW else 0.0
    if n >= EXACT_BELOW and np.any(gram):
        # a fixed start (the same trial, the same step), almost surely not orthogonal to it
        start = np.random.default_rng(0).standard_normal(n)
        try:
            top = float(eigsh(gram, k=1, which="LA", v0=start, tol=TOP_TOL,
                              return_eigenvectors=False)[0])  # fmt: skip
        except ArpackNoConvergence:  # never seen at TOP_TOL; all of them, then
            top = float(np.linalg.eigvalsh(gram)[-1])
    if not top > 0:
        return np.zeros(n)
    factor = cho_factor(gram + damping * top * np.eye(n))
    return np.asarray(cho_solve(factor, jac.T @ e))


def uniform_shift(
    respond: Callable[[FloatArray], FloatArray], u: FloatArray, offset: float, h: float = 1e-3
) -> float:
    """The one shift of every command that moves the output's mean by ``offset`` (a sensor's
    offset), by the mean response to a shift of ``h`` volts: a hysteresis is not additive, so
    the Jacobian's row sums (one sample at a time) are not that response. 0 where it is none.

    Parameters
    ----------
    respond : callable
        Commands (one trial) -> outputs.
    u : ndarray
        The trial's commands (V).
    offset : float
        The output's mean to add.
    h : float
        V, the shift the response is measured with.

    Returns
    -------
    float
        V.
    """
    slope = float(np.mean(respond(u + h) - respond(u))) / h
    return offset / slope if slope != 0 else 0.0
