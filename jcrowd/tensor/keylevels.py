"""Key levels of a motion tensor by greedy search, in-between levels, joint reduction, storage.

Paper 000 §4.2–4.3 and §5.1 (DESIGN §4 step 7). Key level 1 is HOOI at the largest ranks,
key level N HOOI at the smallest; the levels between are found by walking the ranks down from
level 1 and stopping where the HOOI error first exceeds a target that grows linearly with the
level. Accuracy levels between two key levels are truncations of the larger one (§4.1: a
slight truncation of an optimised core costs little), so only the N key tensors are stored.

Readings of the extracted text (say which, and why):

- Error. §4.2 prints E = (1/PTS)·‖M − M̃‖ and calls it the mean-squared error; §5.1 also
  reports "mean squared (MS)" errors. The extraction drops every superscript (``R^{P×T×S}``
  reads as ``�P×T×S``), so we take the lost square: E = ‖M − M̃‖²_F / (P·T·S).
- Target. E_l ≈ l·C_E·E_1 with C_E = E_N/(N·E_1), i.e. the target is l·E_N/N, a line through
  the origin that ends at E_N. (It does not pass through E_1; E_1 is fixed by the largest ranks.)
  We compute the target as l·E_N/N, equal to l·C_E·E_1 but defined when E_1 = 0.
- Which level. "Z̃_2, whose approximation error … is larger than 2C_EE_1, is searched by
  decrementing": key level l is the *first* rank on the path whose HOOI error exceeds the target.
- Rank schedule. The paper does not say how the three ranks are decremented. We walk the
  straight line from max to min ranks in K = max_n(R_max,n − R_min,n) steps, step k having
  R_n = R_max,n − round(k·(R_max,n − R_min,n)/K): the mode with the widest range loses one
  rank per step, the others proportionally, so no rank ever grows. Each step's HOOI starts from
  the previous step's factors (warm start, few sweeps). Level l may use at most step
  K − (N − l), so every later level keeps a step of its own and key ranks strictly decrease.
- In-between levels. §4.2 says level j with KL_{i−1} < j < KL_i is truncated from KL_i; since
  truncation can only shrink a tensor and KL_i is the smaller one, we truncate KL_{i−1}, the
  next-larger key tensor (also what Fig. 2 of the paper draws as "subtensor").
- Joint reduction (§4.3) drops rows of U_P: dropped pose elements are not synthesised at all
  (y_kept = Z ×1 U_P[kept] …), which saves their flops and bytes. Zeroing them instead would
  still compute them and would pose them at exp-map 0 (the rest pose) rather than the frozen
  key posture; the caller fills them from the key posture (paper 003).

NumPy float64 throughout, as in :mod:`jcrowd.tensor.algebra` (every rank tried changes every shape).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import TensorError
from jcrowd.tensor.algebra import RESULT, Tucker, TuckerResult, hooi, truncate, unfold

__all__ = [
    "AccuracyLevel",
    "KeyLevel",
    "KeyLevels",
    "StorageReport",
    "accuracy_levels",
    "accuracy_tucker",
    "drop_pose_elements",
    "key_levels",
    "pca_rank_for_error",
    "rank_path",
    "storage_report",
    "tucker_nbytes",
    "tucker_storage",
]

Array = np.ndarray


@dataclass(frozen=True)
class KeyLevel:
    """One key tensor: HOOI result at ``ranks``, its error and the target it was searched for.

    Attributes:
        tucker: the key tensor (core + factors).
        mse: E_l = ‖M − M̃‖²/(PTS).
        target: l·E_N/N (= l·C_E·E_1); for l = 1 and l = N the error defines the level instead.
        step: index of ``tucker.ranks`` on :attr:`KeyLevels.path`.
        iterations, result: of the HOOI that produced it.
    """

    tucker: Tucker
    mse: float
    target: float
    step: int
    iterations: int
    result: RESULT

    @property
    def ranks(self) -> tuple[int, ...]:
        return self.tucker.ranks


@dataclass(frozen=True)
class KeyLevels:
    """Result of :func:`key_levels`; ``levels[l − 1]`` is the paper's key level l."""

    levels: tuple[KeyLevel, ...]
    path: tuple[tuple[int, ...], ...]
    c_e: float

    @property
    def errors(self) -> tuple[float, ...]:
        return tuple(k.mse for k in self.levels)

    @property
    def ranks(self) -> tuple[tuple[int, ...], ...]:
        return tuple(k.ranks for k in self.levels)

    @property
    def converged(self) -> bool:
        """Whether every key tensor's HOOI converged (see each level's ``result`` otherwise)."""
        return all(k.result is RESULT.CONVERGED for k in self.levels)


