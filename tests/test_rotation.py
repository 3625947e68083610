"""Tests for jcrowd.motion.rotation: SciPy as the oracle, properties with hypothesis, jit/vmap.

Tolerances used below (and why):

- ``TOL64 = 1e-12``: NumPy float64 in and out, a handful of flops against SciPy float64.
- ``TOL32 = 2e-6``: the jnp path computes in float32 (eps 6e-8), compared with SciPy in float64;
  a few dozen roundings on values of size ~1.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, Slerp

from jcrowd.errors import JcrowdError
from jcrowd.motion import (
    EULER_ORDERS,
    euler_to_quat,
    quat_angle,
    quat_canonical,
    quat_conj,
    quat_from_axis_angle,
    quat_from_expmap,
    quat_from_matrix,
    quat_identity,
    quat_inv,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_slerp,
    quat_to_euler,
    quat_to_expmap,
    quat_to_matrix,
    quat_yaw,
    yaw_quat,
)

TOL64 = 1e-12  # float64 NumPy path vs float64 SciPy: rounding only
TOL32 = 2e-6  # float32 jnp path vs float64 SciPy: float32 rounding over a few dozen flops

SETTINGS = settings(max_examples=50, deadline=None)


def random_quats(seed: int, n: int) -> np.ndarray:
    """``n`` random unit quaternions (w, x, y, z), float64, uniform on the sphere."""
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def scipy_rot(q) -> Rotation:
    return Rotation.from_quat(np.asarray(q, np.float64), scalar_first=True)


def scipy_quat(r: Rotation) -> np.ndarray:
    return r.as_quat(scalar_first=True)


def sign_free_error(a, b) -> np.ndarray:
    """Per-quaternion distance that treats ``q`` and ``-q`` as equal."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.minimum(np.abs(a - b).max(axis=-1), np.abs(a + b).max(axis=-1))


def assert_same_rotation(a, b, atol: float) -> None:
    err = sign_free_error(a, b)
    assert err.max() <= atol, f"largest sign-free quaternion error {err.max():.3g} > {atol:g}"


def wrap(angle):
    """Angle difference wrapped into (-π, π]."""
    return np.angle(np.exp(1j * np.asarray(angle, np.float64)))


# Unit quaternions for hypothesis: 4 bounded floats, kept away from the zero vector.
unit_quat = (
    st.lists(st.floats(-1.0, 1.0, allow_nan=False, width=64), min_size=4, max_size=4)
    .map(np.array)
    .filter(lambda q: np.linalg.norm(q) > 0.1)
    .map(lambda q: q / np.linalg.norm(q))
)


