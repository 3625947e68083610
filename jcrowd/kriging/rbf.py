"""Baselines that kriging must beat: RBF interpolation as in "verbs and adverbs", nearest sample.

Rose, Cohen & Bodenheimer (1998), the RBF method that papers 000 and 001 compare against:

1. a linear approximation ``A(c) = [1, c] @ a`` fitted to the samples by least squares;
2. one radial basis per sample on the residuals, ``R_i(c) = B(‖c − c_i‖ / α_i)``, with B the
   uniform cubic B-spline (support |x| < 2, scaled so that B(0) = 1) and α_i the distance from
   c_i to its nearest other sample, so each basis reaches zero at *twice* that distance;
3. the weights ``w`` (one row per basis) solve the S×S system ``Σ_i w_i R_i(c_j) = r_j``.

The interpolant is ``A(c) + Σ_i w_i R_i(c)``. Nothing is tuned. Readings and edge cases:

- the system matrix ``R_ji = B(‖c_j − c_i‖/α_i)`` is not symmetric (radii differ per column);
  it is solved by least squares (SVD, cut-off ``S · eps``), which is the exact solve whenever
  the matrix is regular and the minimum-norm solution when it is not;
- duplicate samples: "nearest other sample" would be at distance 0 and the basis a spike, so
  α_i is the distance to the nearest sample at a *positive* distance (duplicates then have
  identical rows, and the minimum-norm solve shares the weight); when all samples coincide,
  α_i = 1;
- the controls are used as given (the method has no normalisation; pass normalised controls
  if their units differ).

:func:`predict_nearest` returns the value of the nearest sample (lowest index on ties).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from jcrowd.errors import KrigingError
from jcrowd.kriging.crossval import as_values
from jcrowd.kriging.system import default_rcond, trend_basis
from jcrowd.kriging.variogram import as_controls

__all__ = ["RBFModel", "cubic_bspline", "fit_rbf", "predict_nearest", "predict_rbf"]

_HIGHEST = jax.lax.Precision.HIGHEST


def cubic_bspline(x: Any) -> Any:
    """Uniform cubic B-spline, scaled to B(0) = 1: ``1 − 1.5x² + 0.75|x|³`` on |x| ≤ 1,
    ``0.25(2 − |x|)³`` on 1 ≤ |x| ≤ 2, 0 beyond. NumPy in → NumPy out, JAX in → JAX out."""
    xp = jnp if isinstance(x, jax.Array) else np
    a = xp.abs(x)
    inner = 1.0 - 1.5 * a * a + 0.75 * a * a * a
    outer = 0.25 * (2.0 - a) ** 3
    return xp.where(a <= 1.0, inner, xp.where(a < 2.0, outer, 0.0))


class RBFModel(eqx.Module):
    """Fitted RBF interpolant (Rose et al. 1998): ``[1, c] @ linear + Σ_i w_i B(‖c − c_i‖/α_i)``."""

    controls: Float[jax.Array, "S d"]
    dilation: Float[jax.Array, " S"]
    weights: Float[jax.Array, "S V"]
    linear: Float[jax.Array, "d1 V"]
    value_shape: tuple[int, ...] = eqx.field(static=True)


def fit_rbf(
    controls: Float[Any, "S d"], values: Float[Any, "S ..."], *, dtype: Any = np.float32
) -> RBFModel:
    """Fit the verbs-and-adverbs RBF interpolant (module docstring) in NumPy float64."""
    c = as_controls(controls)
    s, d = c.shape
    if s < d + 1:
        raise KrigingError(
            f"RBF interpolation with a linear term in d = {d} dimensions needs at least "
            f"{d + 1} samples; found {s}"
        )
    v, value_shape = as_values(values, s)
    basis = trend_basis(c)
    linear = np.linalg.lstsq(basis, v, rcond=default_rcond(s, np.float64))[0]
    residuals = v - basis @ linear
    diff = c[:, None, :] - c[None, :, :]
    h = np.sqrt(np.sum(diff * diff, axis=-1))
    positive = np.where(h > 0, h, np.inf)
    dilation = positive.min(axis=1)
    dilation = np.where(np.isfinite(dilation), dilation, 1.0)
    system = cubic_bspline(h / dilation[None, :])  # R[j, i] = B(‖c_j − c_i‖ / α_i)
    weights = np.linalg.lstsq(system, residuals, rcond=default_rcond(s, np.float64))[0]
    return RBFModel(
        controls=jnp.asarray(c, dtype),
        dilation=jnp.asarray(dilation, dtype),
        weights=jnp.asarray(weights, dtype),
        linear=jnp.asarray(linear, dtype),
        value_shape=value_shape,
    )


def _queries(c: Any, d: int, dtype: Any) -> tuple[jax.Array, tuple[int, ...]]:
    c = jnp.asarray(c, dtype)
    if c.ndim == 0 or c.shape[-1] != d:
        raise KrigingError(f"queries: expected shape (..., {d}), found {c.shape}")
    c = eqx.error_if(c, ~jnp.all(jnp.isfinite(c)), "queries must be finite")
    return c.reshape(-1, d), c.shape[:-1]


def _distances(a: jax.Array, b: jax.Array) -> jax.Array:
    diff = a[:, None, :] - b[None, :, :]
    h2 = jnp.sum(diff * diff, axis=-1)
    pos = h2 > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, h2, 1.0)), 0.0)


@eqx.filter_jit
def predict_rbf(model: RBFModel, c: Float[Any, "*Q d"]) -> Float[jax.Array, "*Q *value"]:
    """RBF predictions at ``(..., d)`` queries."""
    d = model.controls.shape[1]
    q, lead = _queries(c, d, model.controls.dtype)
    radial = cubic_bspline(_distances(q, model.controls) / model.dilation)
    basis = jnp.concatenate([jnp.ones((q.shape[0], 1), q.dtype), q], axis=1)
    out = jnp.dot(basis, model.linear, precision=_HIGHEST) + jnp.dot(
        radial, model.weights, precision=_HIGHEST
    )
    return out.reshape(lead + model.value_shape)


@eqx.filter_jit
def predict_nearest(
    controls: Float[Any, "S d"], values: Float[Any, "S ..."], c: Float[Any, "*Q d"]
) -> Float[jax.Array, "*Q *value"]:
    """The value of the nearest sample to each ``(..., d)`` query (lowest index on ties)."""
    samples = jnp.asarray(controls)
    vals = jnp.asarray(values)
    if samples.ndim != 2 or vals.shape[:1] != samples.shape[:1]:
        raise KrigingError(
            f"predict_nearest: expected controls (S, d) and values (S, ...), found "
            f"{samples.shape} and {vals.shape}"
        )
    q, lead = _queries(c, samples.shape[1], samples.dtype)
    nearest = jnp.argmin(_distances(q, samples), axis=1)
    return vals[nearest].reshape(lead + vals.shape[1:])
