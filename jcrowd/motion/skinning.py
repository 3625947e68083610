"""Linear-blend skinning of a bound body (:mod:`jcrowd.motion.body`), its weights per level of
detail, and each kept joint's frame found in the points the crowd step places.

**Skinning** (:func:`skin`): ``v' = Σ_k w_k (R_k h l_k + p_k)`` over a vertex's four joints,
with ``R_k, p_k`` the joint's global rotation and position (the step's FK, metres), ``h`` the
agent's height (the motion model's skeleton is 1 m tall, :mod:`jcrowd.crowd.synthesis`) and
``l_k`` the vertex in the joint's frame for a 1 m skeleton: at full detail ``v − p̄_k`` with
``p̄_k`` the joint's rest position (:func:`rest_offsets`), so at the rest pose (``R = I``,
``p = h p̄``) skinning returns ``h`` times the rest vertices.

**Levels** (003 §5.1; :func:`level_skin`): a level that drops a joint freezes it, and the step
places it rigidly in the frame of its nearest kept ancestor. Its weights move to that ancestor,
and the vertex's offset into the ancestor's frame through the frozen joints, so the skin follows
the dropped joint exactly where the level draws it; a vertex's entries for the same kept joint
merge. No weight is left on a dropped joint.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from jaxtyping import Float, Int

from jcrowd.motion.body import (
    INFLUENCES,
    BodyMesh,
    BoundBody,
    merge_influences,
    rest_joints_and_height,
)
from jcrowd.motion.rotation import array_module, quat_rotate, quat_to_matrix
from jcrowd.motion.skeleton import Skeleton

__all__ = [
    "SkinnedLevel",
    "SkinnedMesh",
    "frames_from_points",
    "level_skin",
    "rest_offsets",
    "skeleton_level",
    "skin",
]


def rest_offsets(mesh: BodyMesh, rest: Float[np.ndarray, "J 3"]) -> Float[np.ndarray, "V 4 3"]:
    """A bound mesh's vertices in each of its joints' rest frames, ``v − p̄_k`` ``(V, 4, 3)``:
    what :func:`skin` moves at full detail."""
    v = np.asarray(mesh.vertices, np.float64)
    return (v[:, None, :] - np.asarray(rest, np.float64)[np.asarray(mesh.bones)]).astype(np.float32)


def level_skin(
    mesh: BodyMesh,
    rest: Float[np.ndarray, "J 3"],
    anchor: Int[np.ndarray, " J"],
    frame_rotation: Float[np.ndarray, "J 4"],
    frame_position: Float[np.ndarray, "J 3"],
) -> tuple[Int[np.ndarray, "V 4"], Float[np.ndarray, "V 4"], Float[np.ndarray, "V 4 3"]]:
    """A bound mesh at a level of detail that keeps some joints (003 §5.1).

    ``anchor[j]``: the kept joint (an index among the level's kept joints) whose frame carries
    joint ``j``; ``frame_rotation[j]``, ``frame_position[j]``: ``j``'s frame in its anchor's when
    the joints in between hold their frozen rotations (identity and 0 for a kept joint), for a
    1 m skeleton. Each weight moves to the anchor, the vertex's offset into the anchor's frame
    (``C_j (v − p̄_j) + o_j``), so a vertex follows a dropped joint exactly as the level places
    that joint; entries for the same anchor merge (weights summed, offsets weight-averaged).
    Returns ``(kept joint ids (V, 4), weights (V, 4), offsets (V, 4, 3))`` for :func:`skin`.
    """
    ids = np.asarray(mesh.bones, np.int64)
    w = np.asarray(mesh.weights, np.float64)
    local = rest_offsets(mesh, rest).astype(np.float64)
    rot = np.asarray(frame_rotation, np.float64)[ids]
    moved = quat_rotate(rot, local) + np.asarray(frame_position, np.float64)[ids]
    new_ids, new_w = merge_influences(np.asarray(anchor, np.int64)[ids], w)
    v = ids.shape[0]
    out = np.zeros((v, INFLUENCES, 3))
    for m in range(INFLUENCES):
        same = np.asarray(anchor, np.int64)[ids] == new_ids[:, m : m + 1]  # (V, 4)
        ws = np.where(same, w, 0.0)
        total = ws.sum(axis=1, keepdims=True)
        out[:, m] = np.einsum("vk,vkc->vc", ws, moved) / np.maximum(total, 1e-12)
        # An unused slot (weight 0) copies the main joint's offset: harmless, and finite.
        out[:, m] = np.where(total > 0, out[:, m], out[:, 0])
    return new_ids.astype(np.int32), new_w, out.astype(np.float32)


def skin(
    bones: Int[Any, "V 4"],
    weights: Float[Any, "V 4"],
    offsets: Float[Any, "V 4 3"],
    rotations: Float[Any, "*batch K 4"],
    positions: Float[Any, "*batch K 3"],
    height: Float[Any, "*batch"] | float = 1.0,
) -> Float[Any, "*batch V 3"]:
    """Linear-blend skinning ``v' = Σ_k w_k (R_k h l_k + p_k)`` (module docstring) with ``l_k``
    a vertex's offset in its ``k``-th joint's frame (:func:`rest_offsets`, :func:`level_skin`),
    ``R_k, p_k`` that joint's global rotation and position (m), ``h`` the agent's height. NumPy
    in gives NumPy out, otherwise jax arrays."""
    xp = array_module(rotations, positions)
    h = xp.asarray(height, dtype=positions.dtype)[..., None, None, None]
    b = np.asarray(bones)
    moved = quat_rotate(rotations[..., b, :], h * xp.asarray(offsets, dtype=positions.dtype))
    moved = moved + positions[..., b, :]
    return xp.sum(xp.asarray(weights, dtype=positions.dtype)[..., None] * moved, axis=-2)


@dataclass(frozen=True)
class SkinnedMesh:
    """One resolution of a body skinned to a level's kept joints (:func:`level_skin`).

    Attributes:
        triangles: ``(T, 3)`` int32; normals ``(V, 3)`` at rest; region ``(V,)`` clothing
            region (:data:`~jcrowd.motion.body.SKIN` … :data:`~jcrowd.motion.body.SHOES`).
        bones, weights, offsets: ``(V, 4)`` kept-joint ids, ``(V, 4)`` weights, ``(V, 4, 3)``
            offsets in those joints' frames for a 1 m skeleton.
    """

    triangles: Int[np.ndarray, "T 3"]
    normals: Float[np.ndarray, "V 3"]
    region: Int[np.ndarray, " V"]
    bones: Int[np.ndarray, "V 4"]
    weights: Float[np.ndarray, "V 4"]
    offsets: Float[np.ndarray, "V 4 3"]


@dataclass(frozen=True)
class SkinnedLevel:
    """What a renderer needs to draw one level of detail as skinned bodies: the body's meshes,
    fine to coarse, skinned to the level's kept joints, and how to find those joints' frames in
    the points the step outputs (:func:`frames_from_points`).

    Attributes:
        meshes: one :class:`SkinnedMesh` per resolution, finest first.
        kept: ``(K,)`` the output point each kept joint is; parents ``(K,)`` kept parents (-1
            for the root), parents first.
        local_ref: ``(K, 4)`` each kept joint's rotation in its kept parent's frame when its
            own pose is the reference (the identity for the root).
        ref_points: ``(K, M)`` the output points carried rigidly by each kept joint's frame
            (its kept children, the dropped joints and End Sites anchored at it; ``-1`` pads),
            ref_offsets ``(K, M, 3)`` those points in the joint's frame for a 1 m skeleton.
    """

    meshes: tuple[SkinnedMesh, ...]
    kept: Int[np.ndarray, " K"]
    parents: tuple[int, ...]
    local_ref: Float[np.ndarray, "K 4"]
    ref_points: Int[np.ndarray, "K M"]
    ref_offsets: Float[np.ndarray, "K M 3"]


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)``: the least rotation taking unit vectors ``a`` onto ``b`` (``(N, 3)``)."""
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    k = np.zeros((len(a), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    # Opposite directions (c ≈ −1) have no least rotation; they do not occur between a joint's
    # reference and its pose in a walk, and are left unturned here.
    scale = np.where(c > -1 + 1e-6, 1.0 / (1.0 + np.maximum(c, -1 + 1e-6)), 0.0)
    out = np.eye(3) + k + (k @ k) * scale[:, None, None]
    return np.where((c > -1 + 1e-6)[:, None, None], out, np.eye(3))


def frames_from_points(
    level: SkinnedLevel, points: Float[np.ndarray, "N P 3"], height: Float[np.ndarray, " N"]
) -> tuple[Float[np.ndarray, "N K 3 3"], Float[np.ndarray, "N K 3"]]:
    """The kept joints' global rotations and positions from the points a level places.

    Each kept joint's frame carries some points rigidly (:class:`SkinnedLevel`): its rotation
    is the one taking their offsets onto where they are (the orthogonal Procrustes solution,
    by SVD) when the offsets span a plane. When they lie on one line (a thigh carries only the
    knee), the turn about that line is not in the points: it is taken as the joint's reference
    turn in its parent's frame, and the least rotation takes the line onto its posed direction
    (so a pose whose deviations from the reference do not twist about the bone is found
    exactly). A joint carrying no point keeps its reference turn. The positions are the points
    the kept joints are.
    """
    pts = np.asarray(points, np.float64)
    h = np.maximum(np.asarray(height, np.float64), 1e-9)
    n, k = pts.shape[0], len(level.kept)
    rot = np.zeros((n, k, 3, 3))
    pos = pts[:, level.kept]
    local = quat_to_matrix(np.asarray(level.local_ref, np.float64))
    for j in range(k):
        p = level.parents[j]
        ref = local[j] if p < 0 else rot[:, p] @ local[j]
        ref = np.broadcast_to(ref, (n, 3, 3))
        ids = level.ref_points[j]
        use = ids >= 0
        o = np.asarray(level.ref_offsets[j], np.float64)[use]
        if not use.any():
            rot[:, j] = ref
            continue
        d = (pts[:, ids[use]] - pos[:, j, None]) / h[:, None, None]  # (N, M, 3)
        if np.linalg.matrix_rank(o, tol=1e-4) >= 2:
            cov = np.einsum("mi,nmj->nij", o, d)  # Σ o dᵀ
            u, _, vt = np.linalg.svd(cov)
            sign = np.sign(np.linalg.det(np.swapaxes(vt, 1, 2) @ np.swapaxes(u, 1, 2)))
            fix = np.ones((n, 3))
            fix[:, 2] = np.where(sign == 0, 1.0, sign)
            rot[:, j] = np.swapaxes(vt, 1, 2) @ (fix[:, :, None] * np.swapaxes(u, 1, 2))
        else:
            axis = o[np.argmax(np.linalg.norm(o, axis=1))]
            sign = np.sign(o @ axis)[None, :, None]
            target = np.sum(sign * d, axis=1)
            posed = ref @ (axis / np.linalg.norm(axis))
            tn = np.linalg.norm(target, axis=1, keepdims=True)
            target = np.where(tn > 1e-9, target / np.maximum(tn, 1e-9), posed)
            rot[:, j] = _swing(posed, target) @ ref
    return rot, pos


def skeleton_level(bound: BoundBody, skeleton: Skeleton) -> SkinnedLevel:
    """A :class:`SkinnedLevel` keeping every joint of ``skeleton`` (the one ``bound`` was bound
    to), for points laid out as its joints then its End Sites (a BVH clip's FK, say; End Sites
    may be left out of the points if the renderer is given only joints): a lone bone's twist
    is taken from the rest pose."""
    j = skeleton.num_joints
    offsets = np.asarray(skeleton.offsets, np.float64)
    ends = np.asarray(skeleton.end_offsets_or_empty(), np.float64)
    _, height = rest_joints_and_height(skeleton)
    carried: list[list[tuple[int, np.ndarray]]] = [[] for _ in range(j)]
    for c, p in enumerate(skeleton.parents):
        if p >= 0:
            carried[p].append((c, offsets[c] / height))
    for e, p in enumerate(skeleton.end_parents):
        carried[p].append((j + e, ends[e] / height))
    width = max(1, max(len(c) for c in carried))
    ref_points = np.full((j, width), -1, np.int32)
    ref_offsets = np.zeros((j, width, 3), np.float32)
    for k, items in enumerate(carried):
        for m, (point, off) in enumerate(items):
            ref_points[k, m] = point
            ref_offsets[k, m] = off
    meshes = tuple(
        SkinnedMesh(
            m.triangles,
            m.normals,
            np.ones(len(m.vertices), np.int8) if m.region is None else m.region,
            m.bones,
            m.weights,
            rest_offsets(m, bound.rest),
        )
        for m in bound.meshes
    )
    return SkinnedLevel(
        meshes=meshes,
        kept=np.arange(j, dtype=np.int32),
        parents=tuple(int(p) for p in skeleton.parents),
        local_ref=np.tile([1.0, 0.0, 0.0, 0.0], (j, 1)),
        ref_points=ref_points,
        ref_offsets=ref_offsets,
    )
