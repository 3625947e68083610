"""Multilinear algebra for motion tensors: unfold, mode products, HOSVD, HOOI, truncation.

Owns the Tucker model of a motion tensor (DESIGN §2 ``tensor``, §4 steps 5 and 7): paper 000
§3.2 and §4.1 (M ∈ R^{P×T×S} = Z ×1 U_P ×2 U_T ×3 U_S, truncated HOSVD, ALS refinement) and
paper 004 §2 (natural modes actor × style × repetition, N-mode SVD, synthesis from mode rows).
Natural-mode tensors live in :mod:`jcrowd.tensor.natural`, key levels and storage accounting in
:mod:`jcrowd.tensor.keylevels`.

Conventions:

- Modes are 0-based in code; the papers' mode 1 (joints, P) is code mode 0.
- Unfolding: ``X_(n) = moveaxis(X, n, 0).reshape(I_n, -1)``. Row ``i_n``; the columns run over
  the remaining indices in increasing mode order with the *last varying fastest* (C order).
  This is TensorLy's order, not Kolda–Bader's (first index fastest); any fixed order gives the
  same left singular vectors, and :func:`fold` is its exact inverse.
- Mode product ``Y = X ×_n U`` with ``U`` of shape ``(J, I_n)``: ``Y_(n) = U X_(n)``
  (De Lathauwer, De Moor, Vandewalle 2000, Def. 8).
- A factor ``U_n`` has shape ``(I_n, R_n)`` with orthonormal columns and ``X ≈ Z ×_0 U_0 ×_1 …``.
  Paper 000 Eq. 3 reads ``Ũ_P ∈ R^{R_P×P}`` in the extracted text; for ``Z̃ ×1 Ũ_P`` to map the
  R_P core rows back to P pose elements the factor must be P×R_P, so we take that as the
  intended shape (the extraction also lost the ℝ and every superscript around it).
- Signs: each singular vector is flipped so that its largest-magnitude entry is positive, so
  results are reproducible across LAPACK builds.

Everything here is NumPy float64: this is the offline fit, and every rank tried changes every
array shape, so ``jax.jit`` would recompile for each rank of the key-level search. The model
module converts the chosen factors to float32 ``jax.Array`` for the online decode.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

from jcrowd.errors import TensorError

__all__ = [
    "RESULT",
    "Tucker",
    "TuckerResult",
    "fold",
    "hooi",
    "hosvd",
    "mean_squared_error",
    "mode_product",
    "multi_mode_product",
    "reconstruct",
    "relative_error",
    "truncate",
    "unfold",
]

Array = np.ndarray
_RESIDUAL_FLOOR = 1e3 * np.finfo(np.float64).eps
"""Relative residual energy below which ``1 − ‖Z‖²/‖X‖²`` is rounding noise (HOOI stops)."""


def unfold(X: Float[Array, "*dims"], mode: int) -> Float[Array, "I_n rest"]:
    """Mode-``mode`` unfolding ``X_(n)`` of shape ``(I_n, ∏_{k≠n} I_k)`` (C-order columns)."""
    X = np.asarray(X)
    return np.moveaxis(X, mode, 0).reshape(X.shape[mode], -1)


def fold(M: Float[Array, "I_n rest"], mode: int, shape: Sequence[int]) -> Float[Array, "*dims"]:
    """Inverse of :func:`unfold`: the tensor of ``shape`` whose mode-``mode`` unfolding is ``M``."""
    shape = tuple(int(s) for s in shape)
    moved = (shape[mode], *shape[:mode], *shape[mode + 1 :])
    return np.moveaxis(np.asarray(M).reshape(moved), 0, mode)


def mode_product(X: Float[Array, "*dims"], U: Float[Array, "J I_n"], mode: int) -> Array:
    """``X ×_mode U``: every mode-``mode`` fibre ``v`` of ``X`` replaced by ``U v`` (Def. 8)."""
    X, U = np.asarray(X), np.asarray(U)
    if U.ndim != 2 or U.shape[1] != X.shape[mode]:
        raise TensorError(
            f"mode product: expected a matrix with {X.shape[mode]} columns for mode {mode} of "
            f"a tensor of shape {X.shape}, found shape {U.shape}"
        )
    return np.moveaxis(np.tensordot(U, X, axes=(1, mode)), 0, mode)


def multi_mode_product(
    X: Float[Array, "*dims"], matrices: Sequence[Array | None], *, transpose: bool = False
) -> Array:
    """``X ×_0 A_0 ×_1 A_1 …`` over the modes whose entry in ``matrices`` is not ``None``.

    With ``transpose=True`` each ``A_n`` is applied as ``A_nᵀ`` (projection onto the columns of
    a factor, the step ``X ×_{k≠n} U_kᵀ`` of HOOI). Products on distinct modes commute.
    """
    Y = np.asarray(X)
    if len(matrices) != Y.ndim:
        raise TensorError(f"expected {Y.ndim} matrices (or None), found {len(matrices)}")
    todo = [(n, np.asarray(A)) for n, A in enumerate(matrices) if A is not None]
    todo = [(n, A.T if transpose else A) for n, A in todo]
    # Shrink the tensor fastest first: each product costs in proportion to the current size.
    for n, A in sorted(todo, key=lambda t: t[1].shape[0] / max(t[1].shape[1], 1)):
        Y = mode_product(Y, A, n)
    return Y


@dataclass(frozen=True)
class Tucker:
    """A Tucker model ``X ≈ core ×_0 factors[0] ×_1 factors[1] …`` (paper 000 Eq. 2–3).

    Attributes:
        core: ``(R_0, …, R_{N−1})`` core tensor Z.
        factors: ``N`` matrices, ``factors[n]`` of shape ``(I_n, R_n)``, orthonormal columns
            (except U_P after :func:`jcrowd.tensor.keylevels.drop_pose_elements` removed rows).
    """

    core: Array
    factors: tuple[Array, ...]

    def __post_init__(self) -> None:
        if len(self.factors) != self.core.ndim:
            raise TensorError(
                f"Tucker: expected {self.core.ndim} factors for a core of shape "
                f"{self.core.shape}, found {len(self.factors)}"
            )
        for n, U in enumerate(self.factors):
            if U.ndim != 2 or U.shape[1] != self.core.shape[n]:
                raise TensorError(
                    f"Tucker: expected factor {n} of shape (I, {self.core.shape[n]}), "
                    f"found {U.shape}"
                )

    @property
    def ranks(self) -> tuple[int, ...]:
        return tuple(int(r) for r in self.core.shape)

    @property
    def shape(self) -> tuple[int, ...]:
        """Shape of the tensor the model reconstructs."""
        return tuple(int(U.shape[0]) for U in self.factors)


def _check_ranks(shape: tuple[int, ...], ranks: Sequence[int] | None) -> tuple[int, ...]:
    if ranks is None:
        return shape
    ranks = tuple(int(r) for r in ranks)
    if len(ranks) != len(shape) or any(not 1 <= r <= i for r, i in zip(ranks, shape, strict=True)):
        raise TensorError(
            f"expected one rank per mode with 1 ≤ R_n ≤ I_n for a tensor of shape {shape}, "
            f"found ranks {ranks}"
        )
    return ranks


def _check_tensor(X: Array) -> Array:
    X = np.asarray(X, dtype=np.float64)
    if X.ndim < 2 or X.size == 0:
        raise TensorError(f"expected a non-empty tensor with at least 2 modes, found {X.shape}")
    if not np.all(np.isfinite(X)):
        raise TensorError(f"expected finite entries, found {np.sum(~np.isfinite(X))} non-finite")
    return X


def _leading_left_singular_vectors(A: Array, r: int) -> Array:
    """The ``r`` leading left singular vectors of ``A``, signs fixed.

    With up to a few hundred rows (every unfolding of a motion tensor) it takes the eigenvectors of
    the small Gram matrix ``A Aᵀ``, where an SVD would also form the right vectors (one per row,
    each as long as a row), and it only loses directions with σ² below eps·σ₁², which carry no
    energy worth keeping. A long mode (Data Mode, 004 §2.1) takes the SVD, full when
    ``r > min(A.shape)``.
    """
    if A.shape[0] <= max(A.shape[1], 512):
        U = np.linalg.eigh(A @ A.T)[1][:, ::-1][:, :r]
    else:
        U = np.linalg.svd(A, full_matrices=r > A.shape[1])[0][:, :r]
    flip = np.sign(U[np.argmax(np.abs(U), axis=0), np.arange(r)])
    return U * np.where(flip == 0, 1.0, flip)


def hosvd(X: Float[Array, "*dims"], ranks: Sequence[int] | None = None) -> Tucker:
    """(Truncated) higher-order SVD (De Lathauwer et al. 2000; paper 000 Eq. 2–3).

    ``U_n`` = the ``R_n`` leading left singular vectors of ``X_(n)``; ``Z = X ×_n U_nᵀ`` for all
    n. Without ``ranks`` it is the full HOSVD, ``R_n = min(I_n, ∏_{k≠n} I_k)`` (the rank bound
    of ``X_(n)``, so no all-zero core slices), and :func:`reconstruct` returns ``X``.
    """
    X = _check_tensor(X)
    full = tuple(min(i, X.size // i) for i in X.shape)
    ranks = _check_ranks(X.shape, full if ranks is None else ranks)
    factors = tuple(_leading_left_singular_vectors(unfold(X, n), r) for n, r in enumerate(ranks))
    return Tucker(multi_mode_product(X, factors, transpose=True), factors)


class RESULT(enum.Enum):
    """Outcome of :func:`hooi`; each member's value is its message."""

    CONVERGED = "converged: the relative decrease of the residual energy fell below tol"
    MAX_ITERATIONS = "reached max_iter before the relative decrease of the residual fell below tol"

    @property
    def message(self) -> str:
        return str(self.value)


