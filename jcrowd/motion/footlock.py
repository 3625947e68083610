"""Foot locking by root correction: planted feet do not slide.

A synthesized cycle is an interpolation of captures; small frame-to-frame errors in the legs and in
the decoded root velocity make a planted foot slide more than the captures' own
(``bench/kriging.py`` reports both, before and after locking). The classic clean-up used here moves
only the root: between consecutive frames in which a foot is planted
(:func:`jcrowd.motion.gait.foot_contacts`; the planted joint is the lower of its ankle and toe), the
root's horizontal step is reduced by the planted joint's horizontal slide (averaged over both feet
in double support). In single support the planted joint then stays exactly where it was; the legs'
poses are untouched. The correction is horizontal only, so heights and the pose in the root frame
are unchanged.
"""

from __future__ import annotations

import numpy as np

from jcrowd.motion.clip import Motion, joint_positions
from jcrowd.motion.gait import contacts_from_positions
from jcrowd.motion.skeleton import Skeleton

__all__ = ["lock_feet", "planted_slides", "slides_of_points"]


def planted_slides(motion: Motion) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per foot (left, right): the frames it stays planted over and its planted joint's slide.

    Returns, per foot, ``(frames (n,) int, slide (n, 2) float64)``: the frames ``i`` at which
    the foot is in contact at ``i`` and ``i + 1`` (:func:`~jcrowd.motion.gait.foot_contacts`),
    and the ``[x, z]`` step (m) from ``i`` to ``i + 1`` of its planted joint, the lower of its
    ankle and toe at frame ``i`` (heel down, then toe down).
    """
    pos = np.asarray(joint_positions(motion), np.float64)
    return slides_of_points(pos, motion.skeleton, motion.fps)


def slides_of_points(
    pos: np.ndarray, skeleton: Skeleton, fps: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`planted_slides` of joint positions ``(F, J, 3)`` of ``skeleton`` at ``fps``."""
    contacts = contacts_from_positions(pos, skeleton, fps)
    out = []
    for flags, ankle, toe in (
        (contacts.left, contacts.feet.left_ankle, contacts.feet.left_toe),
        (contacts.right, contacts.feet.right_ankle, contacts.feet.right_toe),
    ):
        on = np.nonzero(flags[:-1] & flags[1:])[0]
        low = np.where(pos[on, ankle, 1] <= pos[on, toe, 1], ankle, toe)
        out.append((on, pos[on + 1, low][:, [0, 2]] - pos[on, low][:, [0, 2]]))
    return out


def lock_feet(motion: Motion) -> Motion:
    """The clip with its root's horizontal path corrected so planted feet stay put."""
    f = motion.num_frames
    slide = np.zeros((f - 1, 2))
    count = np.zeros(f - 1)
    for on, step in planted_slides(motion):
        slide[on] += step
        count[on] += 1
    slide = np.where(count[:, None] > 0, slide / np.maximum(count, 1)[:, None], 0.0)
    root = np.asarray(motion.root_positions, np.float64).copy()
    correction = np.concatenate([np.zeros((1, 2)), np.cumsum(slide, axis=0)])
    root[:, [0, 2]] -= correction
    return Motion(motion.skeleton, motion.rotations, root.astype(np.float32), motion.fps)
