"""The simulated test bench: the paper's experiment (Section 4) without hardware.

It is deliberately *not* a Prandtl-Ishlinskii model, or fitting one to it
would prove nothing: the capacitor's irreversible charge follows a Preisach
model whose density depends on where a loop sits (interaction field), not only
on its width as a PI model's does, the leakage resistance depends on the
voltage, the charge amplifier adds
its bias current and the drift of its own reference capacitor, and the
measurements are quantised and noisy.

Signal chain (paper Fig. 3 and Section 4)::

    V ──► nonlinear capacitor Q_C = C0·V + Σ μ_j s_j(V)   (Preisach relays, rate independent)
      └─► leakage resistor   i_R = G0·(1 + a·|V|/V_ref)·V
    Q_p = Q_C + Q_R ──► active Sawyer-Tower: C_f (leaking through R_f), + bias current
                     ──► amplifier output ──► 16-bit ADC (+ noise) ──► measured charge C_f·V_out
    Q_C ──► displacement S = g·Q_C (eq. 6-7 at zero stress) ──► laser sensor (resolution, noise)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_signal, as_time, same_length
from ..errors import ParameterError
from . import _plant
from .signals import make_signal

__all__ = ["PRESETS", "BenchPreset", "BenchRecord", "simulate"]


@dataclass(frozen=True)
class BenchPreset:
    """Every parameter of the simulated bench (SI units).

    ``sources`` says, for each value, whether it comes from the paper, a
    datasheet, or is an assumption of typical magnitude.
    """

    name: str
    v_max: float  # V, drive amplitude and the actuator's safe limit
    v_min: float  # V
    rate: float  # Hz, DAQ sample rate
    c0: float  # F, linear capacitance
    q_irr: float  # C, saturation irreversible (switching) charge, sum of relay weights
    field_center: float  # V, centre of the Preisach interaction-field density
    field_spread: float  # V, its standard deviation
    coercive_scale: float  # V, scale of the (Rayleigh) coercive-voltage density
    g_leak: float  # S, leakage conductance at 0 V
    leak_voltage_coeff: float  # relative conductance rise at |V| = v_max
    i_bias: float  # A, op-amp input bias current
    c_ref: float  # F, Sawyer-Tower reference (feedback) capacitor
    r_ref: float  # Ohm, its insulation resistance
    adc_bits: int
    adc_range: float  # V, full scale is +-adc_range
    amp_noise: float  # V rms at the ADC input
    gain: float  # m/C, displacement per capacitor charge (g of eq. 6-7 times geometry)
    laser_resolution: float  # m
    laser_noise: float  # m rms
    sources: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


_T226_SOURCES = {
    "v_max": "paper, Section 4.1: 140 V quasi-static drive",
    "v_min": "assumption: a series-poled bender also takes the same voltage reversed",
    "rate": "paper, Section 4: NI DAQ at 1 kHz",
    "c0, q_irr": (
        "assumption: ~12 nF low-field capacitance and a charge loop ~12 % of span, typical "
        "of a two-layer PZT-5H bender of about 32 x 13 mm (the datasheet was not available "
        "here; measure yours)"
    ),
    "field_center, field_spread, coercive_scale": (
        "assumption: a smooth Preisach density, chosen NOT to be a PI model"
    ),
    "g_leak, leak_voltage_coeff": (
        "assumption: ~2 GOhm leakage, 50 % more conductance at 140 V; the paper reports "
        "resistance changing with drive voltage (Section 2.2, Zhang et al. 2013)"
    ),
    "i_bias": "assumption: FET-input op-amp, 5 pA (the paper names bias currents, Section 2.2)",
    "c_ref, r_ref": "assumption: 1 uF film capacitor, 50 GOhm insulation (time constant 5e4 s)",
    "adc_bits, adc_range, amp_noise": "assumption: 16-bit +-10 V NI-class DAQ, 1 mV rms noise",
    "gain": "assumption: ~250 um tip travel at 140 V for a bender of this size",
    "laser_resolution, laser_noise": (
        "assumption: Keyence LK-H020 class sensor, 10 nm steps and 20 nm rms noise (the paper "
        "prints '10 um', which we read as the sensor's 0.01 um display resolution)"
    ),
}

PRESETS: dict[str, BenchPreset] = {
    "T226-H4-203X": BenchPreset(
        name="T226-H4-203X",
        v_max=140.0,
        v_min=-140.0,
        rate=1000.0,
        c0=12e-9,
        q_irr=1.0e-6,
        field_center=70.0,
        field_spread=80.0,
        coercive_scale=35.0,
        g_leak=5e-10,
        leak_voltage_coeff=0.5,
        i_bias=5e-12,
        c_ref=1e-6,
        r_ref=5e10,
        adc_bits=16,
        adc_range=10.0,
        amp_noise=1e-3,
        gain=125.0,
        laser_resolution=10e-9,
        laser_noise=20e-9,
        sources=_T226_SOURCES,
    ),
}

DEFAULT_PRESET = "T226-H4-203X"


@dataclass(frozen=True)
class BenchRecord:
    """One simulated run. Measured channels and the simulator's hidden truth.

    Attributes
    ----------
    t : s; voltage : V (the applied command)
    charge : C, measured by the Sawyer-Tower circuit (what a user records)
    displacement : m, measured by the laser sensor (for checking only)
    capacitor_charge : C, true charge of the nonlinear capacitor Q_C
    leak_charge : C, true charge through the leakage resistor Q_R
    true_displacement : m, g * (Q_C - Q_C at t = 0)
    true_growth_rate : S, the best constant leakage conductance for this run
        (least-squares fit of Q_R on the integral of V), what R should find
    preset : BenchPreset
    """

    t: FloatArray
    voltage: FloatArray
    charge: FloatArray
    displacement: FloatArray
    capacitor_charge: FloatArray
    leak_charge: FloatArray
    true_displacement: FloatArray
    true_growth_rate: float
    preset: BenchPreset


def _preset(preset: str | BenchPreset) -> BenchPreset:
    if isinstance(preset, BenchPreset):
        return preset
    if preset not in PRESETS:
        msg = f"The 'preset' parameter must be one of {sorted(PRESETS)}. Got {preset!r} instead."
        raise ParameterError(msg)
    return PRESETS[preset]


def _preisach_plane(p: BenchPreset, n: int = 120) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Relays on an (interaction field h, coercive voltage c) grid, c > 0.

    Weight ~ exp(-(h - h0)^2 / 2 sh^2) * c * exp(-c^2 / 2 sc^2): a density
    that varies along h, which no PI model (density a function of c alone) has.
    """
    span = p.v_max - min(p.v_min, 0.0)
    h = np.linspace(min(p.v_min, 0.0) - 0.5 * span, p.v_max + 0.5 * span, n)
    c = np.linspace(0.5, 4.0 * p.coercive_scale, n // 2)
    hh, cc = np.meshgrid(h, c, indexing="ij")
    w = np.exp(-0.5 * ((hh - p.field_center) / p.field_spread) ** 2) * cc
    w *= np.exp(-0.5 * (cc / p.coercive_scale) ** 2)
    w *= p.q_irr / w.sum()
    return (hh + cc).ravel(), (hh - cc).ravel(), w.ravel()


def simulate(
    voltage: ArrayLike | None = None,
    t: ArrayLike | None = None,
    *,
    preset: str | BenchPreset = DEFAULT_PRESET,
    signal: str = "hold",
    amplitude: float | None = None,
    frequency: float = 0.5,
    duration: float = 20.0,
    seed: int = 0,
) -> BenchRecord:
    """Run the simulated bench on a voltage command.

    Parameters
    ----------
    voltage, t : array_like, optional
        The command (V) and its time stamps (s). Default: the excitation named
        by ``signal`` (see :func:`~piezohyst.simulation.make_signal`).
    preset : str or BenchPreset
        Bench parameters; default the paper's bimorph, ``"T226-H4-203X"``.
    signal, amplitude, frequency, duration
        Excitation when ``voltage`` is not given. ``amplitude`` defaults to the
        preset's ``v_max``. The default ``"hold"`` identifies the leakage
        best (see ``docs/bench.md``).
    seed : int
        Seeds the measurement noise; equal seeds give equal records.

    Returns
    -------
    BenchRecord

    Raises
    ------
    ParameterError
        If the command leaves the preset's ``[v_min, v_max]``: the bench, like
        an amplifier, refuses voltages outside the actuator's limits.

    Examples
    --------
    >>> rec = simulate(duration=2.0)
    >>> rec.t.size, round(float(rec.voltage.max()))
    (2000, 140)
    """
    p = _preset(preset)
    if voltage is None:
        amp = p.v_max if amplitude is None else amplitude
        ts, v = make_signal(
            signal, amplitude=amp, frequency=frequency, duration=duration, rate=p.rate
        )
    else:
        v = as_signal(voltage, "voltage")
        tt = as_time(t, v.size, required=True, owner="simulate")
        assert tt is not None
        ts = tt
        same_length(v, ts, "voltage", "t")
    if v.min() < p.v_min - 1e-9 or v.max() > p.v_max + 1e-9:
        msg = (
            f"voltage must stay within the actuator's limits [{p.v_min}, {p.v_max}] V. "
            f"Got [{float(v.min()):.6g}, {float(v.max()):.6g}] V."
        )
        raise ParameterError(msg)
    q_c = np.empty_like(v)
    q_r = np.empty_like(v)
    v_amp = np.empty_like(v)
    alpha, beta, mu = _preisach_plane(p)
    relays = np.where(0.5 * (alpha + beta) < v[0], 1.0, -1.0)  # demagnetised about V(0)
    elec = np.array(
        [p.c0, p.g_leak, p.leak_voltage_coeff, max(p.v_max, 1e-9), p.i_bias, p.c_ref, p.r_ref]
    )
    _plant.bench_kernel(ts, v, alpha, beta, mu, relays, elec, q_c, q_r, v_amp)

    rng = np.random.default_rng(seed)
    lsb = 2.0 * p.adc_range / 2**p.adc_bits
    v_meas = np.clip(v_amp + p.amp_noise * rng.standard_normal(v.size), -p.adc_range, p.adc_range)
    charge = np.round(v_meas / lsb) * lsb * p.c_ref
    s_true = p.gain * (q_c - q_c[0])
    s_meas = s_true + p.laser_noise * rng.standard_normal(v.size)
    s_meas = np.round(s_meas / p.laser_resolution) * p.laser_resolution

    integral = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(ts))])
    denom = float(integral @ integral)
    g_eff = float(integral @ q_r) / denom if denom > 0 else p.g_leak
    return BenchRecord(
        t=ts,
        voltage=v,
        charge=charge,
        displacement=s_meas,
        capacitor_charge=q_c,
        leak_charge=q_r,
        true_displacement=s_true,
        true_growth_rate=g_eff,
        preset=p,
    )
