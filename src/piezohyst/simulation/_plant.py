"""Numba kernel of the simulated bench (one pass over the samples)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def bench_kernel(  # type: ignore[no-untyped-def]
    t,
    v,
    alpha,  # (M,) Preisach relay up-switching voltages, V
    beta,  # (M,) down-switching voltages, V (beta < alpha)
    mu,  # (M,) relay weights, C (sum = saturation irreversible charge)
    relays,  # (M,) relay states +-1, updated in place
    elec,  # (C0, G0, leak_voltage_coeff, v_ref, i_bias, C_f, R_f)
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
    by_alpha = np.argsort(alpha)
    by_beta = np.argsort(beta)
    alpha_sorted = alpha[by_alpha]
    beta_sorted = beta[by_beta]
    q_r = 0.0
    v_amp = 0.0
    q_c_prev = 0.0
    i_prev = 0.0
    q_irr = 0.0
    v_prev = 0.0
    for k in range(v.shape[0]):
        vk = v[k]
        if k == 0:  # the first sample settles every relay
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
        if k > 0:
            dt = t[k] - t[k - 1]
            dq_r = 0.5 * (i_r + i_prev) * dt
            q_r += dq_r
            # feedback capacitor: C_f dVo/dt = i_in + i_bias - Vo / R_f, exact decay per step
            decay = math.exp(-dt / (r_f * c_f))
            v_amp = v_amp * decay + ((q_c - q_c_prev) + dq_r + i_bias * dt) / c_f
        q_c_out[k] = q_c
        q_r_out[k] = q_r
        v_amp_out[k] = v_amp
        q_c_prev = q_c
        i_prev = i_r
