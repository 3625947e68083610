"""Tests for jcrowd.tensor.algebra: unfold/fold, mode products, HOSVD, HOOI (TensorLy as the
oracle), truncation, natural-mode tensors (paper 004 §2).

Everything is float64 NumPy. Where a tolerance is not machine precision the reason is stated.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import tensorly as tl
from helpers import smooth_tensor
from tensorly.decomposition import tucker as tl_tucker

from jcrowd.errors import JcrowdError, TensorError
from jcrowd.tensor import (
    RESULT,
    Tucker,
    fold,
    hooi,
    hosvd,
    mean_squared_error,
    mode_product,
    multi_mode_product,
    natural_mode_tensor,
    reconstruct,
    relative_error,
    synthesize,
    truncate,
    unfold,
)

EXACT = 1e-10
"""Relative tolerance for identities that only see rounding (products of a few hundred terms)."""


def low_rank_plus_noise(shape, ranks, noise, seed):
    rng = np.random.default_rng(seed)
    core = rng.standard_normal(ranks)
    factors = [
        np.linalg.qr(rng.standard_normal((i, r)))[0] for i, r in zip(shape, ranks, strict=True)
    ]
    X = multi_mode_product(core, factors)
    return X + noise * np.linalg.norm(X) / np.sqrt(X.size) * rng.standard_normal(shape)


# ------------------------------------------------------------------------------- unfold / fold


@pytest.mark.parametrize("shape", [(3, 4), (3, 4, 5), (2, 3, 4, 5)])
def test_fold_inverts_unfold(shape):
    X = np.random.default_rng(0).standard_normal(shape)
    for n in range(len(shape)):
        M = unfold(X, n)
        assert M.shape == (shape[n], X.size // shape[n])
        np.testing.assert_array_equal(fold(M, n, shape), X)


def test_unfold_column_order_is_c_order_of_remaining_modes():
    """Oracle loop: X_(n)[i_n, j] with j the C-order index of the other indices."""
    shape = (2, 3, 4, 5)
    X = np.random.default_rng(1).standard_normal(shape)
    for n in range(4):
        others = [i for k, i in enumerate(shape) if k != n]
        M = unfold(X, n)
        for idx in itertools.product(*(range(i) for i in shape)):
            rest = [v for k, v in enumerate(idx) if k != n]
            assert M[idx[n], np.ravel_multi_index(rest, others)] == X[idx]


# ------------------------------------------------------------------------------- mode products


def test_mode_product_matches_einsum():
    rng = np.random.default_rng(2)
    X = rng.standard_normal((3, 4, 5, 6))
    letters = "abcd"
    for n in range(4):
        U = rng.standard_normal((7, X.shape[n]))
        out = letters.replace(letters[n], "z")
        expected = np.einsum(f"z{letters[n]},{letters}->{out}", U, X)
        np.testing.assert_allclose(mode_product(X, U, n), expected, rtol=EXACT, atol=EXACT)
        np.testing.assert_allclose(unfold(mode_product(X, U, n), n), U @ unfold(X, n), rtol=EXACT)


def test_multi_mode_product_matches_einsum_and_transpose():
    rng = np.random.default_rng(3)
    X = rng.standard_normal((3, 4, 5))
    A, B, C = (rng.standard_normal((k, i)) for k, i in ((2, 3), (6, 4), (3, 5)))
    expected = np.einsum("ia,jb,kc,abc->ijk", A, B, C, X)
    np.testing.assert_allclose(multi_mode_product(X, [A, B, C]), expected, rtol=EXACT)
    np.testing.assert_allclose(
        multi_mode_product(X, [A.T, None, C.T], transpose=True),
        np.einsum("ia,kc,abc->ibk", A, C, X),
        rtol=EXACT,
    )


def test_mode_product_rejects_wrong_shape():
    with pytest.raises(TensorError, match="expected a matrix with 4 columns for mode 1"):
        mode_product(np.zeros((3, 4, 5)), np.zeros((2, 5)), 1)
    assert issubclass(TensorError, JcrowdError)


# ------------------------------------------------------------------------------- HOSVD


def test_hosvd_full_is_exact_with_orthonormal_factors_and_ordered_core():
    X = smooth_tensor((12, 15, 9), seed=4)
    t = hosvd(X)
    assert t.ranks == (12, 15, 9)
    assert relative_error(X, reconstruct(t)) < EXACT
    for n, U in enumerate(t.factors):
        np.testing.assert_allclose(U.T @ U, np.eye(U.shape[1]), atol=EXACT)
        # All-orthogonality and ordering (paper 000 §3.2): slices along mode n are orthogonal,
        # with norms = singular values of X_(n), non-increasing.
        Zn = unfold(t.core, n)
        gram = Zn @ Zn.T
        np.testing.assert_allclose(gram - np.diag(np.diag(gram)), 0.0, atol=1e-9)
        assert np.all(np.diff(np.diag(gram)) <= 1e-9)


def test_hosvd_tall_unfolding_data_mode():
    """Paper 004's Data Mode: mode 0 (f·n) is longer than the rest together."""
    X = np.random.default_rng(5).standard_normal((300, 3, 2, 2))
    t = hosvd(X)
    assert t.ranks == (12, 3, 2, 2)  # R_0 = min(I_0, ∏ others) = 12: no all-zero core slices
    assert relative_error(X, reconstruct(t)) < EXACT
    U = hosvd(X, (20, 3, 2, 2)).factors[0]  # more columns than the unfolding's rank
    np.testing.assert_allclose(U.T @ U, np.eye(20), atol=EXACT)


