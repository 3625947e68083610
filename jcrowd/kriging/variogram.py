"""Variograms: experimental estimates (Matheron, Cressie–Hawkins) and the spherical and stable
models. Their fit is in :mod:`~jcrowd.kriging.variogram_fit`.

Paper 001 §4.1–4.2; paper 000 §3.3 for the dissimilarity of matrix values.

Conventions (read these before comparing numbers with another library):

- ``gamma`` is always the **semivariogram** γ(h) = ½ Var[Z(c + h) − Z(c)], never 2γ. Both
  estimators below carry the ½ (paper 001 §4.1 writes it explicitly for Cressie–Hawkins).
- A sample's value may be any array (a scalar, an R_P×R_T core); the dissimilarity of two
  samples is the Frobenius norm of their difference ‖K_i − K_j‖ (paper 000 §3.3). For a scalar
  it is ``|r_i − r_j|``, so the scalar estimators are the textbook ones. For vector values the
  Matheron estimate is the *sum* of the per-component semivariograms.
- Lags ``h`` are Euclidean distances between control vectors. Only pairs with
  ``h ≤ h_max / 2`` are used (paper 001 §4.1, after Wackernagel 2003), split into ``bins``
  equal intervals (N_I = 10 in the paper); ``lags`` are the interval centres
  ``h_u = h_step (u − ½)`` as in the paper (``lag="centre"``, the default), or the mean
  distance of the pairs in each interval (``lag="mean"``). In two or more dimensions the pairs
  in an interval crowd towards its upper edge, so centres understate the lag and the fit then
  overstates the nugget (by ~40 % on the simulated fields of the tests); ``"mean"`` removes
  that bias and is what the parameter-recovery test uses.
- Model parameters ``theta = (θ0, θ1, θ2)`` = (nugget, partial sill, range) as in paper 001
  Fig. 4: the total sill is θ0 + θ1. In PyKrige that is ``{"psill": θ1, "range": θ2,
  "nugget": θ0}`` (its *list* form is ``[θ0 + θ1, θ2, θ0]``: total sill first).
- γ(0) = 0 exactly; the nugget applies for h > 0 only (paper 001 §4.2). Two *distinct*
  samples at the same control point are "h → 0⁺" apart: the kriging system gives them the
  nugget (:func:`semivariogram_limit`), which is what keeps it regular for duplicates.

The Cressie–Hawkins estimator follows paper 001 §4.1 literally, denominator
``0.457 + 0.494/n + 0.045/n²`` (Cressie & Hawkins 1980); Cressie (1993, §2.4) drops the
O(n⁻²) term. The constants make the estimate unbiased for *scalar* Gaussian increments; for
Frobenius norms of matrix residuals they are off by a factor that depends on the number of
components (and, unless the components' variograms are proportional, mildly on h). A constant
factor on γ changes neither the kriging weights nor the reliability ρ (both are invariant to
scaling γ), so only the h-dependent part matters.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import KrigingError

__all__ = [
    "ExperimentalVariogram",
    "as_controls",
    "experimental_variogram",
    "pairwise_dissimilarity",
    "semivariogram",
    "semivariogram_limit",
    "spherical",
    "stable",
]

Estimator = Literal["cressie", "matheron"]
Lag = Literal["centre", "mean"]


# ----------------------------------------------------------------------------- estimators


@dataclass(frozen=True)
class ExperimentalVariogram:
    """Binned semivariogram estimate (NumPy float64, fit-time).

    Attributes:
        lags: ``(B,)`` bin centres h_u (control-space units).
        gamma: ``(B,)`` semivariogram estimate γ̄(h_u); 0 where ``counts`` is 0.
        counts: ``(B,)`` number of sample pairs n(I_u) in each bin.
        max_distance: h_max, the largest distance between any two samples.
        estimator: ``"cressie"`` or ``"matheron"``.
    """

    lags: Float[np.ndarray, " B"]
    gamma: Float[np.ndarray, " B"]
    counts: Int[np.ndarray, " B"]
    max_distance: float
    estimator: str


def as_controls(controls: Any) -> np.ndarray:
    """``(S, d)`` float64 control vectors (``(S,)`` read as d = 1), checked finite, S ≥ 2."""
    c = np.asarray(controls, np.float64)
    if c.ndim == 1:
        c = c[:, None]
    if c.ndim != 2 or c.shape[0] < 2:
        raise KrigingError(
            f"control parameters: expected an (S, d) array with S ≥ 2, found shape {c.shape}"
        )
    bad = ~np.all(np.isfinite(c), axis=1)
    if bad.any():
        raise KrigingError(
            f"control parameters must be finite; rows {np.flatnonzero(bad)[:10].tolist()} "
            "hold NaN or inf"
        )
    return c


def pairwise_dissimilarity(values: Any) -> Float[np.ndarray, "S S"]:
    """``D[i, j] = ‖K_i − K_j‖_F`` for values of any shape ``(S, ...)`` (paper 000 §3.3).

    Computed row by row from differences (not from a Gram matrix), so duplicates give exact 0.
    """
    v = np.asarray(values, np.float64)
    v = v.reshape(v.shape[0], -1)
    if not np.all(np.isfinite(v)):
        raise KrigingError("sample values must be finite; found NaN or inf")
    d = np.empty((v.shape[0], v.shape[0]))
    for i in range(v.shape[0]):
        d[i] = np.sqrt(np.sum((v - v[i]) ** 2, axis=1))
    return d


def _pair_distances(c: np.ndarray) -> np.ndarray:
    diff = c[:, None, :] - c[None, :, :]
    return np.sqrt(np.sum(diff * diff, axis=-1))


def experimental_variogram(
    controls: Float[Any, "S d"],
    values: Float[Any, "S ..."] | None = None,
    *,
    dissimilarity: Float[Any, "S S"] | None = None,
    estimator: Estimator = "cressie",
    bins: int = 10,
    max_lag_fraction: float = 0.5,
    lag: Lag = "centre",
) -> ExperimentalVariogram:
    """Binned semivariogram of ``values`` (or of a precomputed dissimilarity) against lag.

    Paper 001 §4.1: pairs with lag ``h = ‖c_i − c_j‖ ≤ max_lag_fraction · h_max`` fall into
    ``bins`` equal intervals. Per interval with ``n`` pairs and dissimilarities ``d_ij``:

    - ``"matheron"``: γ̄ = (1/2n) Σ d_ij²;
    - ``"cressie"`` (Cressie & Hawkins 1980, paper 001 §4.1):
      γ̄ = ½ ((1/n) Σ d_ij^{1/2})⁴ / (0.457 + 0.494/n + 0.045/n²).

    Args:
        controls: ``(S, d)`` control vectors (``(S,)`` is read as d = 1).
        values: ``(S, ...)`` sample values; the dissimilarity is the Frobenius norm of the
            difference (paper 000 §3.3). Give this or ``dissimilarity``.
        dissimilarity: ``(S, S)`` precomputed symmetric, non-negative dissimilarities.
        estimator: ``"cressie"`` (robust, the paper's choice) or ``"matheron"``.
        bins: number of intervals N_I.
        max_lag_fraction: fraction of h_max covered by the bins (½ in the paper).
        lag: ``"centre"`` (paper 001 §4.1) or ``"mean"`` pair distance per interval.

    Returns:
        :class:`ExperimentalVariogram` (semivariogram γ, not 2γ).
    """
    c = as_controls(controls)
    s = c.shape[0]
    _check_binning(estimator, lag, bins, max_lag_fraction)
    dis = _sample_dissimilarity(s, values, dissimilarity)
    iu = np.triu_indices(s, 1)
    h = _pair_distances(c)[iu]
    h_max = float(h.max())
    if h_max <= 0.0:
        raise KrigingError("all control points coincide; a variogram needs distinct lags")
    lags, gamma, counts = _binned_estimate(
        h, dis[iu], h_max * max_lag_fraction, bins, estimator, lag
    )
    return ExperimentalVariogram(lags, gamma, counts, h_max, estimator)


def _check_binning(estimator: str, lag: str, bins: int, max_lag_fraction: float) -> None:
    """Reject an unknown estimator or lag rule, fewer than one bin or a fraction outside (0, 1]."""
    if estimator not in ("cressie", "matheron"):
        raise KrigingError(f"estimator: expected 'cressie' or 'matheron', found {estimator!r}")
    if lag not in ("centre", "mean"):
        raise KrigingError(f"lag: expected 'centre' or 'mean', found {lag!r}")
    if bins < 1 or not 0.0 < max_lag_fraction <= 1.0:
        raise KrigingError(
            f"bins must be ≥ 1 and max_lag_fraction in (0, 1]; found {bins}, {max_lag_fraction}"
        )


def _sample_dissimilarity(s: int, values: Any, dissimilarity: Any) -> np.ndarray:
    """The ``(S, S)`` dissimilarity: computed from ``values`` or checked as given."""
    if dissimilarity is None:
        if values is None:
            raise KrigingError("experimental_variogram needs `values` or `dissimilarity`")
        if np.shape(values)[0] != s:
            raise KrigingError(
                f"values: expected {s} samples (one per control row), found {np.shape(values)[0]}"
            )
        return pairwise_dissimilarity(values)
    dis = np.asarray(dissimilarity, np.float64)
    if dis.shape != (s, s) or not np.all(np.isfinite(dis)) or np.any(dis < 0):
        raise KrigingError(
            f"dissimilarity: expected a finite, non-negative ({s}, {s}) matrix, "
            f"found shape {dis.shape}"
        )
    return dis


def _binned_estimate(
    h: np.ndarray, d: np.ndarray, h_lim: float, bins: int, estimator: str, lag: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(lags, γ̄, counts)`` per bin from pair lags ``h`` and dissimilarities ``d`` ≤ ``h_lim``."""
    step = h_lim / bins
    inside = h <= h_lim * (1.0 + 1e-12)
    idx = np.minimum((h[inside] / step).astype(np.int64), bins - 1)
    counts = np.bincount(idx, minlength=bins)
    n = np.maximum(counts, 1).astype(np.float64)
    if estimator == "matheron":
        gamma = np.bincount(idx, d[inside] ** 2, minlength=bins) / (2.0 * n)
    else:
        mean_root = np.bincount(idx, np.sqrt(d[inside]), minlength=bins) / n
        gamma = 0.5 * mean_root**4 / (0.457 + 0.494 / n + 0.045 / n**2)
    gamma = np.where(counts > 0, gamma, 0.0)
    centres = step * (np.arange(bins) + 0.5)
    if lag == "centre":
        lags = centres
    else:
        lags = np.where(counts > 0, np.bincount(idx, h[inside], minlength=bins) / n, centres)
    return lags, gamma, counts


# ----------------------------------------------------------------------------- models


def _xp(*arrays: Any) -> Any:
    """``jax.numpy`` if any argument is a JAX array (or tracer), else NumPy (float64 fit code)."""
    return jnp if any(isinstance(a, jax.Array) for a in arrays) else np


def _spherical_limit(xp: Any, h: Any, theta: Any) -> Any:
    x = xp.minimum(h / theta[..., 2], 1.0)
    return theta[..., 0] + theta[..., 1] * (1.5 * x - 0.5 * x * x * x)


def _stable_limit(xp: Any, h: Any, theta: Any, p: Any) -> Any:
    # (h/θ2)^p at h = 0 is 0 for p > 0; the where keeps 0**p (and its p-gradient) out of it.
    safe = xp.where(h > 0, h, theta[..., 2])
    power = xp.where(h > 0, (safe / theta[..., 2]) ** p, 0.0)
    return theta[..., 0] + theta[..., 1] * (1.0 - xp.exp(-power))


def semivariogram_limit(h: Any, theta: Any, p: Any) -> Any:
    """The model's value with the nugget included at every lag, h = 0 too (the h → 0⁺ limit).

    Used for the kriging matrix Γ between *distinct* samples, so that two samples at the same
    control point differ by the nugget instead of making Γ singular. p = 0 is spherical.
    """
    xp = _xp(h, theta, p)
    h, theta = xp.asarray(h), xp.asarray(theta)
    sph = _spherical_limit(xp, h, theta)
    stab = _stable_limit(xp, h, theta, xp.where(p == 0, 1.0, p))
    return xp.where(p == 0, sph, stab)


def spherical(h: Float[Any, "*n"], theta: Float[Any, " 3"]) -> Float[Any, "*n"]:
    """Spherical semivariogram (paper 001 §4.2, p = 0); γ(0) = 0.

    γ(h) = θ0 + (θ1/2)(3h/θ2 − (h/θ2)³) for 0 < h ≤ θ2 and θ0 + θ1 beyond. NumPy in → NumPy
    out, JAX in → JAX out. The model is a valid variogram in up to three dimensions only
    (Cressie 1993, Ch. 2); the paper offers it in any dimension, and so do we.
    """
    xp = _xp(h, theta)
    h, theta = xp.asarray(h), xp.asarray(theta)
    return xp.where(h > 0, _spherical_limit(xp, h, theta), 0.0)


def stable(h: Float[Any, "*n"], theta: Float[Any, " 3"], p: Any) -> Float[Any, "*n"]:
    """Stable (powered-exponential) semivariogram, 0 < p ≤ 2 (paper 001 §4.2); γ(0) = 0.

    γ(h) = θ0 + θ1 (1 − exp(−(h/θ2)^p)) for h > 0. p = 1 is exponential, p = 2 Gaussian.
    """
    xp = _xp(h, theta, p)
    h, theta = xp.asarray(h), xp.asarray(theta)
    return xp.where(h > 0, _stable_limit(xp, h, theta, p), 0.0)


def semivariogram(h: Float[Any, "*n"], theta: Float[Any, " 3"], p: Any) -> Float[Any, "*n"]:
    """γ*(h; p, θ) of paper 001 §4.2: spherical for p = 0, stable for 0 < p ≤ 2; γ(0) = 0."""
    xp = _xp(h, theta, p)
    h = xp.asarray(h)
    return xp.where(h > 0, semivariogram_limit(h, theta, p), 0.0)
