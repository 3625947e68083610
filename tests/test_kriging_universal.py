"""Universal kriging (paper 000 Eq. 8, 001 Eq. 3, App. B): PyKrige as the oracle for both kriging
systems and their variances, exact interpolation and reliability, the solution operator against
a bordered solve, transformations (jit, vmap, control scaling, matrix values) and bad input."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from pykrige.ok import OrdinaryKriging
from pykrige.uk import UniversalKriging

from jcrowd.errors import KrigingError
from jcrowd.kriging import (
    fit_kriging,
    kriging_variance,
    kriging_weights,
    kriging_weights_batch,
    make_variogram,
    normalise_controls,
    predict,
    prediction_variance,
    reliability,
    stable,
)
from jcrowd.kriging.system import (
    drift_basis,
    fit_trend,
    gamma_matrix,
    query_gamma,
    solution_operators,
    solve_weights,
)

RNG = np.random.default_rng(7)
THETA = [0.05, 0.8, 4.0]  # nugget, partial sill, range


def _scattered(n=30, q=50, seed=0):
    rng = np.random.default_rng(seed)
    c = rng.uniform(0, 10, (n, 2))
    z = np.sin(c[:, 0]) + 0.3 * c[:, 1] + 0.1 * rng.normal(size=n)
    return c, z, rng.uniform(-1, 11, (q, 2))


def test_drift_system_matches_pykrige_universal():
    c, z, q = _scattered()
    with jax.enable_x64(True):
        vg = make_variogram(THETA, 0.0, dtype=np.float64)
        model = fit_kriging(c, z, vg, system="drift", normalise=False, dtype=np.float64)
        ours, var = np.asarray(predict(model, q)), np.asarray(kriging_variance(model, q))
    uk = UniversalKriging(
        c[:, 0],
        c[:, 1],
        z,
        variogram_model="spherical",
        variogram_parameters={"psill": THETA[1], "range": THETA[2], "nugget": THETA[0]},
        drift_terms=["regional_linear"],
    )
    zp, ss = uk.execute("points", q[:, 0], q[:, 1])
    # float64 on both sides and the same equations; PyKrige inverts the bordered matrix, we
    # use the null-space operator. Measured agreement ~1e-15; 1e-9 leaves room for LAPACK.
    np.testing.assert_allclose(ours, zp, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(var, ss, rtol=1e-9, atol=1e-12)


def test_residual_system_matches_pykrige_ordinary_on_residuals():
    """The papers' form: OLS hyperplane, then ordinary kriging of the residuals (stable p=1.3,
    given to PyKrige as a custom model)."""
    c, z, q = _scattered(seed=1)
    p = 1.3
    coef, r = fit_trend(c, z[:, None])
    with jax.enable_x64(True):
        vg = make_variogram(THETA, p, dtype=np.float64)
        model = fit_kriging(c, z, vg, normalise=False, dtype=np.float64)
        ours, var = np.asarray(predict(model, q)), np.asarray(kriging_variance(model, q))
    ok = OrdinaryKriging(
        c[:, 0],
        c[:, 1],
        r[:, 0],
        variogram_model="custom",
        variogram_parameters=list(THETA),
        variogram_function=lambda params, h: stable(h, np.asarray(params), p),
    )
    zp, ss = ok.execute("points", q[:, 0], q[:, 1])
    trend = np.c_[np.ones(len(q)), q] @ coef[:, 0]
    np.testing.assert_allclose(ours, trend + zp, rtol=1e-9, atol=1e-12)  # as above
    np.testing.assert_allclose(var, ss, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("system", ["residual", "drift"])
def test_operator_equals_bordered_solve(system):
    c = RNG.uniform(0, 1, (12, 3))
    queries = RNG.uniform(-0.5, 1.5, (9, 3))
    theta, p = np.array([0.02, 1.0, 0.8]), 0.8
    gam, f = gamma_matrix(c, theta, p), drift_basis(c, system)
    b, mu = solve_weights(
        solution_operators(gam, f, 1e-14),
        query_gamma(c, queries, theta, p),
        drift_basis(queries, system),
    )
    k = f.shape[1]
    a = np.block([[gam, f], [f.T, np.zeros((k, k))]])
    rhs = np.concatenate([query_gamma(c, queries, theta, p), drift_basis(queries, system)], 1)
    ref = np.linalg.solve(a, rhs.T).T
    # float64, condition ~1e3: both are backward stable, so ~1e-13 apart.
    np.testing.assert_allclose(b, ref[:, :12], rtol=1e-10, atol=1e-11)
    np.testing.assert_allclose(mu, ref[:, 12:], rtol=1e-10, atol=1e-11)


@pytest.fixture(scope="module")
def fitted():
    c, z, _ = _scattered(n=25, seed=3)
    return c, z, fit_kriging(c, z)  # float32, variogram chosen by cross-validation


def test_interpolates_samples_and_reliability(fitted):
    c, z, model = fitted
    assert model.dropped == 0
    leaves = [x for x in jax.tree.leaves(model) if jnp.issubdtype(x.dtype, jnp.floating)]
    assert all(x.dtype == jnp.float32 for x in leaves)  # library arrays are float32
    b1, mu1 = kriging_weights(model, c[0])
    assert b1.shape == (25,) and mu1.shape == (1,) and b1.dtype == jnp.float32
    b, _ = kriging_weights_batch(model, c)
    # float32 operator products: entries up to ~1/θ0 times γ ~ sill, so ~1e-5 rounding.
    np.testing.assert_allclose(np.asarray(b), np.eye(len(c)), atol=1e-4)
    np.testing.assert_allclose(np.asarray(predict(model, c)), z, atol=1e-4)
    np.testing.assert_allclose(np.asarray(reliability(model, c)), 1.0, atol=1e-4)
    np.testing.assert_allclose(np.asarray(prediction_variance(model, c)), 0.0, atol=1e-4)
    queries = RNG.uniform(-5, 15, (200, 2))
    b, _ = kriging_weights_batch(model, queries)
    np.testing.assert_allclose(np.asarray(b).sum(1), 1.0, atol=1e-4)  # Σ b = 1 everywhere
    far = np.array([[1e3, -1e3], [5e3, 2e2]])
    np.testing.assert_allclose(np.asarray(reliability(model, far)), 0.0, atol=1e-5)
    assert model.variogram.sill == pytest.approx(float(prediction_variance(model, far)[0]), 1e-5)


def test_reliability_falls_with_distance(fitted):
    c, _, model = fitted
    direction = np.array([0.6, 0.8])
    ray = c[0] + np.linspace(0, 40, 60)[:, None] * direction  # leaves the sample cloud
    rho = np.asarray(reliability(model, ray))
    assert rho[0] == pytest.approx(1.0, abs=1e-4)
    assert rho[-1] == pytest.approx(0.0, abs=1e-5)
    outside = np.linalg.norm(ray - c.mean(0), axis=1) > 12  # beyond every sample
    # Far out 1 - variance / sill is float32 rounding (~5e-6), the same tolerance as rho[-1].
    assert np.all(np.diff(rho[outside]) <= 1e-5)


def test_variances_relation(fitted):
    _, _, model = fitted
    q = RNG.uniform(0, 10, (7, 2))
    _, mu = kriging_weights_batch(model, q)
    lhs = np.asarray(kriging_variance(model, q)) - np.asarray(prediction_variance(model, q))
    np.testing.assert_allclose(lhs, np.asarray(mu)[:, 0], rtol=1e-4, atol=1e-6)  # μᵀf, f = [1]


def test_jit_eager_vmap_loop_and_one_compile(fitted):
    _, _, model = fitted
    q = jnp.asarray(RNG.uniform(0, 10, (6, 2)), jnp.float32)
    loop = [kriging_weights(model, qi) for qi in q]  # eager, one query at a time
    jitted = jax.jit(kriging_weights)
    batch_b, batch_mu = kriging_weights_batch(model, q)
    # Fused vs unfused float32 sums differ by a few ulps of the *terms* of b = M_γ γ + M_f f,
    # which are much larger than b where the nugget is small: bound by 16 eps Σ|M_ij γ_j|.
    g = np.asarray(model.variogram.sill) * np.ones(model.num_samples)
    terms = (
        np.abs(np.asarray(model.gamma_operator)) @ g
        + np.abs(np.asarray(model.drift_operator))[:, 0]
    )
    tol = 16 * np.finfo(np.float32).eps * terms
    terms_mu = np.abs(np.asarray(model.lagrange_gamma)) @ g + np.abs(
        np.asarray(model.lagrange_drift)
    ).sum(1)
    tol_mu = 16 * np.finfo(np.float32).eps * terms_mu
    for i, (b, mu) in enumerate(loop):
        jb, _ = jitted(model, q[i])
        assert np.all(np.abs(np.asarray(jb) - np.asarray(b)) <= tol)
        assert np.all(np.abs(np.asarray(batch_b[i]) - np.asarray(b)) <= tol)
        assert np.all(np.abs(np.asarray(batch_mu[i]) - np.asarray(mu)) <= tol_mu)
    counted = eqx.filter_jit(
        eqx.debug.assert_max_traces(jax.vmap(kriging_weights, (None, 0)), max_traces=1)
    )
    for _ in range(3):
        counted(model, q + 1.0)
    # Any leading batch shape: (2, 3, d) queries give (2, 3, S) weights.
    b3, _ = kriging_weights_batch(model, q.reshape(2, 3, 2))
    np.testing.assert_array_equal(np.asarray(b3).reshape(6, -1), np.asarray(batch_b))


def test_matrix_values_are_elementwise_kriging():
    """One kernel for all elements (000 §3.3): a (3, 2) value predicts like six scalars."""
    c = RNG.uniform(0, 1, (15, 2))
    values = np.stack([np.sin(3 * c[:, 0] + k) + k * c[:, 1] for k in range(6)], 1)
    vg = make_variogram([0.01, 1.0, 0.7], 1.5)
    model = fit_kriging(c, values.reshape(15, 3, 2), vg)
    q = RNG.uniform(0, 1, (10, 2))
    got = np.asarray(predict(model, q))
    assert got.shape == (10, 3, 2)
    for k in range(6):
        single = np.asarray(predict(fit_kriging(c, values[:, k], vg), q))
        np.testing.assert_allclose(got.reshape(10, 6)[:, k], single, rtol=1e-5, atol=1e-5)


def test_control_scaling_invariance():
    """With normalisation, rescaling a control axis (metres → millimetres) changes nothing."""
    c = RNG.uniform(0, 1, (20, 2))
    z = np.cos(4 * c[:, 0]) + c[:, 1] ** 2
    q = RNG.uniform(0, 1, (30, 2))
    scale = np.array([1.0, 1000.0])
    a = fit_kriging(c, z)
    b = fit_kriging(c * scale, z)
    np.testing.assert_allclose(np.asarray(a.variogram.theta), np.asarray(b.variogram.theta))
    # float32 predictions of two independently rounded models.
    np.testing.assert_allclose(
        np.asarray(predict(a, q)), np.asarray(predict(b, q * scale)), rtol=1e-4, atol=1e-4
    )
    cn, mean, sd = normalise_controls(c * scale)
    np.testing.assert_allclose(cn * sd + mean, c * scale, rtol=1e-12)
    np.testing.assert_allclose(cn.mean(0), 0, atol=1e-12)
    np.testing.assert_allclose(cn.std(0), 1, atol=1e-12)
    np.testing.assert_allclose(normalise_controls(cn)[0], cn, atol=1e-12)  # idempotent
    constant = normalise_controls(np.c_[c[:, 0], np.full(20, 3.0)])
    assert constant[2][1] == 1.0 and np.all(constant[0][:, 1] == 0)


def test_duplicates_never_nan():
    c = RNG.uniform(0, 1, (12, 2))
    c = np.concatenate([c, c[:3], c[3:5] + 1e-9])  # exact and near duplicates
    z = np.sin(5 * c[:, 0]) + RNG.normal(scale=0.05, size=len(c))  # duplicates disagree
    q = np.concatenate([c[:4], RNG.uniform(0, 1, (20, 2))])
    auto = fit_kriging(c, z)
    for model in (auto, fit_kriging(c, z, make_variogram([0.0, 1.0, 0.5], 1.0))):
        b, _ = kriging_weights_batch(model, q)
        assert np.all(np.isfinite(np.asarray(b)))
        assert np.all(np.isfinite(np.asarray(predict(model, q))))
        assert np.all(np.isfinite(np.asarray(reliability(model, q))))
        np.testing.assert_allclose(np.asarray(b).sum(1), 1.0, atol=1e-4)
    # Zero nugget and exact duplicates: Γ is singular; the cut direction shares the weight.
    zero = fit_kriging(c, z, make_variogram([0.0, 1.0, 0.5], 1.0))
    assert zero.dropped >= 3
    b, _ = kriging_weights_batch(zero, c[:1])
    assert float(b[0, 0]) == pytest.approx(0.5, abs=1e-3)
    assert float(b[0, 12]) == pytest.approx(0.5, abs=1e-3)


def test_bad_input_errors():
    c = RNG.uniform(size=(10, 2))
    z = RNG.normal(size=10)
    with pytest.raises(KrigingError, match=r"at least d \+ 2 = 4 samples"):
        fit_kriging(c[:3], z[:3])
    with pytest.raises(KrigingError, match="finite"):
        fit_kriging(np.where(np.arange(20).reshape(10, 2) == 5, np.nan, c), z)
    with pytest.raises(KrigingError, match="finite"):
        fit_kriging(c, np.where(np.arange(10) == 2, np.inf, z))
    with pytest.raises(KrigingError, match="expected 10 samples"):
        fit_kriging(c, z[:9])
    with pytest.raises(KrigingError, match="system"):
        fit_kriging(c, z, system="simple")  # type: ignore[arg-type]
    model = fit_kriging(c, z, make_variogram([0.0, 1.0, 1.0], 1.0))
    with pytest.raises(KrigingError, match=r"expected shape \(\.\.\., 2\)"):
        predict(model, np.zeros((4, 3)))
    with pytest.raises(eqx.EquinoxRuntimeError, match="must be finite"):
        predict(model, np.array([[0.1, np.nan]]))