@dataclass(frozen=True)
class TuckerResult:
    """What :func:`hooi` returns.

    Attributes:
        core, factors: the Tucker model (also as :attr:`tucker`).
        error: relative error ``‖X − X̂‖_F / ‖X‖_F`` (0 when X = 0), from the reconstruction.
        iterations: ALS sweeps done.
        result: :class:`RESULT` code.
    """

    core: Array
    factors: tuple[Array, ...]
    error: float
    iterations: int
    result: RESULT

    @property
    def tucker(self) -> Tucker:
        return Tucker(self.core, self.factors)


def hooi(
    X: Float[Array, "*dims"],
    ranks: Sequence[int],
    *,
    init: str | Tucker = "hosvd",
    max_iter: int = 100,
    tol: float = 1e-8,
    throw: bool = True,
) -> TuckerResult:
    """Best rank-(R_0, …) approximation by alternating least squares (HOOI).

    De Lathauwer, De Moor, Vandewalle, SIAM J. Matrix Anal. Appl. 21(4), 2000, Alg. 4.2; the ALS
    of paper 000 §3.2/§4.1 [11]. One sweep sets, for each mode n in turn, ``U_n`` = the leading
    left singular vectors of ``(X ×_{k≠n} U_kᵀ)_(n)``; then ``Z = X ×_n U_nᵀ``.

    Convergence: with orthonormal factors ``‖X − X̂‖² = ‖X‖² − ‖Z‖²``, so the fit is measured by
    the relative residual energy ``e² = 1 − ‖Z‖²/‖X‖²``, which no sweep can increase. It stops
    with ``CONVERGED`` when one sweep lowers it by at most ``tol`` relative,
    ``e²_{k−1} − e²_k ≤ tol·e²_{k−1}``, or when ``e²_k`` is below 1e3·eps, where that identity is
    rounding noise. A relative criterion keeps the same meaning for a coarse key level (e ~ 30 %)
    and a fine one (e ~ 0.1 %).

    On exit the basis inside each subspace is rotated so the core is all-orthogonal with slices
    ordered by norm (the HOSVD of the core): the error is unchanged and truncating the result
    drops its least important components, the ordering property of paper 000 §3.2 that
    in-between accuracy levels rely on.

    Args:
        X: the tensor, e.g. the motion tensor ``(P, T, S)``.
        ranks: ``(R_0, …)``, ``1 ≤ R_n ≤ I_n``.
        init: ``"hosvd"`` (truncated HOSVD) or a :class:`Tucker` whose factors, truncated to
            ``ranks``, start the sweeps (warm start along a rank path).
        max_iter: most sweeps.
        tol: relative decrease of the residual energy per sweep that counts as converged.
        throw: raise :class:`~jcrowd.errors.TensorError` instead of returning ``MAX_ITERATIONS``.
    """
    X = _check_tensor(X)
    ranks = _check_ranks(X.shape, ranks)
    if isinstance(init, Tucker):
        if init.shape != X.shape or any(r > q for r, q in zip(ranks, init.ranks, strict=True)):
            raise TensorError(
                f"hooi: init of shape {init.shape} and ranks {init.ranks} cannot start ranks "
                f"{ranks} of a tensor of shape {X.shape}"
            )
        factors = [U[:, :r] for U, r in zip(init.factors, ranks, strict=True)]
    elif init == "hosvd":
        factors = list(hosvd(X, ranks).factors)
    else:
        raise TensorError(f'hooi: expected init "hosvd" or a Tucker, found {init!r}')
    norm2 = float(np.sum(X * X))
    core = multi_mode_product(X, factors, transpose=True)
    if norm2 == 0.0:
        return TuckerResult(core, tuple(factors), 0.0, 0, RESULT.CONVERGED)
    residual = max(1.0 - float(np.sum(core * core)) / norm2, 0.0)
    result, k = RESULT.MAX_ITERATIONS, 0
    last = X.ndim - 1
    while k < max_iter and residual > _RESIDUAL_FLOOR:
        k += 1
        for n in range(X.ndim):
            others = [None if m == n else U for m, U in enumerate(factors)]
            Y = multi_mode_product(X, others, transpose=True)
            factors[n] = _leading_left_singular_vectors(unfold(Y, n), ranks[n])
        core = mode_product(Y, factors[last].T, last)
        previous, residual = residual, max(1.0 - float(np.sum(core * core)) / norm2, 0.0)
        if previous - residual <= tol * previous:
            result = RESULT.CONVERGED
            break
    if residual <= _RESIDUAL_FLOOR:
        result = RESULT.CONVERGED
    if result is RESULT.MAX_ITERATIONS and throw:
        raise TensorError(f"hooi at ranks {ranks}: {result.message} (max_iter={max_iter})")
    rotations = hosvd(core, core.shape)  # keep every requested rank, even R_n > ∏_{k≠n} R_k
    factors = [U @ V for U, V in zip(factors, rotations.factors, strict=True)]
    tucker = Tucker(rotations.core, tuple(factors))
    error = relative_error(X, reconstruct(tucker))
    return TuckerResult(tucker.core, tucker.factors, error, k, result)


