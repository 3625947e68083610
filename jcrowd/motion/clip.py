"""Motion clips: the data model and the operations that return new clips.

A :class:`Motion` is a skeleton, per-frame local joint rotations ``(F, J, 4)``, root positions
``(F, 3)`` (metres, Y up) and a frame rate. Operations are free functions that return a new
``Motion`` (nothing is changed in place): slicing, resampling with slerp, dropping the leading
T-pose frame(s) some BVH conversions add, root normalisation, and left↔right mirroring. Gait
analysis (foot contacts, cycles, control parameters) lives in :mod:`jcrowd.motion.gait`.

The offline path runs on NumPy arrays (a ``Motion`` read from BVH holds NumPy float32); the same
functions accept jax arrays.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import numpy as np
from jaxtyping import Float

from jcrowd.errors import MotionError
from jcrowd.motion.rotation import (
    array_module,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_slerp,
    quat_yaw,
    yaw_quat,
)
from jcrowd.motion.skeleton import HostOrDevice, Skeleton, forward_kinematics, rest_positions

__all__ = [
    "Clip",
    "Motion",
    "drop_tpose_frames",
    "headings",
    "joint_positions",
    "mirror",
    "mirror_map",
    "normalize_root",
    "resample",
    "rest_forward",
    "slice_frames",
]


class Motion(eqx.Module):
    """A clip: skeleton, local rotations ``(F, J, 4)``, root positions ``(F, 3)``, frame rate.

    Attributes:
        skeleton: the joint tree (offsets in metres).
        rotations: unit quaternions ``(F, J, 4)``, each joint relative to its parent.
        root_positions: ``(F, 3)`` root translation (m).
        fps: frames per second.
    """

    skeleton: Skeleton
    rotations: Float[HostOrDevice, "F J 4"]
    root_positions: Float[HostOrDevice, "F 3"]
    fps: float = eqx.field(static=True)

    def __check_init__(self) -> None:
        j = self.skeleton.num_joints
        rs, ps = getattr(self.rotations, "shape", None), getattr(self.root_positions, "shape", None)
        if rs is None or ps is None:
            return
        if len(rs) != 3 or rs[1:] != (j, 4):
            raise MotionError(f"motion: expected rotations of shape (F, {j}, 4), found {tuple(rs)}")
        if tuple(ps) != (rs[0], 3):
            raise MotionError(
                f"motion: expected root positions of shape ({rs[0]}, 3), found {tuple(ps)}"
            )
        if not self.fps > 0:
            raise MotionError(f"motion: expected a positive frame rate, found {self.fps}")

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def duration(self) -> float:
        """Seconds spanned by the frames: ``(F - 1) / fps``."""
        return (self.num_frames - 1) / self.fps


@dataclass(frozen=True)
class Clip:
    """One clip of a dataset.

    Attributes:
        path: the BVH file it was read from.
        motion: the clip in metres, leading T-pose frames already dropped.
        dropped_frames: how many leading frames were dropped.
        actor, style, repetition: labels from the labels file, ``None`` where unknown.
    """

    path: str
    motion: Motion
    dropped_frames: int
    actor: str | None = None
    style: str | None = None
    repetition: int | None = None


def joint_positions(motion: Motion) -> Any:
    """World positions of every joint, ``(F, J, 3)`` (m)."""
    return forward_kinematics(motion.skeleton, motion.rotations, motion.root_positions)[1]


def slice_frames(motion: Motion, start: int, stop: int) -> Motion:
    """Frames ``start:stop`` as a new clip."""
    return Motion(
        motion.skeleton, motion.rotations[start:stop], motion.root_positions[start:stop], motion.fps
    )


def resample(motion: Motion, fps: float) -> Motion:
    """The clip at a new frame rate over the same time span.

    Rotations are slerped and root positions linearly interpolated between the two nearest
    source frames. The new clip has ``floor(duration * fps) + 1`` frames starting at t = 0.
    """
    if not fps > 0:
        raise MotionError(f"resample: expected a positive frame rate, found {fps}")
    xp = array_module(motion.rotations)
    n = int(np.floor(motion.duration * fps + 1e-6)) + 1
    t = np.arange(n) * (motion.fps / fps)  # positions in source frames
    i0 = np.clip(np.floor(t).astype(np.int64), 0, motion.num_frames - 1)
    i1 = np.clip(i0 + 1, 0, motion.num_frames - 1)
    a = xp.asarray((t - i0).astype(np.asarray(motion.rotations).dtype if xp is np else np.float32))
    rot = quat_slerp(motion.rotations[i0], motion.rotations[i1], a[:, None])
    pos = motion.root_positions[i0] * (1 - a[:, None]) + motion.root_positions[i1] * a[:, None]
    return Motion(motion.skeleton, rot, pos, float(fps))


def drop_tpose_frames(
    motion: Motion, max_frames: int = 3, jump_factor: float = 8.0
) -> tuple[Motion, int]:
    """Drop leading frames that do not belong to the captured motion.

    Some conversions put a T-pose (CMU's cgspeed release) or an all-zero frame (CMU 07_12) at the
    start. Detect, don't assume (DESIGN §4.1): a leading frame is dropped when the pose change to
    the next frame (largest joint displacement relative to the root, plus the root jump) is more
    than ``jump_factor`` times the clip's median frame-to-frame change. Only the first
    ``max_frames`` are examined, so a real discontinuity later in a clip is never cut.

    Returns:
        ``(clip without those frames, number dropped)``.
    """
    f = motion.num_frames
    if f < 4:
        return motion, 0
    pos = np.asarray(joint_positions(motion), np.float64)
    rel = pos - pos[:, :1]
    step = np.linalg.norm(rel[1:] - rel[:-1], axis=-1).max(axis=-1) + np.linalg.norm(
        pos[1:, 0] - pos[:-1, 0], axis=-1
    )
    typical = float(np.median(step[min(max_frames, len(step) - 1) :])) + 1e-6
    # The last big jump among the first steps ends the junk: CMU 07_12 has a T-pose and then an
    # all-zero frame, whose mutual difference is small but whose jump into the capture is not.
    jumps = np.nonzero(step[: min(max_frames, f - 2)] > jump_factor * typical)[0]
    dropped = int(jumps[-1]) + 1 if len(jumps) else 0
    if dropped == 0:
        return motion, 0
    return slice_frames(motion, dropped, f), dropped


def rest_forward(skeleton: Skeleton) -> np.ndarray:
    """The facing direction at rest, from the hips: ``normalize((left - right) × up)``.

    Uses the first left/right joint pair below the root (e.g. ``LeftUpLeg``/``RightUpLeg`` or
    ``lfemur``/``rfemur``); falls back to +Z when the skeleton has no such pair.
    """
    pairs = _side_pairs(skeleton.names)
    rest, _ = rest_positions(skeleton)
    for left, right in sorted(pairs, key=lambda lr: skeleton.depths[lr[0]]):
        across = rest[left] - rest[right]
        across[1] = 0.0
        if np.linalg.norm(across) > 1e-6:
            fwd = np.cross(across, [0.0, 1.0, 0.0])
            return fwd / np.linalg.norm(fwd)
    return np.array([0.0, 0.0, 1.0])


def headings(motion: Motion) -> Any:
    """Heading (yaw about +Y, radians) of the root per frame; 0 means facing +Z."""
    fwd = rest_forward(motion.skeleton)
    xp = array_module(motion.rotations)
    return quat_yaw(motion.rotations[:, 0], xp.asarray(fwd, dtype=motion.rotations.dtype))


def normalize_root(motion: Motion) -> Motion:
    """Move the clip so frame 0's root is above the origin and faces +Z (height kept).

    The root joint sits at ``root_position + offsets[0]``; the turn is about that point, so the
    clip moves rigidly whatever the root's offset.
    """
    xp = array_module(motion.rotations, motion.root_positions)
    yaw0 = headings(motion)[0]
    turn = yaw_quat(-yaw0)
    off0 = xp.asarray(motion.skeleton.offsets[0], dtype=motion.root_positions.dtype)
    root_joint = motion.root_positions + off0
    start = root_joint[0] * xp.asarray([1.0, 0.0, 1.0], dtype=motion.root_positions.dtype)
    pos = quat_rotate(turn, root_joint - start) - off0
    root = quat_mul(turn, motion.rotations[:, 0])
    rot = xp.concatenate([root[:, None], motion.rotations[:, 1:]], axis=1)
    return Motion(motion.skeleton, rot, pos, motion.fps)


_SIDE_RULES: tuple[tuple[str, str], ...] = (
    (r"Left", "Right"),
    (r"left", "right"),
    (r"LEFT", "RIGHT"),
    (r"^L(?=[A-Z_])", "R"),
    (r"^l(?=[a-z])", "r"),
    (r"_L$", "_R"),
    (r"\.L$", ".R"),
    (r"_l$", "_r"),
)


def _side_pairs(names: tuple[str, ...]) -> list[tuple[int, int]]:
    """``(left, right)`` index pairs: a rule maps the left name to an existing right one."""
    index = {n: i for i, n in enumerate(names)}
    pairs: list[tuple[int, int]] = []
    seen: set[int] = set()
    for i, name in enumerate(names):
        for pattern, repl in _SIDE_RULES:
            if re.search(pattern, name) is None:
                continue
            other = re.sub(pattern, repl, name, count=1)
            j = index.get(other)
            if j is not None and j != i and i not in seen and j not in seen:
                pairs.append((i, j))
                seen.update((i, j))
                break
    return pairs


def mirror_map(names: tuple[str, ...]) -> np.ndarray:
    """Permutation swapping every left joint with its right counterpart (others map to themselves).

    Names pair by these rules, on any skeleton: ``Left``/``Right`` anywhere (``LeftUpLeg``),
    a leading ``L``/``R`` before a capital or ``_`` (``LHipJoint``), a leading ``l``/``r`` before a
    lower-case letter (``lfemur``) and ``_L``/``.L`` suffixes. A name pairs only if its counterpart
    exists, so ``lowerback`` does not.
    """
    perm = np.arange(len(names))
    for left, right in _side_pairs(names):
        perm[left], perm[right] = right, left
    return perm


def left_right_pairs(names: tuple[str, ...]) -> list[tuple[int, int]]:
    """The ``(left, right)`` joint index pairs :func:`mirror_map` uses."""
    return _side_pairs(names)


def mirror(motion: Motion) -> Motion:
    """The left↔right mirror image of a clip, reflected across the character's sagittal plane.

    The reflection is ``x → -x`` (in the rest frame, where the character faces +Z); a rotation
    ``(w, x, y, z)`` reflects to ``(w, x, -y, -z)``, and each left joint takes its right
    counterpart's reflected rotation. The skeleton is kept (its offsets are assumed left/right
    symmetric, as in captured skeletons; the root's own offset need not be: the root joint at
    ``root_position + offsets[0]`` is what gets reflected). Mirroring twice gives the original.

    Reading taken: the reflection plane is the world YZ plane through the origin, which is the
    sagittal plane after :func:`normalize_root`; a mirrored clip therefore walks to ``-x``.
    """
    if len(_side_pairs(motion.skeleton.names)) == 0:
        raise MotionError(
            "mirror: expected left/right joint names (Left*/Right*, L*/R*, l*/r*), found none in "
            f"{list(motion.skeleton.names)}"
        )
    xp = array_module(motion.rotations, motion.root_positions)
    perm = mirror_map(motion.skeleton.names)
    sign_q = xp.asarray([1.0, 1.0, -1.0, -1.0], dtype=motion.rotations.dtype)
    sign_p = xp.asarray([-1.0, 1.0, 1.0], dtype=motion.root_positions.dtype)
    rot = motion.rotations[:, perm] * sign_q
    off0 = xp.asarray(motion.skeleton.offsets[0], dtype=motion.root_positions.dtype)
    pos = (motion.root_positions + off0) * sign_p - off0
    return Motion(motion.skeleton, quat_normalize(rot), pos, motion.fps)