# ---------------------------------------------------------------------------------------------
# Oracles: every function against SciPy (float64 NumPy path and float32 jnp path)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, TOL32)])
def test_mul_conj_inv_match_scipy(to, tol):
    a, b = random_quats(0, 64), random_quats(1, 64)
    expect = scipy_quat(scipy_rot(a) * scipy_rot(b))  # SciPy's a * b applies b first
    assert_same_rotation(quat_mul(to(a), to(b)), expect, tol)
    expect_inv = scipy_quat(scipy_rot(a).inv())
    assert_same_rotation(quat_conj(to(a)), expect_inv, tol)
    assert_same_rotation(quat_inv(to(a)), expect_inv, tol)


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, 5 * TOL32)])
def test_rotate_and_matrix_match_scipy(to, tol):
    # Vectors up to ~3 long, so float32 errors are a few times larger than on unit quantities.
    q = random_quats(2, 64)
    v = np.random.default_rng(3).normal(size=(64, 3))
    np.testing.assert_allclose(quat_rotate(to(q), to(v)), scipy_rot(q).apply(v), atol=tol, rtol=0)
    np.testing.assert_allclose(quat_to_matrix(to(q)), scipy_rot(q).as_matrix(), atol=tol, rtol=0)


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, TOL32)])
def test_from_matrix_matches_scipy(to, tol):
    q = random_quats(4, 256)
    # Include the four Shepperd branches explicitly: identity and half-turns about x, y, z.
    q = np.concatenate([q, np.eye(4), [[0.0, 1, 1, 0] / np.sqrt(2)]])
    m = scipy_rot(q).as_matrix()
    out = np.asarray(quat_from_matrix(to(m)), np.float64)
    assert_same_rotation(out, q, tol)
    assert (out[:, 0] >= 0).all(), "quat_from_matrix must return the w >= 0 representative"


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, 4 * TOL32)])
def test_expmap_log_match_scipy(to, tol):
    # Rotation vectors with angles up to ~3 rad; float32 error grows with the angle.
    q = quat_canonical(random_quats(5, 128))
    rotvec = scipy_rot(q).as_rotvec()
    assert_same_rotation(quat_from_expmap(to(rotvec)), q, tol)
    # Both return the rotation vector of the w >= 0 representative (angle in [0, π]).
    np.testing.assert_allclose(quat_to_expmap(to(q)), rotvec, atol=tol, rtol=0)
    np.testing.assert_allclose(quat_to_expmap(to(-q)), rotvec, atol=tol, rtol=0)


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, TOL32)])
def test_axis_angle_matches_scipy(to, tol):
    rng = np.random.default_rng(6)
    axis = rng.normal(size=(32, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = rng.uniform(-np.pi, np.pi, size=32)
    expect = scipy_quat(Rotation.from_rotvec(axis * angle[:, None]))
    assert_same_rotation(quat_from_axis_angle(to(axis), to(angle)), expect, tol)


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, TOL32)])
def test_slerp_matches_scipy(to, tol):
    a, b = random_quats(7, 40), random_quats(8, 40)
    t = np.random.default_rng(9).uniform(0, 1, size=40)
    out = np.asarray(quat_slerp(to(a), to(b), to(t)), np.float64)
    for i in range(40):
        key = Rotation.concatenate([scipy_rot(a[i]), scipy_rot(b[i])])
        expect = scipy_quat(Slerp([0.0, 1.0], key)([t[i]]))[0]
        assert_same_rotation(out[i], expect, tol)


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, 1e-8), (jnp.asarray, 1e-5)])
def test_angle_matches_scipy_including_small_angles(to, tol):
    # Tolerance: angles are compared as angles; float32 quaternions resolve ~1e-7 per component,
    # so the angle between two float32 quaternions is known to a few 1e-7 rad (1e-5 leaves room).
    # Float64: SciPy's own magnitude() goes through a rotation vector (1e-8 is its precision).
    a = random_quats(10, 64)
    small = scipy_quat(Rotation.from_rotvec(np.random.default_rng(11).normal(size=(64, 3)) * 1e-3))
    b = np.concatenate(
        [
            random_quats(12, 64),
            scipy_quat(scipy_rot(a) * Rotation.from_quat(small, scalar_first=True)),
        ]
    )
    a = np.concatenate([a, a])
    expect = (scipy_rot(a).inv() * scipy_rot(b)).magnitude()
    np.testing.assert_allclose(quat_angle(to(a), to(b)), expect, atol=tol, rtol=0)
    np.testing.assert_allclose(quat_angle(to(a), to(-b)), expect, atol=tol, rtol=0)


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, TOL32)])
def test_yaw_matches_closed_form(to, tol):
    q = random_quats(13, 64)
    f = scipy_rot(q).apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(
        wrap(quat_yaw(to(q)) - np.arctan2(f[:, 0], f[:, 2])), 0, atol=10 * tol
    )
    # A custom rest forward (+X): yaw of the rotated +X, measured from +Z.
    fx = scipy_rot(q).apply([1.0, 0.0, 0.0])
    out = quat_yaw(to(q), to(np.array([1.0, 0.0, 0.0])))
    np.testing.assert_allclose(wrap(out - np.arctan2(fx[:, 0], fx[:, 2])), 0, atol=10 * tol)


@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, TOL32)])
def test_yaw_quat_is_rotation_about_y(to, tol):
    yaw = np.linspace(-3.1, 3.1, 41)
    q = yaw_quat(to(yaw))
    assert_same_rotation(q, scipy_quat(Rotation.from_euler("y", yaw[:, None])), tol)
    np.testing.assert_allclose(quat_yaw(q), yaw, atol=10 * tol)  # atan2 near ±π: looser