def rank_path(max_ranks: Sequence[int], min_ranks: Sequence[int]) -> tuple[tuple[int, ...], ...]:
    """Ranks on the straight line from ``max_ranks`` (step 0) to ``min_ranks`` (step K).

    K = max_n(R_max,n − R_min,n); step k has R_n = R_max,n − round(k·(R_max,n − R_min,n)/K).
    Consecutive steps differ, and no rank grows along the path.
    """
    hi, lo = np.asarray(max_ranks, dtype=np.int64), np.asarray(min_ranks, dtype=np.int64)
    if hi.shape != lo.shape or hi.ndim != 1 or np.any(lo < 1) or np.any(lo > hi):
        raise TensorError(
            f"expected min ranks 1 ≤ R_min ≤ R_max per mode, found max {tuple(hi.tolist())} "
            f"and min {tuple(lo.tolist())}"
        )
    span = hi - lo
    K = int(span.max())
    if K == 0:
        return (tuple(int(r) for r in hi),)
    k = np.arange(K + 1)[:, None]
    path = hi - np.rint(k * span / K).astype(np.int64)
    return tuple(tuple(int(r) for r in row) for row in path)


def _level(M: Array, norm2: float, res: TuckerResult, target: float, step: int) -> KeyLevel:
    mse = res.error**2 * norm2 / M.size
    return KeyLevel(res.tucker, mse, target, step, res.iterations, res.result)


def key_levels(
    M: Float[Array, "P T S"],
    n_levels: int,
    max_ranks: Sequence[int],
    min_ranks: Sequence[int],
    *,
    max_iter: int = 100,
    tol: float = 1e-8,
) -> KeyLevels:
    """Greedy search of the N key tensors (paper 000 §4.2, Fig. 3).

    1. Z̃_1 = HOOI(M, max ranks), Z̃_N = HOOI(M, min ranks); errors E_1, E_N (MSE, see module).
    2. C_E = E_N/(N·E_1); the target of level l is l·C_E·E_1 = l·E_N/N.
    3. For l = 2 … N−1, step down :func:`rank_path` from level l−1, one HOOI per step (warm
       started), until the error exceeds the target; that step is key level l.

    A level that reaches its step cap (K − (N − l), so later levels keep a step each) before
    exceeding its target is kept there, below target; compare ``mse`` with ``target``. HOOI
    codes are kept per level (:attr:`KeyLevels.converged`), never raised mid-search.

    Args:
        M: motion tensor (P, T, S) (any order ≥ 2 works).
        n_levels: N ≥ 2 key levels.
        max_ranks, min_ranks: (R_P, R_T, R_S) of key levels 1 and N.
        max_iter, tol: passed to :func:`jcrowd.tensor.algebra.hooi`.
    """
    M = np.asarray(M, dtype=np.float64)
    path = rank_path(max_ranks, min_ranks)
    K = len(path) - 1
    if n_levels < 2 or K < n_levels - 1:
        raise TensorError(
            f"key levels: expected 2 ≤ N ≤ {K + 1} (one rank step per level between "
            f"{path[0]} and {path[-1]}), found N = {n_levels}"
        )
    norm2 = float(np.sum(M * M))

    def fit(step: int, init: str | Tucker) -> TuckerResult:
        return hooi(M, path[step], init=init, max_iter=max_iter, tol=tol, throw=False)

    first = _level(M, norm2, fit(0, "hosvd"), 0.0, 0)
    last = _level(M, norm2, fit(K, "hosvd"), 0.0, K)
    e_1, e_n = first.mse, last.mse
    first, last = replace(first, target=e_n / n_levels), replace(last, target=e_n)
    levels = [first]
    previous, step = first.tucker, 0
    for l in range(2, n_levels):
        target, cap = l * e_n / n_levels, K - (n_levels - l)
        while True:
            step += 1
            level = _level(M, norm2, fit(step, previous), target, step)
            previous = level.tucker
            if level.mse > target or step >= cap:
                break
        levels.append(level)
    levels.append(last)
    c_e = e_n / (n_levels * e_1) if e_1 > 0 else float("inf")
    return KeyLevels(tuple(levels), path, c_e)


@dataclass(frozen=True)
class AccuracyLevel:
    """An accuracy level: ``ranks`` on the path, truncated from key level ``source + 1``."""

    ranks: tuple[int, ...]
    source: int
    step: int
    is_key: bool


def accuracy_levels(kl: KeyLevels, per_gap: int) -> tuple[AccuracyLevel, ...]:
    """Key levels plus ``per_gap`` in-between levels per gap, evenly spaced in path steps.

    Between key steps k_l < k_{l+1} the in-between steps are k_l + round(j·(k_{l+1} − k_l)/
    (per_gap + 1)), j = 1 … per_gap (fewer when the gap has fewer steps); each is a truncation
    of key level l, the next-larger key tensor (paper 000 §4.2, Fig. 2).
    """
    if per_gap < 0:
        raise TensorError(f"accuracy levels: expected per_gap ≥ 0, found {per_gap}")
    out: list[AccuracyLevel] = []
    for i, key in enumerate(kl.levels):
        out.append(AccuracyLevel(key.ranks, i, key.step, True))
        if i + 1 < len(kl.levels):
            a, b = key.step, kl.levels[i + 1].step
            steps = sorted({a + round(j * (b - a) / (per_gap + 1)) for j in range(1, per_gap + 1)})
            out += [AccuracyLevel(kl.path[s], i, s, False) for s in steps if a < s < b]
    return tuple(out)


