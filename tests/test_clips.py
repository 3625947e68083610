"""Clip choice: the batched (matrix-form) kernels equal the one-agent ones under vmap."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jcrowd import load_default_model
from jcrowd.crowd import build_crowd_model, clip_weights, next_clip, next_clips, next_clips_lod
from jcrowd.kriging.universal import kriging_weights, reliability_one, weights_and_reliability


@pytest.fixture(scope="module")
def cm():
    return build_crowd_model(load_default_model())


def _agents(cm, m: int, seed: int):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(cm.lo), np.asarray(cm.hi)
    origin = np.column_stack([rng.uniform(-50, 50, (m, 2)), rng.uniform(-np.pi, np.pi, m)])
    control = rng.uniform(lo, hi, (m, len(lo)))
    target = rng.uniform(-80, 80, (m, 2))
    speed = rng.uniform(0.8, 1.8, m)
    height = rng.uniform(1.5, 1.9, m)
    return tuple(jnp.asarray(x, jnp.float32) for x in (origin, control, target, speed, height))


def test_weights_and_reliability_equal_the_one_query_kernels(cm):
    k = cm.decoders.kriging
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(cm.lo), np.asarray(cm.hi)
    # Inside the box, beyond it, and exactly at samples (one-hot weights, ρ = 1).
    c = np.concatenate([rng.uniform(lo, hi, (40, 3)), rng.uniform(2 * lo, 2 * hi, (10, 3))])
    c = jnp.asarray(np.concatenate([c, np.asarray(k.controls[:5])]), jnp.float32)
    b, rho = jax.jit(weights_and_reliability)(k, c)
    b1 = jax.vmap(lambda q: kriging_weights(k, q)[0])(c)
    rho1 = jax.vmap(lambda q: reliability_one(k, q))(c)
    # float32 sums over 73 samples in another order: 1e-4 absolute on weights of order 1.
    np.testing.assert_allclose(np.asarray(b), np.asarray(b1), atol=1e-4)
    np.testing.assert_allclose(np.asarray(rho), np.asarray(rho1), atol=1e-4)
    np.testing.assert_allclose(np.asarray(rho[-5:]), 1.0, atol=1e-4)
    assert np.asarray(rho[40:50]).max() < np.asarray(rho[:40]).max()  # far queries less reliable


@pytest.mark.parametrize("min_reliability", [0.0, 0.5, 0.99])
def test_next_clips_equals_vmapped_next_clip(cm, min_reliability):
    args = _agents(cm, 64, seed=int(100 * min_reliability))
    c, a, dur = jax.jit(next_clips, static_argnums=6)(cm, *args, min_reliability)
    c1, a1, dur1 = jax.vmap(lambda *x: next_clip(cm, *x, min_reliability))(*args)
    # Same arithmetic up to summation order (float32): controls to 1e-5 of their ~1 m / 1 rad
    # scale, mixing vectors to 1e-4, durations (~30–70 frames) to 1e-2 frames.
    np.testing.assert_allclose(np.asarray(c), np.asarray(c1), atol=1e-5)
    np.testing.assert_allclose(np.asarray(a), np.asarray(a1), atol=1e-4)
    np.testing.assert_allclose(np.asarray(dur), np.asarray(dur1), atol=1e-2)
    assert np.isfinite(np.asarray(a)).all()


def test_next_clips_lod_krige_rows_are_kriged_and_the_rest_play_the_nearest_sample(cm):
    """Oracle per row: kriged rows are next_clip's choice; the others keep the aimed controls
    (next_clip with no reliability pull) and the nearest sample's own mixing vector."""
    m = 40
    args = _agents(cm, m, seed=7)
    krige = jnp.asarray(np.arange(m) % 3 == 0)
    lod = jax.jit(next_clips_lod, static_argnums=(6, 8))
    c, a, dur, done = lod(cm, *args, 0.5, krige, m)
    assert np.asarray(done).all()
    kriged = jax.vmap(lambda *x: next_clip(cm, *x, 0.5))(*args)
    aimed = jax.vmap(lambda *x: next_clip(cm, *x, -1e9))(*args)[0]  # ρ ≥ -1e9: no pull
    k = cm.decoders.kriging
    scale = np.asarray(k.control_scale)
    samples = np.asarray(cm.sample_controls)
    for i in range(m):
        if krige[i]:
            # Same tolerances as the matrix-form test above.
            np.testing.assert_allclose(np.asarray(c[i]), np.asarray(kriged[0][i]), atol=1e-5)
            np.testing.assert_allclose(np.asarray(a[i]), np.asarray(kriged[1][i]), atol=1e-4)
            continue
        np.testing.assert_allclose(np.asarray(c[i]), np.asarray(aimed[i]), atol=1e-5)
        near = int(np.argmin((((samples - np.asarray(c[i])) / scale) ** 2).sum(axis=1)))
        want = clip_weights(cm.decoders, cm.sample_controls[near])  # one-hot at a sample
        np.testing.assert_allclose(np.asarray(a[i]), np.asarray(want), atol=1e-4)
        assert np.asarray(a[i, : k.num_samples]).max() == 1.0
        assert float(dur[i]) == pytest.approx(float(jnp.dot(want, cm.duration)), abs=1e-2)


def test_next_clips_lod_beyond_the_budget_waits(cm):
    args = _agents(cm, 6, seed=3)
    krige = jnp.asarray([False, True, True, False, True, True])
    lod = jax.jit(next_clips_lod, static_argnums=(6, 8))
    _, _, _, done = lod(cm, *args, 0.5, krige, 2)
    # The first two kriged rows fit; the rows not kriged never wait.
    np.testing.assert_array_equal(np.asarray(done), [True, True, True, True, False, False])
    c_all, a_all, _, done_all = lod(cm, *args, 0.5, jnp.ones(6, bool), 6)
    c, a, _ = next_clips(cm, *args, 0.5)
    assert np.asarray(done_all).all()
    # Jitted and eager float32 solves differ in rounding: up to ~1e-6 in a weight of ~3e-3.
    np.testing.assert_allclose(np.asarray(c_all), np.asarray(c), atol=1e-5)
    np.testing.assert_allclose(np.asarray(a_all), np.asarray(a), atol=1e-5)
