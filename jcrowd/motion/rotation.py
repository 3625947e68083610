"""Rotations: unit quaternions (w, x, y, z), matrices, exp maps, slerp and BVH Euler angles.

Conventions (DESIGN §3):

- A quaternion is ``(w, x, y, z)`` with unit length; ``q`` and ``-q`` are the same rotation.
- ``quat_mul(a, b)`` is the rotation "first ``b``, then ``a``" (matrix product ``A @ B``).
- Rotations act on column vectors: ``v' = R v``.
- An exp map (rotation vector) is ``axis * angle`` with the angle in radians (papers 000, 001 store
  rotations this way in pose vectors).
- Euler angles exist for BVH only. A BVH channel list such as ``Zrotation Yrotation Xrotation``
  means ``R = Rz(z) @ Ry(y) @ Rx(x)`` (intrinsic, in the listed order) — the same as SciPy's
  ``Rotation.from_euler("ZYX", [z, y, x])``. Angles are radians here; degrees live in ``io/bvh``.

Every function works on arrays with any leading batch axes. It returns NumPy arrays (keeping
float64) when every input is a NumPy array or a Python number, and ``jax.numpy`` arrays
otherwise, so the same code serves the NumPy-only BVH reader, float64 oracles and jit-compiled
kernels.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import jax.numpy as jnp
import numpy as np

from jcrowd.motion.fastmath import sincos

__all__ = [
    "EULER_ORDERS",
    "euler_to_quat",
    "quat_angle",
    "quat_canonical",
    "quat_conj",
    "quat_from_axis_angle",
    "quat_from_expmap",
    "quat_from_matrix",
    "quat_identity",
    "quat_inv",
    "quat_mul",
    "quat_normalize",
    "quat_rotate",
    "quat_slerp",
    "quat_to_euler",
    "quat_to_expmap",
    "quat_to_matrix",
    "quat_yaw",
    "yaw_quat",
]

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
"""The six Tait–Bryan orders BVH files use (each axis once)."""

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def array_module(*arrays: Any) -> ModuleType:
    """NumPy when every input is NumPy (or a plain number), else jax.numpy."""
    if all(isinstance(a, np.ndarray | np.generic | float | int) for a in arrays):
        return np
    return jnp


def _sincos(xp: ModuleType, x: Any) -> tuple[Any, Any]:
    """``(sin x, cos x)``: NumPy's for NumPy input, else :func:`jcrowd.motion.fastmath.sincos`
    (XLA:CPU does not vectorise its own ``sin``/``cos``)."""
    if xp is np:
        return np.sin(x), np.cos(x)
    return sincos(x)


def _stack(xp: ModuleType, parts: list[Any]) -> Any:
    return xp.stack(parts, axis=-1)


def quat_identity(shape: tuple[int, ...] = (), dtype: Any = jnp.float32) -> jnp.ndarray:
    """Identity quaternions of the given batch shape, ``(*shape, 4)``."""
    return jnp.zeros((*shape, 4), dtype).at[..., 0].set(1.0)


def quat_mul(a: Any, b: Any) -> Any:
    """Hamilton product ``a ⊗ b`` (apply ``b`` first, then ``a``). Shapes ``(..., 4)``."""
    xp = array_module(a, b)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return _stack(
        xp,
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
    )


def quat_conj(q: Any) -> Any:
    """Conjugate ``(w, -x, -y, -z)``."""
    xp = array_module(q)
    return xp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_inv(q: Any) -> Any:
    """Inverse of a unit quaternion (its conjugate)."""
    return quat_conj(q)


def quat_normalize(q: Any, eps: float = 1e-12) -> Any:
    """Scale to unit length; a zero quaternion becomes the identity rather than NaN."""
    xp = array_module(q)
    n = xp.sqrt(xp.sum(q * q, axis=-1, keepdims=True))
    ident = xp.zeros_like(q) + xp.asarray([1.0, 0.0, 0.0, 0.0], dtype=q.dtype)
    safe = xp.where(n > eps, n, 1.0)
    return xp.where(n > eps, q / safe, ident)


def quat_canonical(q: Any) -> Any:
    """The representative with ``w >= 0`` (``q`` and ``-q`` are the same rotation)."""
    xp = array_module(q)
    return xp.where(q[..., :1] < 0, -q, q)


def quat_rotate(q: Any, v: Any) -> Any:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)``: ``R v``."""
    xp = array_module(q, v)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * xp.cross(u, v)
    return v + w * t + xp.cross(u, t)