def test_normalize_matches_closed_form():
    q = np.random.default_rng(14).normal(size=(32, 4)) * 3.0
    np.testing.assert_allclose(
        quat_normalize(q), q / np.linalg.norm(q, axis=-1, keepdims=True), atol=TOL64, rtol=0
    )


@pytest.mark.parametrize("to", [np.asarray, jnp.asarray])
def test_normalize_zero_gives_identity(to):
    q = to(np.array([[0.0, 0, 0, 0], [0.0, 0, 2, 0]], np.float32))
    out = np.asarray(quat_normalize(q))
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out, [[1, 0, 0, 0], [0, 0, 1, 0]])


def test_identity_and_canonical():
    ident = quat_identity((2, 3))
    assert ident.shape == (2, 3, 4) and ident.dtype == jnp.float32
    np.testing.assert_array_equal(ident[..., 0], 1.0)
    np.testing.assert_array_equal(ident[..., 1:], 0.0)
    q = random_quats(15, 64)
    c = quat_canonical(q)
    assert (c[:, 0] >= 0).all()
    np.testing.assert_array_equal(np.abs(c), np.abs(q))


# ---------------------------------------------------------------------------------------------
# Euler angles (BVH): all six orders against SciPy's intrinsic (uppercase) convention
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("order", EULER_ORDERS)
@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, TOL32)])
def test_euler_to_quat_matches_scipy(order, to, tol):
    angles = np.random.default_rng(16).uniform(-np.pi, np.pi, size=(64, 3))
    expect = scipy_quat(Rotation.from_euler(order, angles))
    assert_same_rotation(euler_to_quat(to(angles), order), expect, tol)
    # BVH meaning: R = R_first @ R_second @ R_third.
    mats = [Rotation.from_euler(order[i], angles[:, i : i + 1]).as_matrix() for i in range(3)]
    np.testing.assert_allclose(
        quat_to_matrix(euler_to_quat(to(angles), order)),
        mats[0] @ mats[1] @ mats[2],
        atol=tol,
        rtol=0,
    )


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_quat_to_euler_matches_scipy_as_euler(order):
    # Middle angle away from ±90° so the decomposition is unique and well conditioned
    # (1e-10: float64 asin/atan2 with conditioning 1/cos(b) ≤ ~6 at |b| ≤ 80°).
    rng = np.random.default_rng(17)
    angles = np.stack(
        [rng.uniform(-3.1, 3.1, 64), rng.uniform(-1.4, 1.4, 64), rng.uniform(-3.1, 3.1, 64)], -1
    )
    q = scipy_quat(Rotation.from_euler(order, angles))
    out = quat_to_euler(q, order)
    np.testing.assert_allclose(
        wrap(out - Rotation.from_euler(order, angles).as_euler(order)), 0, atol=1e-10
    )
    np.testing.assert_allclose(wrap(out - angles), 0, atol=1e-10)


@pytest.mark.parametrize("order", EULER_ORDERS)
@pytest.mark.parametrize(("to", "tol"), [(np.asarray, TOL64), (jnp.asarray, 4 * TOL32)])
def test_euler_round_trip_reproduces_rotation(order, to, tol):
    # Random rotations, some close to gimbal lock: the angles may be ill-conditioned there,
    # but the rotation they rebuild must not be.
    q = random_quats(18, 256)
    q_out = euler_to_quat(quat_to_euler(to(q), order), order)
    assert_same_rotation(q_out, q, tol)


