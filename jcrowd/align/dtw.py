"""Exact dynamic time warping, full or in a Sakoe–Chiba band (DESIGN §4 step 4; paper 004 §3.2).

Given a local cost ``c(i, j)`` between frame ``i`` of sequence A (length N) and frame ``j`` of B
(length M), DTW finds the warping path from ``(0, 0)`` to ``(N-1, M-1)`` with steps ``(1, 0)``,
``(0, 1)``, ``(1, 1)`` whose summed cost is least (paper 004 §3.2, after [ZM06]; no step
weights). The accumulated cost

    D[i, j] = c[i, j] + min(D[i-1, j], D[i-1, j-1], D[i, j-1])

is filled one row at a time. Within a row the horizontal term makes it a recursion, which we
turn into a min-plus prefix scan: with ``A[j] = c[i, j] + min(D[i-1, j], D[i-1, j-1])`` and
``S[j] = c[i, 0] + … + c[i, j]``,

    D[i, j] = min_{k ≤ j} (A[k] + S[j] − S[k]) = S[j] + cummin(A − S)[j],

so a row is a handful of NumPy calls (``cumsum``, ``minimum.accumulate``) instead of a Python
loop over cells. The path is read back from ``D`` (diagonal preferred on ties).

Every variant — full, banded, and each level of :func:`~jcrowd.align.multiscale.multiscale_dtw`
— runs the same kernel over a *window*: per row ``i`` an inclusive column range
``[lo[i], hi[i]]``. The window's cells are stored row after row in one flat array (CSR-like),
so cost evaluation and the DP are ``O(Σ_i (hi[i] − lo[i] + 1))``. (A rectangular ``(N, W)``
block with ``W`` the widest row would be ``O(N·W)`` too, but one long horizontal run of a
coarse path — a pause in one sequence — would make every row that wide.)

Local costs (``metric``: Euclidean, squared Euclidean, paper 004's inner-product cost) are in
:mod:`jcrowd.align.costs`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from jaxtyping import Float, Int

from jcrowd.align.costs import (
    CHUNK_ELEMENTS,
    AlignError,
    LocalCost,
    Metric,
    as_sequence,
    check_metric,
)

__all__ = ["DTWResult", "band_window", "dtw", "windowed_dtw"]


@dataclass(frozen=True)
class DTWResult:
    """A warping path and its cost.

    Attributes:
        cost: summed local cost along ``path``.
        path: ``(K, 2)`` int64 frame pairs ``(i, j)``, from ``(0, 0)`` to ``(N-1, M-1)``, each
            step one of ``(1, 0)``, ``(0, 1)``, ``(1, 1)``.
        cells: number of local costs evaluated (``N·M`` for full DTW).
        levels: resolution levels used (1 for exact DTW).
    """

    cost: float
    path: Int[np.ndarray, "K 2"]
    cells: int
    levels: int = 1

    @property
    def mean_cost(self) -> float:
        """Cost per path step, ``cost / K``."""
        return self.cost / len(self.path)


def _window_costs(
    cost: LocalCost | np.ndarray, lo: np.ndarray, hi: np.ndarray, offset: np.ndarray
) -> Callable[[int, int], np.ndarray]:
    """``(i0, i1) ->`` the window's local costs of rows ``i0:i1``, flat, row after row."""
    count = hi - lo + 1
    if isinstance(cost, np.ndarray):

        def from_matrix(i0: int, i1: int) -> np.ndarray:
            rows = np.repeat(np.arange(i0, i1), count[i0:i1])
            cols = np.arange(offset[i0], offset[i1]) - np.repeat(
                offset[i0:i1] - lo[i0:i1], count[i0:i1]
            )
            return cost[rows, cols]

        return from_matrix
    if np.all(lo == 0) and np.all(hi == cost.num_b - 1):
        return lambda i0, i1: cost.rows(i0, i1).ravel()
    return lambda i0, i1: cost.window(i0, i1, lo, hi)


