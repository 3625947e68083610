"""Greedy reduction of redundant samples by their reliability (paper 001 §5.2).

Paper 001 §5.2: "It computes the reliability at each control parameter c_i by excluding the
corresponding motion sample M_i, and then removes the sample with the highest reliability,
max_i[ρ(c_i)]. This procedure is iterated until the highest reliability falls below a given
threshold τ." That is what :func:`greedy_reduction` does by default. Readings taken where the
text is silent:

- the variogram is fitted once on all samples and kept fixed while samples are removed (the
  paper does not mention refitting, and ρ is a property of the design under one variogram);
- ρ under a reduced set is computed exactly as the model would (same system, same cut-off),
  from the control positions alone — values enter only through the variogram;
- removal also stops when one more removal would leave fewer than d + 2 samples (the trend
  hyperplane needs d + 1 and kriging one more).

A removed sample's reliability is only checked when it is removed; later removals can lower it.
``strict=True`` is a stricter variant (not the paper's): a candidate's score is the *lowest*
reliability, under the set without it, over itself and every sample removed before, so that
at every step all removed samples keep ρ ≥ τ. Paper 001 reduced its 69 gait samples to 29 at
τ = 0.85 (``bench/repro_001.py`` runs the reduction on ours);
:attr:`Reduction.final_reliability` reports where the removed samples end up.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import KrigingError
from jcrowd.kriging.crossval import (
    DEFAULT_EXPONENTS,
    as_values,
    check_sample_count,
    choose_exponent,
)
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
from jcrowd.kriging.universal import normalise_controls
from jcrowd.kriging.variogram import Estimator, Lag, as_controls
from jcrowd.kriging.variogram_fit import VariogramFit, make_variogram

__all__ = ["Reduction", "greedy_reduction"]

_CHUNK = 64


@dataclass(frozen=True)
class Reduction:
    """Result of :func:`greedy_reduction`.

    Attributes:
        kept: ``(K,)`` indices of the samples kept, increasing.
        removed: ``(R,)`` indices removed, in removal order.
        counts: ``(T,)`` sample count at each decision (S, S − 1, …); T = R or R + 1.
        max_reliability: ``(T,)`` the highest candidate score at that count (the curve of
            reliability against sample count); the last entry below τ is what stopped it.
        final_reliability: ``(R,)`` ρ of each removed sample under the kept set.
        variogram: the (fixed) variogram used, in normalised control units if normalised.
        stopped: ``"threshold"`` (highest score < τ) or ``"min_samples"``.
    """

    kept: Int[np.ndarray, " K"]
    removed: Int[np.ndarray, " R"]
    counts: Int[np.ndarray, " T"]
    max_reliability: Float[np.ndarray, " T"]
    final_reliability: Float[np.ndarray, " R"]
    variogram: VariogramFit
    stopped: str


def _reliability_under(
    subsets: np.ndarray, queries: np.ndarray, theta: np.ndarray, p: float, system: str
) -> np.ndarray:
    """ρ at ``queries (B, m, d)`` kriged from ``subsets (B, n, d)`` (batched NumPy float64)."""
    rcond = default_rcond(subsets.shape[1], np.float32)
    ops = system_operators(subsets, theta, p, system, rcond)
    g = query_gamma(subsets, queries, theta, p)
    b, _ = solve_weights(ops, g, drift_basis(queries, system))
    # The nugget as measurement error, as universal.reliability_from_terms (float64 here).
    sigma2 = np.sum(b * np.maximum(g - theta[0], 0.0), axis=-1)
    if theta[1] <= 0:
        return np.where(sigma2 > 0, 0.0, 1.0)
    return 1.0 - sigma2 / theta[1]


def greedy_reduction(
    controls: Float[Any, "S d"],
    values: Float[Any, "S ..."],
    tau: float,
    *,
    variogram: VariogramFit | None = None,
    system: System = "residual",
    strict: bool = False,
    normalise: bool = True,
    min_samples: int | None = None,
    exponents: Sequence[float] = DEFAULT_EXPONENTS,
    estimator: Estimator = "cressie",
    bins: int = 10,
    lag: Lag = "centre",
) -> Reduction:
    """Remove samples greedily while the most reliable left-out sample has ρ ≥ τ (001 §5.2).

    Args:
        controls: ``(S, d)`` control vectors.
        values: ``(S, ...)`` sample values (used to fit the variogram when none is given).
        tau: reliability threshold τ.
        variogram: fixed variogram (normalised units if ``normalise``); default: fitted as in
            :func:`~jcrowd.kriging.universal.fit_kriging`.
        system: kriging system (``"residual"`` as in the papers, or ``"drift"``).
        strict: the stricter variant described in the module docstring.
        normalise: standardise the controls first.
        min_samples: never keep fewer (at least, and by default, d + 2).
        exponents, estimator, bins, lag: the variogram search, when ``variogram`` is ``None``.

    Returns:
        :class:`Reduction`.
    """
    check_system(system)
    if not np.isfinite(tau):
        raise KrigingError(f"tau: expected a finite reliability threshold, found {tau}")
    c = as_controls(controls)
    s, d = c.shape
    check_sample_count(s, d)
    v, _ = as_values(values, s)
    if normalise:
        c = normalise_controls(c)[0]
    floor = max(d + 2, int(min_samples or 0))
    variogram = _reduction_variogram(c, v, variogram, system, exponents, estimator, bins, lag)
    theta = np.asarray(variogram.theta, np.float64)
    p = float(variogram.p)
    active, removed, counts, curve, stopped = _remove_greedily(
        c, theta, p, system, tau, floor, strict
    )
    kept = np.asarray(sorted(active), np.int64)
    if removed:
        final = _reliability_under(c[kept][None], c[np.asarray(removed)][None], theta, p, system)[0]
    else:
        final = np.zeros(0)
    return Reduction(
        kept=kept,
        removed=np.asarray(removed, np.int64),
        counts=np.asarray(counts, np.int64),
        max_reliability=np.asarray(curve),
        final_reliability=final,
        variogram=variogram,
        stopped=stopped,
    )


def _reduction_variogram(
    c: np.ndarray,
    v: np.ndarray,
    variogram: VariogramFit | None,
    system: System,
    exponents: Sequence[float],
    estimator: Estimator,
    bins: int,
    lag: Lag,
) -> VariogramFit:
    """The fixed variogram: fitted on all samples' residuals as ``fit_kriging`` does, or given."""
    if variogram is None:
        _, residuals = fit_trend(c, v)
        return choose_exponent(
            c, residuals, exponents, system=system, estimator=estimator, bins=bins, lag=lag
        ).fit
    return make_variogram(
        np.asarray(variogram.theta, np.float64), float(variogram.p), int(variogram.result)
    )


