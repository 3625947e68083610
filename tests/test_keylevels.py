"""Tests for jcrowd.tensor.keylevels: rank path, greedy key levels (paper 000 §4.2), in-between
levels, joint reduction (§4.3) and storage accounting (§5.1)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from helpers import smooth_tensor

from jcrowd.errors import TensorError
from jcrowd.tensor import (
    RESULT,
    KeyLevels,
    accuracy_levels,
    accuracy_tucker,
    drop_pose_elements,
    hooi,
    key_levels,
    mean_squared_error,
    pca_rank_for_error,
    rank_path,
    reconstruct,
    storage_report,
    truncate,
    tucker_nbytes,
)

N = 6
MAX, MIN = (20, 25, 30), (4, 5, 6)


@pytest.fixture(scope="module")
def M() -> np.ndarray:
    return smooth_tensor((40, 50, 60), seed=21)


@pytest.fixture(scope="module")
def kl(M) -> KeyLevels:
    return key_levels(M, N, MAX, MIN)


# ------------------------------------------------------------------------------- rank path


def test_rank_path_is_a_monotone_straight_line():
    path = rank_path((40, 40, 60), (7, 7, 9))
    assert path[0] == (40, 40, 60) and path[-1] == (7, 7, 9) and len(path) == 52
    hi, lo = np.array([40, 40, 60]), np.array([7, 7, 9])
    for k, (a, b) in enumerate(itertools.pairwise(path), start=1):
        assert a != b and all(y <= x for x, y in zip(a, b, strict=True))
        assert a[2] - b[2] == 1  # the widest mode (60 → 9) loses exactly one rank per step
        # on the line from max to min, to rounding (½ rank)
        assert np.all(np.abs(np.array(b) - (hi + k / 51 * (lo - hi))) <= 0.5)
    assert rank_path((3, 3), (3, 3)) == ((3, 3),)
    with pytest.raises(TensorError, match="1 ≤ R_min ≤ R_max"):
        rank_path((4, 4, 4), (5, 1, 1))


# ------------------------------------------------------------------------------- key levels


def test_key_level_errors_rise_and_follow_the_linear_target(kl, M):
    assert len(kl.levels) == N and kl.converged
    assert kl.ranks[0] == MAX and kl.ranks[-1] == MIN
    errors = np.array(kl.errors)
    assert np.all(np.diff(errors) > 0)
    e_1, e_n = errors[0], errors[-1]
    assert kl.c_e == pytest.approx(e_n / (N * e_1), rel=1e-12)
    for l, level in enumerate(kl.levels, start=1):
        assert level.target == pytest.approx(l * kl.c_e * e_1, rel=1e-12)
        # E is the MSE ‖M − M̃‖²/(PTS) of the stored key tensor (1e-9: rounding of two routes)
        assert level.mse == pytest.approx(
            mean_squared_error(M, reconstruct(level.tucker)), rel=1e-9
        )
    cap = len(kl.path) - 1
    for l in range(2, N):
        level = kl.levels[l - 1]
        if level.step == cap - (N - l):  # forced by the step cap: may sit below its target
            assert level.mse <= level.target * 1.3
            continue
        # First rank on the path above the target. One rank step of this smooth spectrum raises
        # the MSE by at most ~25 %, so the level overshoots its target by at most that much.
        assert level.target < level.mse <= 1.25 * level.target


def test_key_level_ranks_shrink_and_ends_are_plain_hooi(kl, M):
    steps = [k.step for k in kl.levels]
    assert steps == sorted(set(steps))
    for a, b in itertools.pairwise(kl.ranks):
        assert all(y <= x for x, y in zip(a, b, strict=True)) and a != b
    for level in kl.levels:
        assert level.ranks == kl.path[level.step]
        assert level.result is RESULT.CONVERGED
    # Levels 1 and N are HOOI at the given ranks from HOSVD, as in the paper (step 1).
    assert kl.levels[0].mse == pytest.approx(
        mean_squared_error(M, reconstruct(hooi(M, MAX).tucker))
    )
    assert kl.levels[-1].mse == pytest.approx(
        mean_squared_error(M, reconstruct(hooi(M, MIN).tucker))
    )


def test_key_levels_validate(M):
    with pytest.raises(TensorError, match=r"expected 2 ≤ N ≤ 4"):
        key_levels(M, 5, (5, 5, 5), (2, 3, 4))
    with pytest.raises(TensorError, match="found N = 1"):
        key_levels(M, 1, MAX, MIN)


# ------------------------------------------------------------------------------- in-between


def test_in_between_levels_truncate_the_next_larger_key_tensor(kl, M):
    levels = accuracy_levels(kl, per_gap=2)
    keys = [a for a in levels if a.is_key]
    assert [a.ranks for a in keys] == list(kl.ranks)
    assert [a.step for a in levels] == sorted({a.step for a in levels})
    for a in levels:
        key = kl.levels[a.source]
        assert key.step <= a.step and all(q >= r for q, r in zip(key.ranks, a.ranks, strict=True))
        t = accuracy_tucker(kl, a.ranks)
        if a.is_key:
            np.testing.assert_array_equal(t.core, key.tucker.core)
            continue
        assert a.step < kl.levels[a.source + 1].step
        cut = truncate(key.tucker, a.ranks)
        np.testing.assert_array_equal(t.core, cut.core)
        for U, V in zip(t.factors, cut.factors, strict=True):
            np.testing.assert_array_equal(U, V)
        # A truncation keeps a sub-core of an orthogonal projection: it cannot beat the key it
        # came from, and a slight cut costs little next to HOOI at those ranks (§4.1).
        e = mean_squared_error(M, reconstruct(t))
        assert e >= key.mse * (1 - 1e-9)
        assert e <= 1.1 * mean_squared_error(M, reconstruct(hooi(M, a.ranks).tucker))
    with pytest.raises(TensorError, match="exceed key level 1"):
        accuracy_tucker(kl, (21, 1, 1))
    with pytest.raises(TensorError, match="per_gap ≥ 0"):
        accuracy_levels(kl, -1)


# ------------------------------------------------------------------------------- joints


def test_dropping_pose_rows_synthesises_only_the_kept_elements(kl):
    t = kl.levels[2].tucker
    drop = [0, 5, 6, 39]
    reduced, kept = drop_pose_elements(t, drop)
    assert kept.dtype == np.int32 and len(kept) == 36 and not set(drop) & set(kept.tolist())
    np.testing.assert_allclose(reconstruct(reduced), reconstruct(t)[kept], rtol=1e-12, atol=1e-15)
    assert tucker_nbytes(reduced) == tucker_nbytes(t) - 4 * len(drop) * t.ranks[0]
    with pytest.raises(TensorError, match=r"indices in \[0, 40\)"):
        drop_pose_elements(t, [40])


# ------------------------------------------------------------------------------- storage


def test_storage_report(kl, M):
    report = storage_report(M, kl)
    assert report.raw_bytes == 40 * 50 * 60 * 4
    assert report.level_bytes[0] == 4 * (20 * 25 * 30 + 40 * 20 + 50 * 25 + 60 * 30)
    assert all(b < a for a, b in itertools.pairwise(report.level_bytes))
    assert report.total_bytes == sum(report.level_bytes) < report.raw_bytes
    assert report.level1_mse == kl.errors[0]
    assert report.pca_mse <= report.level1_mse
    assert report.pca_bytes == 4 * report.pca_rank * (40 + 50 * 60)
    assert report.total_bytes < report.pca_bytes  # the paper's finding (§5.1), here ~2×


def test_pca_rank_matches_a_truncated_svd_oracle(M, kl):
    A = M.reshape(40, -1)  # pose vectors are the columns of the P × (T·S) unfolding
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    target = kl.errors[0]
    r, mse = pca_rank_for_error(M, target)
    recon = U[:, :r] * s[:r] @ Vt[:r]
    assert mean_squared_error(A, recon) == pytest.approx(mse, rel=1e-8, abs=1e-15)
    assert mse <= target
    prev = U[:, : r - 1] * s[: r - 1] @ Vt[: r - 1]
    assert mean_squared_error(A, prev) > target  # r is the smallest rank that is good enough
    assert pca_rank_for_error(M, 0.0)[0] == 40
