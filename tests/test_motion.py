"""Tests for jcrowd.motion.clip: the Motion model and the clip operations, on synthetic clips.

Clips here are built from closed forms (joint angles that are sines of time, a root moving at
constant velocity), so each operation's answer is known without the library: resampling a
constant-angular-velocity clip must give the rotation at the new times, mirroring must equal
reflecting the joint positions, normalising the root must be a rigid motion.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.distance import pdist
from scipy.spatial.transform import Rotation

from jcrowd.errors import MotionError
from jcrowd.motion import (
    Motion,
    Skeleton,
    drop_tpose_frames,
    forward_kinematics,
    headings,
    joint_positions,
    mirror,
    mirror_map,
    normalize_root,
    resample,
    rest_forward,
    slice_frames,
)

TOL64 = 1e-12  # NumPy float64 paths: rounding only


def wrap(angle):
    """Angle wrapped into (-π, π]."""
    return np.angle(np.exp(1j * np.asarray(angle, np.float64)))


def sign_free_error(a, b) -> np.ndarray:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.minimum(np.abs(a - b).max(axis=-1), np.abs(a + b).max(axis=-1))


# ---------------------------------------------------------------------------------------------
# Synthetic skeletons: left side at +X (the character faces +Z), right side its mirror image
# ---------------------------------------------------------------------------------------------


def symmetric_skeleton(root, center, sided, root_offset=(0.0, 0.0, 0.0)) -> Skeleton:
    """A left/right symmetric skeleton.

    Args:
        root: the root's name.
        center: ``(name, parent, offset)`` joints on the midline (offset x = 0).
        sided: ``(left, right, parent, left_offset)``; the right joint hangs from the right
            counterpart of the parent (or the same midline parent) with x negated.
    """
    names, parents, offsets = [root], [-1], [root_offset]
    for name, parent, off in center:
        names.append(name)
        parents.append(names.index(parent))
        offsets.append(off)
    right_of = {}
    for left, right, parent, off in sided:
        names.append(left)
        parents.append(names.index(parent))
        offsets.append(off)
        right_of[left] = (right, right_of.get(parent, (parent,))[0], (-off[0], off[1], off[2]))
    for left, *_ in sided:
        right, parent, off = right_of[left]
        names.append(right)
        parents.append(names.index(parent))
        offsets.append(off)
    return Skeleton(tuple(names), tuple(parents), np.array(offsets, np.float64))


def skeleton_left_right(root_offset=(0.0, 0.0, 0.0)) -> Skeleton:
    return symmetric_skeleton(
        "Hips",
        [
            ("Spine", "Hips", (0, 0.1, 0)),
            ("Neck", "Spine", (0, 0.4, 0)),
            ("Head", "Neck", (0, 0.1, 0.03)),
        ],
        [
            ("LeftUpLeg", "RightUpLeg", "Hips", (0.1, -0.05, 0)),
            ("LeftLeg", "RightLeg", "LeftUpLeg", (0, -0.45, 0.01)),
            ("LeftFoot", "RightFoot", "LeftLeg", (0, -0.42, -0.03)),
            ("LeftToeBase", "RightToeBase", "LeftFoot", (0, -0.05, 0.13)),
            ("LeftArm", "RightArm", "Neck", (0.18, -0.05, 0)),
            ("LeftForeArm", "RightForeArm", "LeftArm", (0.28, 0, 0)),
            ("LeftHand", "RightHand", "LeftForeArm", (0.25, 0, 0)),
        ],
        root_offset,
    )


def skeleton_cmu16() -> Skeleton:
    return symmetric_skeleton(
        "pelvis",
        [("thorax", "pelvis", (0, 0.4, 0)), ("head", "thorax", (0, 0.2, 0.02))],
        [
            ("lfemur", "rfemur", "pelvis", (0.1, -0.06, 0)),
            ("ltibia", "rtibia", "lfemur", (0, -0.44, 0)),
            ("lfoot", "rfoot", "ltibia", (0, -0.43, 0)),
            ("ltoes", "rtoes", "lfoot", (0, -0.04, 0.12)),
            ("lclavicle", "rclavicle", "thorax", (0.05, 0.02, 0)),
            ("lhumerus", "rhumerus", "lclavicle", (0.15, 0, 0)),
            ("lradius", "rradius", "lhumerus", (0.28, 0, 0)),
            ("lhand", "rhand", "lradius", (0.24, 0, 0)),
        ],
    )


def skeleton_hip_joint() -> Skeleton:
    # CMU layout: LHipJoint has a zero offset, so the hips' width sits on LeftUpLeg.
    return symmetric_skeleton(
        "Hips",
        [("LowerBack", "Hips", (0, 0.1, 0)), ("Spine", "LowerBack", (0, 0.2, 0))],
        [
            ("LHipJoint", "RHipJoint", "Hips", (0.0, 0, 0)),
            ("LeftUpLeg", "RightUpLeg", "LHipJoint", (0.1, -0.08, 0.02)),
            ("LeftLeg", "RightLeg", "LeftUpLeg", (0, -0.43, 0)),
            ("LeftShoulder", "RightShoulder", "Spine", (0.04, 0.2, 0)),
            ("LeftArm", "RightArm", "LeftShoulder", (0.16, 0, 0)),
            ("LThumb", "RThumb", "LeftArm", (0.4, 0, 0.03)),
        ],
    )


SKELETONS = {
    "LeftRight": skeleton_left_right,
    "cmu16": skeleton_cmu16,
    "LHipJoint": skeleton_hip_joint,
}


def axis_angle(axis, angle) -> np.ndarray:
    """(w, x, y, z) of rotations by ``angle (...)`` about unit ``axis (3,)``, via SciPy."""
    angle = np.asarray(angle, np.float64)
    rotvec = angle[..., None] * np.asarray(axis, np.float64)
    return (
        Rotation.from_rotvec(rotvec.reshape(-1, 3))
        .as_quat(scalar_first=True)
        .reshape(*angle.shape, 4)
    )


def smooth_clip(skeleton: Skeleton, frames: int = 90, fps: float = 60.0, seed: int = 0) -> Motion:
    """A walk-like clip: each joint swings about a fixed axis around a bent rest pose, the root
    turns slowly and moves forward; everything is smooth at the frame rate."""
    rng = np.random.default_rng(seed)
    j = skeleton.num_joints
    t = np.arange(frames) / fps
    axes = rng.normal(size=(j, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    # A bent base pose (up to ~1.2 rad from rest) plus a 1 Hz swing of up to 0.4 rad.
    base = rng.uniform(0.5, 1.2, size=j)
    amp = rng.uniform(0.1, 0.4, size=j)
    phase = rng.uniform(0, 2 * np.pi, size=j)
    angles = base + amp * np.sin(2 * np.pi * t[:, None] + phase)
    rot = np.stack([axis_angle(axes[k], angles[:, k]) for k in range(j)], axis=1)
    rot[:, 0] = axis_angle([0.0, 1.0, 0.0], 0.7 + 0.3 * t)  # root: heading turns at 0.3 rad/s
    root = np.stack([2.0 + 1.2 * t, 0.9 + 0.02 * np.sin(4 * np.pi * t), -1.0 + 0.4 * t], -1)
    return Motion(skeleton, rot, root, fps)


def as_float32_jax(m: Motion) -> Motion:
    skel = Skeleton(
        m.skeleton.names, m.skeleton.parents, jnp.asarray(m.skeleton.offsets, jnp.float32)
    )
    return Motion(
        skel,
        jnp.asarray(m.rotations, jnp.float32),
        jnp.asarray(m.root_positions, jnp.float32),
        m.fps,
    )


def reflect_x(p):
    return np.asarray(p) * np.array([-1.0, 1.0, 1.0])


# ---------------------------------------------------------------------------------------------
# The Motion model
# ---------------------------------------------------------------------------------------------


def test_motion_properties():
    clip = smooth_clip(skeleton_cmu16(), frames=61, fps=30.0)
    assert clip.num_frames == 61
    assert clip.duration == pytest.approx(2.0)
    np.testing.assert_allclose(
        joint_positions(clip),
        forward_kinematics(clip.skeleton, clip.rotations, clip.root_positions)[1],
    )


@pytest.mark.parametrize(
    ("rot_shape", "pos_shape", "fps", "match"),
    [
        ((10, 18, 4), (10, 3), 30.0, r"rotations of shape \(F, 19, 4\)"),
        ((10, 19, 3), (10, 3), 30.0, r"rotations of shape \(F, 19, 4\)"),
        ((19, 4), (10, 3), 30.0, r"rotations of shape \(F, 19, 4\)"),
        ((10, 19, 4), (9, 3), 30.0, r"root positions of shape \(10, 3\)"),
        ((10, 19, 4), (10, 2), 30.0, r"root positions of shape \(10, 3\)"),
        ((10, 19, 4), (10, 3), 0.0, "positive frame rate"),
        ((10, 19, 4), (10, 3), -30.0, "positive frame rate"),
    ],
)
def test_motion_validation(rot_shape, pos_shape, fps, match):
    with pytest.raises(MotionError, match=match):
        Motion(skeleton_cmu16(), np.zeros(rot_shape), np.zeros(pos_shape), fps)


def test_slice_frames():
    clip = smooth_clip(skeleton_cmu16(), frames=30)
    part = slice_frames(clip, 5, 12)
    assert part.num_frames == 7 and part.fps == clip.fps and part.skeleton is clip.skeleton
    np.testing.assert_array_equal(part.rotations, clip.rotations[5:12])
    np.testing.assert_array_equal(part.root_positions, clip.root_positions[5:12])


# ---------------------------------------------------------------------------------------------
# resample
# ---------------------------------------------------------------------------------------------


def constant_spin_clip(fps: float, frames: int, omega: float, axis) -> Motion:
    """Every joint turns at ``omega`` rad/s about ``axis``; the root moves at constant velocity."""
    skel = skeleton_cmu16()
    t = np.arange(frames) / fps
    q = axis_angle(axis, omega * t)
    rot = np.repeat(q[:, None], skel.num_joints, axis=1)
    root = np.array([0.3, 0.9, -1.2]) + t[:, None] * np.array([1.1, 0.0, 0.4])
    return Motion(skel, rot, root, fps)


@pytest.mark.parametrize(
    ("src_fps", "dst_fps"), [(120.0, 30.0), (30.0, 120.0), (120.0, 50.0), (24.0, 60.0)]
)
def test_resample_matches_closed_form(src_fps, dst_fps):
    # 2 s of a 3 rad/s spin: consecutive source frames differ by ≤ 0.125 rad, so slerp between
    # them is the exact rotation at the new time; the root is linear in t, so lerp is exact.
    axis = np.array([0.48, 0.6, 0.64])
    clip = constant_spin_clip(src_fps, int(2 * src_fps) + 1, 3.0, axis)
    out = resample(clip, dst_fps)
    assert out.fps == dst_fps
    assert out.num_frames == int(2 * dst_fps) + 1
    t = np.arange(out.num_frames) / dst_fps
    expect = axis_angle(axis, 3.0 * t)
    # Slerp is exact (1e-12, float64 rounding) except for arcs under 0.0632 rad, where
    # quat_slerp uses normalised lerp: its angle error is ≤ 1.02e-6·(arc/0.0632)³ rad (closed
    # form, see test_rotation), i.e. ≤ 6.4e-8 rad for the 0.025 rad steps of a 120 fps source.
    arc = 3.0 / src_fps
    tol = 1e-12 + (1.02e-6 * (arc / 0.0632) ** 3 if arc < 0.0632 else 0.0)
    err = 2 * np.arcsin(np.minimum(1.0, sign_free_error(out.rotations, expect[:, None]))).max()
    assert err < tol, (err, tol)
    np.testing.assert_allclose(
        out.root_positions, clip.root_positions[0] + t[:, None] * [1.1, 0.0, 0.4], atol=1e-12
    )
    # Endpoints preserved.
    np.testing.assert_allclose(out.rotations[[0, -1]], clip.rotations[[0, -1]], atol=1e-12)
    np.testing.assert_allclose(
        out.root_positions[[0, -1]], clip.root_positions[[0, -1]], atol=1e-12
    )


def test_resample_same_fps_is_identity():
    clip = smooth_clip(skeleton_left_right(), frames=40)
    out = resample(clip, clip.fps)
    assert out.num_frames == clip.num_frames
    np.testing.assert_allclose(out.rotations, clip.rotations, atol=TOL64, rtol=0)
    np.testing.assert_allclose(out.root_positions, clip.root_positions, atol=TOL64, rtol=0)


def test_resample_keeps_duration_when_not_a_whole_number_of_frames():
    clip = constant_spin_clip(30.0, 31, 1.0, [0.0, 1.0, 0.0])  # 1 s
    out = resample(clip, 7.5)  # 7.5 frames per second: t = 0, 0.133, ..., 0.933
    assert out.num_frames == 8
    assert out.duration <= clip.duration


def test_resample_bad_fps_raises():
    clip = constant_spin_clip(30.0, 5, 1.0, [0.0, 1.0, 0.0])
    with pytest.raises(MotionError, match="positive frame rate"):
        resample(clip, 0.0)


# ---------------------------------------------------------------------------------------------
# drop_tpose_frames
# ---------------------------------------------------------------------------------------------


def prepend(clip: Motion, rot, root) -> Motion:
    return Motion(
        clip.skeleton,
        np.concatenate([rot[None], clip.rotations]),
        np.concatenate([root[None], clip.root_positions]),
        clip.fps,
    )


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_drop_tpose_drops_a_prepended_wild_pose(name):
    clip = smooth_clip(SKELETONS[name](), seed=1)
    wild = np.random.default_rng(2).normal(size=(clip.skeleton.num_joints, 4))
    wild /= np.linalg.norm(wild, axis=-1, keepdims=True)
    out, dropped = drop_tpose_frames(prepend(clip, wild, clip.root_positions[0]))
    assert dropped == 1
    np.testing.assert_array_equal(out.rotations, clip.rotations)
    np.testing.assert_array_equal(out.root_positions, clip.root_positions)


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_drop_tpose_drops_a_prepended_zero_rotation_frame(name):
    # An all-zero-rotation (rest / T-pose) frame, at the clip's first root position.
    clip = smooth_clip(SKELETONS[name](), seed=3)
    rest = np.tile([1.0, 0.0, 0.0, 0.0], (clip.skeleton.num_joints, 1))
    out, dropped = drop_tpose_frames(prepend(clip, rest, clip.root_positions[0]))
    assert dropped == 1
    np.testing.assert_array_equal(out.rotations, clip.rotations)


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_drop_tpose_keeps_a_clean_clip(name):
    clip = smooth_clip(SKELETONS[name](), seed=4)
    out, dropped = drop_tpose_frames(clip)
    assert dropped == 0
    assert out.num_frames == clip.num_frames


def test_drop_tpose_does_not_cut_a_later_discontinuity():
    clip = smooth_clip(skeleton_left_right(), seed=5)
    rot = np.array(clip.rotations)
    rot[20:] = smooth_clip(skeleton_left_right(), seed=6).rotations[20:]  # a cut at frame 20
    root = np.array(clip.root_positions)
    root[40:] += [0.0, 0.0, 3.0]  # and a teleport at frame 40
    jumpy = Motion(clip.skeleton, rot, root, clip.fps)
    pos = np.asarray(joint_positions(jumpy))
    assert np.linalg.norm(pos[20] - pos[19], axis=-1).max() > 0.3  # the cut is real
    out, dropped = drop_tpose_frames(jumpy)
    assert dropped == 0 and out.num_frames == clip.num_frames


def test_drop_tpose_on_a_very_short_clip_drops_nothing():
    clip = slice_frames(smooth_clip(skeleton_cmu16()), 0, 3)
    assert drop_tpose_frames(clip) == (clip, 0)


# ---------------------------------------------------------------------------------------------
# rest_forward, headings, normalize_root
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_rest_forward_with_left_hip_at_plus_x_is_plus_z(name):
    np.testing.assert_allclose(rest_forward(SKELETONS[name]()), [0.0, 0.0, 1.0], atol=TOL64)


def test_rest_forward_follows_the_hips():
    # The same skeleton turned by 90° about +Y at rest (left hip at -Z) faces +X; with the sides
    # swapped (left at -X) it faces -Z.
    skel = skeleton_left_right()
    turn = Rotation.from_euler("y", [np.pi / 2])
    turned = Skeleton(skel.names, skel.parents, turn.apply(np.asarray(skel.offsets)))
    np.testing.assert_allclose(rest_forward(turned), [1.0, 0.0, 0.0], atol=TOL64)
    swapped = Skeleton(skel.names, skel.parents, reflect_x(skel.offsets))
    np.testing.assert_allclose(rest_forward(swapped), [0.0, 0.0, -1.0], atol=TOL64)
    # No left/right names: the documented fallback is +Z.
    plain = Skeleton(("a", "b"), (-1, 0), np.array([[0.0, 0, 0], [0.3, 0, 0]]))
    np.testing.assert_array_equal(rest_forward(plain), [0.0, 0.0, 1.0])


def test_headings_closed_form():
    skel = skeleton_cmu16()
    frames = 50
    yaw = np.linspace(-3.0, 3.0, frames)
    # Root turned by yaw and tilted by a pitch/roll: the heading is the yaw of the rotated
    # forward direction, atan2(f_x, f_z).
    tilt = Rotation.from_rotvec(np.random.default_rng(7).normal(size=(frames, 3)) * 0.3)
    root = Rotation.from_euler("y", yaw[:, None]) * tilt
    rot = np.tile([1.0, 0.0, 0.0, 0.0], (frames, skel.num_joints, 1))
    rot[:, 0] = root.as_quat(scalar_first=True)
    clip = Motion(skel, rot, np.zeros((frames, 3)), 30.0)
    f = root.apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(wrap(headings(clip) - np.arctan2(f[:, 0], f[:, 2])), 0.0, atol=TOL64)
    # Pure yaw: heading = yaw.
    rot[:, 0] = Rotation.from_euler("y", yaw[:, None]).as_quat(scalar_first=True)
    np.testing.assert_allclose(
        headings(Motion(skel, rot, np.zeros((frames, 3)), 30.0)), yaw, atol=1e-12
    )


@pytest.mark.parametrize("root_offset", [(0.0, 0.0, 0.0), (0.3, 0.1, -0.2)])
def test_normalize_root(root_offset):
    clip = smooth_clip(skeleton_left_right(root_offset), seed=8)
    out = normalize_root(clip)
    before, after = np.asarray(joint_positions(clip)), np.asarray(joint_positions(out))
    # Frame 0: root joint above the origin, facing +Z, at the same height.
    np.testing.assert_allclose(after[0, 0, [0, 2]], 0.0, atol=TOL64)
    assert abs(headings(out)[0]) < TOL64
    np.testing.assert_allclose(after[:, 0, 1], before[:, 0, 1], atol=TOL64)
    np.testing.assert_allclose(out.root_positions[:, 1], clip.root_positions[:, 1], atol=TOL64)
    # Every frame turned by the same yaw.
    np.testing.assert_allclose(
        wrap(headings(out) - headings(clip) + headings(clip)[0]), 0.0, atol=1e-12
    )
    # The whole clip moved rigidly: all distances between all joints of all frames are kept
    # (1e-12: float64, distances of a few metres).
    np.testing.assert_allclose(
        pdist(after.reshape(-1, 3)), pdist(before.reshape(-1, 3)), atol=1e-12
    )
    # Non-root joints' local rotations are untouched.
    np.testing.assert_array_equal(out.rotations[:, 1:], clip.rotations[:, 1:])


# ---------------------------------------------------------------------------------------------
# mirror and mirror_map
# ---------------------------------------------------------------------------------------------


CMU_NAMES = tuple(
    "Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg RightFoot "
    "RightToeBase LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm LeftForeArm LeftHand "
    "LeftFingerBase LeftHandIndex1 LThumb RightShoulder RightArm RightForeArm RightHand "
    "RightFingerBase RightHandIndex1 RThumb".split()
)
CMU_PAIRS = [
    ("LHipJoint", "RHipJoint"),
    ("LeftUpLeg", "RightUpLeg"),
    ("LeftLeg", "RightLeg"),
    ("LeftFoot", "RightFoot"),
    ("LeftToeBase", "RightToeBase"),
    ("LeftShoulder", "RightShoulder"),
    ("LeftArm", "RightArm"),
    ("LeftForeArm", "RightForeArm"),
    ("LeftHand", "RightHand"),
    ("LeftFingerBase", "RightFingerBase"),
    ("LeftHandIndex1", "RightHandIndex1"),
    ("LThumb", "RThumb"),
]
CMU16_NAMES = tuple(
    "pelvis lfemur ltibia lfoot ltoes rfemur rtibia rfoot rtoes thorax head lclavicle lhumerus "
    "lradius lhand rclavicle rhumerus rradius rhand".split()
)
CMU16_PAIRS = [(n, "r" + n[1:]) for n in CMU16_NAMES if n.startswith("l")]


def expected_perm(names, pairs) -> np.ndarray:
    perm = np.arange(len(names))
    for left, right in pairs:
        perm[names.index(left)], perm[names.index(right)] = names.index(right), names.index(left)
    return perm


@pytest.mark.parametrize(
    ("names", "pairs", "alone"),
    [
        (CMU_NAMES, CMU_PAIRS, {"Hips", "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head"}),
        (CMU16_NAMES, CMU16_PAIRS, {"pelvis", "thorax", "head"}),
    ],
)
def test_mirror_map_on_real_names(names, pairs, alone):
    assert len(pairs) == (len(names) - len(alone)) // 2
    perm = mirror_map(names)
    np.testing.assert_array_equal(perm, expected_perm(names, pairs))
    np.testing.assert_array_equal(perm[perm], np.arange(len(names)))  # an involution
    for name in alone:
        assert perm[names.index(name)] == names.index(name)


def test_mirror_map_other_conventions():
    names = (
        "root",
        "lowerback",
        "arm_L",
        "arm_R",
        "leg.L",
        "leg.R",
        "leftHand",
        "rightHand",
        "LEFT_EYE",
        "RIGHT_EYE",
    )
    perm = mirror_map(names)
    np.testing.assert_array_equal(perm, [0, 1, 3, 2, 5, 4, 7, 6, 9, 8])


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_mirror_twice_is_identity(name):
    clip = smooth_clip(SKELETONS[name](), seed=9)
    twice = mirror(mirror(clip))
    np.testing.assert_allclose(twice.rotations, clip.rotations, atol=1e-12)
    np.testing.assert_allclose(twice.root_positions, clip.root_positions, atol=1e-12)


@pytest.mark.parametrize("name", sorted(SKELETONS))
@pytest.mark.parametrize("root_offset_x", [0.0, 0.25])
def test_mirror_reflects_joint_positions_and_swaps_sides(name, root_offset_x):
    skel = SKELETONS[name]()
    off = np.array(skel.offsets)
    off[0] = [root_offset_x, 0.05, 0.1]  # the root's own offset need not be symmetric
    skel = Skeleton(skel.names, skel.parents, off)
    clip = smooth_clip(skel, seed=10)
    out = mirror(clip)
    perm = mirror_map(skel.names)
    assert (perm != np.arange(len(perm))).any()
    # A left joint takes its right counterpart's rotation, reflected: (w, x, -y, -z).
    for left, right in [(i, p) for i, p in enumerate(perm) if i < p]:
        np.testing.assert_allclose(
            out.rotations[:, left], clip.rotations[:, right] * [1, 1, -1, -1], atol=TOL64
        )
        np.testing.assert_allclose(
            out.rotations[:, right], clip.rotations[:, left] * [1, 1, -1, -1], atol=TOL64
        )
    # The root joint is reflected across x = 0.
    before, after = np.asarray(joint_positions(clip)), np.asarray(joint_positions(out))
    np.testing.assert_allclose(after[:, 0], reflect_x(before[:, 0]), atol=TOL64)
    if root_offset_x == 0.0:
        np.testing.assert_allclose(out.root_positions, reflect_x(clip.root_positions), atol=TOL64)
    # Every joint of the mirror is the reflection of its counterpart in the original
    # (1e-12: float64 FK of the same chain of products in mirrored form).
    np.testing.assert_allclose(after, reflect_x(before[:, perm]), atol=1e-12)
    # Heading mirrors too: yaw -> -yaw.
    np.testing.assert_allclose(wrap(headings(out) + headings(clip)), 0.0, atol=1e-12)


def test_mirror_without_sides_raises():
    skel = Skeleton(("root", "spine", "head"), (-1, 0, 1), np.zeros((3, 3)))
    clip = Motion(skel, np.tile([1.0, 0, 0, 0], (4, 3, 1)), np.zeros((4, 3)), 30.0)
    with pytest.raises(MotionError, match="left/right joint names"):
        mirror(clip)


# ---------------------------------------------------------------------------------------------
# jnp float32 in: every operation runs under strict dtype promotion and returns jax arrays
# ---------------------------------------------------------------------------------------------


def test_operations_on_float32_jax_clips_match_numpy():
    clip64 = smooth_clip(skeleton_hip_joint(), frames=24, fps=30.0, seed=11)
    clip = as_float32_jax(clip64)
    # Float32 vs float64 of the same clip: positions of a few metres, ~1e-6 rounding; 1e-5 m.
    for op in (normalize_root, mirror, lambda m: resample(m, 60.0)):
        out, ref = op(clip), op(clip64)
        assert isinstance(out.rotations, jax.Array) and out.rotations.dtype == jnp.float32
        assert isinstance(out.root_positions, jax.Array) and out.root_positions.dtype == jnp.float32
        assert sign_free_error(out.rotations, ref.rotations).max() < 1e-5
        np.testing.assert_allclose(out.root_positions, ref.root_positions, atol=1e-5)
    h = headings(clip)
    assert isinstance(h, jax.Array) and h.dtype == jnp.float32
    np.testing.assert_allclose(h, headings(clip64), atol=1e-5)
    _, dropped = drop_tpose_frames(clip)
    assert dropped == 0


def test_motion_is_a_pytree_for_jit():
    clip = as_float32_jax(smooth_clip(skeleton_cmu16(), frames=8))

    @jax.jit
    def shift(m: Motion) -> Motion:
        return Motion(m.skeleton, m.rotations, m.root_positions + 1.0, m.fps)

    out = shift(clip)
    assert out.fps == clip.fps and out.skeleton.names == clip.skeleton.names
    np.testing.assert_allclose(out.root_positions, clip.root_positions + 1.0)