def test_bad_ranks_and_tensors_raise():
    X = np.zeros((3, 4, 5))
    with pytest.raises(TensorError, match=r"1 ≤ R_n ≤ I_n .* found ranks \(4, 1, 1\)"):
        hosvd(X, (4, 1, 1))
    with pytest.raises(TensorError, match="one rank per mode"):
        hooi(X, (1, 1))
    with pytest.raises(TensorError, match="non-finite"):
        hosvd(np.full((2, 2, 2), np.nan))
    with pytest.raises(TensorError, match='expected init "hosvd" or a Tucker'):
        hooi(np.ones((3, 4, 5)), (1, 1, 1), init="random")
    with pytest.raises(TensorError, match="expected 3 factors"):
        Tucker(np.zeros((2, 2, 2)), (np.zeros((3, 2)),))


# ------------------------------------------------------------------------------- HOOI


@pytest.mark.parametrize(
    ("X", "ranks"),
    [
        (low_rank_plus_noise((20, 25, 30), (4, 5, 6), 0.1, seed=6), (4, 5, 6)),
        (low_rank_plus_noise((20, 25, 30), (6, 6, 6), 0.3, seed=7), (3, 4, 5)),
        (smooth_tensor((60, 100, 40), seed=8), (10, 12, 8)),
        (smooth_tensor((60, 100, 40), seed=8), (20, 20, 15)),
    ],
    ids=["low-rank+noise", "under-ranked", "motion-shaped-10", "motion-shaped-20"],
)
def test_hooi_beats_hosvd_and_matches_tensorly(X, ranks):
    res = hooi(X, ranks)
    assert res.result is RESULT.CONVERGED
    e_hosvd = relative_error(X, reconstruct(hosvd(X, ranks)))
    # HOOI starts from HOSVD and no sweep lowers ‖Z‖, so it can only improve (up to rounding).
    assert res.error <= e_hosvd * (1 + 1e-12)
    tl_res = tl_tucker(tl.tensor(X), rank=list(ranks), init="svd", n_iter_max=100, tol=1e-8)
    e_tl = relative_error(X, tl.tucker_to_tensor(tl_res))
    # Both are ALS from the same start; they may stop at slightly different sweeps (1 % band).
    assert abs(res.error - e_tl) <= 0.01 * e_tl
    for U in res.factors:
        np.testing.assert_allclose(U.T @ U, np.eye(U.shape[1]), atol=EXACT)
    assert res.error == pytest.approx(relative_error(X, reconstruct(res.tucker)), rel=EXACT)


