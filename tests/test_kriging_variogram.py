"""Variograms (paper 001 §4.1–4.2, App. A): estimators against slow loops, the models' closed
forms against PyKrige's, the weighted least-squares fit on exact curves and on simulated
Gaussian random fields, the fit's result codes, and leave-one-out against a bordered solve."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from pykrige.variogram_models import spherical_variogram_model
from scipy.optimize import least_squares

from jcrowd.errors import KrigingError
from jcrowd.kriging import (
    RESULT,
    ExperimentalVariogram,
    choose_exponent,
    experimental_variogram,
    fit_variogram,
    leave_one_out,
    make_variogram,
    pairwise_dissimilarity,
    semivariogram,
    spherical,
    stable,
)
from jcrowd.kriging.system import fit_trend, gamma_matrix, query_gamma

RNG = np.random.default_rng(20240601)


def _slow_variogram(c, values, estimator, bins=10):
    """Pair-by-pair loop over the definition of paper 001 §4.1 (Frobenius norm for matrices)."""
    s = len(c)
    pairs = [(i, j) for i in range(s) for j in range(i + 1, s)]
    h = {p: float(np.linalg.norm(c[p[0]] - c[p[1]])) for p in pairs}
    h_max = max(h.values())
    step = h_max / 2 / bins
    groups: list[list[float]] = [[] for _ in range(bins)]
    for p in pairs:
        if h[p] <= h_max / 2:
            u = min(int(h[p] // step), bins - 1)
            groups[u].append(float(np.sqrt(np.sum((values[p[0]] - values[p[1]]) ** 2))))
    out = []
    for g in groups:
        n = len(g)
        if n == 0:
            out.append(0.0)
        elif estimator == "matheron":
            out.append(sum(d * d for d in g) / (2 * n))
        else:
            mean = sum(np.sqrt(d) for d in g) / n
            out.append(0.5 * mean**4 / (0.457 + 0.494 / n + 0.045 / n**2))
    return np.array(out), np.array([len(g) for g in groups]), step


@pytest.mark.parametrize("estimator", ["cressie", "matheron"])
def test_estimators_match_slow_loop(estimator):
    c = RNG.uniform(0, 3, (23, 2))
    values = RNG.normal(size=(23, 3, 2))  # matrix values: Frobenius norm of differences
    exp = experimental_variogram(c, values, estimator=estimator)
    gamma, counts, step = _slow_variogram(c, values, estimator)
    np.testing.assert_array_equal(exp.counts, counts)
    # float64 on both sides, only the summation order differs.
    np.testing.assert_allclose(exp.gamma, gamma, rtol=1e-12, atol=0)
    np.testing.assert_allclose(exp.lags, step * (np.arange(10) + 0.5), rtol=1e-12)
    assert exp.counts.sum() == np.count_nonzero(
        [np.linalg.norm(a - b) <= exp.max_distance / 2 for i, a in enumerate(c) for b in c[i + 1 :]]
    )


def test_precomputed_dissimilarity_and_mean_lags():
    c = RNG.uniform(0, 1, (15, 3))
    values = RNG.normal(size=(15, 4))
    d = pairwise_dissimilarity(values)
    a = experimental_variogram(c, values)
    b = experimental_variogram(c, dissimilarity=d)
    np.testing.assert_array_equal(a.gamma, b.gamma)
    mean = experimental_variogram(c, values, lag="mean")
    np.testing.assert_array_equal(mean.gamma, a.gamma)  # only the lags change
    step = a.lags[0] * 2
    inside = mean.counts > 0
    assert np.all(mean.lags[inside] >= a.lags[inside] - step / 2)
    assert np.all(mean.lags[inside] <= a.lags[inside] + step / 2)


def test_estimator_errors():
    c = RNG.uniform(size=(6, 2))
    with pytest.raises(KrigingError, match="needs `values` or `dissimilarity`"):
        experimental_variogram(c)
    with pytest.raises(KrigingError, match="finite"):
        experimental_variogram(np.where(np.eye(6, 2) > 0, np.nan, c), np.ones(6))
    with pytest.raises(KrigingError, match="coincide"):
        experimental_variogram(np.zeros((4, 2)), np.arange(4.0))
    with pytest.raises(KrigingError, match="estimator"):
        experimental_variogram(c, np.ones(6), estimator="median")  # type: ignore[arg-type]


def test_models_closed_forms():
    theta = np.array([0.2, 1.3, 0.7])
    h = np.array([0.0, 1e-12, 0.1, 0.35, 0.7, 0.9, 5.0])
    for fn in (lambda x: spherical(x, theta), lambda x: stable(x, theta, 1.0)):
        g = fn(h)
        assert g[0] == 0.0  # γ(0) = 0 exactly, nugget only for h > 0
        assert g[1] == pytest.approx(0.2, abs=1e-9)  # h → 0⁺ gives the nugget
        assert np.all(np.diff(g[1:]) >= 0)
    # PyKrige's spherical model with [psill, range, nugget] = [θ1, θ2, θ0] (its internal list).
    np.testing.assert_allclose(
        spherical(h[1:], theta), spherical_variogram_model([1.3, 0.7, 0.2], h[1:]), rtol=1e-14
    )
    assert spherical(np.array([0.7, 2.0]), theta).tolist() == [1.5, 1.5]  # sill from the range on
    np.testing.assert_allclose(
        stable(h[1:], theta, 1.0), 0.2 + 1.3 * (1 - np.exp(-h[1:] / 0.7)), rtol=1e-14
    )
    np.testing.assert_allclose(
        stable(h[1:], theta, 2.0), 0.2 + 1.3 * (1 - np.exp(-((h[1:] / 0.7) ** 2))), rtol=1e-14
    )
    np.testing.assert_allclose(semivariogram(h, theta, 0.0), spherical(h, theta), rtol=0)
    # JAX and NumPy paths agree (float32: one rounding per operation, ~1e-7 relative).
    for p in (0.0, 0.4, 2.0):
        np.testing.assert_allclose(
            np.asarray(
                semivariogram(jnp.asarray(h, jnp.float32), jnp.asarray(theta, jnp.float32), p)
            ),
            semivariogram(h, theta, p),
            rtol=1e-6,
            atol=1e-7,
        )


@pytest.mark.parametrize(("model", "p"), [("spherical", 0.0), ("stable", 0.6), ("stable", 2.0)])
def test_fit_recovers_exact_curve(model, p):
    theta = np.array([0.15, 2.0, 1.2])
    lags = np.linspace(0.1, 2.5, 10)
    exp = ExperimentalVariogram(
        lags, semivariogram(lags, theta, p), np.full(10, 40), 5.0, "matheron"
    )
    fit = fit_variogram(exp, model, p, throw=True)
    # Noise-free data: the LM optimum is the truth; float32 solve with rtol 1e-4 on φ.
    np.testing.assert_allclose(np.asarray(fit.theta), theta, rtol=2e-3, atol=2e-4)
    assert float(fit.p) == np.float32(p)  # stored in the fit dtype


@pytest.mark.parametrize("p", [1.0, 1.5])
def test_fit_minimises_cressie_weighted_least_squares(p):
    """The fit is the minimiser of Eq. 4, Σ_u n_u (γ̄_u − γ*_u)² / γ*_u², on noisy data.

    Oracle: SciPy's least_squares in float64 on Cressie's residuals √n_u (γ̄_u / γ*_u − 1)
    (Cressie 1985), with the stable model written out here. Guards against a dropped 1/γ*
    weight (plain count-weighted least squares moves θ by up to 23–40 % on these curves).
    """
    rng = np.random.default_rng(0)
    truth, h_max = np.array([0.3, 2.0, 0.8]), 3.0
    lags = np.linspace(0.075, 1.425, 10)  # bin centres up to h_max / 2
    counts = rng.integers(20, 200, 10)

    def model(theta):
        return theta[0] + theta[1] * (1.0 - np.exp(-((lags / theta[2]) ** p)))

    gamma = model(truth) * (1.0 + 0.15 * rng.standard_normal(10))  # 15 % multiplicative noise
    fit = fit_variogram(ExperimentalVariogram(lags, gamma, counts, h_max, "matheron"), "stable", p)
    assert fit.status == RESULT.SUCCESSFUL
    oracle = least_squares(
        lambda theta: np.sqrt(counts) * (gamma / model(theta) - 1.0),
        truth,
        bounds=([0.0, 0.0, 1e-6], [np.inf, np.inf, h_max]),  # the fit's admissible set
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    assert oracle.success and not oracle.active_mask.any()  # an interior optimum
    # float32 LM stopping at rtol 1e-4 on φ (θ0, θ1 = φ²): measured ≤ 2e-5 relative; 1e-3 is
    # well under the 23–40 % shift that dropping the weight causes.
    np.testing.assert_allclose(np.asarray(fit.theta, np.float64), oracle.x, rtol=1e-3)


def _simulate(theta, p, n=300, reals=60, seed=0):
    """Gaussian random field with covariance C(h) = θ0 + θ1 − γ(h) (C(0) = sill: the nugget is
    white noise), sampled at n uniform points in the unit square, ``reals`` realisations."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 1, (n, 2))
    h = np.sqrt(((x[:, None] - x[None]) ** 2).sum(-1))
    cov = theta[0] + theta[1] - semivariogram(h, np.asarray(theta), p)
    chol = np.linalg.cholesky(cov + 1e-10 * np.eye(n))
    return x, chol @ rng.standard_normal((n, reals))


