"""Alignment features: the mass model on both CMU skeletons, COM at rest, invariance to where a
clip is and which way it heads, closed-form COM accelerations, finiteness on every walk."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import load_clip64

from jcrowd.align import (
    DE_LEVA_MALE,
    body_segments,
    center_of_mass,
    physics_features,
    pose_features,
)
from jcrowd.align.features import GRAVITY, to_heading_frame
from jcrowd.errors import MotionError
from jcrowd.motion import (
    Motion,
    Skeleton,
    headings,
    joint_positions,
    quat_mul,
    quat_rotate,
    rest_positions,
    yaw_quat,
)


def _both(cmu_dir: Path, cmu16_dir: Path) -> list[Motion]:
    return [load_clip64(cmu_dir / "walk" / "07_01.bvh"), load_clip64(cmu16_dir / "16_15.bvh")]


def _moved(m: Motion, yaw: float, shift: np.ndarray) -> Motion:
    """The clip turned by ``yaw`` about +Y through the origin, then shifted by ``shift``."""
    q = yaw_quat(np.float64(yaw))
    root = quat_mul(np.broadcast_to(q, (m.num_frames, 4)), m.rotations[:, 0])
    rot = np.concatenate([root[:, None], m.rotations[:, 1:]], axis=1)
    off0 = np.asarray(m.skeleton.offsets[0], np.float64)
    pos = quat_rotate(np.broadcast_to(q, (m.num_frames, 4)), m.root_positions + off0)
    return Motion(m.skeleton, rot, pos + shift - off0, m.fps)


def test_de_leva_fractions_sum_to_one() -> None:
    total = sum(
        share * (2 if c not in ("head", "trunk") else 1) for c, (share, _) in DE_LEVA_MALE.items()
    )
    np.testing.assert_allclose(total, 1.0, atol=1e-12)


def test_both_cmu_skeletons_map_to_the_table(cmu_dir: Path, cmu16_dir: Path) -> None:
    for m in _both(cmu_dir, cmu16_dir):
        segs = body_segments(m.skeleton)
        assert not segs.fallback
        np.testing.assert_allclose(segs.mass.sum(), 1.0, atol=1e-12)
        assert np.all(segs.mass >= 0)
        for category, (share, _) in DE_LEVA_MALE.items():
            got = segs.mass[[s for s, c in enumerate(segs.category) if c == category]].sum()
            bilateral = category not in ("head", "trunk")
            # Both skeletons have every category, so nothing is rescaled: table values exactly.
            np.testing.assert_allclose(got, share * (2 if bilateral else 1), atol=1e-12)
            if bilateral:
                assert len(segs.select(category, "left")) and len(segs.select(category, "right"))


def test_unknown_names_spread_mass_by_bone_length() -> None:
    offsets = np.array([[0, 0, 0], [0, 1.0, 0], [0, 0.5, 0], [1.0, 0, 0]])
    skel = Skeleton(("a", "b", "c", "d"), (-1, 0, 1, 0), offsets)
    segs = body_segments(skel)
    assert segs.fallback
    np.testing.assert_allclose(segs.mass, [1.0 / 2.5, 0.5 / 2.5, 1.0 / 2.5])
    rest = Motion(skel, np.tile([1.0, 0, 0, 0], (1, 4, 1)), np.zeros((1, 3)), 30.0)
    # Uniform rods: midpoints (0, .5, 0), (0, 1.25, 0), (.5, 0, 0) weighted .4, .2, .4.
    np.testing.assert_allclose(center_of_mass(rest)[0], [0.2, 0.45, 0.0], atol=1e-12)
    with pytest.raises(MotionError, match="foot"):
        physics_features(Motion(skel, np.tile([1.0, 0, 0, 0], (5, 4, 1)), np.zeros((5, 3)), 30.0))
    com_only = physics_features(
        Motion(skel, np.tile([1.0, 0, 0, 0], (5, 4, 1)), np.zeros((5, 3)), 30.0), momentum=()
    )
    assert com_only.shape == (5, 3) and np.all(com_only == 0)


def test_com_at_rest_lies_between_hips_and_chest(cmu_dir: Path, cmu16_dir: Path) -> None:
    for m in _both(cmu_dir, cmu16_dir):
        skel = m.skeleton
        rest = Motion(skel, np.tile([1.0, 0, 0, 0], (1, skel.num_joints, 1)), np.zeros((1, 3)), 30)
        com = center_of_mass(rest)[0]
        joints, _ = rest_positions(skel)
        names = [n.lower() for n in skel.names]
        hip_names = ("leftupleg", "rightupleg", "lfemur", "rfemur")
        shoulder_names = ("leftarm", "rightarm", "lhumerus", "rhumerus")
        hips = [i for i, n in enumerate(names) if n in hip_names]
        chest = [i for i, n in enumerate(names) if n in shoulder_names]
        assert len(hips) == 2 and len(chest) == 2
        assert joints[hips, 1].mean() < com[1] < joints[chest, 1].mean()
        # Left/right symmetric skeletons: the COM is near the mid-sagittal plane (2 cm).
        assert abs(com[0] - joints[0, 0]) < 0.02


@pytest.mark.parametrize("kind", ["pose", "physics"])
def test_features_ignore_floor_position_and_heading(
    cmu_dir: Path, cmu16_dir: Path, kind: str
) -> None:
    f = pose_features if kind == "pose" else physics_features
    for m in _both(cmu_dir, cmu16_dir):
        base = f(m)
        for yaw, shift in [(0.7, np.array([3.0, 0.0, -2.0])), (-2.5, np.array([-10.0, 0.0, 4.0]))]:
            moved = f(_moved(m, yaw, shift))
            # float64 throughout; what is left is rounding in FK and the heading (1e-9 m or g).
            np.testing.assert_allclose(moved, base, atol=1e-9)


def test_pose_features_are_the_heading_frame_point_cloud(cmu_dir: Path) -> None:
    m = load_clip64(cmu_dir / "walk" / "07_01.bvh")
    feats = pose_features(m)
    pos = np.asarray(joint_positions(m))
    assert feats.shape == (m.num_frames, 3 * m.skeleton.num_joints)
    np.testing.assert_allclose(feats[:, :3], 0.0, atol=1e-12)  # the root itself
    # Lengths are kept by the turn.
    np.testing.assert_allclose(
        np.linalg.norm(feats.reshape(m.num_frames, -1, 3), axis=-1),
        np.linalg.norm(pos - pos[:, :1], axis=-1),
        atol=1e-12,
    )
    # The root's own forward direction, turned, points along +Z (x = 0).
    h = np.asarray(headings(m))
    fwd = np.stack([np.sin(h), np.zeros_like(h), np.cos(h)], axis=1)
    plus_z = np.tile([0.0, 0.0, 1.0], (len(h), 1))
    np.testing.assert_allclose(to_heading_frame(fwd, h), plus_z, atol=1e-12)
    w = np.random.default_rng(0).uniform(0, 2, m.skeleton.num_joints)
    fw = pose_features(m, weights=w)
    d2 = np.sum((fw[10] - fw[50]) ** 2)
    per_joint = np.sum((feats[10] - feats[50]).reshape(-1, 3) ** 2, axis=1)
    np.testing.assert_allclose(d2, np.sum(w * per_joint), rtol=1e-12)
    with pytest.raises(MotionError, match="weights"):
        pose_features(m, weights=-w)


def test_com_acceleration_of_a_pushed_clip(cmu_dir: Path) -> None:
    """Adding ``v t + ½ a t²`` to the root adds exactly ``a`` (in g, heading frame) to the COM
    acceleration away from the ends; momenta about the COM do not change (relative velocities)."""
    m = load_clip64(cmu_dir / "walk" / "07_01.bvh")
    t = np.arange(m.num_frames)[:, None] / m.fps
    v, a = np.array([0.5, 0.0, -1.0]), np.array([0.3, -0.2, 0.8])
    pushed = Motion(m.skeleton, m.rotations, m.root_positions + v * t + 0.5 * a * t**2, m.fps)
    base, moved = physics_features(m), physics_features(pushed)
    inner = slice(16, -16)  # beyond the smoothing kernel (4σ = 12 frames) and two differences
    expected = to_heading_frame(np.broadcast_to(a / GRAVITY, (m.num_frames, 3)), headings(m))
    # The Gaussian of a quadratic is the quadratic plus a constant; differences are exact for
    # quadratics: only rounding remains (1e-9 g).
    np.testing.assert_allclose(moved[inner, :3] - base[inner, :3], expected[inner], atol=1e-9)
    np.testing.assert_allclose(moved[:, 3:], base[:, 3:], atol=1e-9)


def test_physics_features_finite_on_every_walk(cmu_dir: Path, cmu16_dir: Path) -> None:
    paths = sorted((cmu_dir / "walk").glob("*.bvh")) + sorted(cmu16_dir.glob("*.bvh"))
    assert len(paths) == 26 + 22
    for path in paths:
        m = load_clip64(path)
        f = physics_features(m)
        assert f.shape == (m.num_frames, 15), path.name
        assert np.all(np.isfinite(f)), path.name
        # Walking: the COM accelerates by well under 1 g (measured: 99th percentiles 0.2–0.5 g)
        # and the scaled momenta are of the same order (0.3–0.55), the balance the scaling aims
        # for. A percentile, not the maximum: 08_07 starts with five frozen frames and a 9 cm
        # root jump (a capture artefact drop_tpose_frames keeps), a 4 g spike in the data.
        assert np.percentile(np.abs(f[:, :3]), 95) < 1.0, path.name
        assert np.percentile(np.abs(f[:, 3:]), 99) < 1.0, path.name
        assert np.all(np.isfinite(physics_features(m, about="joint", momentum=("foot",))))


def test_physics_features_reject_bad_arguments(cmu_dir: Path) -> None:
    m = load_clip64(cmu_dir / "walk" / "07_01.bvh")
    with pytest.raises(MotionError, match="about"):
        physics_features(m, about="world")  # type: ignore[arg-type]
    with pytest.raises(MotionError, match="at least 3 frames"):
        physics_features(Motion(m.skeleton, m.rotations[:2], m.root_positions[:2], m.fps))
