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
from dataclasses import dataclass
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
    pb = _Problem(
        residuals,
        constraints,
        params,
        m,
        x0.shape[0],
        jax.eval_shape(lambda y: residuals(y, params), x0).shape[0],
        x0 if prior is None else prior,
        prior_weight,
        ridge,
        curvature,
    )
    qp = EqualityConstrainedQP(solve=_dense_solve, tol=1e-12)

    def body(state: tuple) -> tuple:
        return _iteration(pb, qp, tol, state)

    def cond(state: tuple) -> jax.Array:
        _, _, k, done, bad = state
        return (k < max_iter) & ~done & ~bad

    init = (x0, jnp.zeros((m,), x0.dtype), jnp.asarray(0), jnp.asarray(False), jnp.asarray(False))
    x, lam, k, done, bad = jax.lax.while_loop(cond, body, init)
    code = jnp.where(
        bad, RESULT.NONFINITE, jnp.where(done, RESULT.CONVERGED, RESULT.MAX_ITERATIONS)
    )
    return SQPSolution(x, lam, code.astype(jnp.int32), k)


@dataclass(frozen=True)
class _Problem:
    """One problem's functions of ``x``, with ``params`` bound (used at trace time only).

    ``n`` unknowns, ``m`` constraints, ``k_res`` residuals; ``anchor`` is the prior's centre.
    """

    residuals: Residuals
    constraints: Constraints | None
    params: Any
    m: int
    n: int
    k_res: int
    anchor: jax.Array
    prior_weight: float
    ridge: float
    curvature: Callable[[jax.Array, jax.Array], jax.Array] | None

    def cons(self, x: jax.Array) -> jax.Array:
        if self.constraints is not None and self.m:
            return self.constraints(x, self.params)
        return jnp.zeros((0,), x.dtype)

    def objective(self, x: jax.Array) -> jax.Array:
        r = self.residuals(x, self.params)
        return jnp.sum(r * r) + self.prior_weight * jnp.sum((x - self.anchor) ** 2)

    def merit(self, x: jax.Array, rho: jax.Array) -> jax.Array:
        """The ℓ1 merit function ``f + ρ‖c‖₁``."""
        return self.objective(x) + rho * jnp.sum(jnp.abs(self.cons(x)))

    def constraint_curvature(self, x: jax.Array, lam_abs: jax.Array) -> jax.Array:
        """``Σ|λ_i| ∇²c_i``: the closed form when given, else ``jax.hessian``."""
        if self.curvature is not None:
            return self.curvature(x, lam_abs)
        return jax.hessian(lambda y: jnp.dot(lam_abs, self.cons(y)))(x)


def _gauss_newton(pb: _Problem, x: jax.Array, lam: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Gradient ``g`` and Hessian ``H`` of the subproblem at ``x``: ``2 JᵣᵀJᵣ``, the prior's
    ``2wI``, the ridge and the constraints' ``|λ|``-weighted curvature, symmetrised."""
    r_jac = jax.jacrev if pb.k_res < pb.n else jax.jacfwd  # one pass per output or per input
    r = pb.residuals(x, pb.params)
    jr = r_jac(pb.residuals)(x, pb.params).reshape(pb.k_res, pb.n)
    eye = jnp.eye(pb.n, dtype=x.dtype)
    g = 2.0 * jr.T @ r + 2.0 * pb.prior_weight * (x - pb.anchor)
    hess = 2.0 * jr.T @ jr + (2.0 * pb.prior_weight + pb.ridge) * eye
    if pb.m:
        hess = hess + pb.constraint_curvature(x, jnp.abs(lam))
    return g, 0.5 * (hess + hess.T)


def _subproblem(
    pb: _Problem,
    qp: EqualityConstrainedQP,
    x: jax.Array,
    lam: jax.Array,
    g: jax.Array,
    hess: jax.Array,
) -> tuple[jax.Array, jax.Array]:
    """The step ``d`` and multipliers of the quadratic subproblem (Newton's step without
    constraints, the multipliers then kept)."""
    c = pb.cons(x)
    if pb.m:
        m_jac = jax.jacrev if pb.m < pb.n else jax.jacfwd
        a = m_jac(pb.cons)(x)
        sol = qp.run(params_obj=(hess, g), params_eq=(a, -c)).params
        return sol.primal, sol.dual_eq
    return jnp.linalg.solve(hess, -g), lam


def _step_length(pb: _Problem, x: jax.Array, d: jax.Array, lam_new: jax.Array) -> jax.Array:
    """The largest of ``_STEPS`` that lowers the merit (the smallest when none does), all
    evaluated together so the loop stays branch-free under ``vmap``."""
    rho = 2.0 * jnp.max(jnp.abs(lam_new), initial=0.0) + 1.0
    phi0 = pb.merit(x, rho)
    trials = jnp.stack([pb.merit(x + s * d, rho) for s in _STEPS])
    ok = trials < phi0 + 1e-12 * jnp.abs(phi0)
    step = jnp.asarray(_STEPS, x.dtype)[jnp.argmax(ok)]
    return jnp.where(jnp.any(ok), step, _STEPS[-1])


def _iteration(pb: _Problem, qp: EqualityConstrainedQP, tol: float, state: tuple) -> tuple:
    """One SQP iteration on ``(x, λ, k, done, bad)``; a non-finite iterate is not taken."""
    x, lam, k, _, _ = state
    g, hess = _gauss_newton(pb, x, lam)
    d, lam_new = _subproblem(pb, qp, x, lam, g, hess)
    step = _step_length(pb, x, d, lam_new)
    x_new = x + step * d
    finite = jnp.all(jnp.isfinite(x_new)) & jnp.all(jnp.isfinite(lam_new))
    # Converged: the constraints hold and either the step or the objective's change is
    # negligible (on flat, non-convex angle terms the step can creep while f stands still).
    stalled = jnp.abs(pb.objective(x_new) - pb.objective(x)) <= 1e-7 * (1.0 + pb.objective(x))
    moved = jnp.max(jnp.abs(step * d))
    done = ((moved < tol) | (stalled & (moved < 10 * tol))) & (
        jnp.max(jnp.abs(pb.cons(x_new)), initial=0.0) < tol
    )
    x_new = jnp.where(finite, x_new, x)
    lam_new = jnp.where(finite, lam_new, lam)
    return x_new, lam_new, k + 1, done, ~finite
