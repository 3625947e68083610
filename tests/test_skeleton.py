"""Tests for jcrowd.motion.skeleton: forward kinematics against a slow per-joint loop, and Skeleton
checks.

The oracle builds 3×3 matrices with SciPy and walks the joints one by one in float64:
``G_j = G_parent L_j`` and ``p_j = p_parent + G_parent o_j``. The library instead works one tree
depth at a time on quaternions, so agreement checks both the schedule and the algebra.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jcrowd.errors import SkeletonError
from jcrowd.motion import (
    Skeleton,
    bone_lengths,
    end_site_positions,
    forward_kinematics,
    joint_bone_lengths,
    rest_positions,
)

TOL64 = 1e-12  # float64 NumPy FK vs float64 loop: rounding over a chain of ≤ 12 products
TOL32 = 1e-5  # float32 FK vs float64 loop: positions of a few metres, chains ≤ 8 deep


# Jitted entry points for the float32 tests: eager JAX compiles every primitive for every new
# shape (seconds per FK call), one jit compiles the whole FK once per shape (~0.5 s).
fk_jit = eqx.filter_jit(forward_kinematics)
ends_jit = eqx.filter_jit(end_site_positions)


def random_skeleton(parents, seed: int, n_end: int = 0) -> Skeleton:
    """A skeleton on the given tree with random offsets (0.05–0.5 m bones) and End Sites."""
    rng = np.random.default_rng(seed)
    j = len(parents)
    offsets = rng.normal(size=(j, 3))
    offsets *= rng.uniform(0.05, 0.5, size=(j, 1)) / np.linalg.norm(offsets, axis=-1, keepdims=True)
    end_parents = tuple(int(p) for p in rng.integers(0, j, size=n_end))
    end_offsets = rng.normal(size=(n_end, 3)) * 0.1
    return Skeleton(
        tuple(f"j{i}" for i in range(j)), tuple(parents), offsets, end_parents, end_offsets
    )


def random_quats(seed: int, shape) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(*shape, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def fk_loop(skeleton: Skeleton, quats, root) -> tuple[np.ndarray, np.ndarray]:
    """Slow oracle: one pose, joint by joint, 3×3 matrices in float64. Returns (J,3,3), (J,3)."""
    quats, root = np.asarray(quats, np.float64), np.asarray(root, np.float64)
    offsets = np.asarray(skeleton.offsets, np.float64)
    local = Rotation.from_quat(quats, scalar_first=True).as_matrix()
    glob = np.zeros((skeleton.num_joints, 3, 3))
    pos = np.zeros((skeleton.num_joints, 3))
    for j, p in enumerate(skeleton.parents):
        if p < 0:
            glob[j], pos[j] = local[j], root + offsets[j]
        else:
            glob[j] = glob[p] @ local[j]
            pos[j] = pos[p] + glob[p] @ offsets[j]
    return glob, pos


def end_sites_loop(skeleton: Skeleton, glob, pos) -> np.ndarray:
    eo = np.asarray(skeleton.end_offsets_or_empty(), np.float64)
    return np.array([pos[p] + glob[p] @ eo[e] for e, p in enumerate(skeleton.end_parents)]).reshape(
        -1, 3
    )


def as_matrices(q) -> np.ndarray:
    return Rotation.from_quat(
        np.asarray(q, np.float64).reshape(-1, 4), scalar_first=True
    ).as_matrix()


# A branching tree like a mocap skeleton: hips with two legs and a spine that forks into
# neck and two arms; depths 0..5.
BRANCHY = (-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 12, 11, 14, 15, 11, 17, 18)

# Tree shapes for hypothesis: each joint's parent is any earlier joint.
trees = st.integers(1, 12).flatmap(
    lambda n: st.tuples(*[st.just(-1)] + [st.integers(0, j - 1) for j in range(1, n)])
)


# ---------------------------------------------------------------------------------------------
# Oracle
# ---------------------------------------------------------------------------------------------


@settings(max_examples=50, deadline=None)
@given(trees, st.integers(0, 2**31 - 1))
def test_fk_matches_per_joint_loop_on_random_trees(parents, seed):
    skel = random_skeleton(parents, seed, n_end=2)
    quats = random_quats(seed + 1, (3, len(parents)))
    roots = np.random.default_rng(seed + 2).normal(size=(3, 3))
    grot, gpos = forward_kinematics(skel, quats, roots)
    ends = end_site_positions(skel, grot, gpos)
    assert grot.shape == (3, len(parents), 4) and gpos.shape == (3, len(parents), 3)
    for f in range(3):
        glob, pos = fk_loop(skel, quats[f], roots[f])
        np.testing.assert_allclose(as_matrices(grot[f]), glob, atol=TOL64, rtol=0)
        np.testing.assert_allclose(gpos[f], pos, atol=TOL64, rtol=0)
        np.testing.assert_allclose(ends[f], end_sites_loop(skel, glob, pos), atol=TOL64, rtol=0)


def test_fk_float32_jax_matches_loop():
    skel = random_skeleton(BRANCHY, 0, n_end=4)
    skel32 = Skeleton(
        skel.names,
        skel.parents,
        jnp.asarray(skel.offsets, jnp.float32),
        skel.end_parents,
        skel.end_offsets,
    )
    quats = random_quats(1, (5, len(BRANCHY)))
    roots = np.random.default_rng(2).normal(size=(5, 3))
    grot, gpos = fk_jit(skel32, jnp.asarray(quats, jnp.float32), jnp.asarray(roots, jnp.float32))
    assert isinstance(gpos, jax.Array) and gpos.dtype == jnp.float32 and grot.dtype == jnp.float32
    ends = ends_jit(skel32, grot, gpos)
    assert isinstance(ends, jax.Array) and ends.dtype == jnp.float32
    for f in range(5):
        glob, pos = fk_loop(skel, quats[f], roots[f])
        np.testing.assert_allclose(as_matrices(grot[f]), glob, atol=TOL32, rtol=0)
        np.testing.assert_allclose(gpos[f], pos, atol=TOL32, rtol=0)
        np.testing.assert_allclose(ends[f], end_sites_loop(skel, glob, pos), atol=TOL32, rtol=0)


def test_fk_numpy_in_numpy_out():
    skel = random_skeleton(BRANCHY, 3)
    grot, gpos = forward_kinematics(skel, random_quats(4, (2, len(BRANCHY))), np.zeros((2, 3)))
    assert isinstance(grot, np.ndarray) and grot.dtype == np.float64
    assert isinstance(gpos, np.ndarray) and gpos.dtype == np.float64


def test_fk_of_a_root_only_skeleton():
    """One joint: no bones, the position is the root's plus its offset (NumPy and jax)."""
    skel = random_skeleton((-1,), 5)
    q, root = random_quats(6, (3, 1)), np.arange(9.0).reshape(3, 3)
    for rot, pos in (forward_kinematics(skel, q, root), fk_jit(skel, q, root)):
        np.testing.assert_allclose(np.asarray(rot), q, atol=1e-7)
        np.testing.assert_allclose(np.asarray(pos)[:, 0], root + skel.offsets[0], atol=1e-6)


