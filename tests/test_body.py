"""Skinned bodies (issue 20): the shipped body, binding to skeletons by name, per-level weights
and linear-blend skinning against a 4×4-matrix oracle."""

from __future__ import annotations

import itertools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jcrowd import load_default_model
from jcrowd.errors import SkinError, StoreError
from jcrowd.io.body_file import load_body, save_body
from jcrowd.io.resources import body_path
from jcrowd.motion.body import (
    Body,
    BodyMesh,
    bind_body,
    map_bones,
)
from jcrowd.motion.body import _monotone_pairs as monotone_pairs
from jcrowd.motion.rotation import quat_from_expmap, quat_from_matrix
from jcrowd.motion.skeleton import Skeleton, forward_kinematics, rest_positions
from jcrowd.motion.skinning import (
    frames_from_points,
    level_skin,
    rest_offsets,
    skin,
)

RNG = np.random.default_rng(20)


@pytest.fixture(scope="module")
def body() -> Body:
    return load_body(body_path())


@pytest.fixture(scope="module")
def skeleton() -> Skeleton:
    return load_default_model().skeleton


def _rig_skeleton(body: Body) -> Skeleton:
    """The rig itself as a skeleton (joints at the bones' heads)."""
    heads = np.asarray(body.heads, np.float64)
    off = np.array([heads[b] - (heads[p] if p >= 0 else 0.0) for b, p in enumerate(body.parents)])
    return Skeleton(body.bones, body.parents, off.astype(np.float32))


# -- matrix oracle (shares nothing with skin: 4×4 homogeneous transforms, recursive) ----------


def _mat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _global_matrices(sk: Skeleton, local: np.ndarray, root: np.ndarray, h: float) -> np.ndarray:
    """``(J, 4, 4)`` world transforms by recursion over parents, offsets scaled by ``h``."""
    off = np.asarray(sk.offsets, np.float64) * h
    g = np.zeros((sk.num_joints, 4, 4))
    for j, p in enumerate(sk.parents):
        t = np.eye(4)
        t[:3, :3] = _mat(local[j])
        t[:3, 3] = off[j] + (root if p < 0 else 0.0)
        g[j] = t if p < 0 else g[p] @ t
    return g


def _oracle_skin(mesh: BodyMesh, sk: Skeleton, local: np.ndarray, root: np.ndarray, h: float):
    """``Σ_k w_k G_k G_k,rest⁻¹ (h v)``, one vertex at a time."""
    g = _global_matrices(sk, local, root, h)
    rest = _global_matrices(sk, np.tile([1.0, 0, 0, 0], (sk.num_joints, 1)), np.zeros(3), h)
    out = np.zeros((len(mesh.vertices), 3))
    for i, (v, ids, ws) in enumerate(zip(mesh.vertices, mesh.bones, mesh.weights, strict=True)):
        hv = np.append(h * np.asarray(v, np.float64), 1.0)
        for j, w in zip(ids, ws, strict=True):
            out[i] += w * (g[j] @ np.linalg.solve(rest[j], hv))[:3]
    return out


def _random_pose(sk: Skeleton, scale: float = 0.6) -> np.ndarray:
    e = RNG.normal(scale=scale, size=(sk.num_joints, 3))
    return np.asarray(quat_from_expmap(e.astype(np.float64)))


# -- the shipped asset ------------------------------------------------------------------------


def test_shipped_body_has_five_resolutions_with_valid_weights(body: Body) -> None:
    counts = [len(m.vertices) for m in body.meshes]
    assert counts == [12272, 1229, 615, 369, 152]  # the four and a far one
    for m in body.meshes:
        np.testing.assert_allclose(m.weights.sum(axis=1), 1.0, atol=1e-6)
        assert (m.weights >= 0).all() and m.bones.max() < len(body.bones)
        assert np.isfinite(m.vertices).all() and m.triangles.max() < len(m.vertices)
        np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-5)  # glTF
        assert len(np.unique(m.triangles)) == len(m.vertices)  # no stray vertices
    # Soles on the ground, 1.6–1.8 m tall, facing +z (the nose is in front of the ears).
    v = body.meshes[0].vertices
    assert abs(v[:, 1].min()) < 1e-3 and 1.6 < v[:, 1].max() < 1.8
    head = body.meshes[0].bones[:, 0] == body.bones.index("Head")
    assert v[head, 2].max() > -v[head, 2].min()