@pytest.mark.parametrize("order", EULER_ORDERS)
@pytest.mark.parametrize("middle", [np.pi / 2, -np.pi / 2])
@pytest.mark.parametrize(("to", "tol"), [(np.asarray, 1e-12), (jnp.asarray, 4 * TOL32)])
def test_gimbal_lock_reproduces_rotation(order, middle, to, tol):
    rng = np.random.default_rng(19)
    angles = np.stack([rng.uniform(-3, 3, 32), np.full(32, middle), rng.uniform(-3, 3, 32)], -1)
    # Also exercise "almost locked" middle angles, where asin loses precision in float32.
    near = angles.copy()
    near[:, 1] -= np.sign(middle) * np.geomspace(1e-8, 1e-3, 32)
    for ang in (angles, near):
        q = scipy_quat(Rotation.from_euler(order, ang))
        out = quat_to_euler(to(q), order)
        assert np.isfinite(np.asarray(out)).all()
        assert_same_rotation(euler_to_quat(out, order), q, tol)
        assert_same_rotation(
            scipy_quat(Rotation.from_euler(order, np.asarray(out, np.float64))), q, tol
        )
        assert (np.abs(np.asarray(out)[:, 1]) <= np.pi / 2 + 1e-6).all()
    # Exactly at lock the first angle takes the whole rotation about the shared axis (c = 0),
    # so a BVH writer emits the simple angles rather than an arbitrary split.
    out = quat_to_euler(to(scipy_quat(Rotation.from_euler(order, angles))), order)
    np.testing.assert_allclose(np.asarray(out)[:, 2], 0.0, atol=1e-6)


@pytest.mark.parametrize("bad", ["XYX", "XY", "ABC", "", "XYZW"])
def test_bad_euler_order_raises(bad):
    with pytest.raises(JcrowdError, match="Euler order"):
        euler_to_quat(np.zeros(3), bad)
    with pytest.raises(JcrowdError, match="Euler order"):
        quat_to_euler(np.array([1.0, 0, 0, 0]), bad)


# ---------------------------------------------------------------------------------------------
# Array types: NumPy in -> NumPy float64 out; jnp in -> jax array out
# ---------------------------------------------------------------------------------------------

_CALLS = {
    "quat_mul": lambda to, q, v: quat_mul(to(q), to(q)),
    "quat_conj": lambda to, q, v: quat_conj(to(q)),
    "quat_normalize": lambda to, q, v: quat_normalize(to(q)),
    "quat_canonical": lambda to, q, v: quat_canonical(to(q)),
    "quat_rotate": lambda to, q, v: quat_rotate(to(q), to(v)),
    "quat_to_matrix": lambda to, q, v: quat_to_matrix(to(q)),
    "quat_from_matrix": lambda to, q, v: quat_from_matrix(
        to(np.broadcast_to(np.eye(3), (5, 3, 3)))
    ),
    "quat_from_axis_angle": lambda to, q, v: quat_from_axis_angle(to(v), to(v[:, 0])),
    "quat_from_expmap": lambda to, q, v: quat_from_expmap(to(v)),
    "quat_to_expmap": lambda to, q, v: quat_to_expmap(to(q)),
    "quat_angle": lambda to, q, v: quat_angle(to(q), to(q[::-1])),
    "quat_slerp": lambda to, q, v: quat_slerp(to(q), to(q[::-1]), to(v[:, 0])),
    "euler_to_quat": lambda to, q, v: euler_to_quat(to(v), "ZXY"),
    "quat_to_euler": lambda to, q, v: quat_to_euler(to(q), "YZX"),
    "quat_yaw": lambda to, q, v: quat_yaw(to(q)),
    "yaw_quat": lambda to, q, v: yaw_quat(to(v[:, 0])),
}


@pytest.mark.parametrize("name", sorted(_CALLS))
def test_numpy_in_numpy_float64_out_jax_in_jax_out(name):
    q, v = random_quats(20, 5), np.random.default_rng(21).normal(size=(5, 3))
    out_np = _CALLS[name](np.asarray, q, v)
    assert isinstance(out_np, np.ndarray) and out_np.dtype == np.float64, (
        type(out_np),
        out_np.dtype,
    )
    out_jax = _CALLS[name](lambda x: jnp.asarray(x, jnp.float32), q, v)
    assert isinstance(out_jax, jax.Array) and out_jax.dtype == jnp.float32, (
        type(out_jax),
        out_jax.dtype,
    )
    # The two paths compute the same thing (float32 vs float64 rounding).
    np.testing.assert_allclose(out_jax, out_np, atol=1e-5, rtol=0)