@pytest.mark.parametrize(
    ("theta", "model", "p"),
    [([0.1, 1.0, 0.4], "spherical", 0.0), ([0.2, 1.0, 0.15], "stable", 1.0)],
)
def test_fit_recovers_simulated_field(theta, model, p):
    x, z = _simulate(theta, p)
    reals = z.shape[1]
    # Matheron on the 60 realisations as one vector value: the Frobenius variogram is the sum of
    # 60 identical scalar ones, so the nugget and sill come out 60 times larger.
    mat = fit_variogram(
        experimental_variogram(x, z, estimator="matheron", lag="mean"), model, p, throw=True
    )
    got_m = np.asarray(mat.theta, np.float64) / [reals, reals, 1]
    # Cressie–Hawkins per realisation (its bias correction is for scalar increments), averaged.
    per = [experimental_variogram(x, z[:, k], lag="mean") for k in range(reals)]
    pooled = dataclasses.replace(per[0], gamma=np.mean([e.gamma for e in per], axis=0))
    got_c = np.asarray(fit_variogram(pooled, model, p, throw=True).theta, np.float64)
    # Tolerances: over seeds 0–2 these fits scatter by ±5 % in sill and range and ±0.03 in the
    # nugget (300 points, 60 realisations, correlated pairs); the bounds are about twice that.
    for got in (got_m, got_c):
        assert got[0] == pytest.approx(theta[0], abs=0.06)
        assert got[0] + got[1] == pytest.approx(theta[0] + theta[1], rel=0.12)
        assert got[2] == pytest.approx(theta[2], rel=0.15)