def test_path_matrix_marks_each_joints_ancestors():
    """Row j of the path matrix sums the bones from the root to j: on a branchy tree, the 1s
    of row j are exactly j and its ancestors (the root excluded)."""
    skel = random_skeleton(BRANCHY, 7)
    a = skel.path_matrix
    for j in range(len(BRANCHY)):
        path, k = set(), j
        while k > 0:
            path.add(k)
            k = BRANCHY[k]
        assert set(np.flatnonzero(a[j]) + 1) == path


def test_rest_positions_match_loop_and_identity_fk():
    skel = random_skeleton(BRANCHY, 5, n_end=3)
    pos, ends = rest_positions(skel)
    glob, pos_loop = fk_loop(skel, np.tile([1.0, 0, 0, 0], (len(BRANCHY), 1)), np.zeros(3))
    np.testing.assert_allclose(pos, pos_loop, atol=TOL64, rtol=0)
    np.testing.assert_allclose(ends, end_sites_loop(skel, glob, pos_loop), atol=TOL64, rtol=0)
    # Closed form: a joint's rest position is the sum of the offsets on its path to the root.
    j = 16
    path = [16, 15, 14, 11, 10, 9, 0]
    assert [BRANCHY[a] for a in path[:-1]] == path[1:]
    np.testing.assert_allclose(pos[j], np.asarray(skel.offsets)[path].sum(0), atol=TOL64)
    assert pos.dtype == np.float64 and ends.shape == (3, 3)


def test_rest_positions_without_end_sites():
    skel = random_skeleton((-1, 0, 1), 6)
    pos, ends = rest_positions(skel)
    assert pos.shape == (3, 3) and ends.shape == (0, 3)


def test_bone_lengths_closed_form():
    skel = random_skeleton(BRANCHY, 7)
    expect = np.linalg.norm(np.asarray(skel.offsets), axis=-1)
    expect[0] = 0.0  # the root has no bone
    np.testing.assert_allclose(bone_lengths(skel), expect, atol=TOL64, rtol=0)
    pos, _ = rest_positions(skel)
    np.testing.assert_allclose(joint_bone_lengths(skel, pos), expect, atol=TOL64, rtol=0)


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------


