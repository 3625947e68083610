"""Skinned bodies: a rigged mesh bound to any skeleton, per-level weights, linear-blend skinning.

The shipped body (``jcrowd/assets/body.jcb``, :func:`jcrowd.io.load_body`) is MakeHuman's base
mesh with its ``cmu_mb`` rig: 31 bones named like the CMU MotionBuilder captures. Binding it to
a motion model's skeleton (:func:`bind_body`) takes three steps.

1. **Names** (:func:`map_bones`). Every rig bone belongs to a *part* (``spine``, ``left_thigh``,
   …); a skeleton joint belongs to the part its name says under any convention in
   :data:`~jcrowd.motion.body_parts.PART_NAMES` (CMU MotionBuilder ``LeftUpLeg``, CMU ASF
   ``lfemur``, Mixamo ``mixamorig:LeftUpLeg``, Unreal ``thigh_l``, …; case, separators and a
   ``prefix:`` ignored; right-side names are the left ones mirrored). Within a part, joints and
   bones are paired in chain order by rest position
   (relative to the root, the rig scaled by the ratio of the two legs' heights): a skeleton
   with one spine joint where the rig has three takes the one nearest to it. Reading taken: a
   name says which part of the body a joint moves, and the rest pose says where in that part it
   sits. The 19-joint ``cmu16`` skeleton's ``thorax`` sits 11 cm above its pelvis, where the
   rig's ``LowerBack`` starts (not at ``Spine1``, which its name is in the CMU conversion: a
   trunk bent at the chest would fold the belly), and its ``head`` in the neck (its End Site
   5 cm above), where the rig's upper neck bone starts: the neck and head are one part.
   The pelvis, thighs, shins, feet, upper arms, forearms and head must be found; if one is not,
   :class:`~jcrowd.errors.SkinError` names those parts and the skeleton's joints.
2. **Weights.** A rig bone with no joint gives its weights to its nearest ancestor that has one
   (``cmu16``: ``Head`` → its ``head``, ``Spine1`` → its ``thorax``); each vertex keeps its 4
   largest weights, renormalised.
3. **Rest pose** (the fit). The mesh is turned to face the skeleton's rest forward and scaled
   by ``s``, the skeleton's root-to-ankle height over the rig's. Each bound bone ``b`` (joint
   ``j``) then gets an affine map ``A_b``: its rig joint goes to the skeleton's rest joint, the
   rig's direction to its chain child (the next bound bone along the limb) turns onto the
   skeleton's, and lengths along that direction scale by the ratio of the two bone
   lengths (clamped to ``[0.6, 1.6]``; other directions by ``s``), so two bones meeting at a
   joint agree there and the skin does not tear. A bone with no chain child (feet without toes,
   the head, hands) keeps its parent's turn. The rest vertices are ``Σ_b w_b A_b v``: the mesh
   standing in the skeleton's rest pose, bone directions and lengths.

Skinning, the per-level weights and finding joint frames in the step's points are in
:mod:`jcrowd.motion.skinning`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import SkinError
from jcrowd.motion.body_parts import ALL_PARTS, PART_NAMES, REQUIRED_PARTS, part_of_joint
from jcrowd.motion.skeleton import Skeleton, rest_positions

__all__ = [
    "BOTTOM",
    "PART_NAMES",
    "REQUIRED_PARTS",
    "SHOES",
    "SKIN",
    "TOP",
    "Body",
    "BodyMesh",
    "BoundBody",
    "bind_body",
    "map_bones",
    "rest_stature",
]

INFLUENCES = 4
"""Joints per vertex."""

_AXIAL_CLAMP = (0.6, 1.6)


@dataclass(frozen=True)
class BodyMesh:
    """One resolution of a body: vertices, normals, triangles and 4 bone weights per vertex.

    Attributes:
        vertices, normals: ``(V, 3)`` float32 (metres in the rig's axes, or a bound body's rest).
        triangles: ``(T, 3)`` int32 vertex indices.
        bones: ``(V, 4)`` int bone (or joint) indices; weights ``(V, 4)`` float32 summing to 1.
    """

    vertices: Float[np.ndarray, "V 3"]
    normals: Float[np.ndarray, "V 3"]
    triangles: Int[np.ndarray, "T 3"]
    bones: Int[np.ndarray, "V 4"]
    weights: Float[np.ndarray, "V 4"]
    region: Int[np.ndarray, " V"] | None = None


SKIN, TOP, BOTTOM, SHOES = 0, 1, 2, 3
"""Clothing regions of a bound mesh's vertices (:attr:`BodyMesh.region`), from the part of
the body its strongest rig bone moves: skin (head, neck, hands), top (trunk, collars, arms),
bottom (pelvis, legs), shoes (feet, toes)."""

_REGION_OF_PART = {
    "head": SKIN,
    "spine": TOP,
    "pelvis": BOTTOM,
}


def _region(part: str) -> int:
    if part in _REGION_OF_PART:
        return _REGION_OF_PART[part]
    side = part.split("_", 1)[1]
    if side in ("hand", "fingers", "thumb"):
        return SKIN
    if side in ("collar", "upper_arm", "forearm"):
        return TOP
    if side in ("foot", "toes"):
        return SHOES
    return BOTTOM


@dataclass(frozen=True)
class Body:
    """A rigged body: bone names and parents (parents first), each bone's joint (``heads``) and
    tip (``tails``) at rest ``(B, 3)``, and its meshes from fine to coarse."""

    bones: tuple[str, ...]
    parents: tuple[int, ...]
    heads: Float[np.ndarray, "B 3"]
    tails: Float[np.ndarray, "B 3"]
    meshes: tuple[BodyMesh, ...]


@dataclass(frozen=True)
class BoundBody:
    """A body bound to a skeleton: meshes whose ``bones`` index the skeleton's joints and whose
    vertices stand in the skeleton's rest pose for a 1 m skeleton (``rest`` the joints' rest
    positions, ``(J, 3)``; ``scale`` the rig-to-skeleton factor ``s``; ``joint_of_bone`` each
    rig bone's joint, -1 for none; ``fitted`` each rig bone's joint after the fit, ``(B, 3)``,
    where the rest vertices were moved with it)."""

    meshes: tuple[BodyMesh, ...]
    rest: Float[np.ndarray, "J 3"]
    joint_of_bone: Int[np.ndarray, " B"]
    scale: float
    fitted: Float[np.ndarray, "B 3"] | None = None


def rest_stature(bound: BoundBody) -> float:
    """The bound body's standing height for its 1 m skeleton: the finest mesh's rest vertices,
    top minus bottom along Y (sole to crown; the shipped body on ``cmu16``: 1.147)."""
    y = np.asarray(bound.meshes[0].vertices, np.float64)[:, 1]
    return float(y.max() - y.min())


def rest_joints_and_height(skeleton: Skeleton) -> tuple[np.ndarray, float]:
    """Rest-pose joint positions ``(J, 3)`` and the skeleton's height (End Sites included)."""
    joints, ends = rest_positions(skeleton)
    ys = np.concatenate([joints[:, 1], ends[:, 1]])
    return joints, float(ys.max() - ys.min())