def test_body_file_round_trip_and_rejects_bad_weights(tmp_path, body: Body) -> None:
    m = body.meshes[-1]
    mesh = {
        "vertices": m.vertices,
        "normals": m.normals,
        "triangles": m.triangles,
        "bones": m.bones.astype(np.uint8),
        "weights": m.weights,
    }
    meta = {"bones": list(body.bones), "parents": list(body.parents)}
    path = tmp_path / "b.jcb"
    save_body(path, [mesh], body.heads, body.tails, meta)
    back = load_body(path)
    assert back.bones == body.bones and np.array_equal(back.meshes[0].vertices, m.vertices)
    save_body(path, [{**mesh, "weights": m.weights * 0.5}], body.heads, body.tails, meta)
    with pytest.raises(StoreError, match="sum to 1"):
        load_body(path)


# -- names ------------------------------------------------------------------------------------


def test_monotone_pairs_is_the_cheapest_order_keeping_pairing() -> None:
    for _ in range(40):
        m, n = RNG.integers(1, 5, size=2)
        cost = RNG.random((m, n))
        k = min(m, n)
        best = min(
            sum(cost[r, c] for r, c in zip(rows, cols, strict=True))
            for rows in itertools.combinations(range(m), k)
            for cols in itertools.combinations(range(n), k)
        )
        pairs = monotone_pairs(cost)
        assert len(pairs) == k
        assert all(a[0] < b[0] and a[1] < b[1] for a, b in itertools.pairwise(pairs))
        assert sum(cost[r, c] for r, c in pairs) == pytest.approx(best)


def test_the_rig_maps_onto_itself(body: Body) -> None:
    assert map_bones(body, _rig_skeleton(body)).tolist() == list(range(len(body.bones)))


def test_asf_names_map_by_part_and_position(body: Body, skeleton: Skeleton) -> None:
    jb = map_bones(body, skeleton)
    got = {body.bones[b]: skeleton.names[j] for b, j in enumerate(jb) if j >= 0}
    # thorax sits 11 cm above the pelvis, where the rig's lowest spine bone starts; lhand at
    # the wrist, the rig's LeftHand.
    assert got["LowerBack"] == "thorax" and got["LeftHand"] == "lhand"
    assert got["LeftUpLeg"] == "lfemur" and got["RightLeg"] == "rtibia"
    # cmu16's head joint sits in the neck (its End Site 5 cm above): it takes a neck bone.
    assert "head" in (got.get("Neck"), got.get("Neck1"))
    assert "Spine1" not in got and "Head" not in got and "LeftFingerBase" not in got
    # Every bound pair on the same side of the body.
    rest = rest_positions(skeleton)[0]
    for b, j in enumerate(jb):
        if j >= 0 and min(abs(body.heads[b, 0]), abs(rest[j, 0])) > 0.02:
            assert np.sign(rest[j, 0]) == np.sign(body.heads[b, 0]), body.bones[b]


def test_mixamo_and_unreal_names_map(body: Body) -> None:
    rig = _rig_skeleton(body)
    renames = {
        "Hips": "mixamorig:Hips",
        "LeftUpLeg": "mixamorig:LeftUpLeg",
        "RightUpLeg": "thigh_r",
        "RightLeg": "calf_r",
        "RightFoot": "foot_r",
        "LeftArm": "upperarm_l",
    }
    sk = Skeleton(tuple(renames.get(n, n) for n in rig.names), rig.parents, rig.offsets)
    assert map_bones(body, sk).tolist() == list(range(len(body.bones)))


def test_unknown_names_raise_naming_the_missing_parts(body: Body) -> None:
    rig = _rig_skeleton(body)
    sk = Skeleton(
        tuple("Hips" if n == "Hips" else f"Bone{k:03d}" for k, n in enumerate(rig.names)),
        rig.parents,
        rig.offsets,
    )
    with pytest.raises(SkinError, match=r"left_thigh.*Bone001"):
        map_bones(body, sk)


# -- binding ----------------------------------------------------------------------------------


def test_binding_to_its_own_rig_only_scales(body: Body) -> None:
    """The rig as the skeleton: every bone's map is the identity up to the 1 m normalisation,
    so the bound vertices are the rig's divided by its joints' height (float32: 1e-6 m)."""
    rig = _rig_skeleton(body)
    joints, _ = rest_positions(rig)
    height = joints[:, 1].max() - joints[:, 1].min()
    bound = bind_body(body, rig)
    for m0, m1 in zip(body.meshes, bound.meshes, strict=True):
        np.testing.assert_allclose(m1.vertices, m0.vertices / height, atol=1e-6)
        np.testing.assert_allclose(m1.weights.sum(axis=1), 1.0, atol=1e-6)


