r"""Generalized Prandtl-Ishlinskii model: growth terms, asymmetry and creep, still linear.

Beyond the paper's one growth rate and symmetric, rate-independent loops:

.. math::

    y(t) = c + \sum_i w_i H_{r_i}[x](t)
           + \underbrace{\sum_j \frac{u_j (x - k_j)_+^2 - u'_j (k_j - x)_+^2}{s}}_{\text{asymmetry}}
           + \underbrace{\sum_k g_k L_{\tau_k}[x](t)}_{\text{creep}}
           + \underbrace{\sum_m R_m G_m[x](t)}_{\text{growth}}

* **Asymmetry**: a static monotone term in parallel with the PI operator
  (the "PI plus memoryless polynomial" family, here a one-sided quadratic
  spline with knots :math:`k_j` inside the training range and :math:`u, u' \ge 0`,
  so it never decreases). It bends the loop's centre line: loops become
  asymmetric, as for real piezo stacks and ceramics.
* **Creep**: first-order lags :math:`L_\tau` of unit DC gain with gains
  :math:`g_k \ge 0` (creep operators): after a step the output keeps moving,
  approximately logarithmically with log-spaced :math:`\tau_k`. Rate dependent.
* **Growth** (removed before compensating, like the paper's :math:`R y_2`):
  ``"integral"`` :math:`\int x\,dt` (ohmic leakage, the paper's term),
  ``"time"`` :math:`t` (a constant current: op-amp bias, integrator offset),
  ``"abs_integral"`` :math:`\int x|x|/s\,dt` (leakage rising with voltage).

Every term is linear in its coefficient, so all are identified jointly by one
bounded least-squares solve, with the slope bounds that make the hysteresis
part strictly increasing in the current input. It is then inverted exactly by
a safeguarded one-dimensional solve per sample (:class:`~piezohyst.Compensator`).

``growth_terms="auto"`` chooses the growth terms on held-out data: each subset is
fitted on the first 70 % of the record and scored on the last 30 % (the model
running through the whole record), and the best is refitted on everything.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import minimize

from . import _kernels
from ._validation import FloatArray, as_signal, as_time, check_int, same_length
from .errors import InsufficientDataError, ModelFileError, ParameterError, ShapeError
from .hysteresis import PIHysteresis, Propagation
from .identification import BLOCK, NormalEquations, solve_slopes, time_steps
from .metrics import rmse
from .models import ClassicalPI, _float_field, _register

__all__ = ["GROWTH_TERMS", "GeneralizedPI"]

GROWTH_TERMS = ("integral", "time", "abs_integral")


def _floats(data: dict[str, Any], key: str) -> FloatArray:
    value = data[key]
    if not isinstance(value, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        msg = f"field '{key}' must be a list of finite numbers"
        raise ModelFileError(msg)
    return np.asarray(value, dtype=np.float64)


class _Features:
    """Extra regressor columns, computed block by block with carried state."""

    def __init__(
        self,
        knots: FloatArray,
        scale: float,
        taus: FloatArray,
        growth: tuple[str, ...],
        state: FloatArray | None,
        x0: float,
    ) -> None:
        self.knots, self.scale, self.taus, self.growth = knots, scale, taus, growth
        m = taus.size
        if state is None:
            self.lags = np.full(m, x0)
            self.acc = np.zeros(3)  # integral, elapsed time, abs integral
            self.t_last: float | None = None
        else:
            self.lags = state[:m].copy()
            self.acc = state[m : m + 3].copy()
            self.t_last = None if math.isnan(state[m + 3]) else float(state[m + 3])

    @property
    def width(self) -> int:
        return 2 * self.knots.size + self.taus.size + len(self.growth)

    def state(self) -> FloatArray:
        t = math.nan if self.t_last is None else self.t_last
        return np.concatenate([self.lags, self.acc, [t]])

    def block(self, x: FloatArray, t: FloatArray | None) -> FloatArray:
        out = np.empty((x.size, self.width))
        k = self.knots.size
        if k:
            d = x[:, None] - self.knots[None, :]
            out[:, :k] = np.maximum(d, 0.0) ** 2 / self.scale
            out[:, k : 2 * k] = -(np.maximum(-d, 0.0) ** 2) / self.scale
        col = 2 * k
        if self.taus.size or self.growth:
            assert t is not None
            dt = time_steps(t, self.t_last)
            self.t_last = float(t[-1])
            if self.taus.size:
                lag = np.empty((x.size, self.taus.size))
                _kernels.lag_filter(x, dt, self.taus, self.lags, lag)
                out[:, col : col + self.taus.size] = lag
                col += self.taus.size
            sources = {
                "integral": x * dt,
                "time": dt,
                "abs_integral": x * np.abs(x) / self.scale * dt,
            }
            slots = {"integral": 0, "time": 1, "abs_integral": 2}
            for name in self.growth:
                series = np.cumsum(sources[name]) + self.acc[slots[name]]
                self.acc[slots[name]] = series[-1]
                out[:, col] = series
                col += 1
        return out


@_register
class GeneralizedPI(ClassicalPI):
    """Generalized PI model: PI + asymmetry + creep + selectable growth terms.

    Parameters
    ----------
    n_operators, thresholds, min_slope, input_unit, output_unit
        As for :class:`~piezohyst.ClassicalPI`.
    growth_terms : "auto" or sequence of str, default "auto"
        Growth terms among ``"integral"``, ``"time"``, ``"abs_integral"``;
        ``()`` for none; ``"auto"`` picks a subset on held-out data.
    asymmetry : int, default 3
        Knots of the static monotone term (0 turns it off).
    creep : sequence of float, default ()
        Time constants (s) of the creep operators, e.g. ``(0.1, 1, 10)``.
    optimize_thresholds : bool, default False
        Refine the thresholds by bounded nonlinear least squares around the
        linear solve (L-BFGS-B over threshold increments; slower).

    Attributes
    ----------
    thresholds_, weights_, offset_, initial_state_, operator_, rmse_, nrmse_,
    input_range_
        As for :class:`~piezohyst.ClassicalPI`.
    knots_, static_up_, static_down_, static_scale_ : ndarray, float
        Asymmetry term: knots (V), coefficients (output/V), scale (V).
    creep_taus_, creep_gains_ : ndarray
        Creep time constants (s) and gains (output/V).
    growth_terms_ : tuple of str
        Growth terms used; ``growth_coefs_`` their coefficients (output units
        per V·s, per s, and per V·s).
    selection_ : dict
        Held-out RMSE of every growth subset tried (``growth_terms="auto"``).

    Examples
    --------
    >>> import numpy as np, piezohyst as ph
    >>> rec = ph.simulate(duration=10.0)
    >>> model = ph.GeneralizedPI(10).fit(rec.voltage, rec.charge, t=rec.t)
    >>> bool(model.nrmse_ < 0.005), "integral" in model.growth_terms_
    (True, True)
    """

    rate_dependent: ClassVar[bool] = True

    def __init__(
        self,
        n_operators: int = 10,
        thresholds: ArrayLike | None = None,
        min_slope: float = 1e-3,
        input_unit: str = "V",
        output_unit: str = "C",
        growth_terms: str | Sequence[str] = "auto",
        asymmetry: int = 3,
        creep: Sequence[float] = (),
        optimize_thresholds: bool = False,
    ) -> None:
        super().__init__(n_operators, thresholds, min_slope, input_unit, output_unit)
        self.growth_terms = growth_terms
        self.asymmetry = asymmetry
        self.creep = creep
        self.optimize_thresholds = optimize_thresholds

    def get_params(self) -> dict[str, Any]:
        params = super().get_params()
        params.update(
            growth_terms=(
                self.growth_terms if isinstance(self.growth_terms, str) else list(self.growth_terms)
            ),
            asymmetry=self.asymmetry,
            creep=[float(c) for c in self.creep],
            optimize_thresholds=self.optimize_thresholds,
        )
        return params

    # --------------------------------------------------------------- checks
    def _growth_candidates(self) -> list[tuple[str, ...]]:
        if isinstance(self.growth_terms, str):
            if self.growth_terms != "auto":
                msg = (
                    "The 'growth_terms' parameter of GeneralizedPI must be 'auto' or a sequence "
                    f"of {list(GROWTH_TERMS)}. Got {self.growth_terms!r} instead."
                )
                raise ParameterError(msg)
            subsets = itertools.chain.from_iterable(
                itertools.combinations(GROWTH_TERMS, k) for k in range(len(GROWTH_TERMS) + 1)
            )
            return list(subsets)
        terms: tuple[str, ...] = tuple(self.growth_terms)
        if any(term not in GROWTH_TERMS for term in terms) or len(set(terms)) != len(terms):
            msg = (
                f"The 'growth_terms' parameter of GeneralizedPI must hold distinct terms from "
                f"{list(GROWTH_TERMS)}. Got {list(terms)!r} instead."
            )
            raise ParameterError(msg)
        return [tuple(t for t in GROWTH_TERMS if t in terms)]

    def _creep_taus(self) -> FloatArray:
        try:
            taus = np.asarray(list(self.creep), dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            taus = np.array([np.nan])
        if taus.size > 20 or not np.all(np.isfinite(taus)) or np.any(taus <= 0):
            msg = (
                "The 'creep' parameter of GeneralizedPI must be up to 20 positive time "
                f"constants in s. Got {self.creep!r} instead."
            )
            raise ParameterError(msg)
        return taus

    # ------------------------------------------------------------------ fit
    def fit(
        self,
        x: ArrayLike,
        y: ArrayLike,
        t: ArrayLike | None = None,
        *,
        initial_state: ArrayLike | None = None,
    ) -> GeneralizedPI:
        """Identify every term jointly (and choose growth terms if ``growth_terms="auto"``).

        ``t`` (s) is required; ``initial_state`` as for :meth:`ClassicalPI.fit`.
        """
        xs, ys, ts = self._inputs(x, y, t)
        assert ts is not None
        thr = self._check_params(xs)
        z0 = self._initial_state(thr, xs, initial_state)
        k = check_int(self.asymmetry, "asymmetry", "GeneralizedPI", 0, 50)
        taus = self._creep_taus()
        candidates = self._growth_candidates()
        if not isinstance(self.optimize_thresholds, bool):
            msg = f"'optimize_thresholds' must be True or False. Got {self.optimize_thresholds!r}."
            raise ParameterError(msg)
        lo, hi = float(xs.min()), float(xs.max())
        scale = max(hi - lo, 1e-300)
        knots = lo + (hi - lo) * np.arange(1, k + 1) / (k + 1)
        self.selection_: dict[str, float] = {}
        if len(candidates) > 1:
            split = int(0.7 * xs.size)
            best, best_err = candidates[0], math.inf
            for terms in candidates:
                try:
                    self._solve(
                        xs[:split], ys[:split], ts[:split], thr, z0, knots, scale, taus, terms
                    )
                except InsufficientDataError:
                    continue
                err = rmse(self.predict(xs, t=ts)[split:], ys[split:])
                self.selection_["+".join(terms) or "none"] = err
                if err < best_err * (1 - 1e-3):  # a term must earn its place
                    best, best_err = terms, err
            candidates = [best]
        self._solve(xs, ys, ts, thr, z0, knots, scale, taus, candidates[0])
        if self.optimize_thresholds and thr.size > 1:
            self._refine_thresholds(xs, ys, ts, initial_state, knots, scale, taus, candidates[0])
        self._record_fit(xs, ys, ts)
        return self

    def _solve(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray,
        thr: FloatArray,
        z0: FloatArray,
        knots: FloatArray,
        scale: float,
        taus: FloatArray,
        terms: tuple[str, ...],
    ) -> None:
        n = thr.size
        feats = _Features(knots, scale, taus, terms, None, float(x[0]))
        p = n + 1 + feats.width
        if x.size <= p:
            msg = f"Identifying {p} parameters needs more than {p} samples. Got {x.size}."
            raise InsufficientDataError(msg)
        eqs = NormalEquations.accumulate(
            x,
            y,
            thr,
            z0,
            extra=lambda start, stop: feats.block(x[start:stop], t[start:stop]),
            extra_width=feats.width,
        )
        span_x, span_y = float(np.ptp(x)), float(np.ptp(y))
        mean_slope = span_y / span_x if span_x > 0 and span_y > 0 else 1.0
        k, c = knots.size, taus.size
        lower = np.concatenate(
            [[-np.inf], np.zeros(2 * k + c), np.full(len(terms), -np.inf)]
        )  # offset free; asymmetry and creep non-negative; growth free
        sol = solve_slopes(
            eqs.gram, eqs.rhs, n, min_slope=float(self.min_slope) * mean_slope, lower=lower
        )
        self._set_operator(PIHysteresis(thr, sol[:n], float(sol[n]), z0))
        rest = sol[n + 1 :]
        self.knots_ = knots
        self.static_scale_ = scale
        self.static_up_ = rest[:k].copy()
        self.static_down_ = rest[k : 2 * k].copy()
        self.creep_taus_ = taus
        self.creep_gains_ = rest[2 * k : 2 * k + c].copy()
        self.growth_terms_ = terms
        self.growth_coefs_ = rest[2 * k + c :].copy()

    def _refine_thresholds(
        self,
        x: FloatArray,
        y: FloatArray,
        t: FloatArray,
        initial_state: ArrayLike | None,
        knots: FloatArray,
        scale: float,
        taus: FloatArray,
        terms: tuple[str, ...],
    ) -> None:
        """Nonlinear least squares over the thresholds, the linear solve inside."""
        span = max(float(np.ptp(x)), 1e-300)
        start = np.log(np.diff(self.thresholds_) / span)

        def objective(logs: FloatArray) -> float:
            thr = np.concatenate([[0.0], np.cumsum(np.exp(logs) * span)])
            if thr[-1] >= span:  # a play wider than the range never reverses
                return 1e300
            z0 = self._initial_state(thr, x, initial_state)
            self._solve(x, y, t, thr, z0, knots, scale, taus, terms)
            return rmse(self.predict(x, t=t), y) / span

        before = objective(start)
        res = minimize(objective, start, method="L-BFGS-B", options={"maxiter": 30})
        best = res.x if res.fun < before else start
        objective(best)

    # ------------------------------------------------------------- predict
    def _features(self, state: FloatArray | None, x0: float) -> _Features:
        return _Features(
            self.knots_, self.static_scale_, self.creep_taus_, self.growth_terms_, state, x0
        )

    def _coefficients(self) -> FloatArray:
        return np.concatenate(
            [self.static_up_, self.static_down_, self.creep_gains_, self.growth_coefs_]
        )

    def propagate(
        self, x: ArrayLike, t: ArrayLike | None = None, state: ArrayLike | None = None
    ) -> Propagation:
        """Output and final state: plays, lags, integral, elapsed, abs integral, last t."""
        self._check_fitted()
        xs = as_signal(x, "x", allow_empty=True)
        ts = as_time(t, xs.size, required=True, owner="GeneralizedPI")
        assert ts is not None
        n, m = self.operator_.n_operators, self.creep_taus_.size
        st = None if state is None else np.asarray(state, dtype=np.float64)
        if st is not None and st.shape != (n + m + 4,):
            msg = f"'state' of this GeneralizedPI must hold {n + m + 4} values. Got {st.shape}."
            raise ShapeError(msg)
        feats = self._features(None if st is None else st[n:], float(xs[0]) if xs.size else 0.0)
        hyst = self.operator_.propagate(xs, None if st is None else st[:n])
        out = hyst.output.copy()
        coef = self._coefficients()
        for start in range(0, xs.size, BLOCK):
            sl = slice(start, start + BLOCK)
            out[sl] += feats.block(xs[sl], ts[sl]) @ coef
        return Propagation(out, np.concatenate([hyst.state, feats.state()]))

    def predict(self, x: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """Modelled output for input ``x`` (V) at times ``t`` (s)."""
        return self.propagate(x, t).output

    def growth(self, x: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """The growth terms alone (output units): what :meth:`remove_growth` subtracts."""
        self._check_fitted()
        xs = as_signal(x, "x")
        ts = as_time(t, xs.size, required=True, owner="GeneralizedPI")
        assert ts is not None
        feats = self._features(None, float(xs[0]))
        g = len(self.growth_terms_)
        if g == 0:
            return np.zeros_like(xs)
        return np.asarray(feats.block(xs, ts)[:, -g:] @ self.growth_coefs_)

    def remove_growth(self, x: ArrayLike, y: ArrayLike, t: ArrayLike | None = None) -> FloatArray:
        """The measured output minus the identified growth terms (eq. 19 generalized)."""
        ys = as_signal(y, "y")
        g = self.growth(x, t)
        same_length(g, ys, "x", "y")
        return np.asarray(ys - g)

    def inverse(self) -> ClassicalPI:
        msg = (
            "GeneralizedPI has no closed-form inverse; use ph.Compensator, which inverts it "
            "exactly sample by sample."
        )
        raise ParameterError(msg)

    # ----------------------------------------------------------- persistence
    def _fitted_dict(self) -> dict[str, Any]:
        out = super()._fitted_dict()
        out.update(
            knots=self.knots_.tolist(),
            static_scale=self.static_scale_,
            static_up=self.static_up_.tolist(),
            static_down=self.static_down_.tolist(),
            creep_taus=self.creep_taus_.tolist(),
            creep_gains=self.creep_gains_.tolist(),
            growth_terms=list(self.growth_terms_),
            growth_coefs=self.growth_coefs_.tolist(),
        )
        return out

    def _set_fitted(self, data: dict[str, Any]) -> None:
        super()._set_fitted(data)
        self.knots_ = _floats(data, "knots")
        self.static_scale_ = _float_field(data, "static_scale")
        self.static_up_ = _floats(data, "static_up")
        self.static_down_ = _floats(data, "static_down")
        self.creep_taus_ = _floats(data, "creep_taus")
        self.creep_gains_ = _floats(data, "creep_gains")
        terms = data["growth_terms"]
        if not isinstance(terms, list) or any(t not in GROWTH_TERMS for t in terms):
            raise ModelFileError(f"field 'growth_terms' must list terms from {list(GROWTH_TERMS)}")
        self.growth_terms_ = tuple(terms)
        self.growth_coefs_ = _floats(data, "growth_coefs")
        k = self.knots_.size
        if (
            self.static_up_.size != k
            or self.static_down_.size != k
            or self.creep_gains_.size != self.creep_taus_.size
            or self.growth_coefs_.size != len(terms)
            or np.any(self.static_up_ < 0)
            or np.any(self.static_down_ < 0)
            or np.any(self.creep_gains_ < 0)
            or np.any(self.creep_taus_ <= 0)
            or self.static_scale_ <= 0
        ):
            raise ModelFileError("inconsistent GeneralizedPI terms (sizes or signs)")
        self.selection_ = {}