def reconstruct(tucker: Tucker) -> Array:
    """``X̂ = Z ×_0 U_0 ×_1 U_1 …`` (paper 000 Eq. 3)."""
    return multi_mode_product(tucker.core, tucker.factors)


def truncate(tucker: Tucker, ranks: Sequence[int]) -> Tucker:
    """Keep the leading ``ranks`` of the core and of each factor (paper 000 §4.1, first method)."""
    ranks = _check_ranks(tucker.ranks, ranks)
    core = tucker.core[tuple(slice(r) for r in ranks)]
    return Tucker(core, tuple(U[:, :r] for U, r in zip(tucker.factors, ranks, strict=True)))


def relative_error(X: Float[Array, "*dims"], approx: Float[Array, "*dims"]) -> float:
    """``‖X − X̂‖_F / ‖X‖_F`` (``‖X̂‖_F`` alone when ``X`` is zero)."""
    X, approx = np.asarray(X, dtype=np.float64), np.asarray(approx, dtype=np.float64)
    norm = float(np.linalg.norm(X))
    diff = float(np.linalg.norm(X - approx))
    return diff / norm if norm > 0 else diff


def mean_squared_error(X: Float[Array, "*dims"], approx: Float[Array, "*dims"]) -> float:
    """``‖X − X̂‖²_F / (I_0·I_1·…)``, paper 000 §4.2's E (see :mod:`jcrowd.tensor.keylevels`)."""
    d = np.asarray(X, dtype=np.float64) - np.asarray(approx, dtype=np.float64)
    return float(np.mean(d * d))