def test_fit_result_codes():
    lags = np.linspace(0.05, 0.95, 10)
    flat = ExperimentalVariogram(lags, np.zeros(10), np.full(10, 5), 2.0, "cressie")
    assert fit_variogram(flat).status == RESULT.NO_VARIATION
    # A straight line up to the largest lag never reaches a sill: the range hits its cap.
    line = ExperimentalVariogram(lags, 3.0 * lags, np.full(10, 20), 2.0, "cressie")
    fit = fit_variogram(line, "spherical")
    assert fit.status == RESULT.RANGE_AT_BOUND
    assert np.all(np.isfinite(np.asarray(fit.theta)))
    sparse = ExperimentalVariogram(
        lags, np.r_[0.5, 1.0, np.zeros(8)], np.r_[3, 3, np.zeros(8, int)], 2.0, "cressie"
    )
    assert fit_variogram(sparse).status == RESULT.TOO_FEW_BINS
    with pytest.raises(KrigingError, match="does not level off"):
        fit_variogram(line, "spherical", throw=True)
    with pytest.raises(KrigingError, match="0 < p ≤ 2"):
        fit_variogram(line, "stable", 0.0)
    with pytest.raises(KrigingError, match="total sill"):
        make_variogram([0.0, 0.0, 1.0], 1.0)


def _loo_bordered(c, r, theta, p, system):
    """Leave-one-out by solving each bordered system [[Γ, F], [Fᵀ, 0]] directly (float64)."""
    out = np.empty_like(r)
    for x in range(len(c)):
        keep = np.delete(np.arange(len(c)), x)
        ck = c[keep]
        gam = gamma_matrix(ck, theta, p)
        f = np.ones((len(ck), 1)) if system == "residual" else np.c_[np.ones(len(ck)), ck]
        q = f.shape[1]
        a = np.block([[gam, f], [f.T, np.zeros((q, q))]])
        fx = np.ones(1) if system == "residual" else np.r_[1.0, c[x]]
        rhs = np.r_[query_gamma(ck, c[x][None], theta, p)[0], fx]
        out[x] = np.linalg.solve(a, rhs)[: len(ck)] @ r[keep]
    return out


@pytest.mark.parametrize("system", ["residual", "drift"])
def test_leave_one_out_matches_bordered_solve(system):
    c = RNG.uniform(0, 1, (14, 2))
    r = RNG.normal(size=(14, 3))
    theta, p = np.array([0.05, 1.0, 0.6]), 1.4
    got = leave_one_out(c, r, theta, p, system, rcond=1e-13)
    # Same equations, float64; the null-space solve vs LU differ by rounding (cond ~1e3).
    np.testing.assert_allclose(got, _loo_bordered(c, r, theta, p, system), rtol=1e-9, atol=1e-11)


def test_choose_exponent_picks_lowest_loo_error():
    c = RNG.uniform(0, 1, (25, 2))
    z = np.sin(3 * c[:, 0]) * np.cos(2 * c[:, 1]) + c[:, 0]
    choice = choose_exponent(c, z)
    assert choice.exponents.tolist() == pytest.approx([0.2 * k for k in range(11)])
    k = int(np.argmin(choice.loo_mse))
    assert float(choice.fit.p) == pytest.approx(choice.exponents[k])
    _, r = fit_trend(c, z[:, None])
    theta = np.asarray(choice.fit.theta, np.float64)
    direct = _loo_bordered(c, r, theta, float(choice.fit.p), "residual")
    # The recorded score is App. A's MSE of the left-out residuals (cut-off n·eps32 vs exact
    # LU: agreement to ~1e-6 relative on this well-conditioned design).
    assert choice.loo_mse[k] == pytest.approx(np.mean(np.sum((r - direct) ** 2, 1)), rel=1e-5)
