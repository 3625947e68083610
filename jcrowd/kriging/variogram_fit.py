"""Fitting a variogram model to an experimental variogram: Cressie's weighted least squares.

Paper 001 App. A, Eq. 4 (Cressie 1985), solved with optimistix's Levenberg–Marquardt. Every fit
carries a :class:`RESULT` code; nothing fails silently. The models and estimators are in
:mod:`~jcrowd.kriging.variogram`.
"""

from __future__ import annotations

import enum
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Float, Int

from jcrowd.errors import KrigingError
from jcrowd.kriging.variogram import ExperimentalVariogram, semivariogram

__all__ = ["RESULT", "VariogramFit", "fit_exponents", "fit_variogram", "make_variogram"]

ModelName = Literal["spherical", "stable"]


class RESULT(enum.IntEnum):
    """Outcome of a variogram fit (:func:`fit_variogram`); every fit carries one."""

    SUCCESSFUL = 0
    MAX_STEPS = 1
    RANGE_AT_BOUND = 2
    TOO_FEW_BINS = 3
    NO_VARIATION = 4
    NONFINITE = 5

    @property
    def message(self) -> str:
        return {
            RESULT.SUCCESSFUL: "converged",
            RESULT.MAX_STEPS: "the least-squares solver stopped at its step limit",
            RESULT.RANGE_AT_BOUND: "the range reached its cap (the largest sample distance): "
            "the experimental variogram does not level off within the samples",
            RESULT.TOO_FEW_BINS: "fewer than 3 lag bins hold pairs; the 3 parameters are "
            "underdetermined and the returned values are the initial guess",
            RESULT.NO_VARIATION: "the experimental variogram is zero (the values do not vary); "
            "the returned model is a unit-sill placeholder",
            RESULT.NONFINITE: "the fit produced a non-finite value; the returned values are the "
            "initial guess",
        }[self]


class VariogramFit(eqx.Module):
    """A fitted γ*(h; p, θ): ``theta = (θ0, θ1, θ2)``, exponent ``p`` (0 = spherical), ``result``.

    ``result`` is a :class:`RESULT` code; read it with :attr:`status`. A pytree of arrays, so it
    can sit inside a compiled model.
    """

    theta: Float[jax.Array, " 3"]
    p: Float[jax.Array, ""]
    result: Int[jax.Array, ""]

    def __check_init__(self) -> None:
        if self.theta.shape != (3,) or self.p.shape != () or self.result.shape != ():
            raise KrigingError(
                f"VariogramFit: expected theta (3,), scalar p and result; found "
                f"{self.theta.shape}, {self.p.shape}, {self.result.shape}"
            )

    @property
    def status(self) -> RESULT:
        return RESULT(int(self.result))

    @property
    def sill(self) -> float:
        """Total sill θ0 + θ1 = γ*(∞)."""
        return float(self.theta[0] + self.theta[1])


def make_variogram(
    theta: Any, p: float, result: int = RESULT.SUCCESSFUL, dtype: Any = np.float32
) -> VariogramFit:
    """A :class:`VariogramFit` from known parameters (checked: θ ≥ 0, θ2 > 0, 0 ≤ p ≤ 2)."""
    t = np.asarray(theta, np.float64)
    if t.shape != (3,) or not np.all(np.isfinite(t)) or np.any(t < 0) or t[2] <= 0:
        raise KrigingError(
            f"variogram parameters: expected finite (θ0 ≥ 0, θ1 ≥ 0, θ2 > 0), found {t.tolist()}"
        )
    if t[0] + t[1] <= 0:
        raise KrigingError("variogram parameters: the total sill θ0 + θ1 must be positive")
    if not 0.0 <= float(p) <= 2.0:
        raise KrigingError(f"variogram exponent: expected 0 ≤ p ≤ 2 (0 = spherical), found {p}")
    return VariogramFit(
        jnp.asarray(t, dtype), jnp.asarray(p, dtype), jnp.asarray(int(result), jnp.int32)
    )


# ----------------------------------------------------------------------------- fit (Eq. 4)

