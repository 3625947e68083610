"""``first_true``: the first ``size`` indices of a mask's true entries, padded; and
``first_true_per_class``, the same for each class of a label array at once.

Oracles: NumPy's ``flatnonzero`` (a host loop over the mask, then cut and padded by hand) and
``jnp.nonzero(mask, size=, fill_value=)``, whose result it must equal exactly. Properties:
increasing indices, each a true entry, as many as ``min(size, true count)``. Transformations:
jit == eager, vmap == loop. Per class, the oracle is the NumPy one applied to ``label == c``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.indexing import first_true, first_true_per_class


def _oracle(mask: np.ndarray, size: int, fill: int) -> np.ndarray:
    found = np.flatnonzero(mask)[:size]
    return np.concatenate([found, np.full(size - len(found), fill)]).astype(np.int32)


masks = st.lists(st.booleans(), min_size=1, max_size=300).map(np.asarray)


@settings(max_examples=60, deadline=None)
@given(masks, st.integers(1, 320), st.integers(-5, 400))
def test_first_true_equals_flatnonzero_and_jnp_nonzero(mask, size, fill):
    # Compiled: one program per example (op by op, every op compiles for the new shapes).
    got = np.asarray(jax.jit(first_true, static_argnums=(1, 2))(jnp.asarray(mask), size, fill))
    np.testing.assert_array_equal(got, _oracle(mask, size, fill))
    (ref,) = jax.jit(lambda m: jnp.nonzero(m, size=size, fill_value=fill))(jnp.asarray(mask))
    np.testing.assert_array_equal(got, np.asarray(ref))
    kept = got[: min(size, int(mask.sum()))]
    assert np.all(np.diff(kept) > 0) and np.all(mask[kept])
    assert np.all(got[len(kept) :] == fill) and got.dtype == np.int32


def test_first_true_by_hand():
    mask = jnp.asarray([False, True, True, False, True])
    np.testing.assert_array_equal(np.asarray(first_true(mask, 2, 9)), [1, 2])
    np.testing.assert_array_equal(np.asarray(first_true(mask, 5, 9)), [1, 2, 4, 9, 9])
    np.testing.assert_array_equal(np.asarray(first_true(~mask & False, 3, 5)), [5, 5, 5])


def test_first_true_jit_and_vmap():
    rng = np.random.default_rng(0)
    masks = jnp.asarray(rng.random((7, 50)) < 0.3)
    eager = np.stack([np.asarray(first_true(m, 12, 50)) for m in masks])
    jitted = jax.jit(first_true, static_argnums=(1, 2))
    np.testing.assert_array_equal(np.stack([np.asarray(jitted(m, 12, 50)) for m in masks]), eager)
    mapped = jax.vmap(lambda m: first_true(m, 12, 50))(masks)
    np.testing.assert_array_equal(np.asarray(mapped), eager)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.integers(-1, 5), min_size=1, max_size=200).map(np.asarray),
    st.lists(st.integers(1, 60), min_size=1, max_size=5),
    st.integers(-3, 300),
)
def test_first_true_per_class_equals_one_compaction_per_class(label, sizes, fill):
    per_class = jax.jit(first_true_per_class, static_argnums=(1, 2))  # one program per example
    got = per_class(jnp.asarray(label, jnp.int32), tuple(sizes), fill)
    assert len(got) == len(sizes)
    for c, (size, idx) in enumerate(zip(sizes, got, strict=True)):
        np.testing.assert_array_equal(np.asarray(idx), _oracle(label == c, size, fill), str(c))


def test_first_true_per_class_by_hand_and_jit():
    label = jnp.asarray([2, 0, 1, 0, 3, 0, 1], jnp.int32)  # 3: no class of the three
    want = ([1, 3], [2, 6, 9], [0])
    for got in (
        first_true_per_class(label, (2, 3, 1), 9),
        jax.jit(first_true_per_class, static_argnums=(1, 2))(label, (2, 3, 1), 9),
    ):
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(np.asarray(g), w)