def _chunks(count: np.ndarray) -> list[tuple[int, int]]:
    """Row ranges whose padded ``(rows, widest row)`` block stays within ``CHUNK_ELEMENTS``."""
    out, i0, widest = [], 0, 0
    for i, k in enumerate(count.tolist()):
        widest = max(widest, k)
        if i > i0 and (i - i0 + 1) * widest > CHUNK_ELEMENTS:
            out.append((i0, i))
            i0, widest = i, k
    out.append((i0, len(count)))
    return out


def _row_prefix_sums(costs: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``S``: the running sum of every row's costs, restarted at each row (flat, row after row).

    Restarting matters: one running sum over many rows would grow large enough for the
    cancellation in ``A − S`` to cost digits. Rows are padded into one ``(rows, width)`` block
    so that this is a single ``cumsum``.
    """
    width = int(count.max())
    if np.all(count == width):
        return costs.reshape(len(count), width).cumsum(axis=1).ravel()
    valid = np.arange(width)[None] < count[:, None]
    block = np.zeros((len(count), width))
    block[valid] = costs
    return block.cumsum(axis=1)[valid]


def windowed_dtw(
    cost: LocalCost | np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[float, np.ndarray]:
    """DTW restricted to a window; returns ``(cost, path)``.

    Args:
        cost: prepared features (:class:`~jcrowd.align.costs.LocalCost`) or a cost matrix.
        lo, hi: ``(N,)`` inclusive column range of every row. The window must be *connected*:
            ``lo[0] = 0``, ``hi[-1] = M-1``, ``lo`` and ``hi`` non-decreasing, ``lo ≤ hi`` and
            ``lo[i] ≤ hi[i-1] + 1`` (every row reachable from the previous one).

    Memory and work are ``O(Σ_i (hi - lo + 1))``: the accumulated costs are stored row after
    row, each row followed by ``max(1, hi[i+1] − hi[i])`` cells of ``inf``. With that gap the
    next row reads its vertical and diagonal predecessors as two plain slices of the previous
    row — cells the previous row does not reach read ``inf`` — so a row costs four NumPy calls:
    ``minimum``, ``+=``, ``minimum.accumulate``, ``+=`` (``c − S`` and ``S`` are prepared for a
    block of rows at once).
    """
    n = len(lo)
    count = hi - lo + 1
    offset = np.concatenate([[0], np.cumsum(count)])
    costs_of = _window_costs(cost, lo, hi, offset)
    gap = np.ones(n, np.int64)
    gap[:-1] = np.maximum(1, hi[1:] - hi[:-1])
    start = np.concatenate([[1], 1 + np.cumsum(count + gap)[:-1]])  # cell (i, lo[i])
    acc = np.full(int(start[-1] + count[-1] + 1), np.inf)
    start_l, count_l, lo_l, offset_l = start.tolist(), count.tolist(), lo.tolist(), offset.tolist()
    minimum, cummin = np.minimum, np.minimum.accumulate
    for i0, i1 in _chunks(count):
        costs = costs_of(i0, i1)
        prefix = _row_prefix_sums(costs, count[i0:i1])
        rest = costs - prefix  # A − S = min(up, diag) + (c − S)
        o = offset_l[i0]
        for i in range(i0, i1):
            k, s0 = count_l[i], start_l[i]
            o0 = offset_l[i] - o
            row = acc[s0 : s0 + k]
            s = prefix[o0 : o0 + k]
            if i == 0:
                row[:] = s
                continue
            p = start_l[i - 1] + lo_l[i] - lo_l[i - 1]
            a = minimum(acc[p : p + k], acc[p - 1 : p - 1 + k])
            a += rest[o0 : o0 + k]
            cummin(a, out=row)
            row += s
    last = start_l[-1] + count_l[-1] - 1
    return float(acc[last]), _backtrack(acc, lo, hi, start)


def _backtrack(acc: np.ndarray, lo: np.ndarray, hi: np.ndarray, start: np.ndarray) -> np.ndarray:
    """The cost-minimising path, read back from the accumulated costs (diagonal on ties)."""
    lo_l, hi_l = lo.tolist(), hi.tolist()
    base = (start - lo).tolist()  # flat index of cell (i, j) is base[i] + j
    # A small window is read faster as a list; a full matrix only at the ~N + M cells visited.
    get = acc.tolist().__getitem__ if len(acc) <= 1 << 20 else acc.item
    inf = float("inf")
    i, j = len(lo_l) - 1, hi_l[-1]
    path = [(i, j)]
    while i > 0 and j > 0:
        bp, lp, hp = base[i - 1], lo_l[i - 1], hi_l[i - 1]
        diag = get(bp + j - 1) if lp <= j - 1 <= hp else inf
        up = get(bp + j) if lp <= j <= hp else inf
        left = get(base[i] + j - 1) if j - 1 >= lo_l[i] else inf
        if diag <= up and diag <= left:
            i, j = i - 1, j - 1
        elif up <= left:
            i -= 1
        else:
            j -= 1
        path.append((i, j))
    path.extend((k, 0) for k in range(i - 1, -1, -1))
    path.extend((0, k) for k in range(j - 1, -1, -1))
    return np.asarray(path[::-1], np.int64)


def band_window(n: int, m: int, band: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Per-row column range of a Sakoe–Chiba band of half-width ``band`` frames.

    The band follows the straight line from ``(0, 0)`` to ``(N-1, M-1)``: row ``i`` keeps
    ``|j − i (M−1)/(N−1)| ≤ band``. Where a narrow band on a steep line would leave a gap
    between rows, the earlier row is widened so the end stays reachable. For ``N = M`` this is
    ``|i − j| ≤ band``, dtaidistance's ``window = band + 1``. ``None`` is the full matrix.
    """
    if band is None or n == 1 or m == 1:
        return np.zeros(n, np.int64), np.full(n, m - 1, np.int64)
    if not band >= 0:
        raise AlignError(f"dtw: expected a band width >= 0 (frames), found {band}")
    centre = np.arange(n) * ((m - 1) / (n - 1))
    lo = np.clip(np.ceil(centre - band - 1e-9), 0, m - 1).astype(np.int64)
    hi = np.clip(np.floor(centre + band + 1e-9), 0, m - 1).astype(np.int64)
    hi = np.maximum(hi, lo)
    hi[:-1] = np.maximum(hi[:-1], lo[1:] - 1)
    lo[0], hi[-1] = 0, m - 1
    return lo, hi


def dtw(
    cost_or_features_a: Float[np.ndarray, "N M"] | Float[np.ndarray, "N D"],
    features_b: Float[np.ndarray, "M D"] | None = None,
    *,
    metric: Metric = "euclidean",
    band: float | None = None,
) -> DTWResult:
    """Exact DTW of two feature sequences, or of a precomputed cost matrix.

    Args:
        cost_or_features_a: features of A ``(N, D)`` (or ``(N,)``), or, when ``features_b`` is
            None, the local cost matrix ``(N, M)`` itself (non-negative, finite).
        features_b: features of B ``(M, D)``.
        metric: local cost, :mod:`jcrowd.align.costs` (ignored for a cost matrix).
        band: Sakoe–Chiba half-width in frames of B (:func:`band_window`); None = no band.

    Returns:
        :class:`DTWResult` with the optimal path and its summed cost (paper 004 §3.2).
    """
    check_metric(metric)
    if features_b is None:
        c = np.asarray(cost_or_features_a, np.float64)
        if c.ndim != 2 or c.size == 0 or not np.all(np.isfinite(c)) or np.any(c < 0):
            raise AlignError(
                f"dtw: expected a non-empty finite non-negative (N, M) cost matrix, found shape "
                f"{c.shape}"
            )
        cost: LocalCost | np.ndarray = c
        n, m = c.shape
    else:
        a = as_sequence(cost_or_features_a, "dtw")
        b = as_sequence(features_b, "dtw")
        cost = LocalCost(a, b, metric)
        n, m = len(a), len(b)
    lo, hi = band_window(n, m, band)
    total, path = windowed_dtw(cost, lo, hi)
    return DTWResult(total, path, int((hi - lo + 1).sum()))