_MAX_STEPS = 2048
_LOSS_TIE = 1e-4
"""Relative difference of Eq. 4 losses treated as equal (float32 noise between starts)."""
_RANGE_CAP = 1.0
"""Range cap in units of h_max: a longer range means no sample pair reaches the sill."""


def _theta_scaled(phi: jax.Array) -> jax.Array:
    """(φ0², φ1², cap·exp(min(φ2, 0))): nugget and partial sill ≥ 0 (0 reachable), 0 < range ≤ cap.

    The range is clipped rather than squashed: a sigmoid saturates slowly and the solver would
    stop short of the cap, leaving an unbounded range looking like an interior optimum.
    """
    return jnp.stack([phi[0] ** 2, phi[1] ** 2, _RANGE_CAP * jnp.exp(jnp.minimum(phi[2], 0.0))])


def _wls_residuals(phi: jax.Array, args: tuple) -> jax.Array:
    """Cressie's weighted residuals √n(I_u) (γ̄_u − γ*_u)/γ*_u; their squares sum to Eq. 4."""
    lags, gamma, sqrt_n, p = args
    model = semivariogram(lags, _theta_scaled(phi), p)
    return sqrt_n * (gamma - model) / jnp.maximum(model, 1e-6)


@eqx.filter_jit
def _solve_many(
    phi0: jax.Array,
    ps: jax.Array,
    lags: jax.Array,
    gamma: jax.Array,
    sqrt_n: jax.Array,
    max_steps: int = _MAX_STEPS,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Levenberg–Marquardt on every (start, p) row at once (vmap); one compilation per shape."""
    # Tolerances sized for float32: tighter ones leave converged fits creeping on rounding noise.
    solver: optx.LevenbergMarquardt = optx.LevenbergMarquardt(rtol=1e-4, atol=1e-5)

    def one(y0: jax.Array, p: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        sol: optx.Solution = optx.least_squares(
            _wls_residuals,
            solver,
            y0,
            args=(lags, gamma, sqrt_n, p),
            max_steps=max_steps,
            throw=False,
        )
        r = _wls_residuals(sol.value, (lags, gamma, sqrt_n, p))
        converged = jnp.asarray(sol.result == optx.RESULTS.successful)
        return _theta_scaled(sol.value), jnp.sum(r * r), converged

    return jax.vmap(one)(phi0, ps)


def _starts(gamma_s: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Initial φ from the data (scaled units: max γ̄ = 1, h_max = 1): 2 nuggets × 3 ranges."""
    first = float(gamma_s[np.flatnonzero(counts)[0]])
    rows = []
    for nug in (0.05 * first, 0.5 * first):
        for rng in (0.1, 0.25, 0.5):
            sill = max(1.0 - nug, 0.05)
            rows.append([np.sqrt(nug), np.sqrt(sill), np.log(rng / _RANGE_CAP)])
    return np.asarray(rows)


def fit_exponents(exp: ExperimentalVariogram, ps: np.ndarray, dtype: Any) -> list[VariogramFit]:
    """Fit θ (Eq. 4) for each exponent in ``ps``; all starts and exponents in one vmapped solve."""
    nonempty = exp.counts > 0
    scale_g = float(exp.gamma.max()) if nonempty.any() else 0.0
    scale_h = exp.max_distance
    if scale_g <= 0.0 or not np.isfinite(scale_g):
        return [
            make_variogram([0.0, 1.0, 0.5 * scale_h], p, RESULT.NO_VARIATION, dtype) for p in ps
        ]
    gamma_s = exp.gamma / scale_g
    starts = _starts(gamma_s, exp.counts)
    n_starts = starts.shape[0]
    phi0 = np.tile(starts, (len(ps), 1))
    p_rows = np.repeat(ps, n_starts)
    theta_j, loss_j, ok_j = _solve_many(
        jnp.asarray(phi0, dtype),
        jnp.asarray(p_rows, dtype),
        jnp.asarray(exp.lags / scale_h, dtype),
        jnp.asarray(gamma_s, dtype),
        jnp.asarray(np.sqrt(exp.counts), dtype),
    )
    theta_s = np.asarray(theta_j, np.float64).reshape(len(ps), n_starts, 3)
    loss = np.asarray(loss_j, np.float64).reshape(len(ps), n_starts)
    ok = np.asarray(ok_j).reshape(len(ps), n_starts)
    unit = np.array([scale_g, scale_g, scale_h])
    fits = []
    for k, p in enumerate(ps):
        finite = np.isfinite(loss[k]) & np.all(np.isfinite(theta_s[k]), axis=1)
        finite &= theta_s[k, :, 2] > 0
        if not finite.any():
            guess = np.array([starts[0, 0] ** 2, starts[0, 1] ** 2, 0.1 * _RANGE_CAP]) * unit
            fits.append(make_variogram(guess, p, RESULT.NONFINITE, dtype))
            continue
        masked = np.where(finite, loss[k], np.inf)
        # Starts that reach the same minimum differ by float32 noise; prefer one that also met
        # the solver's termination test over a marginally lower one that did not.
        tied = masked <= masked.min() * (1.0 + _LOSS_TIE) + _LOSS_TIE
        converged = tied & ok[k]
        best = int(np.argmin(np.where(converged, masked, np.inf) if converged.any() else masked))
        theta = theta_s[k, best] * unit
        if np.count_nonzero(nonempty) < 3:
            code = RESULT.TOO_FEW_BINS
        elif theta_s[k, best, 2] >= (1.0 - 1e-6) * _RANGE_CAP:
            code = RESULT.RANGE_AT_BOUND
        elif not ok[k, best]:
            code = RESULT.MAX_STEPS
        else:
            code = RESULT.SUCCESSFUL
        fits.append(make_variogram(theta, p, code, dtype))
    return fits


def fit_variogram(
    exp: ExperimentalVariogram,
    model: ModelName = "stable",
    p: float = 1.0,
    *,
    throw: bool = False,
    dtype: Any = np.float32,
) -> VariogramFit:
    """Fit γ*(h; p, θ) to an experimental variogram by Cressie's weighted least squares.

    Minimises Eq. 4 of paper 001 (App. A; Cressie 1985),
    ``Σ_u n(I_u) / γ*(h_u)² · (γ̄(h_u) − γ*(h_u))²``, with optimistix's Levenberg–Marquardt
    on a reparametrisation that keeps the parameters admissible: θ0 = s_γ φ0², θ1 = s_γ φ1²
    (≥ 0, and 0 is reachable: a zero nugget is common for smooth data, and under exp(φ) it
    would sit at φ → −∞ and never converge), θ2 = h_max · exp(min(φ2, 0)) (0 < θ2 ≤ h_max: a
    longer range means no pair of samples reaches the sill, the sill is then not identifiable,
    and ρ loses its meaning; a fit at the cap is flagged ``RANGE_AT_BOUND``). s_γ = max γ̄
    and h_max make the problem unit-free. Six starts from the data (two nuggets × three
    ranges) are solved together and the best kept.

    Args:
        exp: the experimental variogram.
        model: ``"spherical"`` (p = 0) or ``"stable"`` (0 < p ≤ 2).
        p: the stable model's exponent (ignored for spherical).
        throw: raise :class:`~jcrowd.errors.KrigingError` unless the fit is ``SUCCESSFUL``.
        dtype: dtype of the solve and of the returned arrays.

    Returns:
        :class:`VariogramFit` with ``theta = (nugget, partial sill, range)`` and a result code.
    """
    if model == "spherical":
        p_val = 0.0
    elif model == "stable":
        p_val = float(p)
        if not 0.0 < p_val <= 2.0:
            raise KrigingError(
                f"stable variogram: expected 0 < p ≤ 2 (p = 0 is the spherical model), found {p}"
            )
    else:
        raise KrigingError(f"variogram model: expected 'spherical' or 'stable', found {model!r}")
    fit = fit_exponents(exp, np.array([p_val]), dtype)[0]
    if throw and fit.status != RESULT.SUCCESSFUL:
        raise KrigingError(f"variogram fit ({model}, p = {p_val}): {fit.status.message}")
    return fit
