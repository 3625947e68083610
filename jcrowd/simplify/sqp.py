"""Sequential quadratic programming for small equality-constrained problems, one per frame.

Paper 003 §5.2 solves its joint-position problem by SQP [GMW81, Fle87]. Each iteration here
linearises the constraints at ``x`` and solves the quadratic subproblem

    min_d  ½ dᵀ H d + ∇f(x)ᵀ d    s.t.  ∇c(x) d = -c(x)

with jaxopt's :class:`~jaxopt.EqualityConstrainedQP` (a direct LU solve of the KKT system:
the systems are ~100×100 and dense, where the default GMRES would iterate). The objective is a
sum of squares ``f = ‖r(x)‖²`` (all of paper 003's terms are), and ``H`` is the Gauss–Newton
Hessian ``2 JᵣᵀJᵣ`` plus the constraints' curvature weighted by ``|λ|`` (λ from the previous
subproblem) plus a small ridge. That ``H`` is positive definite, so every subproblem has a
unique minimiser and its step is a descent direction for the merit function; the exact
Lagrangian Hessian is indefinite when many frozen joints' angle terms are far from their key
values, and the coarsest levels then diverge. The step is accepted by
backtracking on the ℓ1 merit function ``f + ρ‖c‖₁`` over four step sizes (1, ½, ¼, ⅛),
evaluated together so the loop stays branch-free under ``vmap``. With no constraints it is a
damped Gauss–Newton method.

Why jaxopt's QP rather than a jaxopt constrained solver: ``jaxopt.ScipyMinimize`` leaves JAX
(no ``vmap`` over frames), and its projected-gradient solvers handle box or simplex sets, not
the nonlinear equalities of rigid bones.

Every frame gets a :class:`RESULT` code; nothing fails silently.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
from jaxopt import EqualityConstrainedQP
from jaxopt.linear_solve import solve_lu

__all__ = ["RESULT", "SQPSolution", "sqp_solve"]


class RESULT(enum.IntEnum):
    """Per-problem outcome of :func:`sqp_solve`."""

    CONVERGED = 0
    """Step and constraint violation below tolerance."""
    MAX_ITERATIONS = 1
    """Stopped at ``max_iter`` before meeting the tolerance."""
    NONFINITE = 2
    """A non-finite value appeared; the returned ``x`` is the last finite iterate."""

    @property
    def message(self) -> str:
        return {
            RESULT.CONVERGED: "converged",
            RESULT.MAX_ITERATIONS: "reached the iteration limit before converging",
            RESULT.NONFINITE: "hit a non-finite value",
        }[self]


class SQPSolution(eqx.Module):
    """``x`` (solution), ``multipliers`` (λ), ``result`` (:class:`RESULT` code), ``iterations``."""

    x: jax.Array
    multipliers: jax.Array
    result: jax.Array
    iterations: jax.Array


def _dense_solve(matvec: Callable, b: Any, init: Any = None, **_: Any) -> Any:
    """jaxopt's LU solve on the flattened KKT pytree ``(primal, dual)`` (``init`` is unused)."""
    flat_b, unravel = ravel_pytree(b)
    return unravel(solve_lu(lambda v: ravel_pytree(matvec(unravel(v)))[0], flat_b))


Residuals = Callable[[jax.Array, Any], jax.Array]
Constraints = Callable[[jax.Array, Any], jax.Array]

_STEPS = (1.0, 0.5, 0.25, 0.125)


