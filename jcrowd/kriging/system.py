"""The kriging system, solved once at fit time (NumPy float64): trend, Γ and its solution operator.

Paper 001 Eq. 2–3 and paper 000 Eq. 8. Two forms of the system share this code:

- ``"residual"`` — the papers' two-step universal kriging (001 §3.1, 000 §3.3): the trend is
  the least-squares hyperplane ``F = K C†`` over ``[1, c]`` (001 Eq. 2, 000 §3.3), and the
  residuals are kriged with the ordinary system ``[[Γ, 1], [1ᵀ, 0]] [b; λ] = [γ(c); 1]``
  (001 Eq. 3), so only Σ b = 1 is imposed.
- ``"drift"`` — Matheron's one-step universal kriging (Huijbregts & Matheron 1971; Cressie 1993
  §3.4): the hyperplane's basis joins the system as unbiasedness constraints,
  ``[[Γ, F], [Fᵀ, 0]] [b; μ] = [γ(c); f(c)]`` with ``F = [1, c_i]`` and ``f(c) = [1, c]``, so
  Σ b_i = 1 and Σ b_i c_i = c. This is what PyKrige's ``UniversalKriging`` with
  ``drift_terms=["regional_linear"]`` solves. The predictions of the two forms differ (the
  weights are not the same), although both add up to ``trend(c) + Σ b_i r_i``.

**How the system is solved** — the null-space method for saddle-point systems (Benzi, Golub &
Liesen 2005, §6), not an LU or an eigendecomposition of the indefinite bordered matrix. With
``F = U Σ Vᵀ`` (SVD; its rank-deficient part dropped), ``P = F⁺ᵀ`` gives a particular solution
``b_p = P f(c)`` of the constraints and ``N`` (the remaining left singular vectors) spans their
null space. Writing ``b = b_p + N z``, minimising the kriging variance ``2bᵀγ − bᵀΓb`` over z is
the symmetric system ``G z = Nᵀ(Γ b_p − γ)`` with ``G = −NᵀΓN``, positive semidefinite for a
valid variogram (Γ is conditionally negative definite). ``G`` is factorised by ``eigh`` and its
pseudo-inverse keeps eigenvalues above ``rcond · max|λ|`` (default ``rcond = n · eps`` of the
*storage* dtype, NumPy's ``matrix_rank`` convention). Hence:

- the constraints hold exactly whatever is dropped (Σ b = 1 even for singular Γ);
- exact duplicates with a zero nugget give one zero eigenvalue, dropped: the two samples share
  the weight equally (the minimum-norm solution); with a nugget the eigenvalue is 2θ0 > 0 — the
  nugget regularises duplicates and near-duplicates, as DESIGN §4.8 asks;
- when nothing is dropped the result equals the bordered system's solution (tested).

Because every piece is linear in ``[γ(c); f(c)]``, the operators are precomputed:
``b = M_γ γ(c) + M_f f(c)`` and ``μ = L_γ γ(c) + L_f f(c)`` (μ = F⁺(γ − Γ b), the multipliers of
``Γ b + F μ = γ``). A query then costs one S×S matrix–vector product (paper 001 §4.3: "only
the calculation of γ*(c) and its multiplication with the precomputed inverse matrix").
Every function here broadcasts over leading batch axes (used by leave-one-out and reduction).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import KrigingError
from jcrowd.kriging.variogram import semivariogram, semivariogram_limit

__all__ = [
    "Operators",
    "System",
    "default_rcond",
    "drift_basis",
    "fit_trend",
    "gamma_matrix",
    "query_gamma",
    "solution_operators",
    "solve_weights",
    "system_operators",
    "trend_basis",
]

System = Literal["residual", "drift"]


def check_system(system: str) -> None:
    if system not in ("residual", "drift"):
        raise KrigingError(f"kriging system: expected 'residual' or 'drift', found {system!r}")


def default_rcond(n: int, dtype: Any) -> float:
    """Relative eigenvalue cut-off ``n · eps(dtype)`` (NumPy's rank tolerance)."""
    return float(n * np.finfo(np.dtype(dtype)).eps)


def trend_basis(c: Float[np.ndarray, "*b n d"]) -> Float[np.ndarray, "*b n d1"]:
    """``[1, c]`` rows: the hyperplane basis of paper 001 §3.3 / 000 §3.3 (``C`` transposed)."""
    return np.concatenate([np.ones((*c.shape[:-1], 1)), c], axis=-1)


def drift_basis(c: Float[np.ndarray, "*b n d"], system: str) -> Float[np.ndarray, "*b n q"]:
    """The constraint basis F of the system: ``[1]`` (residual) or ``[1, c]`` (drift)."""
    return trend_basis(c) if system == "drift" else np.ones((*c.shape[:-1], 1))


def fit_trend(
    c: Float[np.ndarray, "S d"], values: Float[np.ndarray, "S V"]
) -> tuple[Float[np.ndarray, "d1 V"], Float[np.ndarray, "S V"]]:
    """Least-squares hyperplane (paper 001 Eq. 2, 000 ``F = K C†``) and the residuals.

    Returns ``coef`` with ``trend(c) = [1, c] @ coef`` — the transpose of 000's ``F`` — and
    ``values − [1, c_i] @ coef``. A rank-deficient design (samples on a lower-dimensional
    affine set) gets the minimum-norm coefficients of the pseudo-inverse.
    """
    basis = trend_basis(c)
    coef = np.linalg.pinv(basis, rcond=default_rcond(basis.shape[0], np.float64)) @ values
    return coef, values - basis @ coef


def _distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    diff = a[..., :, None, :] - b[..., None, :, :]
    return np.sqrt(np.sum(diff * diff, axis=-1))


def gamma_matrix(c: Float[np.ndarray, "*b n d"], theta: Any, p: float) -> np.ndarray:
    """Γ_ij = γ*(‖c_i − c_j‖) between distinct samples (nugget included even at h = 0), Γ_ii = 0."""
    g = semivariogram_limit(_distances(c, c), np.asarray(theta, np.float64), np.float64(p))
    n = c.shape[-2]
    return np.where(np.eye(n, dtype=bool), 0.0, g)


def query_gamma(
    c: Float[np.ndarray, "*b n d"], queries: Float[np.ndarray, "*b m d"], theta: Any, p: float
) -> Float[np.ndarray, "*b m n"]:
    """γ*(‖q − c_i‖) for each query (γ(0) = 0: a query at a sample is that sample)."""
    return semivariogram(_distances(queries, c), np.asarray(theta, np.float64), np.float64(p))


@dataclass(frozen=True)
class Operators:
    """Precomputed solution of the kriging system (see the module docstring).

    ``b = m_gamma @ γ(c) + m_drift @ f(c)``, ``μ = l_gamma @ γ(c) + l_drift @ f(c)``;
    ``dropped`` counts eigen-directions of ``G`` cut as numerically singular.
    """

    m_gamma: Float[np.ndarray, "*b n n"]
    m_drift: Float[np.ndarray, "*b n q"]
    l_gamma: Float[np.ndarray, "*b q n"]
    l_drift: Float[np.ndarray, "*b q q"]
    dropped: Int[np.ndarray, "*b"]


def _t(a: np.ndarray) -> np.ndarray:
    return np.swapaxes(a, -1, -2)


def solution_operators(
    gamma: Float[np.ndarray, "*b n n"], drift: Float[np.ndarray, "*b n q"], rcond: float
) -> Operators:
    """Null-space solution operators of ``[[Γ, F], [Fᵀ, 0]]`` (module docstring), batched."""
    n, q = drift.shape[-2], drift.shape[-1]
    u, s, vt = np.linalg.svd(drift, full_matrices=True)
    in_range = s > max(n, q) * np.finfo(np.float64).eps * s[..., :1]
    s_inv = np.divide(1.0, s, out=np.zeros_like(s), where=in_range)
    k = s.shape[-1]  # min(n, q)
    p_op = (u[..., :, :k] * s_inv[..., None, :]) @ vt[..., :k, :]  # P = F⁺ᵀ, (n, q)
    null_mask = np.concatenate([~in_range, np.ones((*s.shape[:-1], n - k), bool)], axis=-1)
    null = u * null_mask[..., None, :]  # columns outside null(Fᵀ) zeroed
    g = -(_t(null) @ gamma @ null)
    g = 0.5 * (g + _t(g))
    w, v = np.linalg.eigh(g)
    scale = np.max(np.abs(w), axis=-1, keepdims=True)
    keep = np.abs(w) > rcond * scale
    w_inv = np.divide(1.0, w, out=np.zeros_like(w), where=keep)
    g_pinv = (v * w_inv[..., None, :]) @ _t(v)
    m_gamma = -(null @ g_pinv @ _t(null))
    m_drift = p_op - m_gamma @ gamma @ p_op
    eye = np.eye(n)
    l_gamma = _t(p_op) @ (eye - gamma @ m_gamma)
    l_drift = -(_t(p_op) @ gamma @ m_drift)
    dropped = np.maximum(np.sum(~keep, axis=-1) - np.sum(~null_mask, axis=-1), 0)
    return Operators(m_gamma, m_drift, l_gamma, l_drift, dropped)


def system_operators(
    c: Float[np.ndarray, "*b n d"], theta: Any, p: float, system: str, rcond: float
) -> Operators:
    """:func:`solution_operators` for samples at ``c`` under the variogram ``(theta, p)``."""
    return solution_operators(gamma_matrix(c, theta, p), drift_basis(c, system), rcond)


def solve_weights(
    ops: Operators, g: Float[np.ndarray, "*b m n"], f: Float[np.ndarray, "*b m q"]
) -> tuple[Float[np.ndarray, "*b m n"], Float[np.ndarray, "*b m q"]]:
    """Weights ``b`` and multipliers ``μ`` for query rows ``γ(c)`` (of ``g``) and ``f(c)``."""
    b = g @ _t(ops.m_gamma) + f @ _t(ops.m_drift)
    mu = g @ _t(ops.l_gamma) + f @ _t(ops.l_drift)
    return b, mu
