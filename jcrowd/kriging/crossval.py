"""Choice of the variogram exponent p by leave-one-out cross-validation (paper 001 App. A).

For each p on the grid {0, 0.2, …, 2.0} (0 = spherical), θ is fitted by Cressie's weighted
least squares (Eq. 4, :func:`~jcrowd.kriging.variogram_fit.fit_variogram`) to the experimental
variogram of the detrended samples; then every sample x in turn is left out and its residual
r_x predicted from the others, ``MSE = (1/N) Σ_x ‖r_x − r*(c_x)‖²`` (Frobenius norm for matrix
values). The p with the lowest MSE wins. As in App. A the trend is fitted once on all samples
and the variogram is not refitted per left-out sample; only the kriging system is rebuilt.

Paper 001 picks p once at a "representative frame" and reuses it; with paper 000's per-sample
cores there is one variogram for the whole motion, so the choice is made once per level.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import KrigingError
from jcrowd.kriging.system import (
    System,
    check_system,
    default_rcond,
    drift_basis,
    fit_trend,
    query_gamma,
    solve_weights,
    system_operators,
)
from jcrowd.kriging.variogram import (
    Estimator,
    ExperimentalVariogram,
    Lag,
    as_controls,
    experimental_variogram,
)
from jcrowd.kriging.variogram_fit import RESULT, VariogramFit, fit_exponents

__all__ = [
    "DEFAULT_EXPONENTS",
    "ExponentChoice",
    "as_values",
    "check_sample_count",
    "choose_exponent",
    "leave_one_out",
]

DEFAULT_EXPONENTS: tuple[float, ...] = tuple(round(0.2 * k, 1) for k in range(11))
"""p = 0.0, 0.2, …, 2.0, the line search of paper 001 App. A."""

_LOO_CHUNK = 64
"""Left-out samples whose (S−1)² systems are solved together (bounds memory at large S)."""


def as_values(values: Any, samples: int) -> tuple[np.ndarray, tuple[int, ...]]:
    """``(S, V)`` float64 flattened sample values and the per-sample shape, checked finite."""
    v = np.asarray(values, np.float64)
    if v.ndim == 0 or v.shape[0] != samples:
        raise KrigingError(
            f"values: expected {samples} samples along axis 0 (one per control row), "
            f"found shape {v.shape}"
        )
    bad = ~np.all(np.isfinite(v.reshape(samples, -1)), axis=1)
    if bad.any():
        raise KrigingError(
            f"sample values must be finite; samples {np.flatnonzero(bad)[:10].tolist()} "
            "hold NaN or inf"
        )
    return v.reshape(samples, -1), tuple(v.shape[1:])


def check_sample_count(samples: int, dims: int) -> None:
    """Universal kriging with a hyperplane trend in d dimensions needs S ≥ d + 2 samples."""
    if samples < dims + 2:
        raise KrigingError(
            f"universal kriging with a linear trend in d = {dims} control dimensions needs at "
            f"least d + 2 = {dims + 2} samples (d + 1 fix the hyperplane, one more leaves a "
            f"residual to krige); found {samples}"
        )


def leave_one_out(
    controls: Float[np.ndarray, "S d"],
    residuals: Float[np.ndarray, "S V"],
    theta: Any,
    p: float,
    system: System = "residual",
    rcond: float | None = None,
) -> Float[np.ndarray, "S V"]:
    """``r*(c_x)`` kriged from all samples but x, for every x (NumPy float64)."""
    c = np.asarray(controls, np.float64)
    r = np.asarray(residuals, np.float64)
    s = c.shape[0]
    rcond = default_rcond(s - 1, np.float32) if rcond is None else rcond
    others = np.array([np.delete(np.arange(s), i) for i in range(s)])
    out = np.empty_like(r)
    for start in range(0, s, _LOO_CHUNK):
        rows = np.arange(start, min(start + _LOO_CHUNK, s))
        cs = c[others[rows]]
        ops = system_operators(cs, theta, p, system, rcond)
        query = c[rows][:, None, :]
        b, _ = solve_weights(ops, query_gamma(cs, query, theta, p), drift_basis(query, system))
        out[rows] = np.einsum("bk,bkv->bv", b[:, 0], r[others[rows]])
    return out


@dataclass(frozen=True)
class ExponentChoice:
    """Result of :func:`choose_exponent`.

    Attributes:
        fit: the variogram with the lowest leave-one-out error (its own result code inside).
        exponents: ``(P,)`` the p tried.
        loo_mse: ``(P,)`` leave-one-out mean squared error per p (inf where the fit failed).
        results: ``(P,)`` :class:`~jcrowd.kriging.variogram_fit.RESULT` code of each fit.
        fits: every fitted variogram, in the order of ``exponents``.
        experimental: the experimental variogram of the residuals that was fitted.
    """

    fit: VariogramFit
    exponents: Float[np.ndarray, " P"]
    loo_mse: Float[np.ndarray, " P"]
    results: Int[np.ndarray, " P"]
    fits: tuple[VariogramFit, ...]
    experimental: ExperimentalVariogram


def choose_exponent(
    controls: Float[Any, "S d"],
    values: Float[Any, "S ..."],
    exponents: Sequence[float] = DEFAULT_EXPONENTS,
    *,
    system: System = "residual",
    estimator: Estimator = "cressie",
    bins: int = 10,
    lag: Lag = "centre",
    rcond: float | None = None,
    dtype: Any = np.float32,
) -> ExponentChoice:
    """Fit θ for each p and keep the p with the lowest leave-one-out error (paper 001 App. A).

    Args:
        controls: ``(S, d)`` control vectors, used as given (normalise them first if their
            units differ: :func:`~jcrowd.kriging.universal.normalise_controls`).
        values: ``(S, ...)`` sample values. They are detrended by the least-squares hyperplane
            first (001 §3.3), so passing residuals instead is harmless.
        exponents: the grid of p (0 = spherical, else stable with 0 < p ≤ 2).
        system: kriging system used for the leave-one-out predictions (see
            :mod:`~jcrowd.kriging.system`).
        estimator, bins, lag: experimental variogram settings (001 §4.1; see
            :func:`~jcrowd.kriging.variogram.experimental_variogram`).
        rcond: eigenvalue cut-off of the kriging system (default ``n · eps(dtype)``).
        dtype: dtype of the fit (and of the returned variograms).

    Returns:
        :class:`ExponentChoice`.
    """
    check_system(system)
    c = as_controls(controls)
    s, d = c.shape
    check_sample_count(s, d)
    v, _ = as_values(values, s)
    ps = np.asarray(exponents, np.float64)
    if ps.ndim != 1 or ps.size == 0 or np.any((ps < 0) | (ps > 2)):
        raise KrigingError(f"exponents: expected values in [0, 2] (0 = spherical), found {ps}")
    rcond = default_rcond(s - 1, dtype) if rcond is None else rcond
    _, residuals = fit_trend(c, v)
    exp = experimental_variogram(c, residuals, estimator=estimator, bins=bins, lag=lag)
    fits = fit_exponents(exp, ps, dtype)
    mse = np.full(ps.size, np.inf)
    for k, fit in enumerate(fits):
        if fit.status == RESULT.NONFINITE:
            continue
        theta = np.asarray(fit.theta, np.float64)
        pred = leave_one_out(c, residuals, theta, float(ps[k]), system, rcond)
        err = float(np.mean(np.sum((residuals - pred) ** 2, axis=1)))
        mse[k] = err if np.isfinite(err) else np.inf
    if not np.isfinite(mse).any():
        raise KrigingError(
            "choose_exponent: no exponent gave a finite leave-one-out error; fit results "
            f"{[f.status.name for f in fits]}"
        )
    best = int(np.argmin(mse))
    results = np.array([int(f.result) for f in fits])
    return ExponentChoice(fits[best], ps, mse, results, tuple(fits), exp)