def _candidate_scores(
    c: np.ndarray,
    act: np.ndarray,
    removed: list[int],
    theta: np.ndarray,
    p: float,
    system: System,
    strict: bool,
) -> np.ndarray:
    """Each active sample's score: ρ at it (``strict``: the least over it and ``removed``)
    under the active set without it, in chunks of ``_CHUNK`` candidates."""
    k = len(act)
    scores = np.empty(k)
    for start in range(0, k, _CHUNK):
        rows = np.arange(start, min(start + _CHUNK, k))
        subsets = np.stack([np.delete(act, i) for i in rows])
        probes = (
            np.stack([np.asarray([*removed, act[i]]) for i in rows])
            if strict
            else (act[rows][:, None])
        )
        rho = _reliability_under(c[subsets], c[probes], theta, p, system)
        scores[rows] = rho.min(axis=1)
    return scores


def _remove_greedily(
    c: np.ndarray,
    theta: np.ndarray,
    p: float,
    system: System,
    tau: float,
    floor: int,
    strict: bool,
) -> tuple[list[int], list[int], list[int], list[float], str]:
    """Remove the best-scoring sample while its score is ≥ τ and more than ``floor`` remain.

    Returns ``(active, removed, counts, curve, stopped)`` as :class:`Reduction` reports them.
    """
    active = list(range(c.shape[0]))
    removed: list[int] = []
    counts: list[int] = []
    curve: list[float] = []
    stopped = "min_samples"
    while len(active) - 1 >= floor:
        act = np.asarray(active)
        scores = _candidate_scores(c, act, removed, theta, p, system, strict)
        best = int(np.argmax(scores))
        counts.append(len(active))
        curve.append(float(scores[best]))
        if scores[best] < tau:
            stopped = "threshold"
            break
        removed.append(int(act[best]))
        active.pop(best)
    return active, removed, counts, curve, stopped
