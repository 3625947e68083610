"""Universal kriging over control space: the fitted model and its per-query kernels.

Paper 000 §3.3 (Eq. 8): ``K(c) = K_m(c) + Σ_i b_i(c) K_{r,i}`` with the hyperplane trend
``K_m(c) = F [c; 1]`` (``F = K C†``) and kriging weights ``b(c)`` from the fitted variogram
(paper 001 Eq. 3); paper 001 App. B for the prediction variance and the reliability ρ.

The fit (:func:`fit_kriging`) is host code in NumPy float64: normalise the controls, fit the
trend, choose the variogram (:func:`~jcrowd.kriging.crossval.choose_exponent` unless one is
given) and precompute the solution operator of the kriging system
(:mod:`~jcrowd.kriging.system`). The model it returns is an :class:`equinox.Module` of arrays
(float32 by default). The queries are pure ``jnp`` functions of *one* control vector
(:func:`kriging_weights`, :func:`predict_from_weights`), meant to be ``vmap``-ed inside the
crowd step; the public batched entry points (:func:`kriging_weights_batch`, :func:`predict`,
:func:`prediction_variance`, :func:`kriging_variance`, :func:`reliability`) take ``(..., d)``
queries, are ``filter_jit``-compiled, and reject non-finite queries with ``eqx.error_if``.

Queries are in the caller's units: the model stores the control normalisation and applies it.
A query that equals a sample's control vector gets that sample's weight one-hot (γ(0) = 0), so
the model interpolates the samples exactly, with or without a nugget (the nugget then makes the
prediction jump at the samples, as in PyKrige's ``exact_values=True``).

Reliability. Paper 001 App. B defines ρ(c) = 1 − σ²(c)/(θ0 + θ1) with σ²(c) = Σ_i b_i γ*(h_i).
With a fitted nugget θ0 that ρ is capped near 1 − θ0/(θ0 + θ1) everywhere but exactly at a
sample (every lag h > 0 pays the whole nugget), so the paper's thresholds (0.85, 0.9) are
not met on our captures (nugget share 0.28 on cmu16). Reading taken: the nugget is
measurement error — the capture-to-capture variation of one person's gait at the same
controls, which no control can predict — and ρ measures how well the *control-dependent
signal* is determined: ``σ_S²(c) = Σ_i b_i γ_S(h_i)`` with ``γ_S = γ − θ0`` for h > 0 (the
signal's variogram; equal to σ²(c) − θ0 away from the samples, since Σ b = 1), and
``ρ = 1 − σ_S²/θ1``. It is 1 at a sample, near 1 close to dense samples and 0 where none is
correlated, and equals the paper's when θ0 = 0. The weights b are unchanged (exact
interpolation). The standard deviation to expect of the error against an *unseen capture*
at c — the signal's uncertainty plus that capture's own nugget and the unknown mean — is the
textbook kriging variance (:func:`kriging_variance`); ``jcrowd fit``'s leave-one-clip-out
reports how well it is calibrated (``z_rms``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from jcrowd.errors import KrigingError
from jcrowd.kriging.crossval import (
    DEFAULT_EXPONENTS,
    as_values,
    check_sample_count,
    choose_exponent,
)
from jcrowd.kriging.model import KrigingModel
from jcrowd.kriging.system import (
    Operators,
    System,
    check_system,
    default_rcond,
    fit_trend,
    system_operators,
)
from jcrowd.kriging.variogram import Estimator, Lag, as_controls, spherical, stable
from jcrowd.kriging.variogram import semivariogram as _gamma
from jcrowd.kriging.variogram_fit import VariogramFit, make_variogram

__all__ = [
    "KrigingModel",
    "fit_kriging",
    "kriging_variance",
    "kriging_weights",
    "kriging_weights_batch",
    "normalise_controls",
    "predict",
    "predict_from_weights",
    "prediction_variance",
    "reliability",
    "reliability_from_terms",
    "reliability_one",
    "weights_and_reliability",
]

_HIGHEST = jax.lax.Precision.HIGHEST
"""Full float32 matmuls: GPUs would otherwise use TF32 (~1e-3), too coarse for the operators."""


def normalise_controls(
    controls: Float[Any, "S d"],
) -> tuple[Float[np.ndarray, "S d"], Float[np.ndarray, " d"], Float[np.ndarray, " d"]]:
    """Per-dimension standardisation ``(c − mean) / scale`` (NumPy float64).

    Kriging measures lags with the Euclidean norm, so control dimensions in different units
    (metres, radians, a style scalar) must be made comparable first (paper 001 §6: "all
    parameters must be normalized"). Each dimension gets zero mean and unit standard deviation
    over the samples; a constant dimension keeps scale 1 (it adds nothing to any lag). This is
    isotropic only up to the spread of the samples, not an anisotropy analysis. Idempotent.

    Returns:
        ``(normalised (S, d), mean (d,), scale (d,))``; queries map as ``(c − mean) / scale``.
    """
    c = as_controls(controls)
    mean = c.mean(axis=0)
    std = c.std(axis=0)
    scale = np.where(std > 0, std, 1.0)
    return (c - mean) / scale, mean, scale


def fit_kriging(
    controls: Float[Any, "S d"],
    values: Float[Any, "S ..."],
    variogram: VariogramFit | None = None,
    *,
    system: System = "residual",
    normalise: bool = True,
    exponents: Sequence[float] = DEFAULT_EXPONENTS,
    estimator: Estimator = "cressie",
    bins: int = 10,
    lag: Lag = "centre",
    rcond: float | None = None,
    dtype: Any = np.float32,
) -> KrigingModel:
    """Fit universal kriging of ``values`` over ``controls`` (paper 000 §3.3, 001 §3–4).

    Args:
        controls: ``(S, d)`` control vectors (``(S,)`` is read as d = 1). S ≥ d + 2.
        values: ``(S, ...)`` sample values of any shape (e.g. ``(S, R_P, R_T)`` cores).
        variogram: a fitted or known variogram *in normalised control units* (when
            ``normalise``); ``None`` chooses p by leave-one-out over ``exponents`` and fits θ
            by Eq. 4 on the residuals' experimental variogram.
        system: ``"residual"`` (the papers' OLS trend + ordinary kriging of residuals) or
            ``"drift"`` (Matheron's universal kriging, drift in the system).
        normalise: standardise the controls first (:func:`normalise_controls`).
        exponents, estimator, bins, lag: the variogram search, when ``variogram`` is ``None``
            (:func:`~jcrowd.kriging.crossval.choose_exponent`).
        rcond: relative eigenvalue cut-off of the system (default ``S · eps(dtype)``).
        dtype: dtype of the model's arrays (float32; float64 needs ``jax.enable_x64``).

    Returns:
        :class:`KrigingModel`. Raises :class:`~jcrowd.errors.KrigingError` for non-finite
        inputs, mismatched shapes or fewer than d + 2 samples.
    """
    check_system(system)
    c = as_controls(controls)
    s, d = c.shape
    check_sample_count(s, d)
    v, value_shape = as_values(values, s)
    raw = c
    if normalise:
        c, mean, scale = normalise_controls(c)
    else:
        mean, scale = np.zeros(d), np.ones(d)
    rcond = default_rcond(s, dtype) if rcond is None else float(rcond)
    if not rcond > 0.0:
        raise KrigingError(f"rcond: expected a positive cut-off, found {rcond}")
    coef, residuals = fit_trend(c, v)
    variogram = _model_variogram(
        c, residuals, variogram, system, exponents, estimator, bins, lag, dtype
    )
    ops = system_operators(
        c, np.asarray(variogram.theta, np.float64), float(variogram.p), system, rcond
    )
    return _assemble_model(
        raw, mean, scale, coef, residuals, ops, variogram, value_shape, system, dtype
    )


def _model_variogram(
    c: np.ndarray,
    residuals: np.ndarray,
    variogram: VariogramFit | None,
    system: System,
    exponents: Sequence[float],
    estimator: Estimator,
    bins: int,
    lag: Lag,
    dtype: Any,
) -> VariogramFit:
    """The variogram the model keeps: chosen by leave-one-out on the residuals, or the given
    one rebuilt in ``dtype``."""
    if variogram is None:
        return choose_exponent(
            c,
            residuals,
            exponents,
            system=system,
            estimator=estimator,
            bins=bins,
            lag=lag,
            dtype=dtype,
        ).fit
    return make_variogram(
        np.asarray(variogram.theta, np.float64),
        float(variogram.p),
        int(variogram.result),
        dtype,
    )


def _assemble_model(
    raw: np.ndarray,
    mean: np.ndarray,
    scale: np.ndarray,
    coef: np.ndarray,
    residuals: np.ndarray,
    ops: Operators,
    variogram: VariogramFit,
    value_shape: tuple[int, ...],
    system: System,
    dtype: Any,
) -> KrigingModel:
    """The float64 fit-time pieces as a :class:`KrigingModel` of ``dtype`` arrays."""

    def arr(x: np.ndarray) -> jax.Array:
        return jnp.asarray(x, dtype)

    return KrigingModel(
        controls=arr(raw),
        control_mean=arr(mean),
        control_scale=arr(scale),
        trend=arr(coef),
        residuals=arr(residuals),
        gamma_operator=arr(ops.m_gamma),
        drift_operator=arr(ops.m_drift),
        lagrange_gamma=arr(ops.l_gamma),
        lagrange_drift=arr(ops.l_drift),
        variogram=variogram,
        dropped=jnp.asarray(int(ops.dropped), jnp.int32),
        value_shape=value_shape,
        system=system,
    )


# ----------------------------------------------------------------------------- one query


def _normalised(model: KrigingModel, c: jax.Array) -> jax.Array:
    return (jnp.asarray(c, model.controls.dtype) - model.control_mean) / model.control_scale


def _terms(model: KrigingModel, c: jax.Array) -> tuple[jax.Array, ...]:
    """γ(c) (S,), f(c) (q,), b (S,), μ (q,) for one query in caller units."""
    c = jnp.asarray(c, model.controls.dtype)
    x = _normalised(model, c)
    steps = [(model.controls[:, k] - c[k]) / model.control_scale[k] for k in range(c.shape[0])]
    h2 = sum((s * s for s in steps[1:]), steps[0] * steps[0])  # see _weights_matrix
    pos = h2 > 0
    h = jnp.where(pos, jnp.sqrt(jnp.where(pos, h2, 1.0)), 0.0)  # no NaN gradient at a sample
    g = _gamma(h, model.variogram.theta, model.variogram.p)
    one = jnp.ones((1,), x.dtype)
    f = one if model.system == "residual" else jnp.concatenate([one, x])
    b = jnp.dot(model.gamma_operator, g, precision=_HIGHEST) + jnp.dot(
        model.drift_operator, f, precision=_HIGHEST
    )
    mu = jnp.dot(model.lagrange_gamma, g, precision=_HIGHEST) + jnp.dot(
        model.lagrange_drift, f, precision=_HIGHEST
    )
    return g, f, b, mu


def kriging_weights(
    model: KrigingModel, c: Float[Any, " d"]
) -> tuple[Float[jax.Array, " S"], Float[jax.Array, " q"]]:
    """Kriging weights ``b(c)`` (Σ b = 1) and Lagrange multipliers for one query (001 Eq. 3).

    Pure and unchecked (no ``error_if``): the kernel to ``vmap`` inside a compiled step. The
    multipliers solve ``Γ b + F μ = γ(c)``; μ has one entry (λ) for the residual system and
    d + 1 for the drift system.
    """
    _, _, b, mu = _terms(model, jnp.asarray(c))
    return b, mu


def predict_from_weights(
    model: KrigingModel, c: Float[Any, " d"], weights: Float[Any, " S"]
) -> Float[jax.Array, "*value"]:
    """``trend(c) + Σ_i b_i K_{r,i}`` (paper 000 Eq. 8) for one query and its weights."""
    x = _normalised(model, c)
    basis = jnp.concatenate([jnp.ones((1,), x.dtype), x])
    w = jnp.asarray(weights, model.residuals.dtype)
    out = jnp.dot(basis, model.trend, precision=_HIGHEST) + jnp.dot(
        w, model.residuals, precision=_HIGHEST
    )
    return out.reshape(model.value_shape)


def _predict_one(model: KrigingModel, c: jax.Array) -> jax.Array:
    return predict_from_weights(model, c, kriging_weights(model, c)[0])


def _prediction_variance_one(model: KrigingModel, c: jax.Array) -> jax.Array:
    g, _, b, _ = _terms(model, c)
    return jnp.dot(b, g, precision=_HIGHEST)


def _kriging_variance_one(model: KrigingModel, c: jax.Array) -> jax.Array:
    g, f, b, mu = _terms(model, c)
    return jnp.dot(b, g, precision=_HIGHEST) + jnp.dot(mu, f, precision=_HIGHEST)


def reliability_from_terms(
    weights: Float[jax.Array, "*Q S"], gamma: Float[jax.Array, "*Q S"], theta: jax.Array
) -> Float[jax.Array, "*Q"]:
    """ρ = 1 − Σ_i b_i γ_S(h_i) / θ1 with the nugget treated as measurement error (module doc).

    ``γ_S = max(γ − θ0, 0)`` is the variogram of the control-dependent signal: γ without its
    nugget for h > 0, and 0 at h = 0 (γ(0) = 0 already). With θ0 = 0 this is paper 001's
    ρ = 1 − σ²/(θ0 + θ1) unchanged. A pure-nugget variogram (θ1 = 0) has no signal to be
    reliable about: ρ = 0 there, except 1 at the samples themselves.
    """
    signal = jnp.maximum(gamma - theta[0], 0.0)
    sigma2 = jnp.sum(weights * signal, axis=-1)
    psill = theta[1]
    safe = jnp.where(psill > 0, psill, 1.0)
    return jnp.where(psill > 0, 1.0 - sigma2 / safe, jnp.where(sigma2 > 0, 0.0, 1.0))


def reliability_one(model: KrigingModel, c: Float[Any, " d"]) -> jax.Array:
    """ρ(c) for one query, pure and unchecked (the kernel :func:`reliability` batches)."""
    g, _, b, _ = _terms(model, c)
    return reliability_from_terms(b, g, model.variogram.theta)


# ----------------------------------------------------------------------------- batched


def _batched(fn: Callable, model: KrigingModel, c: Any) -> Any:
    """Apply a one-query kernel to ``(..., d)`` queries, after checking them."""
    d = model.controls.shape[1]
    c = jnp.asarray(c, model.controls.dtype)
    if c.ndim == 0 or c.shape[-1] != d:
        raise KrigingError(f"kriging queries: expected shape (..., {d}), found {c.shape}")
    c = eqx.error_if(c, ~jnp.all(jnp.isfinite(c)), "kriging queries must be finite")
    lead = c.shape[:-1]
    out = jax.vmap(fn, in_axes=(None, 0))(model, c.reshape(-1, d))
    return jax.tree.map(lambda o: o.reshape(lead + o.shape[1:]), out)


def _terms_matrix(model: KrigingModel, c: jax.Array) -> tuple[jax.Array, ...]:
    """γ (Q, S), f (Q, q), b (Q, S) and μ (Q, q) for ``(Q, d)`` queries, as matrix products.

    The same sums as :func:`kriging_weights` under ``vmap``, arranged for throughput: the
    variogram family is chosen once by ``lax.cond`` on the scalar exponent (under ``vmap`` both
    the spherical and the stable branch would run for every entry), and ``Γ⁻¹``-operators act
    on the ``(Q, S)`` variogram matrix as one GEMM.
    """
    x = _normalised(model, c)
    # A sum over the d control columns (d is small and static): a (Q, S, d) broadcast reduced
    # along its short last axis is a strided loop on XLA:CPU.
    steps = [
        (model.controls[None, :, k] - c[:, k, None]) / model.control_scale[k]
        for k in range(c.shape[1])
    ]
    h2 = sum((s * s for s in steps[1:]), steps[0] * steps[0])
    pos = h2 > 0
    h = jnp.where(pos, jnp.sqrt(jnp.where(pos, h2, 1.0)), 0.0)
    theta, p = model.variogram.theta, model.variogram.p
    g = jax.lax.cond(
        p == 0,
        lambda h: spherical(h, theta),
        lambda h: stable(h, theta, jnp.where(p == 0, 1.0, p)),
        h,
    )
    one = jnp.ones((x.shape[0], 1), x.dtype)
    f = one if model.system == "residual" else jnp.concatenate([one, x], axis=1)
    b = jnp.matmul(g, model.gamma_operator.T, precision=_HIGHEST) + jnp.matmul(
        f, model.drift_operator.T, precision=_HIGHEST
    )
    mu = jnp.matmul(g, model.lagrange_gamma.T, precision=_HIGHEST) + jnp.matmul(
        f, model.lagrange_drift.T, precision=_HIGHEST
    )
    return g, f, b, mu


def _weights_matrix(model: KrigingModel, c: jax.Array) -> tuple[jax.Array, jax.Array]:
    """b and μ for ``(Q, d)`` queries at once (:func:`_terms_matrix`)."""
    _, _, b, mu = _terms_matrix(model, c)
    return b, mu


def weights_and_reliability(
    model: KrigingModel, c: Float[jax.Array, "Q d"]
) -> tuple[Float[jax.Array, "Q S"], Float[jax.Array, " Q"]]:
    """Kriging weights ``b(c)`` and reliability ρ(c) (001 App. B) of ``(Q, d)`` queries.

    Pure and unchecked, in matrix form: the batched kernel for compiled code that needs both
    (the crowd's clip choice), equal to :func:`kriging_weights` and :func:`reliability_one`
    under ``vmap``.
    """
    g, _, b, _ = _terms_matrix(model, jnp.asarray(c, model.controls.dtype))
    return b, reliability_from_terms(b, g, model.variogram.theta)


@eqx.filter_jit
def kriging_weights_batch(
    model: KrigingModel, c: Float[Any, "*Q d"]
) -> tuple[Float[jax.Array, "*Q S"], Float[jax.Array, "*Q q"]]:
    """:func:`kriging_weights` for ``(..., d)`` queries (matrix form) plus a finite check."""
    d = model.controls.shape[1]
    c = jnp.asarray(c, model.controls.dtype)
    if c.ndim == 0 or c.shape[-1] != d:
        raise KrigingError(f"kriging queries: expected shape (..., {d}), found {c.shape}")
    c = eqx.error_if(c, ~jnp.all(jnp.isfinite(c)), "kriging queries must be finite")
    lead = c.shape[:-1]
    b, mu = _weights_matrix(model, c.reshape(-1, d))
    return b.reshape(lead + b.shape[1:]), mu.reshape(lead + mu.shape[1:])


@eqx.filter_jit
def predict(model: KrigingModel, c: Float[Any, "*Q d"]) -> Float[jax.Array, "*Q *value"]:
    """Predicted values ``trend(c) + Σ b_i(c) K_{r,i}`` (000 Eq. 8) at ``(..., d)`` queries."""
    return _batched(_predict_one, model, c)


@eqx.filter_jit
def prediction_variance(model: KrigingModel, c: Float[Any, "*Q d"]) -> Float[jax.Array, "*Q"]:
    """σ²(c) = Σ_i b_i(c) γ*(‖c − c_i‖) as in paper 001 App. B.

    This is the paper's estimate: the textbook kriging variance adds the multiplier term
    (:func:`kriging_variance`). The paper's form is 0 at the samples and the total sill
    θ0 + θ1 where no sample is correlated; :func:`reliability` uses it without the nugget
    (module doc). Where some weights are negative it can leave [0, θ0 + θ1] slightly; it is
    not clipped.
    """
    return _batched(_prediction_variance_one, model, c)


@eqx.filter_jit
def kriging_variance(model: KrigingModel, c: Float[Any, "*Q d"]) -> Float[jax.Array, "*Q"]:
    """Textbook kriging variance ``2bᵀγ − bᵀΓb = bᵀγ(c) + μᵀf(c)`` (Cressie 1993 §3.2, §3.4).

    Equal to PyKrige's ``sigmasq`` for the same system; exceeds the sill far from the samples
    (it includes the uncertainty of the mean / trend). Not used by :func:`reliability`.
    """
    return _batched(_kriging_variance_one, model, c)


@eqx.filter_jit
def reliability(model: KrigingModel, c: Float[Any, "*Q d"]) -> Float[jax.Array, "*Q"]:
    """ρ(c) = 1 − σ_S²(c) / θ1, paper 001 App. B with the nugget as measurement error.

    1 at the samples, 0 where no sample is correlated, continuous in between (module doc:
    "Reliability"). With no nugget it is the paper's 1 − σ²(c) / (θ0 + θ1).
    """
    return _batched(reliability_one, model, c)