def test_bound_rest_mesh_keeps_its_surface(body: Body, skeleton: Skeleton) -> None:
    """Bound to the default model's 19-joint skeleton (arms down where the rig's are 45° out),
    edges keep their length ÷ s within [0.6, 2.0] from the 1st to the 99th percentile
    (measured 0.68–0.80 and 1.75–1.88); a wrong scale, a mirrored or swapped limb, or bones
    anchored at the wrong joints moves whole regions and the percentiles with them. The
    armpits alone stretch more (an arm turned 45° by linear blending)."""
    bound = bind_body(body, skeleton)
    for m0, m1 in zip(body.meshes, bound.meshes, strict=True):
        tri = m0.triangles
        ratios = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            e0 = np.linalg.norm(m0.vertices[tri[:, a]] - m0.vertices[tri[:, b]], axis=1)
            e1 = np.linalg.norm(m1.vertices[tri[:, a]] - m1.vertices[tri[:, b]], axis=1)
            ratios.append(e1 / (bound.scale * np.maximum(e0, 1e-9)))
        lo, hi = np.percentile(np.concatenate(ratios), [1, 99])
        assert 0.6 < lo and hi < 2.0


def test_rest_pose_skins_to_the_rest_vertices(body: Body, skeleton: Skeleton) -> None:
    """Every joint at its bind pose (identity rotations, FK positions): the rest vertices ×
    height, to 1e-5 m (the issue's bound; float32 vertices)."""
    bound = bind_body(body, skeleton)
    h = 1.7
    ident = np.tile([1.0, 0.0, 0.0, 0.0], (skeleton.num_joints, 1))
    rot, pos = forward_kinematics(skeleton.scaled(h), ident, np.zeros(3))
    for mesh in bound.meshes:
        got = skin(mesh.bones, mesh.weights, rest_offsets(mesh, bound.rest), rot, pos, h)
        np.testing.assert_allclose(got, h * mesh.vertices.astype(np.float64), atol=1e-5)


def test_skin_matches_the_matrix_oracle(body: Body, skeleton: Skeleton) -> None:
    """A random pose, the coarsest mesh: quaternion LBS against 4×4 matrices per vertex (float64:
    agreement to 1e-9 m up to float32 offsets, so 1e-6)."""
    bound = bind_body(body, skeleton)
    mesh, h = bound.meshes[-1], 1.62
    local = _random_pose(skeleton)
    root = np.array([3.0, 0.9, -2.0])
    rot, pos = forward_kinematics(skeleton.scaled(h), local, root)
    got = skin(mesh.bones, mesh.weights, rest_offsets(mesh, bound.rest), rot, pos, h)
    want = _oracle_skin(mesh, skeleton, local, root, h)
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_a_vertex_on_one_bone_moves_rigidly_with_it(body: Body, skeleton: Skeleton) -> None:
    """Vertices weighted 100 % to one joint keep their distances to that joint's frame points
    (its position and the tips of its frame axes) in every pose: the joint's FK transform."""
    bound = bind_body(body, skeleton)
    mesh = bound.meshes[1]
    single = mesh.weights[:, 0] > 1 - 1e-6
    assert single.sum() > 100
    h = 1.0
    ident = np.tile([1.0, 0.0, 0.0, 0.0], (skeleton.num_joints, 1))
    offs = rest_offsets(mesh, bound.rest)
    r0, p0 = forward_kinematics(skeleton, ident, np.zeros(3))
    v0 = skin(mesh.bones, mesh.weights, offs, r0, p0, h)
    local = _random_pose(skeleton, 0.9)
    g = _global_matrices(skeleton, local, np.array([1.0, 0.0, 0.5]), h)
    r1, p1 = forward_kinematics(skeleton, local, np.array([1.0, 0.0, 0.5]))
    v1 = skin(mesh.bones, mesh.weights, offs, r1, p1, h)
    for i in np.flatnonzero(single)[::7]:
        j = mesh.bones[i, 0]
        want = g[j] @ np.append(v0[i] - bound.rest[j], 1.0)
        np.testing.assert_allclose(v1[i], want[:3], atol=1e-6)


