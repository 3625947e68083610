"""Motion analysis for joint simplification (paper 003 §4): posture error, key posture, importance.

Posture error of joint ``j`` from frame ``t_ref`` to ``t`` (003 Eq. 1)::

    E_j(t_ref, t) = Σ_c |(r_j^c(t_ref) + r_j^c(t)) θ_j^c(t_ref, t)| / (2π r_max)

How we read the extracted equation:

- ``c`` runs over the *direct* children of ``j`` — the joints and the End Sites hanging from it —
  as the text says ("m is the total number of children of joint j", "r_j^c is the distance
  between joint j and its child c"). The hierarchy enters through ``m`` and the lengths, as the
  paper says it does. A child at zero distance (CMU's ``Neck``, ``LeftShoulder``: helper joints
  sitting on their parent) would make a busy joint such as ``Spine1`` look idle, so such a child
  is looked through: its own children count, reached through its rotation.
- ``θ_j^c`` is the angle at ``p_j`` between the child's positions at ``t_ref`` and ``t``
  (Fig. 3: the angle of ``p_c(t_ref) p_j p_c(t)``), measured in the frame of ``j``'s parent.
  In world coordinates every joint would inherit its ancestors' swing (a finger would look as
  busy as the arm). In the parent's frame the child's position relative to ``j`` is
  ``q_j o_c``, so ``θ`` is the turn of ``j``'s own rotation about the bone, ``r`` is the bone
  length ``|o_c|`` (constant), and a joint whose rotation never changes (CMU fingers, thumbs,
  the zero-rotation ``*HipJoint``s) or that has no children has zero error: such joints carry
  no data and are eliminated first at no cost.
- ``r_max``: the paper sums ``r_root^c`` over the root's children. On skeletons whose root
  children sit at the root (CMU: ``LHipJoint``, ``RHipJoint``, ``LowerBack`` have zero offsets)
  that sum is 0, so we sum the rest-pose distances from the root to *every* joint and End Site
  instead. It is one constant for all joints, so it scales the importances without reordering
  them.

Key frame (Eq. 2): ``t_j^key = argmin_{t_ref} Σ_t E_j(t_ref, t)``; the key posture applies each
joint's local rotation at its own key frame. Importance (Eq. 3): ``ε_j = (1/n) Σ_t
E_j(t_j^key, t)``. The elimination priority list sorts joints by ``ε`` (least important first,
ties broken deepest first, then by index); the root is never in it.

Everything is vectorised over frames: the full ``(J, F, F)`` error matrix for small clips, and
row sums computed in blocks of reference frames so long clips stay in memory (NumPy float64:
clip lengths vary, so a compiled kernel would recompile for each one).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jcrowd.errors import MotionError
from jcrowd.motion.clip import Motion, left_right_pairs
from jcrowd.motion.rotation import array_module, quat_rotate
from jcrowd.motion.skeleton import Skeleton, rest_positions

__all__ = [
    "JointAnalysis",
    "analyse_motion",
    "elimination_order",
    "joint_importance",
    "key_posture",
    "posture_error",
]


@dataclass(frozen=True)
class JointAnalysis:
    """Per-joint results of 003 §4 for one clip.

    Attributes:
        key_frames: ``(J,)`` ``t_j^key`` (Eq. 2).
        importance: ``(J,)`` ``ε_j`` (Eq. 3).
        r_max: the normaliser of Eq. 1 (m).
    """

    key_frames: np.ndarray
    importance: np.ndarray
    r_max: float


def _child_table(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(owner joint, chain of joints below it, offsets)`` for every effective child.

    A child at zero distance (CMU's ``Neck``, ``LeftShoulder``, ``LeftFingerBase`` sit exactly on
    their parent) has no arc of its own, so it is looked through: its own children (or End
    Sites) count as the owner's children, reached through the zero-offset joint's rotation.
    Returns ``owners (C,)``, ``via (C, D)`` (the zero-offset joints between owner and child, -1
    padded) and the child's offset ``(C, 3)`` from the last of them.
    """
    offsets = np.asarray(skeleton.offsets, np.float64)
    ends = np.asarray(skeleton.end_offsets_or_empty(), np.float64)
    kids: list[list[tuple[str, int]]] = [[] for _ in skeleton.names]
    for j, p in enumerate(skeleton.parents[1:], start=1):
        kids[p].append(("joint", j))
    for e, p in enumerate(skeleton.end_parents):
        kids[p].append(("end", e))
    rows: list[tuple[int, list[int], np.ndarray]] = []

    def visit(owner: int, via: list[int], node: tuple[str, int]) -> None:
        kind, i = node
        off = offsets[i] if kind == "joint" else ends[i]
        if kind == "joint" and np.linalg.norm(off) < 1e-9:
            for child in kids[i]:
                visit(owner, [*via, i], child)
        else:
            rows.append((owner, via, off))

    for j in range(skeleton.num_joints):
        for child in kids[j]:
            visit(j, [], child)
    depth = max((len(v) for _, v, _ in rows), default=0)
    owners = np.array([o for o, _, _ in rows], np.int32)
    via = np.array([v + [-1] * (depth - len(v)) for _, v, _ in rows], np.int32).reshape(
        len(rows), depth
    )
    return owners, via, np.array([off for _, _, off in rows]).reshape(-1, 3)


