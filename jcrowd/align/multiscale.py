"""Multiscale dynamic time warping (paper 004 §3.2, after Zinke & Mayer [ZM06]).

"The warping path computed at a coarse resolution level is projected to the next higher level,
where the projected path is refined to yield a warping path at the higher level. To obtain
features at the coarse levels, we use simple windowing and averaging procedures."

Here:

1. **Pyramid.** Each coarser level averages consecutive pairs of frames (an odd last frame is
   kept alone), both sequences together, while the shorter one stays at least ``min_length``
   frames long (paper 004 uses six levels from 120 Hz down to ~4 Hz; with the default
   ``min_length`` a 3000-frame pair gets six levels, a 300-frame pair four).
2. **Coarsest level.** Exact DTW on the full (small) cost matrix.
3. **Refinement.** Coarse cell ``(i, j)`` covers fine rows ``2i, 2i+1`` and columns
   ``2j, 2j+1``. Per fine row we take the column range the projected path covers, widen it by
   ``radius`` cells in every direction (rows ``r ± radius`` and columns ``± radius``), and run
   the exact DTW kernel of :mod:`jcrowd.align.dtw` only inside that window — local costs
   and DP both proportional to the window's cells, about ``N (2·radius + 3)`` plus the
   path's local slope.

The result is the optimal path *within the window*, so its cost is never below the exact cost;
how close it comes depends on ``radius`` (the tests and ``bench/dtw.py`` measure it).
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Float

from jcrowd.align.costs import AlignError, LocalCost, Metric, as_sequence, check_metric
from jcrowd.align.dtw import DTWResult, windowed_dtw

__all__ = ["downsample_pairs", "multiscale_dtw", "project_path"]


def downsample_pairs(x: Float[np.ndarray, "N D"]) -> Float[np.ndarray, "ceil(N/2) D"]:
    """Average consecutive frame pairs, ``(ceil(N/2), D)``; an odd last frame is kept as is."""
    n = len(x) // 2 * 2
    head = 0.5 * (x[0:n:2] + x[1:n:2])
    return np.concatenate([head, x[n:]], axis=0) if len(x) % 2 else head


def project_path(path: np.ndarray, n: int, m: int, radius: int) -> tuple[np.ndarray, np.ndarray]:
    """The fine-level window ``(lo, hi)`` (per-row inclusive column ranges) around a coarse path.

    Args:
        path: ``(K, 2)`` coarse path, monotone, from ``(0, 0)`` to its corner.
        n, m: fine sequence lengths (the coarse ones are ``ceil(n/2)``, ``ceil(m/2)``).
        radius: cells added on each side, in rows and in columns.

    Returns:
        ``lo, hi`` ``(n,)`` int64, a connected window (see :func:`windowed_dtw`).
    """
    rows = path[:, 0]
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    # Coarse rows are visited in order, each a contiguous run of the path.
    lo_c = path[starts, 1]
    hi_c = np.r_[path[starts[1:] - 1, 1], path[-1, 1]]
    fine = np.arange(n) // 2
    lo = 2 * lo_c[fine]
    hi = np.minimum(2 * hi_c[fine] + 1, m - 1)
    if radius > 0:
        idx = np.arange(n)
        lo = lo[np.maximum(idx - radius, 0)] - radius
        hi = hi[np.minimum(idx + radius, n - 1)] + radius
    lo = np.clip(lo, 0, m - 1)
    hi = np.clip(hi, 0, m - 1)
    lo[0], hi[-1] = 0, m - 1
    return lo.astype(np.int64), hi.astype(np.int64)


def multiscale_dtw(
    features_a: Float[np.ndarray, "N D"],
    features_b: Float[np.ndarray, "M D"],
    *,
    metric: Metric = "euclidean",
    radius: int = 12,
    min_length: int = 32,
    max_levels: int = 6,
) -> DTWResult:
    """Coarse-to-fine DTW (paper 004 §3.2, [ZM06]); same result type as :func:`dtw`.

    Args:
        features_a: ``(N, D)`` (or ``(N,)``) features of A.
        features_b: ``(M, D)`` features of B.
        metric: local cost, as for :func:`~jcrowd.align.dtw.dtw`.
        radius: search radius (cells) around the projected path at each finer level. The
            default 12 keeps the cost close to exact in every case the tests and
            ``bench/dtw.py`` (its ``cost_ratio``) try. Smaller is faster but can lock onto a
            worse path where many are almost equally good, as on concatenations of unrelated
            walks (``bench/dtw.py --sequences clips``), with physics features most of all.
        min_length: the coarsest level keeps the shorter sequence at least this long; a pair
            shorter than ``2·min_length`` gets exact DTW.
        max_levels: at most this many levels, the finest included (paper 004 uses six: from
            120 Hz down to 3.75 Hz, each coarse frame averaging 32 captured ones).

    Returns:
        :class:`DTWResult`; ``cells`` counts the local costs evaluated over all levels and
        ``levels`` the number of resolution levels.
    """
    check_metric(metric)
    if not (isinstance(radius, int | np.integer) and radius >= 0):
        raise AlignError(f"multiscale_dtw: expected an integer radius >= 0, found {radius!r}")
    if not (isinstance(max_levels, int | np.integer) and max_levels >= 1):
        raise AlignError(
            f"multiscale_dtw: expected an integer max_levels >= 1, found {max_levels!r}"
        )
    if not (isinstance(min_length, int | np.integer) and min_length >= 2):
        raise AlignError(
            f"multiscale_dtw: expected an integer min_length >= 2, found {min_length!r}"
        )
    a = as_sequence(features_a, "multiscale_dtw")
    b = as_sequence(features_b, "multiscale_dtw")
    if a.shape[1] != b.shape[1]:
        raise AlignError(
            f"multiscale_dtw: expected features of equal width, found {a.shape[1]} and {b.shape[1]}"
        )
    pyramid = [(a, b)]
    while len(pyramid) < max_levels and min(len(x) for x in pyramid[-1]) >= 2 * min_length:
        pa, pb = pyramid[-1]
        pyramid.append((downsample_pairs(pa), downsample_pairs(pb)))

    ca, cb = pyramid[-1]
    lo = np.zeros(len(ca), np.int64)
    hi = np.full(len(ca), len(cb) - 1, np.int64)
    cost, path = windowed_dtw(LocalCost(ca, cb, metric), lo, hi)
    cells = len(ca) * len(cb)
    for fa, fb in reversed(pyramid[:-1]):
        lo, hi = project_path(path, len(fa), len(fb), radius)
        cost, path = windowed_dtw(LocalCost(fa, fb, metric), lo, hi)
        cells += int((hi - lo + 1).sum())
    return DTWResult(cost, path, cells, len(pyramid))
