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

import math
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._lazy import LazyModule
from .._validation import FloatArray, as_signal, as_time, same_length
from ..errors import ParameterError
from ..model.dynamics import OutputDynamics
from .signals import make_signal

if TYPE_CHECKING:
    from . import _plant
else:  # numba loads when the bench first runs (see piezohyst._lazy)
    _plant = LazyModule("piezohyst.simulation._plant", globals(), "_plant")

__all__ = ["PLANTS", "PRESETS", "Bench", "BenchPreset", "BenchRecord", "Reading", "simulate"]


#: How a DAC reconstructs the commands between samples (see ``BenchPreset.dac``)
DACS = ("staircase", "interpolating")


@dataclass(frozen=True)
class BenchPreset:
    """Every parameter of the simulated bench (SI units).

    ``sources`` says, for each value, whether it comes from the paper, a
    datasheet, or is an assumption of typical magnitude.

    Attributes
    ----------
    name : str
    v_max, v_min : float
        V: the drive's range and the actuator's safe limits.
    rate : float
        Hz, the DAQ's sample rate.
    c0, q_irr : float
        F, the linear capacitance; C, the irreversible (switching) charge at saturation.
    field_center, field_spread, coercive_scale : float
        V, the Preisach density's interaction field (centre, spread) and coercive scale.
    g_leak, leak_voltage_coeff, i_bias : float
        The leakage: S at 0 V, its relative rise at ``v_max``; A, the op-amp's bias current.
    c_ref, r_ref : float
        The Sawyer-Tower reference capacitor (F) and its insulation (Ohm).
    adc_bits, adc_range, amp_noise : int, float, float
        The ADC's resolution, full scale (V) and the noise at its input (V rms).
    gain : float
        m/C, displacement per capacitor charge (eq. 6-7).
    laser_resolution, laser_noise : float
        m, the checking laser's resolution and noise.
    sources : dict of str to str
        Where each value comes from.
    amp_tau, dac : float, str
        The amplifier's lag (s) and the DAC's hold (``"staircase"`` or ``"interpolating"``).
    mech_f0, mech_zeta : float
        The bender's first mode (Hz; 0: none) and its damping ratio.
    law, law_params : str, tuple of float
        The capacitor's law and its parameters (see :data:`PLANTS`).
    relax_taus, relax_gains : tuple of float
        Debye relaxation branches: time constants (s) and capacitances (F).
    strain_curvature, strain_q_ref : float
        An electrostrictive part of the strain (``S = g (dQ + k dQ^2 / q_ref)``).
    relay_grid : int
        The Preisach plane's relays along the interaction field (half as many along the
        coercive voltage): 120 gives 7200 relays, whose charge moves in bunches on a fast
        ramp (see ``docs/bench.md``); a finer grid holds the same density in finer steps.
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
    amp_tau: float = 0.0  # s, the amplifier's lag driving the capacitive load (0: none)
    #: how the DAC turns commands into a voltage: "staircase" holds each over its sample,
    #: "interpolating" ramps from one to the next (first-order hold)
    dac: str = "staircase"
    mech_f0: float = 0.0  # Hz, the bender's first mode between charge and displacement (0: none)
    mech_zeta: float = 0.0  # its damping ratio
    #: the capacitor's law: "preisach" (the bench's relays), "bouc-wen", "duhem",
    #: "two-state" (see :data:`PLANTS`), with its parameters
    law: str = "preisach"
    law_params: tuple[float, ...] = ()
    #: Debye relaxation branches added to the capacitor's charge: time constants (s), F each
    relax_taus: tuple[float, ...] = ()
    relax_gains: tuple[float, ...] = ()
    #: An electrostrictive part of the strain: S = g (dQ + k dQ^2 / q_ref), dQ the capacitor
    #: charge from its value at rest (k = ``strain_curvature``, 0: S = g dQ, eq. 6-7)
    strain_curvature: float = 0.0
    strain_q_ref: float = 1e-6  # C
    #: the Preisach plane's relays along the interaction field (x half as many coercive
    #: voltages): the bench's discretisation of a smooth density, not a physical value
    relay_grid: int = 120

    def strain(self, dq: FloatArray) -> FloatArray:
        """The quasi-static displacement (m) for capacitor charges ``dq`` from rest (C).

        Parameters
        ----------
        dq : ndarray
            C, the capacitor's charge from its value at rest.

        Returns
        -------
        ndarray
            m.
        """
        if self.strain_curvature == 0.0:
            return self.gain * dq
        return self.gain * (dq + self.strain_curvature * dq * dq / self.strain_q_ref)

    def to_dict(self) -> dict[str, Any]:
        """Every parameter by name (JSON-ready but for the tuples).

        Returns
        -------
        dict
        """
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

PRESETS["T226-H4-203X-amp4ms"] = replace(
    PRESETS["T226-H4-203X"],
    name="T226-H4-203X-amp4ms",
    amp_tau=4e-3,
    sources={
        **_T226_SOURCES,
        "amp_tau": (
            "assumption: a high-voltage amplifier whose output resistance and current limit "
            "charge the piezo's capacitance with a 4 ms time constant (about 40 Hz bandwidth); "
            "it logs the command, not the piezo voltage, as the measured 1 Hz sets do"
        ),
    },
)

PRESETS["T226-H4-203X-mode"] = replace(
    PRESETS["T226-H4-203X-amp4ms"],
    name="T226-H4-203X-mode",
    mech_f0=150.0,
    mech_zeta=0.05,
    sources={
        **PRESETS["T226-H4-203X-amp4ms"].sources,
        "mech_f0, mech_zeta": (
            "assumption: a first bending mode at 150 Hz with 5 % damping, the order of a "
            "cantilevered bender some centimetres long carrying a small mirror; the laser sees "
            "it, the charge does not"
        ),
    },
)

PRESETS["T226-H4-203X-mode-y"] = replace(
    PRESETS["T226-H4-203X-mode"],
    name="T226-H4-203X-mode-y",
    amp_tau=3e-3,
    mech_f0=120.0,
    mech_zeta=0.04,
    sources={
        **PRESETS["T226-H4-203X-mode"].sources,
        "amp_tau": (
            "assumption: the second axis's amplifier, a 3 ms time constant (another channel "
            "of a stage's driver, another cable)"
        ),
        "mech_f0, mech_zeta": (
            "assumption: an XY stage's second axis carries the first (a stacked or nested "
            "flexure), so its mode is lower, 120 Hz with 4 % damping"
        ),
    },
)

DEFAULT_PRESET = "T226-H4-203X"

_ZOO_CHAIN = (
    "the bench's charge amplifier, ADC, laser and limits (T226-H4-203X); leakage and bias "
    "current of their own (assumption: same magnitudes as the bench, other values)"
)

#: Actuators of other physics than the bench's Preisach capacitor, for validation: each a
#: nonlinear capacitor from a family of the literature, with voltage-dependent leakage, a
#: bias current and the bench's measuring chain (``simulate(plant=NAME)``). Their
#: parameters were set for plausible loops (about 10-20 % of the charge span) before any
#: model was fitted to them, and not changed after.
PLANTS: dict[str, BenchPreset] = {
    "preisach": PRESETS[DEFAULT_PRESET],
    "bouc-wen": replace(
        PRESETS[DEFAULT_PRESET],
        name="bouc-wen",
        law="bouc-wen",
        law_params=(12e-9, 12e-9, 0.009, 0.003, 1.0),
        g_leak=3e-10,
        leak_voltage_coeff=1.0,
        i_bias=20e-12,
        sources={
            "law": (
                "Bouc-Wen capacitor q = c0 v + z, dz/dv = A - beta sign(dv) |z|^(n-1) z - "
                "gamma |z|^n (Low and Guo 1995 for piezo stages; Ismail, Ikhouane and "
                "Rodellar 2009, Arch. Comput. Methods Eng. 16); c0 = A = 12 nF, beta = "
                "0.009/V, gamma = 0.003/V, n = 1: z saturates at 1 uC"
            ),
            "chain": _ZOO_CHAIN,
        },
    ),
    "duhem": replace(
        PRESETS[DEFAULT_PRESET],
        name="duhem",
        law="duhem",
        law_params=(0.06, 20e-9, 6e-9),
        g_leak=8e-10,
        leak_voltage_coeff=0.2,
        i_bias=-10e-12,
        sources={
            "law": (
                "Coleman-Hodgdon (Duhem) capacitor dq/dv = alpha sign(dv) (c_an v - q) + "
                "c_rev (Coleman and Hodgdon 1986, Int. J. Eng. Sci. 24; Stepanenko and Su "
                "1998 for piezo actuators); alpha = 0.06/V, c_an = 20 nF, c_rev = 6 nF"
            ),
            "chain": _ZOO_CHAIN,
        },
    ),
    "two-state": replace(
        PRESETS[DEFAULT_PRESET],
        name="two-state",
        law="two-state",
        law_params=(12e-9, 2.0, 4.0),
        g_leak=4e-10,
        leak_voltage_coeff=0.8,
        i_bias=8e-12,
        sources={
            "law": (
                "thermally activated two-state dipoles (Smith 2005, Smart Material Systems, "
                "ch. 7: homogenized energy models): 64 populations, centres N(70, 80) V, "
                "half-widths 17-52 V, rates 2/s * exp(+-(v - v_switch)/4 V); rate-dependent, "
                "and it keeps relaxing on a hold near a switching voltage"
            ),
            "chain": _ZOO_CHAIN,
        },
    ),
    "bouc-wen-creep-lag": replace(
        PRESETS[DEFAULT_PRESET],
        name="bouc-wen-creep-lag",
        law="bouc-wen",
        law_params=(10e-9, 10e-9, 0.008, 0.004, 1.0),
        relax_taus=(0.2, 5.0),
        relax_gains=(1.5e-9, 1.0e-9),
        amp_tau=4e-3,
        g_leak=6e-10,
        leak_voltage_coeff=0.5,
        i_bias=15e-12,
        sources={
            "law": (
                "a Bouc-Wen capacitor with Debye dielectric relaxation (two branches, 0.2 s "
                "and 5 s, 1.5 and 1 nF: creep of the charge after a step) behind an amplifier "
                "with a 4 ms lag (as T226-H4-203X-amp4ms)"
            ),
            "chain": _ZOO_CHAIN,
        },
    ),
}

#: Relative spreads of a unit off one production line (assumption: datasheet tolerances
#: of PZT benders are +-10-20 % for capacitance; leakage varies more, +-30 %)
UNIT_SPREAD = {
    "c0": 0.1,
    "q_irr": 0.1,
    "g_leak": 0.3,
    "leak_voltage_coeff": 0.3,
    "i_bias": 0.5,
    "coercive_scale": 0.1,
}


def batch_unit(preset: str | BenchPreset, unit: int) -> BenchPreset:
    """Unit ``unit`` of a production batch of ``preset``; unit 0 is the preset itself.

    Each other unit draws its capacitance, loop, leakage and bias current from
    :data:`UNIT_SPREAD` (normal, clipped at 2.5 standard deviations), seeded by
    ``unit``: the same unit is the same actuator on every run. Limits, rate and
    sensors are the bench's, shared by every unit.

    Parameters
    ----------
    preset : str or BenchPreset
    unit : int
        0 or more.

    Returns
    -------
    BenchPreset
    """
    p = _preset(preset)
    if not isinstance(unit, int | np.integer) or isinstance(unit, bool) or unit < 0:
        msg = f"The 'unit' must be an integer 0 or more. Got {unit!r}."
        raise ParameterError(msg)
    if unit == 0:
        return p
    rng = np.random.default_rng([0x5EED, int(unit)])
    drawn = {
        name: getattr(p, name) * (1.0 + spread * float(np.clip(rng.standard_normal(), -2.5, 2.5)))
        for name, spread in UNIT_SPREAD.items()
    }
    return replace(p, name=f"{p.name} unit {unit}", **drawn)


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
    true_displacement : m, ``preset.strain(Q_C - Q_C at t = 0)``: g (Q_C - Q_C at t = 0) unless
        the preset has an electrostrictive part
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


def _preisach_plane(p: BenchPreset) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Relays on an (interaction field h, coercive voltage c) grid, c > 0: ``relay_grid``
    fields x half as many coercive voltages.

    Weight ~ exp(-(h - h0)^2 / 2 sh^2) * c * exp(-c^2 / 2 sc^2): a density
    that varies along h, which no PI model (density a function of c alone) has.
    """
    n = p.relay_grid
    span = p.v_max - min(p.v_min, 0.0)
    h = np.linspace(min(p.v_min, 0.0) - 0.5 * span, p.v_max + 0.5 * span, n)
    c = np.linspace(0.5, 4.0 * p.coercive_scale, n // 2)
    hh, cc = np.meshgrid(h, c, indexing="ij")
    w = np.exp(-0.5 * ((hh - p.field_center) / p.field_spread) ** 2) * cc
    w *= np.exp(-0.5 * (cc / p.coercive_scale) ** 2)
    w *= p.q_irr / w.sum()
    return (hh + cc).ravel(), (hh - cc).ravel(), w.ravel()


LAWS = ("preisach", "bouc-wen", "duhem", "two-state")
TWO_STATE_POPULATIONS = 64


def _two_state_populations(p: BenchPreset) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Switching voltages up/down and weights of the two-state dipole populations: centres
    around ``field_center`` (spread ``field_spread``), half-widths from ``coercive_scale``,
    weights summing to ``q_irr``; drawn once from a fixed seed (the plant, not the noise)."""
    rng = np.random.default_rng(20261125)
    m = TWO_STATE_POPULATIONS
    centre = p.field_center + p.field_spread * np.clip(rng.standard_normal(m), -2.5, 2.5)
    half = p.coercive_scale * (0.5 + rng.random(m))
    return centre + half, centre - half, np.full(m, p.q_irr / m)


def _e6_above(value: float) -> float:
    """The smallest E6 capacitor value (1, 1.5, 2.2, 3.3, 4.7, 6.8 per decade) >= ``value``."""
    decade = 10.0 ** math.floor(math.log10(value))
    for mantissa in (1.0, 1.5, 2.2, 3.3, 4.7, 6.8, 10.0):
        if mantissa * decade >= value * (1 - 1e-12):
            return mantissa * decade
    raise AssertionError  # pragma: no cover - 10 * decade > value


class _Plant:
    """The bench's physics with its state carried from call to call."""

    def __init__(self, p: BenchPreset, v0: float) -> None:
        self.p = p
        if p.law not in LAWS or (p.law == "preisach" and p.relax_taus):
            msg = f"unknown capacitor law {p.law!r} (relaxation goes with the others)"
            raise ParameterError(msg)
        if p.dac not in DACS:
            msg = f"unknown DAC {p.dac!r}; one of {', '.join(DACS)}"
            raise ParameterError(msg)
        if not (isinstance(p.relay_grid, int) and 8 <= p.relay_grid <= 2000):
            msg = f"'relay_grid' must be an integer in [8, 2000]. Got {p.relay_grid!r}."
            raise ParameterError(msg)
        self.law_state = np.zeros(2 + max(TWO_STATE_POPULATIONS, 1))
        self.relax_state = np.zeros(2 + len(p.relax_taus))
        if p.law == "two-state":
            self.up, self.down, self.weights = _two_state_populations(p)
        self.alpha, self.beta, self.mu = _preisach_plane(p)
        self.by_alpha = np.argsort(self.alpha)
        self.by_beta = np.argsort(self.beta)
        self.relays = np.where(0.5 * (self.alpha + self.beta) < v0, 1.0, -1.0)  # demagnetised
        self.elec = np.array(
            [p.c0, p.g_leak, p.leak_voltage_coeff, max(p.v_max, 1e-9), p.i_bias, p.c_ref, p.r_ref]
        )
        self.state = np.zeros(_plant.STATE_SIZE)
        self.lag_state = np.zeros(4)
        self.lsb = 2.0 * p.adc_range / 2**p.adc_bits
        self.mode = OutputDynamics(p.mech_f0, p.mech_zeta, 1.0 / p.rate)
        self.mode_state: FloatArray | None = None

    def displacement(self, static: FloatArray) -> FloatArray:
        """The displacement the bender makes of its quasi-static one (its first mode, if any)."""
        if not self.mode.active:
            return static
        if self.mode_state is None:
            self.mode_state = self.mode.rest_state([static[0]])
        return self.mode.apply_columns(static[:, None], self.mode_state)[:, 0]

    def run(
        self, t: FloatArray, v: FloatArray, out: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Capacitor charge, leaked charge and amplifier output at each sample.

        ``out`` (3, N) receives them when given (no allocation per call).
        """
        if out is None:
            out = np.empty((3, v.size))
        q_c, q_r, v_amp = out[0], out[1], out[2]
        if self.p.amp_tau > 0.0:  # the piezo sees the amplifier's lagging output
            lagged = np.empty_like(v)
            ramp = self.p.dac == "interpolating"
            _plant.amplifier_lag(t, v, self.p.amp_tau, ramp, self.lag_state, lagged)
            v = lagged
        p = self.p
        if p.law == "preisach" and not p.relax_taus:
            _plant.bench_kernel(
                t, v, self.alpha, self.beta, self.mu, self.by_alpha, self.by_beta, self.relays,
                self.elec, self.state, q_c, q_r, v_amp,
            )  # fmt: skip
            return q_c, q_r, v_amp
        law = np.asarray(p.law_params, dtype=np.float64)
        if p.law == "bouc-wen":
            _plant.boucwen_law(t, v, law, self.law_state, q_c)
        elif p.law == "duhem":
            _plant.duhem_law(t, v, law, self.law_state, q_c)
        else:
            _plant.two_state_law(t, v, self.up, self.down, self.weights, law, self.law_state, q_c)
        if p.relax_taus:
            taus = np.asarray(p.relax_taus, dtype=np.float64)
            gains = np.asarray(p.relax_gains, dtype=np.float64)
            _plant.relaxation_add(t, v, taus, gains, self.relax_state, q_c)
        _plant.chain_kernel(t, v, q_c, self.elec, self.state, q_r, v_amp)
        return q_c, q_r, v_amp

    def adc(self, v_out: FloatArray) -> FloatArray:
        """Charge (C) read through the quantising ADC from the amplifier output (V, noisy)."""
        p = self.p
        v_meas = np.clip(v_out, -p.adc_range, p.adc_range)
        return np.asarray(np.round(v_meas / self.lsb) * self.lsb * p.c_ref, dtype=np.float64)

    def laser(self, s: FloatArray) -> FloatArray:
        """Displacement (m) in the laser sensor's resolution steps."""
        res = self.p.laser_resolution
        return np.asarray(np.round(s / res) * res, dtype=np.float64)


@dataclass(frozen=True)
class Reading:
    """What the bench's DAQ reads at one sample.

    Attributes
    ----------
    t : float
        Time (s).
    voltage : float
        The voltage applied (V).
    charge : float
        Charge measured by the Sawyer-Tower circuit (C): all a self-sensing
        controller may use.
    displacement : float
        The laser's reading (m): for checking only.
    capacitor_charge, leak_charge, true_displacement : float
        The simulator's hidden truth (C, C, m).
    """

    t: float
    voltage: float
    charge: float
    displacement: float
    capacitor_charge: float
    leak_charge: float
    true_displacement: float


class Bench:
    """The simulated bench driven one sample at a time: a plant for closed loops.

    Each :meth:`apply` sends one voltage for one sample period and returns
    what the DAQ reads at the end of it, as on a rig where the controller
    reads the ADC, computes, and writes the DAC once per sample. The
    measured charge at a sample is therefore the response to the commands
    before it. Blocks (:meth:`apply_block`) equal the same samples one by one.

    Parameters
    ----------
    preset : str or BenchPreset
        Bench parameters (``dataclasses.replace`` a preset to change, say,
        the op-amp's bias current).
    voltage : float, default 0.0
        The actuator rests here at t = 0, its hysteresis demagnetised about it.
    seed : int, default 0
        Seeds the measurement noise.

    Examples
    --------
    >>> bench = Bench(seed=1)
    >>> r = bench.apply(70.0)
    >>> r.t, r.voltage, r.charge > 0
    (0.001, 70.0, True)
    """

    def __init__(
        self, preset: str | BenchPreset = DEFAULT_PRESET, *, voltage: float = 0.0, seed: int = 0
    ) -> None:
        self.preset = _preset(preset)
        self._plant = _Plant(self.preset, float(voltage))
        self._rng = np.random.default_rng(seed)
        self._k = 0
        self._q_rest = 0.0
        self._t, self._v, self._out = np.zeros(1), np.zeros(1), np.zeros((3, 1))
        self.reading = self.apply_block([float(voltage)], _at_rest=True)

    @property
    def sample_rate(self) -> float:
        """Samples per second (Hz)."""
        return float(self.preset.rate)

    def apply(self, voltage: float) -> Reading:
        """Send ``voltage`` for one sample; the DAQ's reading at its end.

        Parameters
        ----------
        voltage : float
            V, inside the preset's limits (an amplifier refuses others).

        Returns
        -------
        Reading
        """
        p = self.preset
        v = float(voltage)
        if not (math.isfinite(v) and p.v_min - 1e-9 <= v <= p.v_max + 1e-9):
            self.run([v])  # raises naming the limits
        self._k += 1
        self._t[0] = self._k / p.rate
        self._v[0] = v
        self._plant.run(self._t, self._v, self._out)  # the same arithmetic as run(), scalar
        q_c, v_amp = float(self._out[0, 0]), float(self._out[2, 0])
        noise = self._rng.standard_normal(2)
        lsb = self._plant.lsb
        v_meas = min(max(v_amp + p.amp_noise * float(noise[0]), -p.adc_range), p.adc_range)
        s_true = float(p.strain(np.asarray(q_c - self._q_rest)))
        if self._plant.mode.active:
            s_true = float(self._plant.displacement(np.array([s_true]))[0])
        res = p.laser_resolution
        self.reading = Reading(
            float(self._t[0]),
            v,
            round(v_meas / lsb) * lsb * p.c_ref,
            round((s_true + p.laser_noise * float(noise[1])) / res) * res,
            q_c,
            float(self._out[1, 0]),
            s_true,
        )
        return self.reading

    def apply_block(self, voltages: ArrayLike, *, _at_rest: bool = False) -> Reading:
        """Send several voltages, one per sample; the reading after the last.

        Use :meth:`run` for every sample's reading.

        Parameters
        ----------
        voltages : array_like
            V, one per sample, sent in turn.

        Returns
        -------
        Reading
            The DAQ's reading after the last voltage.
        """
        rec = self.run(voltages, _at_rest=_at_rest)
        k = -1
        self.reading = Reading(
            float(rec.t[k]),
            float(rec.voltage[k]),
            float(rec.charge[k]),
            float(rec.displacement[k]),
            float(rec.capacitor_charge[k]),
            float(rec.leak_charge[k]),
            float(rec.true_displacement[k]),
        )
        return self.reading

    def run(self, voltages: ArrayLike, *, _at_rest: bool = False) -> BenchRecord:
        """Send voltages, one per sample, and record every reading.

        Parameters
        ----------
        voltages : array_like
            V, one per sample.

        Returns
        -------
        BenchRecord
            ``true_growth_rate`` is the preset's conductance at 0 V.

        Raises
        ------
        ParameterError
            A voltage outside the preset's limits, or not finite.
        """
        p = self.preset
        v = as_signal(voltages, "voltages")
        if v.min() < p.v_min - 1e-9 or v.max() > p.v_max + 1e-9:
            msg = (
                f"voltage must stay within the actuator's limits [{p.v_min}, {p.v_max}] V. "
                f"Got [{float(v.min()):.6g}, {float(v.max()):.6g}] V."
            )
            raise ParameterError(msg)
        first = self._k if _at_rest else self._k + 1
        t = (first + np.arange(v.size, dtype=np.float64)) / p.rate
        self._k = first + v.size - 1
        q_c, q_r, v_amp = self._plant.run(t, v)
        if _at_rest:
            self._q_rest = float(q_c[0])
        noise = self._rng.standard_normal((v.size, 2))
        charge = self._plant.adc(v_amp + p.amp_noise * noise[:, 0])
        s_true = self._plant.displacement(p.strain(q_c - self._q_rest))
        s_meas = self._plant.laser(s_true + p.laser_noise * noise[:, 1])
        return BenchRecord(t, v, charge, s_meas, q_c, q_r, s_true, p.g_leak, p)


def simulate(
    voltage: ArrayLike | None = None,
    t: ArrayLike | None = None,
    *,
    preset: str | BenchPreset = DEFAULT_PRESET,
    plant: str | None = None,
    signal: str = "hold",
    amplitude: float | None = None,
    frequency: float = 0.5,
    duration: float = 20.0,
    seed: int = 0,
    auto_range: bool = True,
    dac: str | None = None,
) -> BenchRecord:
    """Run the simulated bench on a voltage command.

    Parameters
    ----------
    voltage, t : array_like, optional
        The command (V) and its time stamps (s). Default: the excitation named
        by ``signal`` (see :func:`~piezohyst.simulation.make_signal`).
    preset : str or BenchPreset
        Bench parameters; default the paper's bimorph, ``"T226-H4-203X"``.
    plant : str, optional
        An actuator of other physics from :data:`PLANTS` (``"bouc-wen"``,
        ``"duhem"``, ``"two-state"``, ``"bouc-wen-creep-lag"``; ``"preisach"`` is
        the bench), instead of ``preset``.
    signal, amplitude, frequency, duration
        Excitation when ``voltage`` is not given. ``amplitude`` defaults to the
        preset's ``v_max``. The default ``"hold"`` identifies the leakage
        best (see ``docs/bench.md``).
    seed : int
        Seeds the measurement noise; equal seeds give equal records.
    auto_range : bool, default True
        Choose the Sawyer-Tower reference capacitor as a lab would: when the
        preset's would take the charge amplifier's output beyond 90 % of the
        ADC's full scale (long records accumulate leaked charge), the next
        E6 value that keeps it under 80 % is used (``record.preset.c_ref``).
        False keeps the preset's, and the charge clips at full scale.
    dac : {"staircase", "interpolating"}, optional
        How the DAC turns the commands into a voltage, if not the preset's
        (``"staircase"``): held over each sample, or ramped from one to the
        next. It matters behind an amplifier lag (``amp_tau``).

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
    if plant is not None:
        if plant not in PLANTS:
            msg = f"unknown plant {plant!r}; available: {', '.join(PLANTS)}"
            raise ParameterError(msg)
        preset = PLANTS[plant]
    p = _preset(preset)
    if dac is not None:
        p = replace(p, dac=dac)
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
    physics = _Plant(p, float(v[0]))
    q_c, q_r, v_amp = physics.run(ts, v)
    peak = float(np.abs(v_amp).max())
    if auto_range and peak > 0.9 * p.adc_range:
        p = replace(p, c_ref=_e6_above(p.c_ref * peak / (0.8 * p.adc_range)))
        physics = _Plant(p, float(v[0]))
        q_c, q_r, v_amp = physics.run(ts, v)

    rng = np.random.default_rng(seed)
    charge = physics.adc(v_amp + p.amp_noise * rng.standard_normal(v.size))
    s_true = physics.displacement(p.strain(q_c - q_c[0]))
    s_meas = physics.laser(s_true + p.laser_noise * rng.standard_normal(v.size))

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