def _r_max(skeleton: Skeleton) -> float:
    joints, ends = rest_positions(skeleton)
    pts = np.concatenate([joints[1:], ends]) - joints[0]
    return float(np.linalg.norm(pts, axis=-1).sum())


def _child_vectors(skeleton: Skeleton, rotations: Any) -> tuple[Any, np.ndarray]:
    """Effective children relative to their joint in its parent's frame ``(F, C, 3)``, owners.

    NumPy in (the offline analysis, float64, no compilation per clip length) gives NumPy out;
    jax arrays give jax arrays.
    """
    xp = array_module(rotations)
    owners, via, offsets = _child_table(skeleton)
    shape = (rotations.shape[0], len(owners), 3)
    v = xp.broadcast_to(xp.asarray(offsets, rotations.dtype), shape)
    for k in range(via.shape[1] - 1, -1, -1):  # innermost zero-offset joint first
        q = rotations[:, np.maximum(via[:, k], 0)]
        v = xp.where((via[:, k] >= 0)[None, :, None], quat_rotate(q, v), v)
    return quat_rotate(rotations[:, owners], v), owners


def _pair_error(v_ref: Any, v: Any) -> Any:
    """``(r(t_ref) + r(t)) θ`` for child vectors ``(..., C, 3)``; ``θ`` via atan2 (exact near 0)."""
    xp = array_module(v_ref, v)
    r_ref = xp.linalg.norm(v_ref, axis=-1)
    r = xp.linalg.norm(v, axis=-1)
    theta = xp.arctan2(xp.linalg.norm(xp.cross(v_ref, v), axis=-1), xp.sum(v_ref * v, axis=-1))
    # Equal vectors turn by exactly 0: a fused multiply-add in the cross product leaves ~1e-8
    # rad, which would make a never-rotating joint look busy and order idle joints by noise.
    theta = xp.where(xp.all(v_ref == v, axis=-1), 0.0, theta)
    return (r_ref + r) * xp.abs(theta)


def posture_error(motion: Motion) -> jnp.ndarray:
    """``E_j(t_ref, t)`` for every joint and frame pair, ``(J, F, F)`` (003 Eq. 1).

    Memory grows as ``J F²``; for long clips use :func:`analyse_motion`, which only needs row sums.
    """
    sk = motion.skeleton
    v, owners = _child_vectors(sk, jnp.asarray(motion.rotations, jnp.float32))
    per_child = _pair_error(v[:, None], v[None, :])  # (F, F, C)
    e = jax.ops.segment_sum(jnp.moveaxis(per_child, -1, 0), owners, num_segments=sk.num_joints)
    return e / (2 * jnp.pi * _r_max(sk))