def test_hooi_error_falls_as_rank_rises_and_full_rank_is_exact():
    X = smooth_tensor((15, 18, 12), seed=9)
    errors = [hooi(X, (r, r + 1, r)).error for r in range(1, 12)]
    # Nested HOOI optima: the best error cannot rise with rank; 1e-9 absorbs ALS stopping noise.
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(errors))
    full = hooi(X, X.shape)
    assert full.error < EXACT and full.result is RESULT.CONVERGED


def test_hooi_result_codes():
    easy = low_rank_plus_noise((10, 12, 14), (3, 3, 3), 0.0, seed=10)
    res = hooi(easy, (3, 3, 3))
    assert res.result is RESULT.CONVERGED and res.error < 1e-7
    hard = np.random.default_rng(11).standard_normal((20, 20, 20))
    one = hooi(hard, (3, 3, 3), max_iter=1, throw=False)
    assert one.result is RESULT.MAX_ITERATIONS and one.iterations == 1
    assert "max_iter" in one.result.message
    with pytest.raises(TensorError, match=r"hooi at ranks \(3, 3, 3\): reached max_iter"):
        hooi(hard, (3, 3, 3), max_iter=1)
    zero = hooi(np.zeros((3, 4, 5)), (1, 2, 3))
    assert zero.result is RESULT.CONVERGED and zero.error == 0.0


def test_hooi_stopping_test_is_scale_free():
    """X·1e3 and X·1e−3 take the same sweeps to the same factors (signs aside).

    The stopping test is relative (e²_{k−1} − e²_k ≤ tol·e²_{k−1}, e² = ‖X − X̂‖²/‖X‖²), so
    scaling X changes nothing. Guards against an absolute test, e.g. on the residual energy
    ‖X − X̂‖² itself: then the large copy runs on (21 sweeps here) and the small one stops at 4.
    """
    X = low_rank_plus_noise((20, 25, 30), (6, 6, 6), 0.3, seed=7)
    big, small = hooi(1e3 * X, (3, 4, 5)), hooi(1e-3 * X, (3, 4, 5))
    assert big.iterations == small.iterations
    assert big.iterations >= 5  # measured 10: several sweeps, so a misplaced stop shows
    # Same sweeps on a scaled copy: only rounding differs (measured ~1e-15); EXACT leaves room
    # for the 1/(singular-value gap) amplification of that rounding in the eigenvectors.
    for U, V in zip(big.factors, small.factors, strict=True):
        sign = np.sign(np.sum(U * V, axis=0))  # columns are unique up to sign
        np.testing.assert_allclose(U, V * sign, rtol=0, atol=EXACT)
    assert big.error == pytest.approx(small.error, rel=EXACT)


def test_hooi_stops_at_the_first_sweep_below_the_relative_tolerance():
    """HOOI stops after the first sweep k with e²_{k−1} − e²_k ≤ tol·e²_{k−1}, as documented.

    Oracle: the same HOOI run for exactly j = 0, 1, … sweeps (``tol=0``, ``max_iter=j``), its
    e² = error² read from each reconstruction. Guards against a stopping test that is absolute
    in e² (``≤ tol``): with e² ≈ 0.16 here it is 6× looser and stops after 2 sweeps, not 4.
    """
    X = low_rank_plus_noise((20, 25, 30), (6, 6, 6), 0.05, seed=7)
    ranks, tol = (5, 5, 5), 1e-3
    k = hooi(X, ranks, tol=tol).iterations
    assert k >= 3  # several sweeps: where it stops is a decision of the test under check
    e2 = [hooi(X, ranks, tol=0.0, max_iter=j, throw=False).error ** 2 for j in range(k + 1)]
    drop = -np.diff(e2)
    assert np.all(drop[:-1] > tol * np.asarray(e2[:-2])), drop / np.asarray(e2[:-1])
    assert drop[-1] <= tol * e2[-2], drop / np.asarray(e2[:-1])


def test_hooi_keeps_ranks_above_the_product_of_the_others():
    """R_0 = 6 > R_1·R_2 = 4: the extra columns span nothing, but the ranks asked for stay."""
    X = smooth_tensor((10, 8, 9), seed=22)
    res = hooi(X, (6, 2, 2))
    assert res.tucker.ranks == (6, 2, 2)
    assert res.error == pytest.approx(hooi(X, (4, 2, 2)).error, rel=1e-6)  # same fit, ALS noise
    U = res.factors[0]
    np.testing.assert_allclose(U.T @ U, np.eye(6), atol=EXACT)