def map_bones(body: Body, skeleton: Skeleton) -> Int[np.ndarray, " B"]:
    """Each rig bone's skeleton joint (``-1``: none), by part names and rest positions (module
    docstring, step 1)."""
    joints, _ = rest_joints_and_height(skeleton)
    heads = np.asarray(body.heads, np.float64)
    rel_j = joints - joints[0]
    rel_b = (heads - heads[0]) * _leg_ratio(joints, heads)
    by_part: dict[str, list[int]] = {}
    for j, name in enumerate(skeleton.names):
        part = part_of_joint(name)
        if part is not None:
            by_part.setdefault(part, []).append(j)
    out = np.full(len(body.bones), -1, np.int64)
    for part, (bone_names, _) in ALL_PARTS.items():
        cand = by_part.get(part, [])
        bones = [body.bones.index(b) for b in bone_names if b in body.bones]
        cand = list(cand)
        # Pair along the chain, nearest in rest position.
        cost = np.linalg.norm(rel_j[cand][:, None, :] - rel_b[bones][None, :, :], axis=-1)
        for k, m in _monotone_pairs(cost):
            out[bones[m]] = cand[k]
    found = {
        p for p, (names, _) in ALL_PARTS.items() for b in names if out[body.bones.index(b)] >= 0
    }
    missing = [p for p in REQUIRED_PARTS if p not in found]
    if missing:
        raise SkinError(
            f"body: could not map the parts {missing} onto the skeleton's joints "
            f"{list(skeleton.names)}; expected joint names like {_examples(missing)} "
            "(jcrowd.motion.body_parts.PART_NAMES lists the conventions understood)"
        )
    return out


def _leg_ratio(joints: np.ndarray, heads: np.ndarray) -> float:
    """The skeleton's root-to-lowest-joint height over the rig's: the scale that brings the
    rig to the skeleton (legs are where skeletons agree; a skeleton's top may be its neck)."""
    sk = joints[0, 1] - joints[:, 1].min()
    rig = heads[0, 1] - heads[:, 1].min()
    return float(sk / rig) if rig > 1e-9 and sk > 1e-9 else 1.0


