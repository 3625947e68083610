"""Compaction for compiled steps: the first ``size`` indices where a mask holds.

:func:`first_true` returns what ``jnp.nonzero(mask, size=size, fill_value=fill)[0]`` returns
for a 1-D mask: the indices of the true entries in increasing order, the first ``size`` of
them, padded with ``fill``. It is built as one prefix sum and one scatter: each true entry's
rank among the true ones (``cumsum(mask) − 1``) is its place in the output, and the index is
written there (ranks past ``size`` and false entries dropped). ``jnp.nonzero`` builds the same
result from two prefix sums and a histogram; on XLA:CPU a prefix sum is a tree of 7–11
kernels (a reduce-window rewritten level by level), so the crowd step, which compacts a dozen
masks a frame, launches fewer kernels with this one; :func:`first_true_per_class` compacts
several classes of one short list with a single prefix sum.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Int

__all__ = ["first_true", "first_true_per_class"]


def first_true(mask: Bool[Array, " n"], size: int, fill: int) -> Int[Array, " size"]:
    """The first ``size`` indices where ``mask`` is true, increasing, padded with ``fill``
    (int32)."""
    n = mask.shape[0]
    rank = jnp.cumsum(mask, dtype=jnp.int32) - 1
    place = jnp.where(mask & (rank < size), rank, size)
    out = jnp.full((size,), fill, jnp.int32)
    return out.at[place].set(jnp.arange(n, dtype=jnp.int32), mode="drop", unique_indices=True)


def first_true_per_class(
    label: Int[Array, " n"], sizes: tuple[int, ...], fill: int
) -> tuple[Int[Array, " size"], ...]:
    """For each class ``c`` of ``len(sizes)``, what ``first_true(label == c, sizes[c], fill)``
    returns (labels outside ``[0, len(sizes))`` belong to none).

    One prefix sum over the ``(n, len(sizes))`` one-hot labels ranks every entry within its
    class, and one scatter writes all classes' indices, where a compaction per class takes a
    prefix sum each; the one-hot matrix is ``n × classes``, so it is for short lists (a
    bucket's slots, not the whole crowd).
    """
    n, classes = label.shape[0], len(sizes)
    ours = label[:, None] == jnp.arange(classes, dtype=label.dtype)[None, :]
    rank = jnp.sum(jnp.where(ours, jnp.cumsum(ours, axis=0, dtype=jnp.int32), 0), axis=1) - 1
    start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int32)
    safe = jnp.clip(label, 0, classes - 1)
    member = (label >= 0) & (label < classes)
    total = int(start[-1])
    kept = member & (rank < jnp.asarray(sizes, jnp.int32)[safe])
    place = jnp.where(kept, jnp.asarray(start)[safe] + rank, total)
    out = jnp.full((total,), fill, jnp.int32)
    out = out.at[place].set(jnp.arange(n, dtype=jnp.int32), mode="drop", unique_indices=True)
    return tuple(out[int(start[c]) : int(start[c + 1])] for c in range(classes))