def test_hooi_warm_start_reaches_the_same_fit():
    X = smooth_tensor((30, 40, 20), seed=12)
    cold = hooi(X, (8, 9, 7))
    warm = hooi(X, (8, 9, 7), init=hooi(X, (10, 11, 9)).tucker)
    # Different starts, same local optimum on a smooth spectrum; 1e-4 relative covers the
    # tol=1e-8 stopping point on the residual energy.
    assert warm.error == pytest.approx(cold.error, rel=1e-4)
    with pytest.raises(TensorError, match="cannot start ranks"):
        hooi(X, (12, 9, 7), init=cold.tucker)


def test_hooi_core_is_ordered_so_slight_truncation_is_nearly_optimal():
    """Paper 000 §4.1: truncating a (D+1) optimised tensor ≈ D-dimensional ALS."""
    X = smooth_tensor((40, 50, 60), seed=13)
    big = hooi(X, (11, 13, 15))
    cut = truncate(big.tucker, (10, 12, 14))
    e_cut = relative_error(X, reconstruct(cut))
    e_als = hooi(X, (10, 12, 14)).error
    assert e_als <= e_cut * (1 + 1e-9)
    assert e_cut <= 1.05 * e_als  # measured 1.000–1.01 on this spectrum; 5 % is "slight"


# ------------------------------------------------------------------------------- truncation


def test_truncate_is_slicing():
    t = hosvd(smooth_tensor((6, 7, 8), seed=14))
    cut = truncate(t, (2, 3, 4))
    np.testing.assert_array_equal(cut.core, t.core[:2, :3, :4])
    for U, V, r in zip(cut.factors, t.factors, (2, 3, 4), strict=True):
        np.testing.assert_array_equal(U, V[:, :r])
    with pytest.raises(TensorError, match="found ranks"):
        truncate(cut, (3, 3, 4))


def test_error_helpers():
    X = np.arange(8.0).reshape(2, 2, 2)
    Y = X + 1.0
    assert mean_squared_error(X, Y) == 1.0
    assert relative_error(X, Y) == pytest.approx(np.sqrt(8) / np.linalg.norm(X), rel=EXACT)


# ------------------------------------------------------------------------------- natural modes


def _labelled_samples(seed: int, sample_shape=(20, 6), counts=None):
    """3 actors × 2 styles, with repetition counts per cell (default 3 everywhere)."""
    rng = np.random.default_rng(seed)
    counts = counts or {(a, s): 3 for a in range(3) for s in range(2)}
    samples, actors, styles = [], [], []
    for (a, s), c in counts.items():
        base = rng.standard_normal(sample_shape)
        for _ in range(c):
            samples.append(base + 0.1 * rng.standard_normal(sample_shape))
            actors.append(f"actor{a}")
            styles.append(("straight", "left")[s])
    return np.stack(samples), actors, styles


def test_natural_mode_tensor_layout_oracle():
    samples, actors, styles = _labelled_samples(15)
    nm = natural_mode_tensor(samples, actors, styles)
    assert nm.tensor.shape == (20, 6, 3, 2, 3) and nm.sample_shape == (20, 6)
    assert nm.actors == ("actor0", "actor1", "actor2") and nm.styles == ("straight", "left")
    np.testing.assert_array_equal(nm.counts, 3)
    seen: dict[tuple[int, int], int] = {}
    for x, a, s in zip(samples, actors, styles, strict=True):
        i, j = nm.actors.index(a), nm.styles.index(s)
        r = seen.get((i, j), 0)
        seen[(i, j)] = r + 1
        np.testing.assert_array_equal(nm.tensor[..., i, j, r], x)