def sqp_solve(
    residuals: Residuals,
    constraints: Constraints | None,
    x0: jax.Array,
    params: Any,
    *,
    num_constraints: int,
    max_iter: int = 30,
    tol: float = 1e-6,
    ridge: float = 1e-6,
    prior_weight: float = 0.0,
    prior: jax.Array | None = None,
    curvature: Callable[[jax.Array, jax.Array], jax.Array] | None = None,
) -> SQPSolution:
    """Minimise ``w‖x − prior‖² + ‖residuals(x, params)‖²`` s.t. ``constraints(x, params) = 0``.

    Written for one problem (``x0`` a vector); batch with ``jax.vmap``.

    Args:
        residuals: ``(k,)`` residual vector of ``x (n,)``; the objective is its squared norm.
        constraints: ``(m,)`` residuals, or ``None`` when ``num_constraints == 0``.
        x0: ``(n,)`` start (here: the original joint positions).
        num_constraints: ``m``, static.
        max_iter: iteration cap.
        tol: converged when ``max|c| < tol`` and either ``max|step| < tol`` (units of ``x``) or
            ``max|step| < 10 tol`` while the objective changed by at most 1e-7 relative (float32
            cannot resolve much less; on flat angle terms the step creeps while f stands still).
        ridge: added to the Hessian's diagonal; keeps the KKT matrix invertible where the
            objective is flat along a constraint-free direction.
        prior_weight, prior: an optional quadratic term ``w‖x − prior‖²`` handled in closed
            form (gradient ``2w(x − prior)``, Hessian ``2wI``) instead of as ``n`` residuals, so
            the residual Jacobian only has the nonlinear rows.
        curvature: ``(x, |λ|) ↦ Σ|λ_i| ∇²c_i`` if known in closed form; default ``jax.hessian``.
    """
    m = num_constraints
    n = x0.shape[0]
    qp = EqualityConstrainedQP(solve=_dense_solve, tol=1e-12)

    def cons(x: jax.Array) -> jax.Array:
        return constraints(x, params) if constraints is not None and m else jnp.zeros((0,), x.dtype)

    anchor = x0 if prior is None else prior
    k_res = jax.eval_shape(lambda y: residuals(y, params), x0).shape[0]
    m_jac = jax.jacrev if m < n else jax.jacfwd  # fewer passes: one per output or per input
    r_jac = jax.jacrev if k_res < n else jax.jacfwd

    def objective(x: jax.Array) -> jax.Array:
        r = residuals(x, params)
        return jnp.sum(r * r) + prior_weight * jnp.sum((x - anchor) ** 2)

    def constraint_curvature(x: jax.Array, lam_abs: jax.Array) -> jax.Array:
        if curvature is not None:
            return curvature(x, lam_abs)
        return jax.hessian(lambda y: jnp.dot(lam_abs, cons(y)))(x)

    def merit(x: jax.Array, rho: jax.Array) -> jax.Array:
        return objective(x) + rho * jnp.sum(jnp.abs(cons(x)))

    def body(state: tuple) -> tuple:
        x, lam, k, _, _ = state
        r = residuals(x, params)
        jr = r_jac(residuals)(x, params).reshape(k_res, n)
        eye = jnp.eye(n, dtype=x.dtype)
        g = 2.0 * jr.T @ r + 2.0 * prior_weight * (x - anchor)
        hess = 2.0 * jr.T @ jr + (2.0 * prior_weight + ridge) * eye
        if m:
            hess = hess + constraint_curvature(x, jnp.abs(lam))
        hess = 0.5 * (hess + hess.T)
        c = cons(x)
        if m:
            a = m_jac(cons)(x)
            sol = qp.run(params_obj=(hess, g), params_eq=(a, -c)).params
            d, lam_new = sol.primal, sol.dual_eq
        else:
            d, lam_new = jnp.linalg.solve(hess, -g), lam
        rho = 2.0 * jnp.max(jnp.abs(lam_new), initial=0.0) + 1.0
        phi0 = merit(x, rho)
        trials = jnp.stack([merit(x + s * d, rho) for s in _STEPS])
        ok = trials < phi0 + 1e-12 * jnp.abs(phi0)
        step = jnp.asarray(_STEPS, x.dtype)[jnp.argmax(ok)]
        step = jnp.where(jnp.any(ok), step, _STEPS[-1])
        x_new = x + step * d
        finite = jnp.all(jnp.isfinite(x_new)) & jnp.all(jnp.isfinite(lam_new))
        # Converged: the constraints hold and either the step or the objective's change is
        # negligible (on flat, non-convex angle terms the step can creep while f stands still).
        stalled = jnp.abs(objective(x_new) - objective(x)) <= 1e-7 * (1.0 + objective(x))
        moved = jnp.max(jnp.abs(step * d))
        done = ((moved < tol) | (stalled & (moved < 10 * tol))) & (
            jnp.max(jnp.abs(cons(x_new)), initial=0.0) < tol
        )
        x_new = jnp.where(finite, x_new, x)
        lam_new = jnp.where(finite, lam_new, lam)
        return x_new, lam_new, k + 1, done, ~finite

    def cond(state: tuple) -> jax.Array:
        _, _, k, done, bad = state
        return (k < max_iter) & ~done & ~bad

    init = (x0, jnp.zeros((m,), x0.dtype), jnp.asarray(0), jnp.asarray(False), jnp.asarray(False))
    x, lam, k, done, bad = jax.lax.while_loop(cond, body, init)
    code = jnp.where(
        bad, RESULT.NONFINITE, jnp.where(done, RESULT.CONVERGED, RESULT.MAX_ITERATIONS)
    )
    return SQPSolution(x, lam, code.astype(jnp.int32), k)