def accuracy_tucker(kl: KeyLevels, ranks: Sequence[int]) -> Tucker:
    """The model at ``ranks``: the smallest key tensor with every rank ≥ ``ranks``, truncated."""
    want = tuple(int(r) for r in ranks)
    fits = [k for k in kl.levels if all(q >= r for q, r in zip(k.ranks, want, strict=True))]
    if len(want) != len(kl.levels[0].ranks) or not fits:
        raise TensorError(f"accuracy level: ranks {want} exceed key level 1's {kl.levels[0].ranks}")
    return truncate(fits[-1].tucker, want)


def drop_pose_elements(
    tucker: Tucker, drop: Sequence[int], mode: int = 0
) -> tuple[Tucker, Int[Array, " kept"]]:
    """Remove the rows ``drop`` of U_P (paper 000 §4.3): those elements are not synthesised.

    Returns the model whose reconstruction is ``reconstruct(tucker)[kept]`` along ``mode`` and
    the kept indices, in order, for the caller to scatter into a full pose vector whose dropped
    (frozen-joint) elements come from the key posture.
    """
    size = tucker.shape[mode]
    drop_idx = np.asarray(drop, dtype=np.int64).reshape(-1)
    if np.any((drop_idx < 0) | (drop_idx >= size)):
        raise TensorError(f"drop pose elements: expected indices in [0, {size}), found {drop}")
    kept = np.setdiff1d(np.arange(size), drop_idx).astype(np.int32)
    factors = list(tucker.factors)
    factors[mode] = factors[mode][kept]
    return Tucker(tucker.core, tuple(factors)), kept


def tucker_nbytes(tucker: Tucker, itemsize: int = 4) -> int:
    """Bytes to store core + factors with ``itemsize``-byte floats (float32 by default)."""
    return itemsize * (tucker.core.size + sum(U.size for U in tucker.factors))


def pca_rank_for_error(M: Float[Array, "P T S"], mse: float) -> tuple[int, float]:
    """Smallest PCA rank r of the P-dim pose vectors with MSE ≤ ``mse``, and that MSE.

    Paper 000 §5.1's baseline: principal components over joint DOF by a matrix SVD of the pose
    vectors, i.e. of the P × (T·S) unfolding, storing P·r components and r·T·S coefficients.
    Not mean-centred, like the tensor model (which has no mean term either), so both errors
    measure the same thing; the rank-r error is then Σ_{i>r} σ_i² (Eckart–Young).
    """
    M = np.asarray(M, dtype=np.float64)
    A = unfold(M, 0)
    sigma2 = np.sort(np.clip(np.linalg.eigvalsh(A @ A.T), 0.0, None))[::-1]
    norm2 = float(np.sum(A * A))
    residual = np.maximum(norm2 - np.concatenate([[0.0], np.cumsum(sigma2)]), 0.0) / M.size
    slack = 1e3 * np.finfo(np.float64).eps * norm2 / M.size
    r = int(np.argmax(residual <= mse + slack)) if np.any(residual <= mse + slack) else A.shape[0]
    return r, float(residual[r])


@dataclass(frozen=True)
class StorageReport:
    """Bytes stored by the key levels vs raw samples vs PCA at level 1's error (000 §5.1).

    Attributes:
        level_bytes: core + factors per key level.
        total_bytes: their sum (what the hybrid scheme stores).
        raw_bytes: P·T·S·itemsize, every sample stored as is.
        pca_rank, pca_bytes, pca_mse: smallest PCA with MSE ≤ ``level1_mse``, (P + T·S)·r floats.
        level1_mse: E_1, the finest key level's error.
        itemsize: bytes per float (4: float32; paper 000's 13.34 MB raw is 94·100·186 doubles
            in MiB, so its figures use 8).
    """

    level_bytes: tuple[int, ...]
    total_bytes: int
    raw_bytes: int
    pca_rank: int
    pca_bytes: int
    pca_mse: float
    level1_mse: float
    itemsize: int


def storage_report(M: Float[Array, "P T S"], kl: KeyLevels, *, itemsize: int = 4) -> StorageReport:
    """Storage accounting of a key-level model of ``M`` (see :class:`StorageReport`)."""
    return tucker_storage(M, [k.tucker for k in kl.levels], kl.levels[0].mse, itemsize=itemsize)


def tucker_storage(
    M: Float[Array, "P T S"], tuckers: Sequence[Tucker], level1_mse: float, *, itemsize: int = 4
) -> StorageReport:
    """Storage of any list of Tucker levels of ``M`` whose finest has MSE ``level1_mse``."""
    M = np.asarray(M, dtype=np.float64)
    P = M.shape[0]
    level_bytes = tuple(tucker_nbytes(t, itemsize) for t in tuckers)
    r, pca_mse = pca_rank_for_error(M, level1_mse)
    return StorageReport(
        level_bytes=level_bytes,
        total_bytes=sum(level_bytes),
        raw_bytes=M.size * itemsize,
        pca_rank=r,
        pca_bytes=(P + M.size // P) * r * itemsize,
        pca_mse=pca_mse,
        level1_mse=level1_mse,
        itemsize=itemsize,
    )