def test_fk_keeps_bone_lengths_across_frames_float32():
    skel = random_skeleton(BRANCHY, 8)
    skel32 = Skeleton(skel.names, skel.parents, jnp.asarray(skel.offsets, jnp.float32))
    frames = 60
    quats = jnp.asarray(random_quats(9, (frames, len(BRANCHY))), jnp.float32)
    roots = jnp.asarray(np.random.default_rng(10).normal(size=(frames, 3)) * 5, jnp.float32)
    _, gpos = fk_jit(skel32, quats, roots)
    lengths = joint_bone_lengths(skel32, gpos)
    assert lengths.shape == (frames, len(BRANCHY))
    # 1e-5 m: float32 positions up to ~10 m from the origin carry ~1e-6 m rounding each.
    np.testing.assert_allclose(
        lengths, jnp.broadcast_to(bone_lengths(skel32), lengths.shape), atol=1e-5
    )


@settings(max_examples=50, deadline=None)
@given(trees)
def test_depth_groups_cover_every_joint_once(parents):
    skel = random_skeleton(parents, 0)
    groups = skel.depth_groups
    flat = np.concatenate(groups)
    np.testing.assert_array_equal(np.sort(flat), np.arange(len(parents)))
    np.testing.assert_array_equal(groups[0], [0])
    for d, group in enumerate(groups[1:], start=1):
        assert len(group) > 0
        # Every parent of a depth-d joint is at depth d-1: the FK schedule is valid.
        assert set(np.asarray(parents)[group]) <= set(groups[d - 1].tolist())
    np.testing.assert_array_equal(
        skel.depths[flat], np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    )


def test_children_index_and_scaled():
    skel = random_skeleton(BRANCHY, 11, n_end=2)
    assert skel.num_joints == len(BRANCHY)
    assert skel.children(11) == (12, 14, 17)
    assert skel.children(4) == ()
    assert skel.index("j7") == 7
    with pytest.raises(SkeletonError, match="joint named 'nope'"):
        skel.index("nope")
    big = skel.scaled(2.0)
    np.testing.assert_allclose(big.offsets, 2.0 * np.asarray(skel.offsets))
    np.testing.assert_allclose(big.end_offsets, 2.0 * np.asarray(skel.end_offsets))
    assert big.names == skel.names and big.parents == skel.parents


# ---------------------------------------------------------------------------------------------
# Transformations: batching, jit == eager, vmap == loop
# ---------------------------------------------------------------------------------------------


def _skel32(parents=BRANCHY, seed=12, n_end=3):
    skel = random_skeleton(parents, seed, n_end=n_end)
    return Skeleton(
        skel.names,
        skel.parents,
        jnp.asarray(skel.offsets, jnp.float32),
        skel.end_parents,
        jnp.asarray(skel.end_offsets, jnp.float32),
    )


def test_fk_batched_over_extra_leading_axes():
    skel = _skel32()
    j = skel.num_joints
    quats = jnp.asarray(random_quats(13, (2, 3, 4, j)), jnp.float32)
    roots = jnp.asarray(np.random.default_rng(14).normal(size=(2, 3, 4, 3)), jnp.float32)
    grot, gpos = fk_jit(skel, quats, roots)
    assert grot.shape == (2, 3, 4, j, 4) and gpos.shape == (2, 3, 4, j, 3)
    ends = ends_jit(skel, grot, gpos)
    assert ends.shape == (2, 3, 4, 3, 3)
    # Each pose equals the float64 NumPy FK of that pose alone (no batch axis at all).
    skel64 = Skeleton(skel.names, skel.parents, np.asarray(skel.offsets, np.float64))
    q64, r64 = np.asarray(quats, np.float64), np.asarray(roots, np.float64)
    for idx in np.ndindex(2, 3, 4):
        one_rot, one_pos = forward_kinematics(skel64, q64[idx], r64[idx])
        np.testing.assert_allclose(gpos[idx], one_pos, atol=TOL32, rtol=0)
        g = np.asarray(grot[idx], np.float64)
        assert np.minimum(np.abs(g - one_rot).max(-1), np.abs(g + one_rot).max(-1)).max() < TOL32