@pytest.mark.parametrize("data_mode", [False, True], ids=["frame×dof", "data-mode"])
def test_natural_mode_svd_reconstructs_and_synthesizes_samples(data_mode):
    samples, actors, styles = _labelled_samples(16)
    if data_mode:
        samples = samples.reshape(len(samples), -1)
    nm = natural_mode_tensor(samples, actors, styles)
    model = hosvd(nm.tensor)
    assert relative_error(nm.tensor, reconstruct(model)) < EXACT
    for i, (a, s) in enumerate(zip(actors, styles, strict=True)):
        r = i % 3
        y = synthesize(model, nm.actors.index(a), nm.styles.index(s), r)
        np.testing.assert_allclose(y, samples[i], atol=1e-9)  # full rank: rounding only


def test_synthesis_is_linear_in_mode_weights_and_uniform_is_the_mean():
    samples, actors, styles = _labelled_samples(17)
    nm = natural_mode_tensor(samples, actors, styles)
    model = hosvd(nm.tensor)
    w = np.array([0.3, 0.7, 0.0])
    mixed = synthesize(model, w, 1, None)
    expected = 0.3 * nm.tensor[..., 0, 1, :].mean(-1) + 0.7 * nm.tensor[..., 1, 1, :].mean(-1)
    np.testing.assert_allclose(mixed, expected, atol=1e-9)
    np.testing.assert_allclose(synthesize(model, np.eye(3)[2], 0), synthesize(model, 2, 0))
    np.testing.assert_allclose(synthesize(model), nm.tensor.mean(axis=(-3, -2, -1)), atol=1e-9)
    with pytest.raises(TensorError, match="expected 3 actor weights"):
        synthesize(model, [1.0, 0.0])
    with pytest.raises(TensorError, match=r"style index in \[0, 2\)"):
        synthesize(model, 0, 5)


def test_missing_repetitions_are_filled_by_the_cell_mean():
    counts = {(0, 0): 3, (0, 1): 1, (1, 0): 2, (1, 1): 3, (2, 0): 3, (2, 1): 2}
    samples, actors, styles = _labelled_samples(18, counts=counts)
    nm = natural_mode_tensor(samples, actors, styles)
    np.testing.assert_array_equal(nm.counts, [[3, 1], [2, 3], [3, 2]])
    cell = nm.tensor[..., 1, 0, :]
    np.testing.assert_allclose(cell[..., 2], cell[..., :2].mean(-1), rtol=EXACT)
    model = hosvd(nm.tensor)
    # The fill keeps each cell's mean, so the uniform repetition weight returns the observed mean.
    cell_rows = [i for i, a in enumerate(actors) if a == "actor1" and styles[i] == "straight"]
    observed = samples[cell_rows]
    np.testing.assert_allclose(synthesize(model, 1, 0), observed.mean(0), atol=1e-9)
    with pytest.raises(TensorError, match="repetition counts"):
        natural_mode_tensor(samples, actors, styles, fill="require")


def test_empty_cell_and_bad_labels_raise():
    counts = {(0, 0): 2, (0, 1): 2, (1, 0): 2}  # actor1 never walked "left"
    samples, actors, styles = _labelled_samples(19, counts=counts)
    with pytest.raises(TensorError, match=r"cells with no sample: \[\('actor1', 'left'\)\]"):
        natural_mode_tensor(samples, actors, styles)
    with pytest.raises(TensorError, match="n actor and style labels"):
        natural_mode_tensor(samples, actors[:-1], styles)
    with pytest.raises(TensorError, match='fill "mean" or "require"'):
        natural_mode_tensor(samples, actors, styles, fill="zero")


def test_per_mode_truncation_error_falls_with_rank():
    samples, actors, styles = _labelled_samples(20)
    nm = natural_mode_tensor(samples, actors, styles)
    full = nm.tensor.shape
    base = hosvd(nm.tensor).ranks
    for mode in range(nm.tensor.ndim):
        errors = []
        for r in range(1, base[mode] + 1):
            ranks = tuple(r if k == mode else q for k, q in enumerate(base))
            errors.append(relative_error(nm.tensor, reconstruct(hosvd(nm.tensor, ranks))))
        # Truncated HOSVD along one mode: error² = Σ of the dropped σ², strictly falling to 0.
        assert all(b < a for a, b in itertools.pairwise(errors)), (mode, errors)
        assert errors[-1] < EXACT
    assert full[-3:] == (3, 2, 3)
