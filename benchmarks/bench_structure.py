"""StructureModel: simulating a structure (coupled state space, each actuator's play operators
in the loop), against a naive NumPy loop measured in the same run, and its identification.

Run: ``python benchmarks/bench_structure.py [--order 48] [--samples 16384]``.

1. Simulation of ``--samples`` samples of three inputs and three outputs at the given order
   with 6 operators per actuator (the fine-steering mirror's size): the numba kernel
   (``StructureModel.predict``) against the same recursion written with NumPy products per
   sample; the outputs compared, the ratio printed.
2. Its inverse (``StructureCompensator.process``: the tracker with preview) on the outputs
   of step 1, against the same tracker written with NumPy products per sample (the
   feed-forward of the targets ahead summed row by row); the commands compared.
3. Identification of a generated three-actuator structure of that order from 12 periodic
   records of 8192 samples (the benchmark's layout), the order chosen by held-out records.

Not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import piezohyst as ph
from piezohyst.model import structure_fit as sf


def naive(st: sf.Structure, v: np.ndarray) -> np.ndarray:
    """The kernel's recursion with NumPy products per sample."""
    x = np.zeros(st.order)
    z = np.repeat((st.t @ st.off)[:, None], st.r.shape[1], axis=1)
    out = np.empty((v.shape[0], st.c.shape[0]))
    for k in range(v.shape[0]):
        out[k] = st.c @ x + st.d @ v[k] + st.off
        s = st.t @ out[k]
        z = np.minimum(np.maximum(z, s[:, None] - st.r), s[:, None] + st.r)
        x = st.a @ x + st.b @ v[k] + st.e @ (z - s[:, None]).reshape(-1)
    return out


def naive_inverse(comp: ph.StructureCompensator, targets: np.ndarray) -> np.ndarray:
    """The tracker's step with NumPy products per sample: the operators on the targets'
    strokes, the feed-forward of the targets ahead (held past the end), the feedback, the
    model run on the commands (no limits)."""
    st, g = comp.model.structure_, comp._g
    nk = st.r.shape[1]
    zd = np.repeat((st.t @ st.off)[:, None], nk, axis=1)
    rows = []
    for row in targets:  # each target's row: less the offsets, then its operators' lags
        s = st.t @ row
        zd = np.minimum(np.maximum(zd, s[:, None] - st.r), s[:, None] + st.r)
        rows.append(np.concatenate([row - st.off, (zd - s[:, None]).reshape(-1)]))
    z = np.array(rows)
    ahead = g["ahead"]
    x = np.zeros(st.order)
    zm = np.repeat((st.t @ st.off)[:, None], nk, axis=1)
    out = np.empty((targets.shape[0], st.b.shape[1]))
    for k in range(targets.shape[0]):
        idx = np.minimum(np.arange(k + 1, k + 1 + ahead.shape[0]), z.shape[0] - 1)
        u = g["f0"] @ z[k] + np.einsum("jic,jc->i", ahead, z[idx]) - g["gain"] @ x
        y = st.c @ x + st.d @ u + st.off
        s = st.t @ y
        zm = np.minimum(np.maximum(zm, s[:, None] - st.r), s[:, None] + st.r)
        x = st.a @ x + st.b @ u + st.e @ (zm - s[:, None]).reshape(-1)
        out[k] = u
    return out


def structure(order: int, rng: np.random.Generator) -> sf.Structure:
    """A random stable structure: ``order / 2`` lightly damped modes, three inputs and outputs,
    6 operators per actuator acting weakly on the modes."""
    a = np.zeros((order, order))
    for k in range(order // 2):
        rad, th = rng.uniform(0.97, 0.995), rng.uniform(0.05, 2.5)
        a[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = rad * np.array(
            [[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]
        )
    b, c = rng.standard_normal((order, 3)), rng.standard_normal((3, order)) / order
    d = 0.1 * np.eye(3)
    t = np.linalg.pinv(d + c @ np.linalg.solve(np.eye(order) - a, b))
    r = np.geomspace(0.01, 1.0, 6)[None, :].repeat(3, axis=0)
    e = 0.02 * rng.standard_normal((order, 18))
    return sf.Structure(a, b, c, d, e, t, r, np.zeros(3))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--order", type=int, default=48)
    parser.add_argument("--samples", type=int, default=16384)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    st = structure(args.order, rng)
    v = rng.standard_normal((args.samples, 3))
    st.run(v[:10], periodic=False)  # compile
    best = min(_timed(lambda: st.run(v, periodic=False)) for _ in range(5))
    ref_t = _timed(lambda: naive(st, v))
    diff = np.abs(st.run(v, periodic=False) - naive(st, v)).max()
    print(f"simulation, order {args.order}, {args.samples} samples x 3 inputs, 18 operators:")
    print(f"  kernel {1e3 * best:.1f} ms, naive NumPy loop {1e3 * ref_t:.0f} ms: "
          f"{ref_t / best:.0f}x; largest difference {diff:.2g}")  # fmt: skip

    model = ph.StructureModel(order=args.order)
    model.structure_, model.sample_rate_ = st, 6400.0
    model.n_inputs_ = model.n_outputs_ = 3
    lim = 100.0 * np.abs(v).max()  # no command held: the naive loop has no limits
    comp = ph.StructureCompensator(model, v_min=-lim, v_max=lim)
    targets = st.run(v, periodic=False)
    comp.process(targets[:10])  # compile
    best = min(_timed(lambda: (comp.reset(), comp.process(targets))) for _ in range(3))
    ref_t = _timed(lambda: naive_inverse(comp, targets))
    comp.reset()
    diff = np.abs(comp.process(targets) - naive_inverse(comp, targets)).max()
    print(f"its inverse with preview ({comp.preview} samples ahead), the same targets:")
    print(f"  process {1e3 * best:.1f} ms, naive NumPy loop {1e3 * ref_t:.0f} ms: "
          f"{ref_t / best:.0f}x; largest difference {diff:.2g} V")  # fmt: skip

    spec = np.zeros((4097, 3), dtype=complex)
    u, y = [], []
    for level in (0.5, 1.0, 1.5):
        for _ in range(4):
            spec[1:4096] = np.exp(2j * np.pi * rng.random((4095, 3)))
            one = np.fft.irfft(spec, n=8192, axis=0)
            one *= level / one.std(axis=0)
            u.append(one)
            y.append(st.run(one, periodic=True))
    t0 = time.perf_counter()
    model = ph.StructureModel(max_order=args.order + 16).fit(
        u, y, sample_rate=6400.0, initial_state="periodic"
    )
    took = time.perf_counter() - t0
    print(f"identification of 12 periodic records of 8192 samples: {took:.1f} s")
    print(f"  {model.describe()}")


def _timed(run: object) -> float:
    t0 = time.perf_counter()
    run()  # type: ignore[operator]
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
