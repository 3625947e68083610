"""Local costs between feature frames, for DTW (paper 004 §3.2).

``metric``:

- ``"euclidean"``: ``‖a_i − b_j‖``.
- ``"sqeuclidean"``: ``‖a_i − b_j‖²`` (what ``dtaidistance.dtw_ndim`` sums before its final
  square root).
- ``"inner"``: paper 004's inner-product cost. The extracted text lost the formula; it keeps
  "for two non-zero feature vectors v and w (otherwise c(v,w) is set to zero). Note that c(v,w)
  is zero in case v and w coincide and assumes values in the real interval [0, 1]". Reading
  taken: ``c(v, w) = ½ (1 − ⟨v, w⟩ / (‖v‖ ‖w‖))``. The normalised inner product is what makes
  it zero when v = w; the factor ½ is what keeps it in [0, 1] for signed features such as
  accelerations (``1 − cos`` alone spans [0, 2]; Müller's chroma version omits ½ because its
  features are non-negative).

:class:`LocalCost` evaluates either whole rows (full DTW) or the cells of a window (banded and
multiscale DTW, in blocks of rows over the columns they span, so the work follows the window,
not ``N·M``); both are matrix products.

Euclidean costs use ``|a|² + |b|² − 2⟨a, b⟩`` (a BLAS product, so no ``(rows, columns, D)`` array of
differences is formed) after centring both sequences on their common mean, and then recompute from
explicit differences every cell whose ``d²`` is below ``10⁻³ (|a|² + |b|²)``. The rounding error of
the expansion is at most about ``(D + 2) ε (|a|² + |b|²)``, so every cell keeps a relative error
below ``(D + 2) ε / 10⁻³`` (2·10⁻¹¹ for 93 dims), and equal frames still cost exactly 0.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from jaxtyping import Float

from jcrowd.errors import AlignError

__all__ = ["AlignError", "LocalCost", "Metric", "cost_matrix"]

Metric = Literal["euclidean", "sqeuclidean", "inner"]
METRICS = ("euclidean", "sqeuclidean", "inner")
CHUNK_ELEMENTS = 1 << 21
"""Floats of scratch (16 MB) one block of cost evaluation may use."""
_REFINE = 1e-3  # relative d² below which a cell is recomputed from explicit differences
_BLOCK_ROWS = 64  # window rows per padded block: bounds padding waste when widths vary


def as_sequence(x: object, what: str) -> np.ndarray:
    """A finite, non-empty ``(frames, dims)`` float64 array (a 1-D series becomes one column)."""
    a = np.asarray(x, np.float64)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or len(a) == 0 or a.shape[1] == 0:
        raise AlignError(f"{what}: expected a non-empty (frames, dims) array, found {a.shape}")
    if not np.all(np.isfinite(a)):
        raise AlignError(f"{what}: expected finite values, found NaN or inf")
    return a


def check_metric(metric: str) -> None:
    if metric not in METRICS:
        raise AlignError(f"dtw: expected metric in {METRICS}, found {metric!r}")


class LocalCost:
    """Two validated feature sequences prepared for one metric.

    Args:
        a: ``(N, D)`` features of A (rows of the cost matrix).
        b: ``(M, D)`` features of B (columns).
        metric: see the module doc.
    """

    def __init__(self, a: np.ndarray, b: np.ndarray, metric: str) -> None:
        check_metric(metric)
        if a.shape[1] != b.shape[1]:
            raise AlignError(
                f"dtw: expected features of equal width, found {a.shape[1]} and {b.shape[1]}"
            )
        self.metric = metric
        self.dims = a.shape[1]
        self.num_b = len(b)
        if metric == "inner":
            na = np.linalg.norm(a, axis=1, keepdims=True)
            nb = np.linalg.norm(b, axis=1, keepdims=True)
            self.a = np.divide(a, na, out=np.zeros_like(a), where=na > 0)
            self.b = np.divide(b, nb, out=np.zeros_like(b), where=nb > 0)
            self.live_a, self.live_b = na[:, 0] > 0, nb[:, 0] > 0
        else:
            # Distances do not change when both move by one vector; the expansion's rounding
            # shrinks with the norms.
            centre = 0.5 * (a.mean(axis=0) + b.mean(axis=0))
            self.a, self.b = a - centre, b - centre
            self.sq_a = np.einsum("nd,nd->n", self.a, self.a)
            self.sq_b = np.einsum("md,md->m", self.b, self.b)

    def _dense(self, i0: int, i1: int, j0: int, j1: int) -> np.ndarray:
        """Costs of rows ``i0:i1`` against columns ``j0:j1``, ``(i1 - i0, j1 - j0)``."""
        a, b = self.a[i0:i1], self.b[j0:j1]
        prod = a @ b.T
        if self.metric == "inner":
            live = self.live_a[i0:i1, None] & self.live_b[None, j0:j1]
            return np.where(live, np.clip(0.5 * (1.0 - prod), 0.0, 1.0), 0.0)
        scale = self.sq_a[i0:i1, None] + self.sq_b[None, j0:j1]
        d2 = scale - 2.0 * prod
        r, c = np.nonzero(d2 <= _REFINE * scale)
        step = max(1, CHUNK_ELEMENTS // self.dims)
        for k in range(0, len(r), step):
            rk, ck = r[k : k + step], c[k : k + step]
            diff = a[rk] - b[ck]
            d2[rk, ck] = np.einsum("kd,kd->k", diff, diff)
        return np.sqrt(d2) if self.metric == "euclidean" else d2

    def rows(self, i0: int, i1: int) -> np.ndarray:
        """Costs of rows ``i0:i1`` against every column, ``(i1 - i0, M)``."""
        return self._dense(i0, i1, 0, self.num_b)

    def window(self, i0: int, i1: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Costs of the cells ``lo[i]..hi[i]`` of rows ``i0:i1``, flat, row after row.

        Rows go in blocks of at most 64; a block is the dense product over the columns its
        rows span (``lo`` and ``hi`` are monotone, so that is one range), from which the window's
        cells are kept. Blocks stay near the window (a few times its cells) and need no gathers.
        """
        out = []
        for i in range(i0, i1, _BLOCK_ROWS):
            j = min(i + _BLOCK_ROWS, i1)
            # A very wide span (a long pause in B) goes in fewer rows per product.
            span = int(hi[j - 1]) - int(lo[i]) + 1
            step = min(_BLOCK_ROWS, max(1, CHUNK_ELEMENTS // span))
            for k in range(i, j, step):
                kk = min(k + step, j)
                c0, c1 = int(lo[k]), int(hi[kk - 1]) + 1
                block = self._dense(k, kk, c0, c1)
                cols = np.arange(c0, c1)[None]
                out.append(block[(cols >= lo[k:kk, None]) & (cols <= hi[k:kk, None])])
        return np.concatenate(out)


def cost_matrix(
    features_a: Float[np.ndarray, "N D"],
    features_b: Float[np.ndarray, "M D"],
    metric: Metric = "euclidean",
) -> Float[np.ndarray, "N M"]:
    """The full local cost matrix ``C[i, j] = c(a_i, b_j)`` (paper 004 §3.2)."""
    check_metric(metric)
    cost = LocalCost(
        as_sequence(features_a, "cost_matrix"), as_sequence(features_b, "cost_matrix"), metric
    )
    n = len(cost.a)
    step = max(1, CHUNK_ELEMENTS // cost.num_b)
    return np.concatenate([cost.rows(i, min(n, i + step)) for i in range(0, n, step)], axis=0)
