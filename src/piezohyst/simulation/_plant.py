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
    ``s_j`` (up at ``V >= alpha_j``, down at ``V <= beta_j``); the leakage
    and the amplifier are :func:`chain_kernel`'s. Calls continue where the
    last one stopped (``state``): blocks of any size, down to one sample,
    equal one call.
    """
    c0 = elec[0]
    m = alpha.shape[0]
    # Relays sorted by switching voltage: after a sample at v, every relay with
    # alpha <= v is up and every one with beta >= v is down, so when the input
    # rises from v_prev to v only relays with alpha in (v_prev, v] can flip (and
    # falling, only beta in [v, v_prev)). Each sample visits those alone.
    alpha_sorted = alpha[by_alpha]
    beta_sorted = beta[by_beta]
    q_irr = state[S_Q_IRR]
    v_prev = state[S_V]
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
            started = True
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
        q_c_out[k] = c0 * vk + q_irr
    state[S_Q_IRR] = q_irr
    state[S_V] = v_prev
    chain_kernel(t, v, q_c_out, elec, state, q_r_out, v_amp_out)


@njit(cache=True)
def chain_kernel(t, v, q_c, elec, state, q_r_out, v_amp_out):  # type: ignore[no-untyped-def]
    """The leakage and the charge amplifier around a capacitor whose charge is ``q_c``.

    Leakage current ``i_R = G0 (1 + a |V| / v_ref) V`` (trapezoid in time). The
    active Sawyer-Tower amplifier integrates the piezo current plus its input
    bias current on the feedback capacitor ``C_f`` that leaks through ``R_f``.
    ``state`` carries the last sample (every plant's capacitor shares this chain).
    """
    g0, a_leak, v_ref, i_bias, c_f, r_f = elec[1], elec[2], elec[3], elec[4], elec[5], elec[6]
    q_r = state[S_Q_R]
    v_amp = state[S_V_AMP]
    q_c_prev = state[S_Q_C]
    i_prev = state[S_I_R]
    t_prev = state[S_T]
    started = state[S_STARTED] > 0.0
    for k in range(v.shape[0]):
        vk = v[k]
        i_r = g0 * (1.0 + a_leak * abs(vk) / v_ref) * vk
        if started:
            dt = t[k] - t_prev
            dq_r = 0.5 * (i_r + i_prev) * dt
            q_r += dq_r
            # feedback capacitor: C_f dVo/dt = i_in + i_bias - Vo / R_f, exact decay per step
            decay = math.exp(-dt / (r_f * c_f))
            v_amp = v_amp * decay + ((q_c[k] - q_c_prev) + dq_r + i_bias * dt) / c_f
        started = True
        t_prev = t[k]
        q_r_out[k] = q_r
        v_amp_out[k] = v_amp
        q_c_prev = q_c[k]
        i_prev = i_r
    state[S_Q_R] = q_r
    state[S_V_AMP] = v_amp
    state[S_Q_C] = q_c_prev
    state[S_I_R] = i_prev
    state[S_T] = t_prev
    state[S_STARTED] = 1.0 if started else 0.0


@njit(cache=True)
def amplifier_lag(t, v, tau, ramp, state, out):  # type: ignore[no-untyped-def]
    """The voltage that reaches the piezo: a first-order lag ``tau`` (s) of the DAC's output.

    The command ``v[k]`` takes effect over the sample ending at ``t[k]``. A
    staircase DAC (``ramp`` False) holds it there, so
    ``u[k] = u[k-1] + (1 - e) (v[k] - u[k-1])`` with ``e = exp(-dt/tau)``; an
    interpolating DAC (``ramp`` True) ramps from ``v[k-1]`` to ``v[k]`` over it,
    so ``u[k] = e u[k-1] + (1 - e) v[k-1] + (1 - (tau/dt)(1 - e)) (v[k] - v[k-1])``.
    Both exact. ``state`` = [u, t, started, v]; the first sample starts settled
    at its command.
    """
    u = state[0]
    t_prev = state[1]
    started = state[2] > 0.0
    v_prev = state[3]
    for k in range(v.shape[0]):
        if not started or tau <= 0.0:
            u = v[k]
            started = True
        else:
            dt = t[k] - t_prev
            e = math.exp(-dt / tau)
            if ramp and dt > 0.0:
                u = e * u + (1.0 - e) * v_prev + (1.0 - tau / dt * (1.0 - e)) * (v[k] - v_prev)
            else:
                u += (1.0 - e) * (v[k] - u)
        t_prev = t[k]
        v_prev = v[k]
        out[k] = u
    state[0] = u
    state[1] = t_prev
    state[2] = 1.0
    state[3] = v_prev


# ------------------------------------------------------------ other capacitors (the zoo)
# Each writes the capacitor's charge for the voltages v (V) at times t (s), carrying its
# own state (law_state, updated in place); chain_kernel then adds leakage and amplifier.
SUBSTEPS = 16  # integration steps per sample of the rate-independent laws


@njit(cache=True)
def boucwen_law(t, v, p, law_state, q_out):  # type: ignore[no-untyped-def]
    """Bouc-Wen capacitor ``q = c0 v + z``, ``dz/dv = A - beta sign(dv) |z|^(n-1) z -
    gamma |z|^n`` (Ismail et al. 2009), midpoint steps. p = [c0, A, beta, gamma, n];
    law_state = [z, v_prev, started]."""
    c0, a, beta, gamma, n = p[0], p[1], p[2], p[3], p[4]
    z = law_state[0]
    v_prev = law_state[1]
    started = law_state[2] > 0.0
    for k in range(v.shape[0]):
        if started and v[k] != v_prev:
            h = (v[k] - v_prev) / SUBSTEPS
            s = 1.0 if h > 0.0 else -1.0
            for _ in range(SUBSTEPS):
                az = abs(z)
                f1 = a - beta * s * az ** (n - 1.0) * z - gamma * az**n
                zm = z + 0.5 * h * f1
                azm = abs(zm)
                z += h * (a - beta * s * azm ** (n - 1.0) * zm - gamma * azm**n)
        started = True
        v_prev = v[k]
        q_out[k] = c0 * v[k] + z
    law_state[0] = z
    law_state[1] = v_prev
    law_state[2] = 1.0


@njit(cache=True)
def duhem_law(t, v, p, law_state, q_out):  # type: ignore[no-untyped-def]
    """Coleman-Hodgdon (Duhem) capacitor: ``dq/dv = alpha sign(dv) (c_an v - q) + c_rev``,
    midpoint steps. p = [alpha, c_an, c_rev]; law_state = [q, v_prev, started]."""
    alpha, c_an, c_rev = p[0], p[1], p[2]
    q = law_state[0]
    v_prev = law_state[1]
    started = law_state[2] > 0.0
    for k in range(v.shape[0]):
        if not started:
            q = c_an * v[k]  # at rest on the anhysteretic curve
        elif v[k] != v_prev:
            h = (v[k] - v_prev) / SUBSTEPS
            s = 1.0 if h > 0.0 else -1.0
            x = v_prev
            for _ in range(SUBSTEPS):
                f1 = alpha * s * (c_an * x - q) + c_rev
                qm = q + 0.5 * h * f1
                q += h * (alpha * s * (c_an * (x + 0.5 * h) - qm) + c_rev)
                x += h
        started = True
        v_prev = v[k]
        q_out[k] = q
    law_state[0] = q
    law_state[1] = v_prev
    law_state[2] = 1.0


@njit(cache=True)
def two_state_law(t, v, up, down, mu, p, law_state, q_out):  # type: ignore[no-untyped-def]
    """Thermally activated two-state dipoles: population i is up with probability p_i,
    ``dp_i/dt = r0 exp((v - up_i)/w) (1 - p_i) - r0 exp((down_i - v)/w) p_i`` (rates held
    over each sample: exact), ``q = c0 v + sum mu_i (2 p_i - 1)``. Rate-dependent, and it
    keeps relaxing on a hold near a switching voltage. p = [c0, r0, w];
    law_state = [t_prev, started, p_1..p_M]."""
    c0, r0, w = p[0], p[1], p[2]
    m = up.shape[0]
    t_prev = law_state[0]
    started = law_state[1] > 0.0
    for k in range(v.shape[0]):
        vk = v[k]
        if not started:  # at rest: each population in equilibrium at the first voltage
            for i in range(m):
                ru = math.exp(min((vk - up[i]) / w, 60.0))
                rd = math.exp(min((down[i] - vk) / w, 60.0))
                law_state[2 + i] = ru / (ru + rd)
        else:
            dt = t[k] - t_prev
            for i in range(m):
                ru = r0 * math.exp(min((vk - up[i]) / w, 60.0))
                rd = r0 * math.exp(min((down[i] - vk) / w, 60.0))
                total = ru + rd
                p_inf = ru / total
                law_state[2 + i] = p_inf + (law_state[2 + i] - p_inf) * math.exp(-total * dt)
        started = True
        t_prev = t[k]
        q = c0 * vk
        for i in range(m):
            q += mu[i] * (2.0 * law_state[2 + i] - 1.0)
        q_out[k] = q
    law_state[0] = t_prev
    law_state[1] = 1.0


@njit(cache=True)
def relaxation_add(t, v, taus, gains, law_state, q_out):  # type: ignore[no-untyped-def]
    """Dielectric relaxation added to a capacitor's charge: Debye branches
    ``q_k' = (c_k v - q_k) / tau_k`` (voltage held over each sample: exact).
    law_state = [t_prev, started, q_1..q_K]."""
    kk = taus.shape[0]
    t_prev = law_state[0]
    started = law_state[1] > 0.0
    for k in range(v.shape[0]):
        extra = 0.0
        for j in range(kk):
            if not started:
                law_state[2 + j] = gains[j] * v[k]
            else:
                target = gains[j] * v[k]
                law_state[2 + j] = target + (law_state[2 + j] - target) * math.exp(
                    -(t[k] - t_prev) / taus[j]
                )
            extra += law_state[2 + j]
        started = True
        t_prev = t[k]
        q_out[k] += extra
    law_state[0] = t_prev
    law_state[1] = 1.0