def test_fk_jit_equals_eager_and_compiles_once():
    skel = _skel32()
    quats = jnp.asarray(random_quats(15, (6, skel.num_joints)), jnp.float32)
    roots = jnp.asarray(np.random.default_rng(16).normal(size=(6, 3)), jnp.float32)

    @eqx.debug.assert_max_traces(max_traces=1)
    def fk_and_ends(skeleton, q, r):
        grot, gpos = forward_kinematics(skeleton, q, r)
        return grot, gpos, end_site_positions(skeleton, grot, gpos)

    fast = eqx.filter_jit(fk_and_ends)
    eager = fk_and_ends.__wrapped__(skel, quats, roots)
    for _ in range(2):  # a second call with new values must not retrace
        jitted = fast(skel, quats, roots)
        for a, b in zip(jitted, eager, strict=True):
            np.testing.assert_allclose(a, b, atol=1e-6, rtol=0)  # XLA fusion: a few ulps
        roots = roots + 1.0
        eager = fk_and_ends.__wrapped__(skel, quats, roots)


def test_fk_vmap_over_frames_equals_loop():
    skel = _skel32()
    quats = jnp.asarray(random_quats(17, (5, skel.num_joints)), jnp.float32)
    roots = jnp.asarray(np.random.default_rng(18).normal(size=(5, 3)), jnp.float32)

    def pose(q, r):
        return forward_kinematics(skel, q, r)

    grot, gpos = jax.jit(jax.vmap(pose))(quats, roots)
    single = jax.jit(pose)
    for f in range(5):
        r_f, p_f = single(quats[f], roots[f])
        np.testing.assert_allclose(grot[f], r_f, atol=1e-6, rtol=0)  # a few float32 ulps
        np.testing.assert_allclose(gpos[f], p_f, atol=1e-6, rtol=0)


def test_fk_gradient_is_finite():
    # FK sits inside fitted losses (simplify): its gradient w.r.t. offsets and rotations exists.
    skel = _skel32()
    quats = jnp.asarray(random_quats(19, (skel.num_joints,)), jnp.float32)

    def loss(offsets, q):
        s = Skeleton(skel.names, skel.parents, offsets)
        return jnp.sum(forward_kinematics(s, q, jnp.zeros(3, jnp.float32))[1] ** 2)

    g_off, g_q = jax.jit(jax.grad(loss, argnums=(0, 1)))(skel.offsets, quats)
    assert np.isfinite(g_off).all() and np.isfinite(g_q).all()
    # Check one offset component against a central difference in float64 (oracle loop).
    off64, q64 = np.asarray(skel.offsets, np.float64), np.asarray(quats, np.float64)

    def loss64(off):
        s = Skeleton(skel.names, skel.parents, off)
        return float(np.sum(fk_loop(s, q64, np.zeros(3))[1] ** 2))

    h = 1e-6
    bump = np.zeros_like(off64)
    bump[7, 1] = h
    numeric = (loss64(off64 + bump) - loss64(off64 - bump)) / (2 * h)
    assert abs(g_off[7, 1] - numeric) < 1e-3 * max(1.0, abs(numeric))  # float32 gradient


# ---------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("names", "parents", "offsets", "match"),
    [
        ((), (), np.zeros((0, 3)), "at least one joint"),
        (("a", "b", "a"), (-1, 0, 1), np.zeros((3, 3)), r"duplicates \['a'\]"),
        (("a", "b", "c"), (-1, 0, -1), np.zeros((3, 3)), "second at joint 2"),
        (("a", "b", "c"), (0, -1, 1), np.zeros((3, 3)), "joint 0 to be the root"),
        (("a", "b", "c"), (-1, 2, 0), np.zeros((3, 3)), "parent before child"),
        (("a", "b", "c"), (-1, 0, 2), np.zeros((3, 3)), "parent before child"),
        (("a", "b"), (-1, 0, 1), np.zeros((2, 3)), "one parent per joint"),
        (("a", "b"), (-1, 0), np.zeros((2, 2)), r"offsets of shape \(2, 3\)"),
        (("a", "b"), (-1, 0), np.zeros((3, 3)), r"offsets of shape \(2, 3\)"),
    ],
)
def test_invalid_skeleton_raises(names, parents, offsets, match):
    with pytest.raises(SkeletonError, match=match):
        Skeleton(names, parents, offsets)


def test_invalid_end_sites_raise():
    with pytest.raises(SkeletonError, match="End Site 0 has parent 5"):
        Skeleton(("a", "b"), (-1, 0), np.zeros((2, 3)), (5,), np.zeros((1, 3)))
    with pytest.raises(SkeletonError, match=r"end_offsets of shape \(1, 3\)"):
        Skeleton(("a", "b"), (-1, 0), np.zeros((2, 3)), (1,), np.zeros((2, 3)))


def test_skeleton_error_is_a_value_error():
    with pytest.raises(ValueError):
        Skeleton(("a", "a"), (-1, 0), np.zeros((2, 3)))