def quat_to_matrix(q: Any) -> Any:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)``."""
    xp = array_module(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def quat_from_matrix(m: Any) -> Any:
    """Unit quaternions (``w >= 0``) of rotation matrices ``(..., 3, 3)``.

    Shepperd's method: of the four candidate formulas, use the one whose pivot
    (``1 + trace`` or ``1 + 2 m_ii - trace``) is largest, so no division by a small number.
    """
    xp = array_module(m)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    tr = m00 + m11 + m22
    pivots = xp.stack([1 + tr, 1 + 2 * m00 - tr, 1 + 2 * m11 - tr, 1 + 2 * m22 - tr], axis=-1)
    k = xp.argmax(pivots, axis=-1)
    # Each candidate is 4x a quaternion scaled by its pivot's square root.
    c0 = xp.stack(
        [
            1 + tr,
            m[..., 2, 1] - m[..., 1, 2],
            m[..., 0, 2] - m[..., 2, 0],
            m[..., 1, 0] - m[..., 0, 1],
        ],
        axis=-1,
    )
    c1 = xp.stack(
        [
            m[..., 2, 1] - m[..., 1, 2],
            1 + 2 * m00 - tr,
            m[..., 0, 1] + m[..., 1, 0],
            m[..., 0, 2] + m[..., 2, 0],
        ],
        axis=-1,
    )
    c2 = xp.stack(
        [
            m[..., 0, 2] - m[..., 2, 0],
            m[..., 0, 1] + m[..., 1, 0],
            1 + 2 * m11 - tr,
            m[..., 1, 2] + m[..., 2, 1],
        ],
        axis=-1,
    )
    c3 = xp.stack(
        [
            m[..., 1, 0] - m[..., 0, 1],
            m[..., 0, 2] + m[..., 2, 0],
            m[..., 1, 2] + m[..., 2, 1],
            1 + 2 * m22 - tr,
        ],
        axis=-1,
    )
    cands = xp.stack([c0, c1, c2, c3], axis=-2)
    idx = k[..., None, None]
    chosen = xp.take_along_axis(cands, xp.broadcast_to(idx, (*k.shape, 1, 4)), axis=-2)[..., 0, :]
    return quat_canonical(quat_normalize(chosen))


def quat_from_axis_angle(axis: Any, angle: Any) -> Any:
    """Rotation by ``angle`` (radians) about unit ``axis`` ``(..., 3)``."""
    xp = array_module(axis, angle)
    sin, cos = _sincos(xp, 0.5 * xp.asarray(angle)[..., None])
    return xp.concatenate([cos, sin * axis], axis=-1)


def quat_from_expmap(r: Any) -> Any:
    """Quaternion of a rotation vector ``r = axis * angle`` ``(..., 3)``.

    Uses ``sin(θ/2)/θ`` with its Taylor series near 0, so it is smooth (and differentiable) at 0.
    """
    xp = array_module(r)
    # Written out, not xp.sum: XLA:CPU sends a 3-element reduce to a separate library kernel,
    # where a sum of products fuses with the work around it.
    theta2 = r[..., 0:1] * r[..., 0:1] + r[..., 1:2] * r[..., 1:2] + r[..., 2:3] * r[..., 2:3]
    small = theta2 < 1e-8
    theta = xp.sqrt(xp.where(small, 1.0, theta2))
    sin, cos = _sincos(xp, 0.5 * theta)
    s = xp.where(small, 0.5 - theta2 / 48.0, sin / theta)
    c = xp.where(small, 1.0 - theta2 / 8.0, cos)
    return xp.concatenate([c, s * r], axis=-1)


def quat_to_expmap(q: Any) -> Any:
    """Rotation vector ``axis * angle`` of ``q``; the angle is in ``[0, π]`` (``w >= 0`` side)."""
    xp = array_module(q)
    q = quat_canonical(q)
    v = q[..., 1:]
    s2 = xp.sum(v * v, axis=-1, keepdims=True)
    small = s2 < 1e-12
    s = xp.sqrt(xp.where(small, 1.0, s2))
    angle = 2.0 * xp.arctan2(s, q[..., :1])
    scale = xp.where(small, 2.0 / xp.maximum(q[..., :1], 1e-12), angle / s)
    return scale * v


def quat_angle(a: Any, b: Any) -> Any:
    """Angle in radians ``[0, π]`` of the rotation taking ``b`` to ``a`` (sign-invariant)."""
    xp = array_module(a, b)
    # 2·arccos|a·b| loses half the digits near 0 (float32: ~1e-3 rad error at small angles).
    # For unit a, b at 4-D angle Ω: |a - b| = 2 sin(Ω/2), |a + b| = 2 cos(Ω/2), so the rotation
    # angle 2Ω = 4·atan2(|a - b|, |a + b|), accurate everywhere.
    b = xp.where(xp.sum(a * b, axis=-1, keepdims=True) < 0, -b, b)
    return 4.0 * xp.arctan2(_safe_norm(xp, a - b), _safe_norm(xp, a + b))


def _safe_norm(xp: ModuleType, v: Any) -> Any:
    """Euclidean norm over the last axis whose gradient at 0 is 0 rather than NaN."""
    n2 = xp.sum(v * v, axis=-1)
    nonzero = n2 > 0
    return xp.where(nonzero, xp.sqrt(xp.where(nonzero, n2, 1.0)), 0.0)


def quat_slerp(a: Any, b: Any, t: Any) -> Any:
    """Spherical linear interpolation from ``a`` (t=0) to ``b`` (t=1) along the short arc."""
    xp = array_module(a, b, t)
    t = xp.asarray(t)
    if t.ndim < a.ndim:
        t = t[..., None]
    d = xp.sum(a * b, axis=-1, keepdims=True)
    b = xp.where(d < 0, -b, b)
    d = xp.abs(d)
    near = d > 0.9995
    omega = xp.arccos(xp.clip(d, -1.0, 1.0))
    so = xp.sin(xp.where(near, 1.0, omega))
    wa = xp.where(near, 1.0 - t, xp.sin((1.0 - t) * omega) / so)
    wb = xp.where(near, t, xp.sin(t * omega) / so)
    return quat_normalize(wa * a + wb * b)


def euler_to_quat(angles: Any, order: str) -> Any:
    """Quaternion of Euler angles (radians) in BVH channel order.

    Args:
        angles: ``(..., 3)``, the angle of each axis in the order the letters of ``order`` give.
        order: one of :data:`EULER_ORDERS`, e.g. ``"ZYX"`` means ``R = Rz @ Ry @ Rx``.
    """
    order = _check_order(order)
    xp = array_module(angles)
    q = None
    for i, letter in enumerate(order):
        axis = np.zeros(3)
        axis[_AXIS[letter]] = 1.0
        axis_arr = xp.asarray(axis, dtype=angles.dtype)
        qi = quat_from_axis_angle(
            xp.broadcast_to(axis_arr, (*angles.shape[:-1], 3)), angles[..., i]
        )
        q = qi if q is None else quat_mul(q, qi)
    return q


def quat_to_euler(q: Any, order: str) -> Any:
    """Euler angles (radians, ``(..., 3)`` in the letters' order) with ``R = R_i R_j R_k``.

    For axes ``(i, j, k)`` and ``s = +1`` for a cyclic order (XYZ, YZX, ZXY), ``-1`` otherwise,
    the first angle is ``a = atan2(-s R[j,k], R[k,k])``. The other two are read from
    ``M = R_i(-a) R = R_j(b) R_k(c)``: ``b = atan2(s R[i,k], M[k,k])`` and
    ``c = atan2(s M[j,i], M[j,j])`` (Shoemake's method, as in Eigen's ``eulerAngles``). Because
    ``b`` and ``c`` are computed *given* ``a``, the angles rebuild ``R`` to rounding even at or
    near gimbal lock (``|b| ≈ π/2``), where ``a`` is ill-determined; there ``a`` is read as the
    whole rotation about the shared axis so that ``c ≈ 0``.
    """
    order = _check_order(order)
    xp = array_module(q)
    i, j, k = (_AXIS[c] for c in order)
    s = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    m = quat_to_matrix(q)
    a = xp.arctan2(-s * m[..., j, k], m[..., k, k])
    # cos b = |(R[j,k], R[k,k])|; at rounding level a is atan2 of noise. The a below is exact
    # at lock and gives c ≈ 0 there; replacing the true a costs |Δa|·cos b ≤ 4π·eps, rounding.
    locked = xp.hypot(m[..., j, k], m[..., k, k]) < 4 * xp.finfo(m.dtype).eps
    a = xp.where(locked, xp.arctan2(s * m[..., k, j], m[..., j, j]), a)
    ca, sa = xp.cos(a), xp.sin(a)
    b = xp.arctan2(s * m[..., i, k], ca * m[..., k, k] - s * sa * m[..., j, k])
    c = xp.arctan2(
        s * ca * m[..., j, i] + sa * m[..., k, i], ca * m[..., j, j] + s * sa * m[..., k, j]
    )
    return xp.stack([a, b, c], axis=-1)


def _check_order(order: str) -> str:
    up = order.upper()
    if up not in EULER_ORDERS:
        from jcrowd.errors import JcrowdError

        raise JcrowdError(f"Euler order: expected one of {EULER_ORDERS}, found {order!r}")
    return up


def quat_yaw(q: Any, forward: Any = None) -> Any:
    """Heading angle (radians) of ``q`` about +Y: ``atan2(f_x, f_z)`` of the rotated forward.

    ``forward`` is the rest-pose facing direction (default +Z). A positive yaw turns +Z towards
    +X, i.e. to the character's left when it faces +Z (right-handed, Y up).
    """
    xp = array_module(q) if forward is None else array_module(q, forward)
    if forward is None:
        forward = xp.asarray([0.0, 0.0, 1.0], dtype=q.dtype)
    f = quat_rotate(q, xp.broadcast_to(forward, (*q.shape[:-1], 3)))
    return xp.arctan2(f[..., 0], f[..., 2])


def yaw_quat(yaw: Any) -> Any:
    """Rotation by ``yaw`` radians about +Y, ``(..., 4)``."""
    xp = array_module(yaw)
    yaw = xp.asarray(yaw)
    zero = xp.zeros_like(yaw)
    sin, cos = _sincos(xp, 0.5 * yaw)
    return xp.stack([cos, zero, sin, zero], axis=-1)