def test_numpy_float32_in_keeps_float32():
    q = random_quats(22, 5).astype(np.float32)
    out = quat_mul(q, q)
    assert isinstance(out, np.ndarray) and out.dtype == np.float32


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------


@SETTINGS
@given(unit_quat, unit_quat, st.floats(0.0, 1.0))
def test_unit_length_is_kept(a, b, t):
    for q in (
        quat_mul(a, b),
        quat_slerp(a, b, t),
        quat_from_expmap(quat_to_expmap(a)),
        quat_conj(a),
    ):
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12  # float64 rounding


@SETTINGS
@given(unit_quat)
def test_times_inverse_is_identity(q):
    np.testing.assert_allclose(quat_mul(q, quat_inv(q)), [1, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(quat_mul(quat_inv(q), q), [1, 0, 0, 0], atol=1e-12)


@SETTINGS
@given(unit_quat, st.lists(st.floats(-10, 10), min_size=6, max_size=6))
def test_rotation_preserves_lengths_and_angles(q, uv):
    u, v = np.array(uv[:3]), np.array(uv[3:])
    ru, rv = quat_rotate(q, u), quat_rotate(q, v)
    # Vectors up to ~17 long, products up to ~300: 1e-10 is float64 rounding at that scale.
    assert abs(np.linalg.norm(ru) - np.linalg.norm(u)) < 1e-10
    assert abs(ru @ rv - u @ v) < 1e-10
    np.testing.assert_allclose(quat_to_matrix(q) @ u, ru, atol=1e-10)


@SETTINGS
@given(unit_quat, unit_quat)
def test_matrix_is_a_homomorphism(a, b):
    np.testing.assert_allclose(
        quat_to_matrix(quat_mul(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-12
    )
    assert sign_free_error(quat_from_matrix(quat_to_matrix(a)), a) < 1e-12


@SETTINGS
@given(unit_quat)
def test_exp_of_log_is_plus_minus_q(q):
    r = quat_to_expmap(q)
    assert np.linalg.norm(r) <= np.pi + 1e-12
    assert sign_free_error(quat_from_expmap(r), q) < 1e-12


@SETTINGS
@given(unit_quat, unit_quat)
def test_slerp_endpoints(a, b):
    np.testing.assert_allclose(quat_slerp(a, b, 0.0), a, atol=1e-12)
    assert sign_free_error(quat_slerp(a, b, 1.0), b) < 1e-12


@SETTINGS
@given(unit_quat, unit_quat, st.floats(0.0, 1.0))
def test_slerp_has_constant_angular_speed(a, b, t):
    # 1.1e-6 rad: for arcs below 0.063 rad (|a·b| > 0.9995) quat_slerp switches to normalised
    # lerp, whose angle deviates from t·θ by at most 1.01e-6 rad (at the switch; computed in
    # closed form); above the switch it is exact to float64 rounding.
    total = quat_angle(a, b)
    s = quat_slerp(a, b, t)
    assert abs(quat_angle(s, a) - t * total) < 1.1e-6
    assert abs(quat_angle(s, b) - (1 - t) * total) < 1.1e-6


def test_slerp_constant_speed_on_small_arcs():
    # Hypothesis rarely draws nearly equal quaternions: cover the normalised-lerp branch directly,
    # with arcs on both sides of the switch at 0.063 rad (bound as in the test above).
    a = random_quats(28, 1)[0]
    axis = np.array([0.0, 0.6, 0.8])
    t = np.linspace(0.0, 1.0, 21)
    for theta in (1e-6, 1e-3, 0.03, 0.0632, 0.0633, 0.1):
        b = quat_mul(a, quat_from_axis_angle(axis, theta))
        s = quat_slerp(np.broadcast_to(a, (21, 4)), np.broadcast_to(b, (21, 4)), t)
        np.testing.assert_allclose(quat_angle(s, a), t * theta, atol=1.1e-6, rtol=0)
        np.testing.assert_allclose(np.linalg.norm(s, axis=-1), 1.0, atol=1e-12)


@SETTINGS
@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3), st.floats(1e-9, 1.0))
def test_expmap_near_zero_is_finite_and_exact(direction, scale):
    # Rotation vectors from 1e-9 to ~1.7 rad cross the Taylor-series switch at |r| = 1e-4.
    r = np.array(direction) * scale
    q = quat_from_expmap(r)
    assert np.isfinite(q).all()
    assert sign_free_error(q, scipy_quat(Rotation.from_rotvec(r))) < 1e-12
    np.testing.assert_allclose(quat_to_expmap(q), r, atol=1e-12)


def test_expmap_at_zero_and_its_gradient():
    zero32 = jnp.zeros(3, jnp.float32)
    np.testing.assert_array_equal(quat_from_expmap(zero32), [1, 0, 0, 0])
    np.testing.assert_array_equal(quat_from_expmap(np.zeros(3)), [1, 0, 0, 0])
    # d/dr [cos(|r|/2), sin(|r|/2) r/|r|] at r = 0 is [0; I/2].
    for jacobian in (jax.jacfwd, jax.jacrev):
        jac = jax.jit(jacobian(quat_from_expmap))(zero32)
        np.testing.assert_allclose(jac, np.vstack([np.zeros((1, 3)), 0.5 * np.eye(3)]), atol=1e-7)
    # The inverse map is differentiable at the identity too (Jacobian [0 | 2I]).
    jac_log = jax.jit(jax.jacfwd(quat_to_expmap))(jnp.array([1.0, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(jac_log, np.hstack([np.zeros((3, 1)), 2 * np.eye(3)]), atol=1e-6)


def test_expmap_float32_is_continuous_across_series_switch():
    # Angles just below and just above the switch at θ² = 1e-8 agree with the closed form.
    axis = np.array([0.6, 0.0, 0.8])
    theta = np.array([0.9999e-4, 1e-4, 1.0001e-4, 3e-4], np.float32)
    r = jnp.asarray(axis[None] * theta[:, None], jnp.float32)
    expect = np.concatenate([np.cos(theta[:, None] / 2), np.sin(theta[:, None] / 2) * axis], -1)
    np.testing.assert_allclose(quat_from_expmap(r), expect, atol=1e-7, rtol=0)  # float32 eps


# ---------------------------------------------------------------------------------------------
# Transformations: jit == eager, vmap == Python loop
# ---------------------------------------------------------------------------------------------


def test_jit_equals_eager():
    a = jnp.asarray(random_quats(23, 16), jnp.float32)
    b = jnp.asarray(random_quats(24, 16), jnp.float32)
    t = jnp.linspace(0.0, 1.0, 16, dtype=jnp.float32)
    m = quat_to_matrix(a)
    # Same float32 operations; XLA may fuse or reorder them, so allow a few ulps.
    for fn, args in [
        (quat_mul, (a, b)),
        (quat_slerp, (a, b, t)),
        (quat_from_matrix, (m,)),
        (quat_to_expmap, (a,)),
        (lambda q: quat_to_euler(q, "ZXY"), (a,)),
    ]:
        np.testing.assert_allclose(jax.jit(fn)(*args), fn(*args), atol=1e-6, rtol=0)


def test_vmap_equals_loop():
    a = jnp.asarray(random_quats(25, 8), jnp.float32)
    b = jnp.asarray(random_quats(26, 8), jnp.float32)
    t = jnp.linspace(0.0, 1.0, 8, dtype=jnp.float32)
    r = jnp.asarray(np.random.default_rng(27).normal(size=(8, 3)), jnp.float32)
    # The loop calls the unbatched function (jitted once, so the loop is quick) per element.
    for fn, args in [
        (quat_slerp, (a, b, t)),
        (quat_from_expmap, (r,)),
        (lambda q: quat_to_euler(q, "XZY"), (a,)),
        (quat_angle, (a, b)),
    ]:
        single = jax.jit(fn)
        looped = jnp.stack([single(*(x[i] for x in args)) for i in range(8)])
        np.testing.assert_allclose(jax.vmap(fn)(*args), looped, atol=1e-6, rtol=0)  # a few ulps
