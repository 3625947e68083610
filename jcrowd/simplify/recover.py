"""Rotation recovery for simplified levels (paper 003 §5.2: "the local transformation value of
each joint is recovered from the optimization result and the hierarchical information").

Local rotations of a level's skeleton from optimised positions, top-down over the kept joints,
starting from each joint's captured global rotation ``G°``:

- one kept child: the minimal rotation taking the child's bone direction under ``G°`` to its
  optimised direction, applied to ``G°`` (so the captured twist about the bone is kept);
- several kept children: the rotation that best maps their bones onto the optimised directions
  (Kabsch/Wahba by SVD), with ``G°``'s own axes as weak extra pairs so a degenerate (collinear)
  set still has a unique, twist-preserving answer;
- no kept child: ``G°`` unchanged.

One rigid rotation per joint cannot follow a change of the angles *between* sibling bones, which
the position problem allows, so a level's FK can differ from the optimised positions below
joints with several kept children; below single-child joints the
direction is matched exactly.
"""

from __future__ import annotations

import numpy as np

from jcrowd.motion.rotation import (
    quat_conj,
    quat_from_matrix,
    quat_mul,
    quat_normalize,
    quat_rotate,
)
from jcrowd.simplify.levels import LevelPlan

__all__ = ["expand_rotations", "recover_rotations"]


def _min_rotation(u: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Quaternions ``(F, 4)`` of the smallest rotations taking directions ``u`` to ``d``.

    Where either vector has no length (a zero-length bone) there is no direction to match and
    the rotation is the identity.
    """
    nu = np.linalg.norm(u, axis=-1, keepdims=True)
    nd = np.linalg.norm(d, axis=-1, keepdims=True)
    degenerate = (nu < 1e-9) | (nd < 1e-9)
    u = u / np.maximum(nu, 1e-12)
    d = d / np.maximum(nd, 1e-12)
    w = 1.0 + np.sum(u * d, axis=-1, keepdims=True)
    q = np.concatenate([w, np.cross(u, d)], axis=-1)
    # Opposite directions: any half turn about an axis perpendicular to u.
    perp = np.cross(u, np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    half = np.concatenate([np.zeros_like(w), perp], axis=-1)
    q = np.where(w < 1e-9, half, q)
    return quat_normalize(np.where(degenerate, [[1.0, 0.0, 0.0, 0.0]], q))


def _kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Rotations ``(F, 4)`` minimising ``Σ w ‖R src − dst‖²`` (src, dst: ``(F, P, 3)``)."""
    h = np.einsum("p,fpi,fpj->fij", weights, dst, src)
    u, _, vt = np.linalg.svd(h)
    det = np.sign(np.linalg.det(u @ vt))
    fix = np.ones((len(h), 3))
    fix[:, 2] = det
    return quat_from_matrix(u @ (fix[:, :, None] * vt))


def recover_rotations(
    plan: LevelPlan, positions: np.ndarray, captured_global: np.ndarray
) -> np.ndarray:
    """Local rotations ``(F, K, 4)`` of a level's skeleton reaching optimised ``positions``.

    Args:
        plan: the level.
        positions: ``(F, J, 3)`` optimised positions of every original joint.
        captured_global: ``(F, J, 4)`` captured global rotations, the twist reference.
    """
    sk = plan.skeleton
    offs = np.asarray(sk.offsets, np.float64)
    glob = np.zeros((positions.shape[0], sk.num_joints, 4))
    for i, j in enumerate(plan.kept):
        g0 = captured_global[:, j]
        kids = sk.children(i)
        if len(kids) == 1:
            c = kids[0]
            u = quat_rotate(g0, np.broadcast_to(offs[c], g0[:, :3].shape))
            d = positions[:, plan.kept[c]] - positions[:, j]
            glob[:, i] = quat_mul(_min_rotation(u, d), g0)
        elif len(kids) > 1:
            axes = np.eye(3)
            src = np.concatenate([offs[list(kids)], axes])
            dst_bones = np.stack(
                [positions[:, plan.kept[c]] - positions[:, j] for c in kids], axis=1
            )
            dst_axes = quat_rotate(g0[:, None], np.broadcast_to(axes, (len(g0), 3, 3)))
            scale = float(np.mean(np.sum(offs[list(kids)] ** 2, axis=-1)))
            weights = np.concatenate([np.ones(len(kids)), np.full(3, 1e-3 * scale)])
            glob[:, i] = _kabsch(
                np.broadcast_to(src, (len(g0), *src.shape)),
                np.concatenate([dst_bones, dst_axes], 1),
                weights,
            )
        else:
            glob[:, i] = g0
    local = glob.copy()
    for i in range(1, sk.num_joints):
        local[:, i] = quat_mul(quat_conj(glob[:, sk.parents[i]]), glob[:, i])
    return quat_normalize(local)


def expand_rotations(
    plan: LevelPlan, key: np.ndarray, local: np.ndarray, parents: tuple[int, ...]
) -> np.ndarray:
    """The level's local rotations ``(F, K, 4)`` on the *original* skeleton, ``(F, J, 4)``.

    Frozen joints take their key rotation; a kept joint under frozen ones takes back the
    rotations the level composed into it, so FK on the original skeleton puts kept joints where
    the level does and frozen joints where they ride along (rigidly, with their parent).
    """
    f = local.shape[0]
    full = np.broadcast_to(np.asarray(key, np.float64), (f, *np.shape(key))).copy()
    frozen = set(plan.frozen)
    for i, j in enumerate(plan.kept):
        chain = np.array([1.0, 0.0, 0.0, 0.0])
        a = parents[j]
        while a >= 0 and a in frozen:  # q_f1 ⊗ … ⊗ q_fm, nearest frozen ancestor last
            chain = quat_mul(np.asarray(key[a], np.float64), chain)
            a = parents[a]
        full[:, j] = quat_mul(np.broadcast_to(quat_conj(chain), (f, 4)), local[:, i])
    return full