def _monotone_pairs(cost: np.ndarray) -> list[tuple[int, int]]:
    """The order-keeping pairing of rows with columns (``min(rows, cols)`` pairs, each row and
    column at most once, both increasing) of least total ``cost``: a joint chain of the spine
    meets the rig's spine bottom to top, whatever their counts."""
    m, n = cost.shape
    if m == 0 or n == 0:
        return []
    if m > n:
        return [(k, c) for c, k in _monotone_pairs(cost.T)]
    # best[i, j]: least cost pairing rows[:i] into columns[:j] (every row paired).
    best = np.full((m + 1, n + 1), np.inf)
    best[0, :] = 0.0
    for i in range(1, m + 1):
        for j in range(i, n + 1):
            best[i, j] = min(best[i, j - 1], best[i - 1, j - 1] + cost[i - 1, j - 1])
    pairs, i, j = [], m, n
    while i > 0:
        if j > i and best[i, j] == best[i, j - 1]:
            j -= 1
        else:
            pairs.append((i - 1, j - 1))
            i, j = i - 1, j - 1
    return pairs[::-1]


def _examples(parts: list[str]) -> list[str]:
    return [f"{ALL_PARTS[p][0][0]}/{ALL_PARTS[p][1][-1]}" for p in parts]


def _owner(body: Body, joint_of_bone: np.ndarray) -> np.ndarray:
    """Each bone's nearest bound ancestor (itself when bound)."""
    owner = np.full(len(body.bones), -1, np.int64)
    for b, p in enumerate(body.parents):
        owner[b] = b if joint_of_bone[b] >= 0 else (owner[p] if p >= 0 else -1)
    if (owner < 0).any():
        raise SkinError(
            f"body: bone {body.bones[int(np.argmax(owner < 0))]!r} has no bound ancestor"
        )
    return owner


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation matrix taking direction ``a`` onto ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    if c < -1 + 1e-9:  # opposite: half a turn about any axis perpendicular to a
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def _yaw_matrix(forward_from: np.ndarray, forward_to: np.ndarray) -> np.ndarray:
    f0 = np.array([forward_from[0], 0.0, forward_from[2]])
    f1 = np.array([forward_to[0], 0.0, forward_to[2]])
    return _rotation_between(f0, f1)


def _part_of_bone(name: str) -> str:
    return next(p for p, (bones, _) in ALL_PARTS.items() if name in bones)


def _chain_child(body: Body, joint_of_bone: np.ndarray, b: int) -> int:
    """The bound bone that continues bone ``b``'s chain, -1 for none: of the first bound bones
    below ``b`` (through unbound ones), the only one, or where the chain branches the one in
    ``b``'s own part, else the neck, else the head (a trunk continues up the spine, not into a
    collarbone). The root has none (it turns as a whole)."""
    if body.parents[b] < 0:
        return -1
    first, todo = [], [c for c, p in enumerate(body.parents) if p == b]
    while todo:
        c = todo.pop(0)
        if joint_of_bone[c] >= 0:
            first.append(c)
        else:
            todo += [k for k, p in enumerate(body.parents) if p == c]
    if len(first) <= 1:
        return first[0] if first else -1
    parts = [_part_of_bone(body.bones[c]) for c in first]
    for want in (_part_of_bone(body.bones[b]), "head"):
        if want in parts:
            return first[parts.index(want)]
    return -1