def _row_sums(v: np.ndarray, owners: np.ndarray, num_joints: int, block: int = 32) -> np.ndarray:
    """``Σ_t E`` per (reference frame, joint), unnormalised, ``(F, J)``, without the full matrix.

    Reference frames go in blocks, each block one vectorised ``(B, F, C)`` evaluation, so memory
    stays ``O(B·F·C)`` for long clips. NumPy: clip lengths vary, and a compiled kernel would be
    recompiled for every length.
    """
    per_child = np.empty((len(v), v.shape[1]))
    for start in range(0, len(v), block):
        per_child[start : start + block] = _pair_error(v[start : start + block, None], v[None]).sum(
            axis=1
        )
    onehot = np.eye(num_joints)[owners]
    return per_child @ onehot


def analyse_motion(motion: Motion) -> JointAnalysis:
    """Key frames and importance of every joint of one clip (003 Eq. 1–3)."""
    sk = motion.skeleton
    if motion.num_frames < 2:
        raise MotionError(f"joint analysis: expected at least 2 frames, found {motion.num_frames}")
    rot = np.asarray(motion.rotations)
    if not np.all(np.isfinite(rot)):
        raise MotionError("joint analysis: the clip has non-finite rotations")
    v, owners = _child_vectors(sk, rot.astype(np.float64))
    r_max = _r_max(sk)
    sums = _row_sums(v, owners, sk.num_joints) / (2 * np.pi * r_max)  # (F, J)
    key = np.argmin(sums, axis=0)
    importance = sums[key, np.arange(sk.num_joints)] / motion.num_frames
    return JointAnalysis(key.astype(np.int32), importance, r_max)


def joint_importance(motions: Motion | Sequence[Motion]) -> np.ndarray:
    """``ε_j`` (Eq. 3) of one clip, or summed over clips that share a skeleton's joint names."""
    clips = [motions] if isinstance(motions, Motion) else list(motions)
    if not clips:
        raise MotionError("joint importance: expected at least one clip, found none")
    names = clips[0].skeleton.names
    total = np.zeros(len(names))
    for i, clip in enumerate(clips):
        if clip.skeleton.names != names:
            raise MotionError(
                f"joint importance: clip {i} has joints {list(clip.skeleton.names)}, expected the "
                f"first clip's {list(names)}"
            )
        total += analyse_motion(clip).importance
    return total


def elimination_order(skeleton: Skeleton, importance: np.ndarray) -> tuple[int, ...]:
    """Non-root joints, least important first (ties: deepest first, then lowest index), a
    mirrored pair (left and right names, :func:`jcrowd.motion.clip.left_right_pairs`) side by
    side, left first, at the larger of its two importances.

    Why pairs: on mirrored data the two importances of a pair are nearly equal, and ranked
    apart the tie falls by noise, so a level could keep one knee and freeze the other. Ranked as
    one at the larger importance, a pair goes only when neither side is needed; a level's cut
    then falls between pairs (:func:`jcrowd.simplify.levels.pair_safe_counts`).
    """
    depth = skeleton.depths
    partner: dict[int, int] = {}
    for a, b in left_right_pairs(skeleton.names):
        partner[a], partner[b] = b, a
    units: list[tuple[int, ...]] = []
    for j in range(1, skeleton.num_joints):
        other = partner.get(j)
        if other is None or other == 0:
            units.append((j,))
        elif j < other:
            units.append((j, other))

    def key(unit: tuple[int, ...]) -> tuple[float, int, int]:
        return (max(float(importance[j]) for j in unit), -int(depth[unit[0]]), unit[0])

    return tuple(j for unit in sorted(units, key=key) for j in unit)


def key_posture(motion: Motion, key_frames: np.ndarray) -> np.ndarray:
    """Local rotations ``(J, 4)``: each joint's rotation at its own key frame (003 §4.2)."""
    rot = np.asarray(motion.rotations)
    return rot[np.asarray(key_frames), np.arange(motion.skeleton.num_joints)]
