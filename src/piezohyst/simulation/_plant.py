"""Numba kernel of the simulated bench (one pass over the samples)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# state of the bench between calls (one float array)
S_Q_R = 0  # charge through the leakage resistor (C)
S_V_AMP = 1  # charge-amplifier output (V)
S_Q_C = 2  # capacitor charge at the last sample (C)
S_I_R = 3  # leakage current at the last sample (A)
S_Q_IRR = 4  # irreversible (relay) charge (C)
S_V = 5  # last voltage (V)
S_T = 6  # last time (s)
S_STARTED = 7  # 1 once the first sample settled the relays
STATE_SIZE = 8


@njit(cache=True)
def bench_kernel(  # type: ignore[no-untyped-def]
    t,
    v,
    alpha,  # (M,) Preisach relay up-switching voltages, V
    beta,  # (M,) down-switching voltages, V (beta < alpha)
    mu,  # (M,) relay weights, C (sum = saturation irreversible charge)
    by_alpha,  # (M,) relay indices sorted by alpha
    by_beta,  # (M,) relay indices sorted by beta
    relays,  # (M,) relay states +-1, updated in place
    elec,  # (C0, G0, leak_voltage_coeff, v_ref, i_bias, C_f, R_f)
    state,  # (STATE_SIZE,) carried between calls, updated in place
    q_c_out,
    q_r_out,
    v_amp_out,
):
    """Integrate the nonlinear capacitor, the leakage and the charge amplifier.

    Capacitor charge ``Q_C = C0 V + sum_j mu_j s_j`` with Preisach relays
    ``s_j`` (up at ``V >= alpha_j``, down at ``V <= beta_j``). Leakage current
    ``i_R = G0 (1 + a |V| / v_ref) V`` (trapezoid in time). The active
    Sawyer-Tower amplifier integrates the piezo current plus its input bias
    current on the feedback capacitor ``C_f`` that leaks through ``R_f``.
    Calls continue where the last one stopped (``state``): blocks of any
    size, down to one sample, equal one call.
    """
    c0, g0, a_leak, v_ref, i_bias, c_f, r_f = (
        elec[0],
        elec[1],
        elec[2],
        elec[3],
        elec[4],
        elec[5],
        elec[6],
    )
    m = alpha.shape[0]
    # Relays sorted by switching voltage: after a sample at v, every relay with
    # alpha <= v is up and every one with beta >= v is down, so when the input
    # rises from v_prev to v only relays with alpha in (v_prev, v] can flip (and
    # falling, only beta in [v, v_prev)). Each sample visits those alone.
    alpha_sorted = alpha[by_alpha]
    beta_sorted = beta[by_beta]
    q_r = state[S_Q_R]
    v_amp = state[S_V_AMP]
    q_c_prev = state[S_Q_C]
    i_prev = state[S_I_R]
    q_irr = state[S_Q_IRR]
    v_prev = state[S_V]
    t_prev = state[S_T]
    started = state[S_STARTED] > 0.0
    for k in range(v.shape[0]):
        vk = v[k]
        if not started:  # the first sample settles every relay
            for j in range(m):
                if vk >= alpha[j]:
                    relays[j] = 1.0
                elif vk <= beta[j]:
                    relays[j] = -1.0
                q_irr += mu[j] * relays[j]
        elif vk > v_prev:
            lo = np.searchsorted(alpha_sorted, v_prev, side="right")
            hi = np.searchsorted(alpha_sorted, vk, side="right")
            for i in range(lo, hi):
                j = by_alpha[i]
                if relays[j] < 0.0:
                    relays[j] = 1.0
                    q_irr += 2.0 * mu[j]
        elif vk < v_prev:
            lo = np.searchsorted(beta_sorted, vk, side="left")
            hi = np.searchsorted(beta_sorted, v_prev, side="left")
            for i in range(lo, hi):
                j = by_beta[i]
                if relays[j] > 0.0:
                    relays[j] = -1.0
                    q_irr -= 2.0 * mu[j]
        v_prev = vk
        q_c = c0 * vk + q_irr
        i_r = g0 * (1.0 + a_leak * abs(vk) / v_ref) * vk
        if started:
            dt = t[k] - t_prev
            dq_r = 0.5 * (i_r + i_prev) * dt
            q_r += dq_r
            # feedback capacitor: C_f dVo/dt = i_in + i_bias - Vo / R_f, exact decay per step
            decay = math.exp(-dt / (r_f * c_f))
            v_amp = v_amp * decay + ((q_c - q_c_prev) + dq_r + i_bias * dt) / c_f
        started = True
        t_prev = t[k]
        q_c_out[k] = q_c
        q_r_out[k] = q_r
        v_amp_out[k] = v_amp
        q_c_prev = q_c
        i_prev = i_r
    state[S_Q_R] = q_r
    state[S_V_AMP] = v_amp
    state[S_Q_C] = q_c_prev
    state[S_I_R] = i_prev
    state[S_Q_IRR] = q_irr
    state[S_V] = v_prev
    state[S_T] = t_prev
    state[S_STARTED] = 1.0 if started else 0.0


@njit(cache=True)
def amplifier_lag(t, v, tau, state, out):  # type: ignore[no-untyped-def]
    """The voltage that reaches the piezo: a first-order lag ``tau`` (s) of the command.

    The command ``v[k]`` is held over the sample ending at ``t[k]``, so the
    piezo voltage there is ``u[k] = u[k-1] + (1 - exp(-dt/tau)) (v[k] - u[k-1])``
    (exact for the held command). ``state`` = [u, t, started]; the first sample
    starts settled at its command.
    """
    u = state[0]
    t_prev = state[1]
    started = state[2] > 0.0
    for k in range(v.shape[0]):
        if not started or tau <= 0.0:
            u = v[k]
            started = True
        else:
            u += (1.0 - math.exp(-(t[k] - t_prev) / tau)) * (v[k] - u)
        t_prev = t[k]
        out[k] = u
    state[0] = u
    state[1] = t_prev
    state[2] = 1.0
