"""Baselines (Rose et al. 1998 RBF, nearest sample) against slow formulas, and the accuracy
comparison on held-out points: kriging must beat both."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial import Delaunay

from jcrowd.errors import KrigingError
from jcrowd.kriging import fit_kriging, fit_rbf, predict, predict_nearest, predict_rbf
from jcrowd.kriging.rbf import cubic_bspline

RNG = np.random.default_rng(11)


def test_cubic_bspline():
    x = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0])
    # Uniform cubic B-spline ×1.5 (so B(0) = 1): (4 − 6x² + 3x³)/4, (2 − x)³/4.
    np.testing.assert_allclose(cubic_bspline(x), [1.0, 0.71875, 0.25, 0.03125, 0.0, 0.0])
    np.testing.assert_allclose(cubic_bspline(-x), cubic_bspline(x))
    # C² at the knots x = 1 and 2: one-sided second differences agree (step 1e-4 → ~1e-4).
    for k in (1.0, 2.0):
        e = 1e-4
        left = (cubic_bspline(k) - 2 * cubic_bspline(k - e) + cubic_bspline(k - 2 * e)) / e**2
        right = (cubic_bspline(k + 2 * e) - 2 * cubic_bspline(k + e) + cubic_bspline(k)) / e**2
        assert left == pytest.approx(right, abs=1e-3)
    np.testing.assert_allclose(np.asarray(cubic_bspline(jnp.asarray(x))), cubic_bspline(x))


def _rbf_slow(c, v, q):
    """The verbs-and-adverbs formula written out with loops (float64)."""
    s = c.shape[0]
    basis = np.c_[np.ones(s), c]
    lin = np.linalg.lstsq(basis, v, rcond=None)[0]
    res = v - basis @ lin
    alpha = [min(np.linalg.norm(c[i] - c[j]) for j in range(s) if j != i) for i in range(s)]
    mat = np.array(
        [
            [cubic_bspline(np.linalg.norm(c[j] - c[i]) / alpha[i]) for i in range(s)]
            for j in range(s)
        ]
    )
    w = np.linalg.solve(mat, res)
    out = []
    for x in q:
        radial = np.array([cubic_bspline(np.linalg.norm(x - c[i]) / alpha[i]) for i in range(s)])
        out.append(np.r_[1.0, x] @ lin + radial @ w)
    return np.array(out), np.array(alpha), lin


def test_rbf_matches_formula_and_interpolates():
    c = RNG.uniform(0, 1, (12, 2))
    v = np.sin(4 * c[:, 0]) + c[:, 1] ** 2
    q = RNG.uniform(-0.2, 1.2, (40, 2))
    model = fit_rbf(c, v)
    ref, alpha, lin = _rbf_slow(c, v, q)
    np.testing.assert_allclose(np.asarray(model.dilation), alpha, rtol=1e-6)
    # float32 model vs float64 formula; values O(1).
    np.testing.assert_allclose(np.asarray(predict_rbf(model, q)), ref, atol=2e-5)
    np.testing.assert_allclose(np.asarray(predict_rbf(model, c)), v, atol=2e-5)
    far = np.array([[10.0, -7.0]])  # beyond every support radius 2 α_i: only the hyperplane
    np.testing.assert_allclose(
        np.asarray(predict_rbf(model, far)), np.r_[1.0, far[0]] @ lin, rtol=1e-5
    )


def test_rbf_duplicates_and_errors():
    c = RNG.uniform(0, 1, (8, 2))
    c = np.concatenate([c, c[:2]])
    v = RNG.normal(size=10)
    out = np.asarray(predict_rbf(fit_rbf(c, v), RNG.uniform(0, 1, (20, 2))))
    assert np.all(np.isfinite(out))
    with pytest.raises(KrigingError, match="at least 3 samples"):
        fit_rbf(c[:2], v[:2])
    with pytest.raises(KrigingError, match="finite"):
        fit_rbf(np.where(c > 0.9, np.nan, c), v)


def test_nearest():
    c = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    v = np.arange(4.0)[:, None] * np.ones((1, 3))
    q = np.array([[0.1, 0.1], [0.9, 0.0], [0.0, 1.9], [0.5, 0.0]])
    got = np.asarray(predict_nearest(c, v, q))
    np.testing.assert_array_equal(got[:, 0], [0.0, 1.0, 3.0, 0.0])  # ties: lowest index
    assert got.shape == (4, 3)


def _franke(x, y):
    """Franke's (1979) test function for scattered-data interpolation on the unit square."""
    return (
        0.75 * np.exp(-((9 * x - 2) ** 2 + (9 * y - 2) ** 2) / 4)
        + 0.75 * np.exp(-((9 * x + 1) ** 2) / 49 - (9 * y + 1) / 10)
        + 0.5 * np.exp(-((9 * x - 7) ** 2 + (9 * y - 3) ** 2) / 4)
        - 0.2 * np.exp(-((9 * x - 4) ** 2) - (9 * y - 7) ** 2)
    )


def _rmse(a, b):
    return float(np.sqrt(np.mean((np.asarray(a) - b) ** 2)))


def test_kriging_beats_rbf_beats_nearest_2d():
    """Franke's function, 25 uniform random samples, 400 held-out points inside the samples'
    convex hull (interpolation, as in paper 001 §5.1), RMSE averaged over seeds 0–9.

    Measured means: kriging 0.053, RBF 0.080, nearest 0.109 (kriging wins 9/10 seeds against
    RBF, 10/10 against nearest). The RBF's lead over nearest is not general: its supports
    shrink with the sample spacing, so its error does not fall as samples are added; with 60
    samples nearest wins, and in 1-D nearest wins (next test)."""
    errors = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        c = rng.uniform(0, 1, (25, 2))
        z = _franke(*c.T)
        q = rng.uniform(0, 1, (2000, 2))
        q = q[Delaunay(c).find_simplex(q) >= 0][:400]
        truth = _franke(*q.T)
        errors.append(
            [
                _rmse(predict(fit_kriging(c, z), q), truth),
                _rmse(predict_rbf(fit_rbf(c, z), q), truth),
                _rmse(predict_nearest(c, z, q), truth),
            ]
        )
    krig, rbf, near = np.mean(errors, axis=0)
    assert krig < 0.8 * rbf
    assert rbf < 0.85 * near


def test_kriging_beats_baselines_1d():
    """sin(2πx) + x/2 from 20 uniform samples, 400 held-out points between the extreme samples,
    RMSE averaged over seeds 0–4. Measured: kriging 0.009, RBF 0.27, nearest 0.12 — Rose's
    bases (radius twice the nearest-neighbour distance) leave dips between unevenly spaced
    samples, which is why RBF loses to nearest here."""
    errors = []
    for seed in range(5):
        rng = np.random.default_rng(seed)
        c = rng.uniform(0, 1, (20, 1))
        z = np.sin(2 * np.pi * c[:, 0]) + 0.5 * c[:, 0]
        q = rng.uniform(c.min(), c.max(), (400, 1))
        truth = np.sin(2 * np.pi * q[:, 0]) + 0.5 * q[:, 0]
        errors.append(
            [
                _rmse(predict(fit_kriging(c, z), q), truth),
                _rmse(predict_rbf(fit_rbf(c, z), q), truth),
                _rmse(predict_nearest(c, z, q), truth),
            ]
        )
    krig, rbf, near = np.mean(errors, axis=0)
    assert krig < 0.2 * near
    assert krig < 0.2 * rbf
