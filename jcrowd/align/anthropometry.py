"""Body segments and their masses for any skeleton (paper 004 §3.1).

Paper 004 computes the centre of mass (COM) of every segment and of the whole body "by using
the anthropometric tables described in [RW03]" (Robbins & Wu 2003, a software tool). That tool
is not available to us; we use the table it builds on in spirit, the one most used in
biomechanics: P. de Leva, "Adjustments to Zatsiorsky–Seluyanov's segment inertia parameters",
Journal of Biomechanics 29(9):1223–1230, 1996, Table 4 (male subjects), as
:data:`DE_LEVA_MALE`: each segment's mass as a fraction of body mass (a limb segment per side)
and its COM as a fraction of its length from the proximal end. The fractions sum to 1 for a
full body. Head and trunk COMs are defined between landmarks (vertex, cervicale, mid-hip) that a
capture skeleton does not have, so their mass sits at the midpoints of their bones instead.

A *segment* of a skeleton is the bone from a joint to one of its children (or to an End Site);
it belongs to the category of its proximal joint's name — in BVH a joint is named after the bone
it moves (``LeftUpLeg``/``lfemur`` sits at the hip and moves the thigh). The name rules
(``_RULES``: case-insensitive, the first category that matches wins) put CMU's ``LHipJoint``,
the pelvis bone from the root to the hip, and ``LeftShoulder``/``lclavicle``, the shoulder
girdle that de Leva counts in the trunk, in the trunk. Sides come from
:func:`jcrowd.motion.clip.left_right_pairs`.

Within a limb category and side (trunk and head: the whole category, whatever side a bone is
on) the table's mass is spread over its bones in proportion to their length; a segment made of
a single bone puts its COM at the table fraction, several bones (CMU's foot: ankle→toe
base→toe tip) each count as a uniform rod. Categories a skeleton lacks (no hands) lose their
share and the rest is rescaled to sum to 1. When the names do not reveal at least a thigh, a
shank and a trunk bone, the skeleton is unknown to these rules and the whole mass is spread
over all bones by length, each a uniform rod (COM at its midpoint). The table with de Leva's
landmarks and the name rules in words are in ``docs/design/align.md``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from jcrowd.motion.clip import left_right_pairs
from jcrowd.motion.skeleton import Skeleton, rest_positions

__all__ = ["DE_LEVA_MALE", "BodySegments", "body_segments"]

DE_LEVA_MALE: dict[str, tuple[float, float]] = {
    "head": (0.0694, 0.5),
    "trunk": (0.4346, 0.5),
    "upper_arm": (0.0271, 0.5772),
    "forearm": (0.0162, 0.4574),
    "hand": (0.0061, 0.7900),
    "thigh": (0.1416, 0.4095),
    "shank": (0.0433, 0.4459),
    "foot": (0.0137, 0.4415),
}
"""``category -> (mass fraction, COM fraction from the proximal end)``, de Leva 1996 Table 4."""

_BILATERAL = frozenset({"upper_arm", "forearm", "hand", "thigh", "shank", "foot"})

_RULES: tuple[tuple[str, str], ...] = (
    ("hand", r"hand|finger|thumb|index|wrist|palm"),
    ("forearm", r"forearm|lowerarm|radius|ulna|elbow"),
    ("upper_arm", r"humerus|upperarm|arm"),
    ("foot", r"toe|foot|ankle|heel"),
    ("thigh", r"upleg|upperleg|thigh|femur|hip$|hip[_.]"),
    ("shank", r"shin|tibia|lowerleg|knee|calf|leg"),
    (
        "trunk",
        r"hips|hipjoint|pelvis|spine|back|chest|thorax|torso|abdomen|waist|root|clavicle|"
        r"shoulder|collar",
    ),
    ("head", r"head|neck|skull|jaw"),
)


@dataclass(frozen=True)
class BodySegments:
    """The mass model of a skeleton: one entry per bone.

    Points are indexed over joints then End Sites (``J + E`` of them), as
    ``concatenate([joint_positions, end_site_positions])``.

    Attributes:
        proximal: ``(S,)`` index of each bone's proximal point (a joint).
        distal: ``(S,)`` index of its distal point (a child joint or an End Site).
        com_fraction: ``(S,)`` where the bone's COM lies from proximal (0) to distal (1).
        mass: ``(S,)`` mass as a fraction of body mass; sums to 1.
        category: the category of each bone (a key of :data:`DE_LEVA_MALE`, or ``"bone"`` in
            the fallback).
        side: ``"left"``, ``"right"`` or ``"centre"`` for each bone.
        fallback: True when the names were not recognised and mass follows bone length.
    """

    proximal: np.ndarray
    distal: np.ndarray
    com_fraction: np.ndarray
    mass: np.ndarray
    category: tuple[str, ...]
    side: tuple[str, ...]
    fallback: bool

    def select(self, category: str, side: str) -> np.ndarray:
        """Indices of the bones of one category on one side."""
        pairs = enumerate(zip(self.category, self.side, strict=True))
        return np.array([s for s, (c, d) in pairs if c == category and d == side], np.int64)


def _category(name: str) -> str | None:
    low = name.lower()
    for category, pattern in _RULES:
        if re.search(pattern, low):
            return category
    return None


def body_segments(skeleton: Skeleton) -> BodySegments:
    """Bones of ``skeleton`` with their de Leva masses and COM fractions (see the module doc)."""
    joints, ends = rest_positions(skeleton)
    points = np.concatenate([joints, ends])
    num_joints = skeleton.num_joints
    proximal = [p for p in skeleton.parents[1:]] + list(skeleton.end_parents)
    distal = list(range(1, num_joints)) + [num_joints + e for e in range(len(skeleton.end_parents))]
    prox = np.asarray(proximal, np.int64)
    dist = np.asarray(distal, np.int64)
    length = np.linalg.norm(points[dist] - points[prox], axis=-1)

    side_of = ["centre"] * num_joints
    for left, right in left_right_pairs(skeleton.names):
        side_of[left], side_of[right] = "left", "right"
    sides = tuple(side_of[p] for p in proximal)
    cats = [_category(skeleton.names[p]) for p in proximal]
    known = {c for c, ln in zip(cats, length, strict=True) if c is not None and ln > 0}

    if not {"thigh", "shank", "trunk"} <= known or length.sum() <= 0:
        total = max(float(length.sum()), 1e-300)
        return BodySegments(
            prox, dist, np.full(len(prox), 0.5), length / total, ("bone",) * len(prox), sides, True
        )

    mass = np.zeros(len(prox))
    frac = np.full(len(prox), 0.5)
    groups: dict[tuple[str, str], list[int]] = {}
    for s, (c, d) in enumerate(zip(cats, sides, strict=True)):
        if c is not None and length[s] > 0:
            # Trunk and head are one segment each, whatever side a bone of theirs is on (CMU's
            # LHipJoint is a left pelvis bone); limbs are one segment per side.
            groups.setdefault((c, d if c in _BILATERAL else "centre"), []).append(s)
    for (c, d), members in groups.items():
        share, com = DE_LEVA_MALE[c]
        # A bilateral segment found without a side (e.g. an unpaired "Arm") stands for both.
        if c in _BILATERAL and d == "centre":
            share *= 2.0
        idx = np.asarray(members)
        mass[idx] = share * length[idx] / length[idx].sum()
        if len(idx) == 1:
            frac[idx] = com
    mass /= mass.sum()
    return BodySegments(prox, dist, frac, mass, tuple(c or "none" for c in cats), sides, False)
