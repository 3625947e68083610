"""Sine and cosine as plain float32 arithmetic, for the compiled crowd step.

XLA:CPU evaluates ``sin`` and ``cos`` element by element without vectorising them, while the
polynomial below is plain multiply-adds, which it vectorises and fuses with the work around
them. The step evaluates two or three of them per agent every frame (dead reckoning) and two
per kept joint (exp map → quaternion), so their cost scales with the whole crowd.

The method is the textbook one (Cody–Waite reduction, then minimax polynomials on a quarter
period):

- ``k = round(x · 2/π)`` and ``r = x − k·π/2`` with ``π/2`` split into three float32 parts
  (the first, ``201/128``, has 8 significant bits, so ``k · part₁`` is exact for
  ``|k| < 2¹⁶``), which leaves ``|r| ≤ π/4``;
- ``sin r`` and ``cos r`` by the degree-7 and degree-8 minimax polynomials of the Cephes
  library's ``sinf``/``cosf`` (coefficients are numbers from that library; the code is this
  project's own);
- the quadrant ``k mod 4`` swaps and negates them.

Accuracy (test: against NumPy float64 over ``|x| ≤ 10⁴``): absolute error ≤ 2.5e-7, about two
float32 ulps of 1 — XLA's own float32 ``sin`` is within 3e-8 on the same points. Beyond
``|x| ≈ 10⁵`` the reduction loses bits, but a float32 angle that large is itself only known
to ~0.01 rad. ``±inf`` and NaN give NaN, as ``sin`` does. The functions are smooth in ``x``
(``k`` is piecewise constant), so gradients are the polynomials' derivatives, within 1e-6 of
the true ones.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

__all__ = ["sincos"]

_TWO_OVER_PI = np.float32(2.0 / np.pi)
# π/2 = _PI2_A + _PI2_B + _PI2_C to about 2⁻⁷⁰ (Cody–Waite; twice Cephes's π/4 split).
_PI2_A = np.float32(201 / 128)
_PI2_B = np.float32(4.837512969970703125e-4)
_PI2_C = np.float32(7.54978995489188216e-8)
# Cephes sinf / cosf minimax coefficients on [−π/4, π/4].
_S1 = np.float32(-1.6666654611e-1)
_S2 = np.float32(8.3321608736e-3)
_S3 = np.float32(-1.9515295891e-4)
_C1 = np.float32(4.166664568298827e-2)
_C2 = np.float32(-1.388731625493765e-3)
_C3 = np.float32(2.443315711809948e-5)


def sincos(x: ArrayLike) -> tuple[Array, Array]:
    """``(sin x, cos x)`` elementwise (module doc: method and accuracy).

    Float32 (and narrower, or integer) input takes the polynomial; a float64 array (with
    ``jax_enable_x64``) keeps XLA's own ``sin``/``cos``, whose precision the polynomial lacks.
    """
    x = jnp.asarray(x)
    if x.dtype == jnp.float64:
        return jnp.sin(x), jnp.cos(x)
    x = x.astype(jnp.float32)
    k = jnp.round(x * _TWO_OVER_PI)
    r = ((x - k * _PI2_A) - k * _PI2_B) - k * _PI2_C
    r2 = r * r
    s = r + r * r2 * (_S1 + r2 * (_S2 + r2 * _S3))
    c = 1.0 - 0.5 * r2 + r2 * r2 * (_C1 + r2 * (_C2 + r2 * _C3))
    # Quadrant q = k mod 4: sin x = (s, c, −s, −c)[q] and cos x = (c, −s, −c, s)[q].
    q = jnp.where(jnp.isfinite(k), k, 0.0).astype(jnp.int32) & 3
    odd = (q & 1) == 1
    sin = jnp.where(odd, c, s)
    cos = jnp.where(odd, s, c)
    sin = jnp.where(q >= 2, -sin, sin)
    cos = jnp.where((q == 1) | (q == 2), -cos, cos)
    return sin, cos
