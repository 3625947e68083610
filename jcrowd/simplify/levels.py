"""Frozen joints and the per-level position problem (paper 003 §5).

A level freezes the first ``k`` joints of the elimination list at their key-posture local
rotation (§5.1). Its skeleton keeps the other joints; each kept joint hangs from its first kept
ancestor with the offset composed through the frozen joints in between (at their key rotations),
and End Sites of frozen joints move to the first kept ancestor the same way. FK on a level
visits only the kept joints.

The position problem of one frame (§5.2). Unknowns: the positions of every non-root joint —
frozen ones included, because Eq. 8's angle is a function of frozen joints' positions; as the
paper says, "the frozen joints are removed after fitting". The root stays at its captured
position. With ``x°`` the captured positions and the key posture giving the constants::

    E_d = Σ_{j≠root} ‖x_j − x°_j‖²                         (Eq. 6)
    E_s = Σ_{kept c≠root} (‖x_c − x_p‖ − b_{c,p}(0))²       (Eq. 7; p = first kept ancestor)
    E_a = Σ_{frozen r} Σ_{children c of r} (cos θ_r^c − cos θ_r^c(0))²   (Eq. 8)

where ``θ_r^c`` is the angle at frozen joint ``r`` between its parent and its child ``c``
(pairs with a zero-length bone have no angle and are skipped). Default ("hard") mode: the
rigid bones ``‖x_c − x_p‖² = b_{c,p}(0)²`` are equality constraints and ``αE_d + γE_a`` the
objective — the "rigid constraints" of the title. The paper's all-weighted form
``αE_d + βE_s + γE_a`` (Eq. 5) is ``mode="weighted"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from jcrowd.errors import MotionError
from jcrowd.motion.rotation import quat_rotate
from jcrowd.motion.skeleton import Skeleton, forward_kinematics

__all__ = [
    "LevelPlan",
    "Weights",
    "joint_counts",
    "pair_safe_counts",
    "plan_level",
    "position_problem",
]


@dataclass(frozen=True)
class Weights:
    """α, β, γ of Eq. 5 (the paper's 0.2, 0.4, 0.4)."""

    alpha: float = 0.2
    beta: float = 0.4
    gamma: float = 0.4


@dataclass(frozen=True)
class LevelPlan:
    """One level: which joints are kept, and its simplified skeleton.

    Attributes:
        kept: original indices of the kept joints, in order (the root first).
        frozen: original indices of the frozen joints.
        kept_parent: for each kept joint, the original index of its first kept ancestor (-1).
        skeleton: the level's skeleton (kept joints, composed offsets, re-attached End Sites).
    """

    kept: tuple[int, ...]
    frozen: tuple[int, ...]
    kept_parent: tuple[int, ...]
    skeleton: Skeleton


_PAPER_FRACTIONS = (1.0, 0.82, 0.70, 0.58, 0.45, 0.33, 0.20, 0.08)  # 003 Fig. 1


def joint_counts(num_joints: int, levels: int, lowest_fraction: float = 0.08) -> list[int]:
    """Joints per level, level 0 = all, down to ``lowest_fraction`` of the joints.

    The fractions follow paper 003 Fig. 1 (100, 82, 70, 58, 45, 33, 20, 8 %: a first step of
    18 %, then about 12.3 % a level, so not linear from 100 %): with 8 levels and the default
    ``lowest_fraction`` they are the paper's; other level counts resample that curve piecewise
    linearly, and another ``lowest_fraction`` rescales it to end there. Counts are strictly
    decreasing and at least 2 (the root and one more joint).
    """
    if levels < 1:
        raise MotionError(f"simplify: expected at least 1 level, found {levels}")
    if levels > num_joints - 1:
        raise MotionError(
            f"simplify: expected at most {num_joints - 1} levels for a {num_joints}-joint skeleton "
            f"(each level drops at least one joint), found {levels}"
        )
    paper = np.asarray(_PAPER_FRACTIONS)
    fracs = np.interp(np.linspace(0, len(paper) - 1, levels), np.arange(len(paper)), paper)
    fracs = lowest_fraction + (fracs - paper[-1]) / (1 - paper[-1]) * (1 - lowest_fraction)
    counts = [num_joints]
    for i in range(1, levels):
        # Below the level above, and high enough that every later level can still drop one.
        target = min(round(num_joints * fracs[i]), counts[-1] - 1)
        counts.append(max(target, 2 + (levels - 1 - i)))
    return counts


def pair_safe_counts(skeleton: Skeleton, order: tuple[int, ...], counts: list[int]) -> list[int]:
    """``counts`` moved so that no level keeps one joint of a mirrored pair and freezes the
    other: each level freezes a prefix of ``order`` (:func:`plan_level`) that ends
    between two pairs — the nearest such cut to the one asked for, the smaller on a tie, and
    past the level above's so the counts still fall strictly. Pairs must sit side by side in
    ``order`` (:func:`jcrowd.simplify.analysis.elimination_order` puts them so); a level that
    finds no such cut left keeps the count it asked for.
    """
    from jcrowd.motion.clip import left_right_pairs

    partner: dict[int, int] = {}
    for a, b in left_right_pairs(skeleton.names):
        partner[a], partner[b] = b, a
    n = len(order)
    cuts = [k for k in range(n + 1) if k in (0, n) or partner.get(order[k - 1]) != order[k]]
    j = skeleton.num_joints
    out, last = [], -1
    for count in counts:
        want = j - count
        options = [k for k in cuts if k > last and j - k >= 2]
        best = min(options, key=lambda k: (abs(k - want), k)) if options else max(want, last + 1)
        out.append(j - best)
        last = best
    return out


def plan_level(
    skeleton: Skeleton, order: tuple[int, ...], num_frozen: int, key: np.ndarray
) -> LevelPlan:
    """The level that freezes the first ``num_frozen`` joints of ``order`` at ``key`` (J, 4)."""
    frozen = set(order[:num_frozen])
    parents = skeleton.parents
    offsets = np.asarray(skeleton.offsets, np.float64)
    key = np.asarray(key, np.float64)
    kept = tuple(j for j in range(skeleton.num_joints) if j not in frozen)
    new_index = {j: i for i, j in enumerate(kept)}

    def lift(j: int, vec: np.ndarray) -> tuple[int, np.ndarray]:
        """Carry ``vec`` (in joint ``j``'s frame) up through frozen joints to a kept one."""
        while j in frozen:
            vec = offsets[j] + quat_rotate(key[j], vec)
            j = parents[j]
        return j, vec

    kept_parent, new_parents, new_offsets = [], [], []
    for j in kept:
        if j == 0:
            kept_parent.append(-1)
            new_parents.append(-1)
            new_offsets.append(offsets[0])
            continue
        anc, vec = lift(parents[j], offsets[j])
        kept_parent.append(anc)
        new_parents.append(new_index[anc])
        new_offsets.append(vec)
    end_parents, end_offsets = [], []
    for e, j in enumerate(skeleton.end_parents):
        anc, vec = lift(j, np.asarray(skeleton.end_offsets_or_empty(), np.float64)[e])
        end_parents.append(new_index[anc])
        end_offsets.append(vec)
    sk = Skeleton(
        tuple(skeleton.names[j] for j in kept),
        tuple(new_parents),
        np.asarray(new_offsets, np.float32).reshape(-1, 3),
        tuple(end_parents),
        np.asarray(end_offsets, np.float32).reshape(-1, 3),
    )
    return LevelPlan(kept, tuple(sorted(frozen)), tuple(kept_parent), sk)


@dataclass(frozen=True)
class PositionProblem:
    """Static structure and constants of one level's per-frame problem (NumPy, host side)."""

    bones: np.ndarray  # (B, 2) kept (child, first kept ancestor) original indices
    bone_lengths: np.ndarray  # (B,) b_{c,p}(0), m; zero-length bones are tied point to point
    angles: np.ndarray  # (A, 3) (parent, frozen joint, child) original indices
    angle_cos: np.ndarray  # (A,) cos θ at the key posture
    num_joints: int


def position_problem(skeleton: Skeleton, plan: LevelPlan, key: np.ndarray) -> PositionProblem:
    """Bones, key bone lengths and frozen-joint angle triples of a level (Eq. 7–8 constants)."""
    _, key_pos = forward_kinematics(skeleton, np.asarray(key, np.float64), np.zeros(3, np.float64))
    bones = np.array([(c, p) for c, p in zip(plan.kept[1:], plan.kept_parent[1:], strict=True)])
    bones = bones.reshape(-1, 2)
    lengths = np.linalg.norm(key_pos[bones[:, 0]] - key_pos[bones[:, 1]], axis=-1)
    triples = []
    for r in plan.frozen:
        p = skeleton.parents[r]
        for c in skeleton.children(r):
            a, b = key_pos[p] - key_pos[r], key_pos[c] - key_pos[r]
            if min(np.linalg.norm(a), np.linalg.norm(b)) > 1e-6:
                triples.append((p, r, c))
    angles = np.asarray(triples, np.int64).reshape(-1, 3)
    cos0 = np.asarray(angle_cosines(key_pos, angles)) if len(angles) else np.zeros(0)
    return PositionProblem(bones, lengths, angles, cos0, skeleton.num_joints)


def angle_cosines(pos: np.ndarray | jnp.ndarray, angles: np.ndarray) -> np.ndarray | jnp.ndarray:
    """Cosine of the angle at ``r`` of each ``(p, r, c)`` row of ``angles``; ``pos (..., J, 3)``.

    NumPy in → NumPy out, JAX in → JAX out (the SQP residuals call it on traced positions).
    """
    xp = jnp if isinstance(pos, jnp.ndarray) else np
    a = pos[..., angles[:, 0], :] - pos[..., angles[:, 1], :]
    b = pos[..., angles[:, 2], :] - pos[..., angles[:, 1], :]
    dot = xp.sum(a * b, axis=-1)
    return dot / xp.sqrt(xp.sum(a * a, axis=-1) * xp.sum(b * b, axis=-1) + 1e-18)
