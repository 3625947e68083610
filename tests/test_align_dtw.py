"""Exact and multiscale DTW: dtaidistance and a double-loop DP as oracles, path properties,
multiscale against exact on CMU walks, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from dtaidistance import dtw as dtai_dtw
from dtaidistance import dtw_ndim
from helpers import load_clip

from jcrowd.align import (
    AlignError,
    band_window,
    cost_matrix,
    downsample_pairs,
    dtw,
    multiscale_dtw,
    physics_features,
    pose_features,
)
from jcrowd.align.multiscale import project_path
from jcrowd.motion import Motion


def _loop_dtw(c: np.ndarray, lo: np.ndarray | None = None, hi: np.ndarray | None = None) -> float:
    """The textbook O(NM) double loop, restricted to ``lo[i] <= j <= hi[i]`` when given."""
    n, m = c.shape
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(n):
        for j in range(m):
            if lo is not None and hi is not None and not lo[i] <= j <= hi[i]:
                continue
            acc[i + 1, j + 1] = c[i, j] + min(acc[i, j], acc[i, j + 1], acc[i + 1, j])
    return float(acc[n, m])


def _check_path(path: np.ndarray, n: int, m: int) -> None:
    assert path.dtype == np.int64 and path.shape[1] == 2
    assert tuple(path[0]) == (0, 0) and tuple(path[-1]) == (n - 1, m - 1)
    steps = {tuple(s) for s in np.diff(path, axis=0).tolist()}
    assert steps <= {(1, 0), (0, 1), (1, 1)}


SHAPES = [(1, 1), (1, 6), (6, 1), (23, 37), (37, 23), (40, 40)]


@pytest.mark.parametrize(("n", "m"), SHAPES)
@pytest.mark.parametrize("dims", [1, 4])
def test_exact_dtw_equals_dtaidistance(n: int, m: int, dims: int) -> None:
    rng = np.random.default_rng(n * 100 + m + dims)
    a = rng.normal(size=(n, dims))
    b = rng.normal(size=(m, dims))
    ours = np.sqrt(dtw(a, b, metric="sqeuclidean").cost)
    # dtaidistance sums squared Euclidean distances per cell and returns the square root of
    # the total; its C and Python versions must agree with ours to rounding (1e-9 relative).
    theirs = dtw_ndim.distance(a, b)
    theirs_c = dtw_ndim.distance(a, b, use_c=True)
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)
    np.testing.assert_allclose(ours, theirs_c, rtol=1e-9)
    if dims == 1:
        np.testing.assert_allclose(ours, dtai_dtw.distance(a[:, 0], b[:, 0]), rtol=1e-9)
    # Random reals leave no ties, so the optimal path is unique and both must find it.
    if dims == 1:  # its C ndim path rejects one-column arrays
        their = dtai_dtw.warping_path(a[:, 0], b[:, 0], use_c=True)
    else:
        their = dtw_ndim.warping_path(a, b, use_c=True)
    their_path = np.asarray(their, np.int64).reshape(-1, 2)
    np.testing.assert_array_equal(dtw(a, b, metric="sqeuclidean").path, their_path)


@pytest.mark.parametrize("band", [0, 1, 3, 10])
def test_banded_dtw_equals_dtaidistance_window(band: int) -> None:
    # For equal lengths our band |i - j| <= band is dtaidistance's window = band + 1.
    rng = np.random.default_rng(band)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    ours = np.sqrt(dtw(a, b, metric="sqeuclidean", band=band).cost)
    np.testing.assert_allclose(ours, dtw_ndim.distance(a, b, window=band + 1), rtol=1e-9)


@pytest.mark.parametrize("metric", ["euclidean", "sqeuclidean", "inner"])
@pytest.mark.parametrize("band", [None, 0, 2, 7])
@pytest.mark.parametrize(("n", "m"), [(1, 5), (5, 1), (19, 31), (31, 19), (12, 60)])
def test_dtw_equals_double_loop(metric: str, band: int | None, n: int, m: int) -> None:
    rng = np.random.default_rng(7 * n + m)
    a, b = rng.normal(size=(n, 5)), rng.normal(size=(m, 5))
    c = cost_matrix(a, b, metric)  # type: ignore[arg-type]
    lo, hi = band_window(n, m, band)
    expected = _loop_dtw(c, lo, hi)
    result = dtw(a, b, metric=metric, band=band)  # type: ignore[arg-type]
    from_matrix = dtw(c, band=band)
    # Rounding only: the prefix scan subtracts running sums (1e-12 relative is ~1000 ulp).
    np.testing.assert_allclose(result.cost, expected, rtol=1e-12)
    np.testing.assert_allclose(from_matrix.cost, expected, rtol=1e-12)
    _check_path(result.path, n, m)
    i, j = result.path[:, 0], result.path[:, 1]
    assert np.all((j >= lo[i]) & (j <= hi[i]))
    np.testing.assert_allclose(c[i, j].sum(), result.cost, rtol=1e-12)
    assert result.cells == int((hi - lo + 1).sum())


def test_inner_cost_is_paper_004_cost() -> None:
    v = np.array([[1.0, 0.0], [0.0, 0.0], [3.0, 4.0]])
    w = np.array([[2.0, 0.0], [-1.0, 0.0], [0.0, 5.0], [0.0, 0.0]])
    c = cost_matrix(v, w, "inner")
    # c = ½(1 − cos): parallel 0, opposite 1, orthogonal ½, any zero vector 0 (paper 004 §3.2).
    np.testing.assert_allclose(c[0], [0.0, 1.0, 0.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(c[1], [0.0, 0.0, 0.0, 0.0], atol=0)
    np.testing.assert_allclose(c[2], [0.5 * (1 - 0.6), 0.5 * (1 + 0.6), 0.5 * (1 - 0.8), 0.0])
    assert np.all((c >= 0) & (c <= 1))


@pytest.mark.parametrize("metric", ["euclidean", "sqeuclidean", "inner"])
def test_dtw_of_a_sequence_with_itself_is_zero_on_the_diagonal(metric: str) -> None:
    x = np.random.default_rng(3).normal(size=(150, 6))
    r = dtw(x, x, metric=metric)  # type: ignore[arg-type]
    # Euclidean costs of equal frames are exactly 0; the inner cost is ½(1 − cos) of a vector
    # with itself, 0 up to a few ulp.
    assert r.cost <= (1e-13 if metric == "inner" else 0.0)
    np.testing.assert_array_equal(r.path, np.stack([np.arange(150)] * 2, axis=1))
    ms = multiscale_dtw(x, x, metric=metric, min_length=8)  # type: ignore[arg-type]
    assert ms.levels > 1 and ms.cost <= (1e-13 if metric == "inner" else 0.0)


def test_one_dimensional_input_and_symmetry() -> None:
    rng = np.random.default_rng(11)
    a, b = rng.normal(size=40), rng.normal(size=55)
    ab, ba = dtw(a, b), dtw(b, a)
    np.testing.assert_allclose(ab.cost, ba.cost, rtol=1e-12)
    assert ab.cells == 40 * 55


def test_errors_say_what_was_expected() -> None:
    a = np.zeros((5, 3))
    with pytest.raises(AlignError, match="equal width"):
        dtw(a, np.zeros((4, 2)))
    with pytest.raises(AlignError, match="finite"):
        dtw(a, np.full((4, 3), np.nan))
    with pytest.raises(AlignError, match="non-empty"):
        dtw(np.zeros((0, 3)), a)
    with pytest.raises(AlignError, match="metric"):
        dtw(a, a, metric="cosine")  # type: ignore[arg-type]
    with pytest.raises(AlignError, match="band"):
        dtw(a, a, band=-1)
    with pytest.raises(AlignError, match="cost matrix"):
        dtw(-np.ones((3, 3)))
    with pytest.raises(AlignError, match="radius"):
        multiscale_dtw(a, a, radius=-1)


def test_downsample_and_projection_give_a_connected_window() -> None:
    x = np.arange(7.0)[:, None]
    np.testing.assert_allclose(downsample_pairs(x)[:, 0], [0.5, 2.5, 4.5, 6.0])
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(33, 2)), rng.normal(size=(20, 2))
    coarse = dtw(downsample_pairs(a), downsample_pairs(b)).path
    for radius in (0, 1, 3):
        lo, hi = project_path(coarse, 33, 20, radius)
        assert lo[0] == 0 and hi[-1] == 19
        assert np.all(np.diff(lo) >= 0) and np.all(np.diff(hi) >= 0) and np.all(lo <= hi)
        assert np.all(lo[1:] <= hi[:-1] + 1)
        # Every fine cell under a coarse path cell is inside the window.
        for i, j in coarse:
            for fi in (2 * i, 2 * i + 1):
                if fi < 33:
                    assert lo[fi] <= min(2 * j, 19) and hi[fi] >= min(2 * j + 1, 19)


def _dilated_window(coarse: np.ndarray, n: int, m: int, radius: int) -> np.ndarray:
    """The module docstring's window as a boolean (n, m) mask, by brute force.

    Mark every fine cell under a coarse path cell (coarse ``(i, j)`` covers fine rows ``2i, 2i+1``
    and columns ``2j, 2j+1``, clipped to the matrix), then mark every cell within ``radius``
    rows AND ``radius`` columns of a marked one (a square dilation), clipped to the matrix.
    """
    covered = np.zeros((n, m), bool)
    for i, j in coarse:
        for fi in (2 * i, 2 * i + 1):
            for fj in (2 * j, 2 * j + 1):
                covered[min(fi, n - 1), min(fj, m - 1)] = True
    window = np.zeros((n, m), bool)
    for fi, fj in zip(*np.nonzero(covered), strict=True):
        window[
            max(fi - radius, 0) : min(fi + radius, n - 1) + 1,
            max(fj - radius, 0) : min(fj + radius, m - 1) + 1,
        ] = True
    return window


def test_projected_window_is_widened_by_radius_on_both_sides() -> None:
    """``project_path``'s per-row ``[lo, hi]`` equals the docstring's window exactly: the fine
    cells under the coarse path, widened by ``radius`` rows and ``radius`` columns on EACH side
    (a brute-force dilation as oracle). Guards against dropping the column radius on one side
    (``lo`` or ``hi`` not widened), which the coverage-only test above does not see."""
    rng = np.random.default_rng(11)
    # A random-walk pair (a slanted, uneven coarse path) and a hand-made staircase; the shapes
    # are odd so the last coarse row/column covers a single fine one, and wide enough that most
    # rows are not clipped at either edge (else a missing radius would be hidden by the clip).
    a, b = np.cumsum(rng.normal(size=(61, 2)), 0), np.cumsum(rng.normal(size=(47, 2)), 0)
    walk = dtw(downsample_pairs(a), downsample_pairs(b)).path
    stairs = np.array([(0, 0), (1, 1), (1, 2), (1, 3), (2, 4), (3, 4), (4, 4), (5, 5)])
    stairs = np.concatenate([stairs, np.stack([np.arange(6, 20), np.arange(6, 20)], 1)])
    for coarse, n, m in ((walk, 61, 47), (stairs, 39, 40)):
        for radius in (0, 1, 2, 5):
            want = _dilated_window(coarse, n, m, radius)
            lo, hi = project_path(coarse, n, m, radius)
            cols = np.arange(m)
            got = (cols[None, :] >= lo[:, None]) & (cols[None, :] <= hi[:, None])
            # The test can only catch a one-sided widening if the window is not clipped away:
            # some row's window must start after column 0 and some end before column m - 1.
            assert (~want[:, 0]).any() and (~want[:, -1]).any()
            for r in range(n):  # Integer windows: exact equality, row by row for a clear message.
                want_lo, want_hi = np.flatnonzero(want[r])[[0, -1]]
                assert (lo[r], hi[r]) == (want_lo, want_hi), (n, m, radius, r)
            np.testing.assert_array_equal(got, want)  # the oracle's rows are intervals too


def test_multiscale_is_exact_when_short_or_unconstrained() -> None:
    rng = np.random.default_rng(2)
    a = np.cumsum(rng.normal(size=(200, 3)), axis=0)
    b = np.cumsum(rng.normal(size=(170, 3)), axis=0)
    exact = dtw(a, b)
    short = multiscale_dtw(a, b, min_length=150)  # 170 < 2 * 150: one level
    assert short.levels == 1
    np.testing.assert_array_equal(short.path, exact.path)
    wide = multiscale_dtw(a, b, radius=400, min_length=8)  # the window is the whole matrix
    assert wide.levels > 1
    np.testing.assert_allclose(wide.cost, exact.cost, rtol=1e-12)


def test_multiscale_on_random_walk_signals() -> None:
    rng = np.random.default_rng(9)
    for _ in range(5):
        a = np.cumsum(rng.normal(size=(600, 4)), axis=0)
        t = np.sort(rng.uniform(0, 599, size=700))
        b = np.stack([np.interp(t, np.arange(600), a[:, d]) for d in range(4)], axis=1)
        b += rng.normal(scale=0.3, size=b.shape)
        exact, ms = dtw(a, b), multiscale_dtw(a, b)
        _check_path(ms.path, 600, 700)
        # Never below the optimum (rounding aside); within the 2 % DESIGN §4 asks for.
        assert exact.cost * (1 - 1e-12) <= ms.cost <= 1.02 * exact.cost
        # About 2·12 + 4 cells per row around the path (radius 12) at each of 5 levels.
        assert ms.cells < 0.2 * 600 * 700


def _pairs(cmu_dir: Path, cmu16_dir: Path) -> list[tuple[Motion, Motion]]:
    walk = cmu_dir / "walk"
    return [
        (load_clip(walk / "07_01.bvh"), load_clip(walk / "08_03.bvh")),
        (load_clip(walk / "02_01.bvh"), load_clip(walk / "07_05.bvh")),
        (load_clip(cmu16_dir / "16_15.bvh"), load_clip(cmu16_dir / "16_16.bvh")),
        (load_clip(cmu16_dir / "16_11.bvh"), load_clip(cmu16_dir / "16_33.bvh")),
    ]


@pytest.mark.parametrize(
    ("features", "metric"),
    [("pose", "euclidean"), ("physics", "euclidean"), ("physics", "inner")],
)
def test_multiscale_cost_within_2_percent_on_cmu_walks(
    cmu_dir: Path, cmu16_dir: Path, features: str, metric: str
) -> None:
    f = pose_features if features == "pose" else physics_features
    for x, y in _pairs(cmu_dir, cmu16_dir):
        a, b = f(x), f(y)
        exact = dtw(a, b, metric=metric)  # type: ignore[arg-type]
        ms = multiscale_dtw(a, b, metric=metric)  # type: ignore[arg-type]
        _check_path(ms.path, len(a), len(b))
        assert ms.levels >= 2
        # DESIGN §4 step 4: multiscale within a stated tolerance of exact; ours is 2 %.
        assert exact.cost * (1 - 1e-12) <= ms.cost <= 1.02 * exact.cost, (len(a), len(b))