def bind_body(body: Body, skeleton: Skeleton, forward: np.ndarray | None = None) -> BoundBody:
    """Bind ``body`` to ``skeleton`` (module docstring): meshes in the skeleton's rest pose for a
    1 m skeleton, weighted to its joints. ``forward``: the skeleton's rest facing direction
    (default ``+z``; :func:`jcrowd.motion.clip.rest_forward` gives it)."""
    jb = map_bones(body, skeleton)
    owner = _owner(body, jb)
    joints, height = rest_joints_and_height(skeleton)
    rest = joints / height  # the model's skeletons are 1 m tall; others are normalised here
    heads = np.asarray(body.heads, np.float64)
    turn = _yaw_matrix(
        np.array([0.0, 0.0, 1.0]), np.asarray(forward if forward is not None else [0, 0, 1.0])
    )
    heads = heads @ turn.T

    def part_bone(part: str) -> int:
        return body.bones.index(ALL_PARTS[part][0][0])

    pelvis, foot = part_bone("pelvis"), part_bone("left_foot")
    sk = rest
    s = float((sk[jb[pelvis], 1] - sk[jb[foot], 1]) / (heads[pelvis, 1] - heads[foot, 1]))

    maps = _bone_maps(body, jb, heads, rest, s)
    meshes = []
    for mesh in body.meshes:
        v = np.asarray(mesh.vertices, np.float64) @ turn.T
        n = np.asarray(mesh.normals, np.float64) @ turn.T
        own = owner[np.asarray(mesh.bones, np.int64)]  # (V, 4) bound bones
        w = np.asarray(mesh.weights, np.float64)
        out = np.zeros_like(v)
        nout = np.zeros_like(n)
        for k in range(INFLUENCES):
            for b in np.unique(own[:, k]):
                sel = own[:, k] == b
                lin, h0, h1 = maps[int(b)]
                out[sel] += w[sel, k, None] * ((v[sel] - h0) @ lin.T + h1)
                nout[sel] += w[sel, k, None] * (n[sel] @ np.linalg.inv(lin))
        nout /= np.maximum(np.linalg.norm(nout, axis=1, keepdims=True), 1e-12)
        joint_ids, joint_w = merge_influences(jb[own], w)
        main = np.asarray(mesh.bones, np.int64)[:, 0]  # the strongest rig bone (sorted)
        regions = np.array([_region(_part_of_bone(b)) for b in body.bones], np.int8)[main]
        meshes.append(
            BodyMesh(
                out.astype(np.float32),
                nout.astype(np.float32),
                np.asarray(mesh.triangles, np.int32),
                joint_ids,
                joint_w,
                regions,
            )
        )
    fitted = np.stack(
        [
            maps[int(owner[b])][0] @ (heads[b] - maps[int(owner[b])][1]) + maps[int(owner[b])][2]
            for b in range(len(body.bones))
        ]
    )
    return BoundBody(tuple(meshes), rest.astype(np.float32), jb, s, fitted)


def _bone_maps(
    body: Body, jb: np.ndarray, heads: np.ndarray, rest: np.ndarray, s: float
) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each bound bone's affine map ``x ↦ M (x − a) + b`` from the (turned) rig onto the
    skeleton's rest pose, as ``(M, a, b)`` (module docstring, step 3)."""
    sk = rest
    # Affine map per bound bone: x ↦ M (x − head_rig) + head_skel.
    maps: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for b in range(len(body.bones)):
        if jb[b] < 0:
            continue
        j = int(jb[b])
        c = _chain_child(body, jb, b)
        if c >= 0:
            d_rig = heads[c] - heads[b]
            d_sk = sk[jb[c]] - sk[j]
            if np.linalg.norm(d_rig) > 1e-6 and np.linalg.norm(d_sk) > 1e-6:
                rot = _rotation_between(d_rig, d_sk)
                ratio = np.linalg.norm(d_sk) / (s * np.linalg.norm(d_rig))
                axial = float(np.clip(ratio, *_AXIAL_CLAMP))
                u = d_rig / np.linalg.norm(d_rig)
                stretch = s * (np.eye(3) + (axial - 1.0) * np.outer(u, u))
                maps[b] = (rot @ stretch, heads[b], sk[j])
                continue
        p = body.parents[b]
        while p >= 0 and p not in maps:
            p = body.parents[p]
        lin = s * np.eye(3) if p < 0 else maps[p][0] / np.cbrt(abs(np.linalg.det(maps[p][0]))) * s
        maps[b] = (lin, heads[b], sk[j])

    return maps


def merge_influences(ids: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex, the entries for the same joint summed and the four largest kept, largest
    first (unused slots point at the main joint with weight 0), renormalised to sum to 1."""
    v = ids.shape[0]
    dense = np.zeros((v, int(ids.max()) + 1))
    np.add.at(dense, (np.repeat(np.arange(v), ids.shape[1]), ids.ravel()), w.ravel())
    out_ids = np.argsort(-dense, axis=1, kind="stable")[:, :INFLUENCES]
    out_w = np.take_along_axis(dense, out_ids, axis=1)
    if out_ids.shape[1] < INFLUENCES:  # fewer joints than influences
        pad = INFLUENCES - out_ids.shape[1]
        out_ids = np.concatenate([out_ids, np.repeat(out_ids[:, :1], pad, axis=1)], axis=1)
        out_w = np.concatenate([out_w, np.zeros((v, pad))], axis=1)
    out_ids = np.where(out_w > 0, out_ids, out_ids[:, :1])
    out_w = out_w / np.maximum(out_w.sum(axis=1, keepdims=True), 1e-12)
    return out_ids.astype(np.int32), out_w.astype(np.float32)