def test_level_skin_follows_dropped_joints_where_the_level_places_them(
    body: Body, skeleton: Skeleton
) -> None:
    """Keep some joints, freeze the rest at fixed rotations: skinning at the level with only the
    kept joints' frames equals full-detail skinning of the full pose (1e-6 m), and no weight
    falls on a dropped joint."""
    bound = bind_body(body, skeleton)
    mesh = bound.meshes[2]
    names = skeleton.names
    kept = [j for j, n in enumerate(names) if n in ("pelvis", "lfemur", "rfemur", "thorax", "head")]
    kept_set = set(kept)
    frozen = _random_pose(skeleton, 0.3)
    local = frozen.copy()
    live = _random_pose(skeleton, 0.7)
    local[kept] = live[kept]
    root = np.array([0.2, 0.95, 0.1])
    rot, pos = forward_kinematics(skeleton, local, root)
    full = skin(mesh.bones, mesh.weights, rest_offsets(mesh, bound.rest), rot, pos, 1.0)
    # The level: anchors, and each joint's frame in its anchor's (depends on frozen joints only).
    anchor = np.zeros(skeleton.num_joints, np.int64)
    f_rot = np.zeros((skeleton.num_joints, 4))
    f_pos = np.zeros((skeleton.num_joints, 3))
    frot, fpos = forward_kinematics(skeleton, frozen, np.zeros(3))  # any kept rotations do
    for j in range(skeleton.num_joints):
        a = j
        while a not in kept_set:
            a = skeleton.parents[a]
        anchor[j] = kept.index(a)
        ra = _mat(np.asarray(frot[a]))
        rel = ra.T @ _mat(np.asarray(frot[j]))
        f_pos[j] = ra.T @ (np.asarray(fpos[j]) - np.asarray(fpos[a]))
        f_rot[j] = quat_from_matrix(rel)
    ids, ws, offs = level_skin(mesh, bound.rest, anchor, f_rot, f_pos)
    assert ids.max() < len(kept)
    np.testing.assert_allclose(ws.sum(axis=1), 1.0, atol=1e-6)
    got = skin(ids, ws, offs, np.asarray(rot)[kept], np.asarray(pos)[kept], 1.0)
    np.testing.assert_allclose(got, full, atol=1e-5)


def test_skin_jit_equals_eager_and_vmap_equals_loop(body: Body, skeleton: Skeleton) -> None:
    """float32 on device: jit and eager agree to 1e-6 m, vmap over agents matches a loop
    exactly up to float32 rounding (1e-6)."""
    bound = bind_body(body, skeleton)
    mesh = bound.meshes[-1]
    offs = rest_offsets(mesh, bound.rest)
    poses = [_random_pose(skeleton).astype(np.float32) for _ in range(3)]
    frames = [forward_kinematics(skeleton, jnp.asarray(q), jnp.zeros(3)) for q in poses]
    rots = jnp.stack([f[0] for f in frames])
    poss = jnp.stack([f[1] for f in frames])
    hs = jnp.asarray([1.5, 1.7, 1.9], jnp.float32)

    def one(r, p, h):
        return skin(mesh.bones, mesh.weights, offs, r, p, h)

    eager = [one(rots[i], poss[i], hs[i]) for i in range(3)]
    jitted = jax.jit(one)
    batched = jax.vmap(one)(rots, poss, hs)
    for i in range(3):
        np.testing.assert_allclose(jitted(rots[i], poss[i], hs[i]), eager[i], atol=1e-6)
        np.testing.assert_allclose(batched[i], eager[i], atol=1e-6)


def test_skin_commutes_with_a_rigid_motion_of_the_whole_body(
    body: Body, skeleton: Skeleton
) -> None:
    bound = bind_body(body, skeleton)
    mesh = bound.meshes[-1]
    offs = rest_offsets(mesh, bound.rest)
    local = _random_pose(skeleton)
    rot, pos = forward_kinematics(skeleton, local, np.zeros(3))
    q = np.asarray(quat_from_expmap(np.array([0.3, -1.1, 0.4])))
    t = np.array([4.0, 0.5, -7.0])
    moved_rot, moved_pos = forward_kinematics(
        skeleton, np.concatenate([_qmul(q, local[:1]), local[1:]]), t
    )
    a = skin(mesh.bones, mesh.weights, offs, rot, pos, 1.0)
    b = skin(mesh.bones, mesh.weights, offs, moved_rot, moved_pos, 1.0)
    o0 = np.asarray(skeleton.offsets[0], np.float64)  # the root sits at root_position + o0
    np.testing.assert_allclose(b, (a - o0) @ _mat(q).T + o0 + t, atol=1e-6)


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b[0]
    return np.array(
        [
            [
                w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            ]
        ]
    )


# -- frames from the step's points --------------------------------------------------------------


