"""Tests for jcrowd.motion.fastmath.sincos: NumPy float64 as the oracle, properties, jit/vmap/grad.

Tolerances (and why):

- ``ABS = 2.5e-7`` against float64 ``sin``/``cos``: the input is float32 (exact as given), the
  reduced argument carries ~1 float32 ulp of ``π/2·k`` error and the polynomials ~1 ulp of 1
  (6e-8 each); the module doc promises 2.5e-7. Measured: 9.2e-8.
- ``2 · ABS`` on ``sin² + cos² − 1``: two values each within ``ABS``.
- Gradients within 1e-6 of ``cos``/``−sin``: the polynomials' derivatives, not the function's.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.motion import sincos

ABS = 2.5e-7


def _points() -> np.ndarray:
    rng = np.random.default_rng(7)
    near = np.linspace(-10.0, 10.0, 20_001)
    quadrants = np.arange(-64, 65) * (np.pi / 4)  # every octant boundary, where branches meet
    edges = np.concatenate([quadrants, np.nextafter(quadrants, np.inf), -quadrants])
    wide = rng.uniform(-1e4, 1e4, 200_000)
    return np.concatenate([near, edges, wide, [0.0, -0.0, 1e-30, -1e-30]]).astype(np.float32)


def test_matches_float64_numpy() -> None:
    x = _points()
    s, c = jax.jit(sincos)(x)
    xs = x.astype(np.float64)  # the float32 input, exactly
    assert np.abs(np.asarray(s, np.float64) - np.sin(xs)).max() <= ABS
    assert np.abs(np.asarray(c, np.float64) - np.cos(xs)).max() <= ABS


def test_non_finite_gives_nan_like_sin() -> None:
    s, c = sincos(jnp.asarray([np.inf, -np.inf, np.nan], jnp.float32))
    assert np.isnan(np.asarray(s)).all() and np.isnan(np.asarray(c)).all()


def test_float64_input_keeps_xla_precision() -> None:
    with jax.enable_x64(True):
        x = jnp.asarray([0.1, 1.0, 3.0, 1000.0], jnp.float64)
        s, c = sincos(x)
        assert s.dtype == jnp.float64
        np.testing.assert_allclose(np.asarray(s), np.sin(np.asarray(x)), atol=1e-15)
        np.testing.assert_allclose(np.asarray(c), np.cos(np.asarray(x)), atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4, allow_nan=False, width=32))
def test_properties(x: float) -> None:
    s, c = (float(v) for v in sincos(jnp.float32(x)))
    sn, cn = (float(v) for v in sincos(jnp.float32(-x)))
    assert abs(s * s + c * c - 1.0) <= 2 * ABS
    assert sn == -s and cn == c  # round() is symmetric, so odd and even exactly
    assert abs(s) <= 1.0 + ABS and abs(c) <= 1.0 + ABS


def test_jit_eager_vmap_agree() -> None:
    x = jnp.asarray(_points()[:5000])
    eager = sincos(x)
    jitted = jax.jit(sincos)(x)
    mapped = jax.jit(jax.vmap(sincos))(x)
    for a, b, m in zip(eager, jitted, mapped, strict=True):
        # Eager runs op by op; the compiled fusion may contract a·b + c into one FMA, a rounding
        # fewer: at most 2 float32 ulps of 1 apart (measured 6e-8).
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1.2e-7)
        np.testing.assert_array_equal(np.asarray(b), np.asarray(m))


def test_gradients_are_cos_and_minus_sin() -> None:
    x = jnp.asarray(np.linspace(-20.0, 20.0, 4001), jnp.float32)
    ds = jax.vmap(jax.grad(lambda v: sincos(v)[0]))(x)
    dc = jax.vmap(jax.grad(lambda v: sincos(v)[1]))(x)
    xs = np.asarray(x, np.float64)
    assert np.abs(np.asarray(ds) - np.cos(xs)).max() <= 1e-6
    assert np.abs(np.asarray(dc) + np.sin(xs)).max() <= 1e-6