def test_frames_from_points_recover_the_level_fk(body: Body) -> None:
    """At the coarsest and the finest level: a pose whose joints do not twist about a lone
    bone (deviations from the reference perpendicular to it) is recovered exactly from the
    points the level places — rotations to 1e-4 (float32 points), and the skin on the recovered
    frames equals the skin on the FK's own to 1e-5 m."""
    from jcrowd.crowd.bodies import skinned_levels
    from jcrowd.crowd.synthesis import build_decoders, level_points
    from jcrowd.motion.rotation import quat_mul, yaw_quat

    model = load_default_model()
    bound = bind_body(body, model.skeleton)
    dec = build_decoders(model)
    levels = skinned_levels(model, bound, decoders=dec)
    for lv in (0, len(levels) - 1):
        sl, ld = levels[lv], dec.levels[lv]
        kk = len(sl.kept)
        e = RNG.normal(scale=0.4, size=(kk, 3))
        for k in range(kk):
            o = sl.ref_offsets[k][sl.ref_points[k] >= 0]
            if len(o) and np.linalg.matrix_rank(o, tol=1e-4) == 1:
                axis = o[np.argmax(np.linalg.norm(o, axis=1))] / np.linalg.norm(o).max()
                axis = axis / np.linalg.norm(axis)
                e[k] -= (e[k] @ axis) * axis
        y = np.zeros(ld.u_pose.shape[0], np.float32)
        y[0] = 0.55
        y[4:7] = e[0]
        y[7 : 7 + 3 * (kk - 1)] = e[1:].ravel()
        heading, h = 0.7, 1.74
        pts = np.asarray(level_points(ld, jnp.asarray(y), jnp.asarray([2.0, -1.0]), heading, h))
        root = quat_mul(np.asarray(yaw_quat(heading)), np.asarray(quat_from_expmap(e[0])))
        local = np.concatenate(
            [
                root[None],
                np.asarray(quat_mul(np.asarray(ld.local_ref[1:]), quat_from_expmap(e[1:]))),
            ]
        )
        want_rot, _ = forward_kinematics(
            ld.skeleton, jnp.asarray(local, jnp.float32), jnp.zeros(3, jnp.float32)
        )
        want_rot = np.asarray(want_rot, np.float64)
        rot, pos = frames_from_points(sl, pts[None], np.array([h]))
        for k in range(kk):
            np.testing.assert_allclose(rot[0, k], _mat(want_rot[k]), atol=1e-4)
        np.testing.assert_allclose(pos[0], pts[sl.kept], atol=0)
        want_q = np.asarray(want_rot)[None]
        sm = sl.meshes[-1]
        got = skin(sm.bones, sm.weights, sm.offsets, _to_quat(rot), pos, h)
        ref = skin(sm.bones, sm.weights, sm.offsets, want_q, pos, h)
        np.testing.assert_allclose(got, ref, atol=1e-5)


def _to_quat(rot: np.ndarray) -> np.ndarray:
    return np.asarray(quat_from_matrix(rot))


@pytest.mark.parametrize("folder", ["cmu_dir", "cmu16_dir"])
def test_fitted_rig_joints_sit_on_the_shared_skeletons(
    body: Body, folder: str, request: pytest.FixtureRequest
) -> None:
    """Bound to the shared captures' skeletons (31 and 19 joints): every mapped joint of the
    fitted rig lies within 2 cm of the skeleton's rest joint at the capture's own scale (each
    bone's map anchors its rig joint there, so this checks the mapping and the fit end to end
    on real skeletons), the body stands on the skeleton's feet (its soles 0–8 cm below the
    lowest joint, a toe joint above the sole: measured 4.8 cm on cmu, 7.6 cm on cmu16), and
    left bones map to joints other than their right twins'."""
    from jcrowd.io.bvh import load_bvh
    from jcrowd.motion import character_height, rest_forward

    path = sorted(Path(request.getfixturevalue(folder)).rglob("*.bvh"))[0]
    skeleton = load_bvh(path).motion.skeleton
    height = character_height(skeleton)
    bound = bind_body(body, skeleton, rest_forward(skeleton))
    jb = bound.joint_of_bone
    mapped = jb >= 0
    assert mapped.sum() >= 16
    assert bound.fitted is not None
    gap = np.linalg.norm(bound.fitted[mapped] - bound.rest[jb[mapped]], axis=1) * height
    assert gap.max() < 0.02
    sole = bound.meshes[1].vertices[:, 1].min()
    lowest = bound.rest[:, 1].min()
    assert -0.08 < (sole - lowest) * height < 0.02
    names = skeleton.names
    for b, j in enumerate(jb):
        if j >= 0 and body.bones[b].startswith("Left"):
            right = jb[body.bones.index("Right" + body.bones[b][4:])]
            assert right >= 0 and names[right] != names[j]
