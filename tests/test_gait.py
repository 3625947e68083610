"""Foot contacts and gait cycles: real captures of two skeletons, invariances, synthetic signals."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from helpers import load_clip

from jcrowd.errors import MotionError
from jcrowd.motion import (
    Motion,
    Skeleton,
    mirror,
    normalize_root,
    quat_mul,
    quat_rotate,
    resample,
    yaw_quat,
)
from jcrowd.motion.gait import (
    ContactThresholds,
    _hysteresis,
    character_height,
    find_feet,
    foot_contacts,
    gait_cycles,
)


def _walks(cmu_dir: Path, cmu16_dir: Path) -> list[Path]:
    return sorted((cmu_dir / "walk").glob("*.bvh")) + sorted(cmu16_dir.glob("*.bvh"))


def test_every_walk_has_sane_cycles(cmu_dir: Path, cmu16_dir: Path) -> None:
    walks = _walks(cmu_dir, cmu16_dir)
    assert len(walks) == 26 + 22
    for path in walks:
        cycles = gait_cycles(load_clip(path), foot="both")
        assert len(cycles) >= 1, path.name
        for c in cycles:
            # Human walking cycles (two steps) last ~0.8–1.6 s; 0.7–1.8 s is the band.
            assert 0.7 <= c.duration <= 1.8, (path.name, c)
            assert c.foot in ("left", "right")
        forward = [c for c in cycles if path.stem != "09_12"]  # 09_12 also walks backwards
        for c in forward:
            assert c.dz > 0.3, (path.name, c)


def test_07_01_reports_two_cycles(cmu_dir: Path) -> None:
    cycles = gait_cycles(load_clip(cmu_dir / "walk" / "07_01.bvh"), foot="both")
    assert len(cycles) >= 2
    assert all(0.8 <= c.dz <= 2.0 for c in cycles)
    # Left-started cycles alone: the clip holds one full left-to-left cycle.
    assert [c.foot for c in gait_cycles(load_clip(cmu_dir / "walk" / "07_01.bvh"))] == ["left"]


def test_cmu16_turns_are_seen_with_their_sign(cmu16_dir: Path) -> None:
    with open(cmu16_dir / "index.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    turns = [r for r in rows if "90-degree" in r["cmu_description"]]
    assert len(turns) >= 4
    for row in turns:
        cycles = gait_cycles(load_clip(cmu16_dir / row["file"]), foot="both")
        biggest = max(cycles, key=lambda c: abs(c.dyaw))
        assert abs(np.degrees(biggest.dyaw)) > 60, row["file"]
        left = "left" in row["cmu_description"]
        # + yaw turns +Z towards +X, the character's left (DESIGN §3).
        assert (biggest.dyaw > 0) == left, (row["file"], biggest.dyaw)


def test_mirror_flips_turn_and_side(cmu16_dir: Path) -> None:
    clip = normalize_root(load_clip(cmu16_dir / "16_15.bvh"))  # a straight walk
    orig = gait_cycles(clip, foot="both")
    mirr = gait_cycles(mirror(clip), foot="both")
    assert len(orig) == len(mirr)
    for a, b in zip(orig, mirr, strict=True):
        # The mirror's left foot is the original's right: same frames, other foot.
        assert (a.start, a.end) == (b.start, b.end)
        assert a.foot != b.foot
        # Exact up to float32 rounding of the mirrored quaternions.
        assert b.dyaw == pytest.approx(-a.dyaw, abs=1e-4)
        assert b.dx == pytest.approx(-a.dx, abs=1e-4)
        assert b.dz == pytest.approx(a.dz, abs=1e-4)
    straight = [c for c in orig if abs(c.dyaw) > np.radians(0.5)]
    assert straight, "a straight walk still has a small nonzero heading change per cycle"
    for a in straight:
        b = next(m for m in mirr if m.start == a.start)
        assert np.sign(a.dyaw) == -np.sign(b.dyaw)


def _moved(motion: Motion, yaw: float, shift: np.ndarray) -> Motion:
    """The clip turned by ``yaw`` about +Y and shifted: the world frame changes, not the walk."""
    q = yaw_quat(np.float64(yaw))
    rot = np.asarray(motion.rotations, np.float64).copy()
    rot[:, 0] = quat_mul(np.broadcast_to(q, rot[:, 0].shape), rot[:, 0])
    pos = quat_rotate(q, np.asarray(motion.root_positions, np.float64)) + shift
    return Motion(motion.skeleton, rot.astype(np.float32), pos.astype(np.float32), motion.fps)


def test_cycles_do_not_depend_on_the_world_frame(cmu_dir: Path) -> None:
    clip = load_clip(cmu_dir / "walk" / "07_03.bvh")
    base = gait_cycles(clip, foot="both")
    moved = gait_cycles(_moved(clip, 2.1, np.array([5.0, 0.0, -3.0])), foot="both")
    assert [(c.start, c.end, c.foot) for c in base] == [(c.start, c.end, c.foot) for c in moved]
    for a, b in zip(base, moved, strict=True):
        # float32 positions ~5 m from the origin: ~1e-6 relative, so 1e-4 m/rad is generous.
        assert (a.dx, a.dz, a.dyaw) == pytest.approx((b.dx, b.dz, b.dyaw), abs=1e-4)


def test_cycles_survive_resampling(cmu_dir: Path) -> None:
    clip = load_clip(cmu_dir / "walk" / "07_06.bvh")
    base = gait_cycles(clip)
    half = gait_cycles(resample(clip, 60.0))
    assert len(half) == len(base)
    for a, b in zip(base, half, strict=True):
        # Strikes move by at most a frame of the coarser rate (1/60 s): at ~1.3 m/s that is
        # ~2 cm of displacement at each end of the cycle.
        assert abs(a.start / 120 - b.start / 60) <= 2 / 60
        assert a.dz == pytest.approx(b.dz, abs=0.05)


def test_feet_are_found_on_both_skeletons(cmu_dir: Path, cmu16_dir: Path) -> None:
    cmu = load_clip(cmu_dir / "walk" / "07_01.bvh").skeleton
    f = find_feet(cmu)
    names = [cmu.names[i] for i in (f.left_ankle, f.left_toe, f.right_ankle, f.right_toe)]
    assert names == ["LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase"]
    c16 = load_clip(cmu16_dir / "16_15.bvh").skeleton
    f = find_feet(c16)
    names = [c16.names[i] for i in (f.left_ankle, f.left_toe, f.right_ankle, f.right_toe)]
    assert names == ["lfoot", "ltoes", "rfoot", "rtoes"]
    # CMU people are 1.4–1.9 m tall; these conversions' rest skeletons measure ~1.4 m.
    assert 1.2 < character_height(cmu) < 2.0
    assert 1.2 < character_height(c16) < 2.0


def test_feet_fall_back_to_the_lowest_side_joints() -> None:
    # Names pair through the leading L/R rule but say nothing about feet.
    names = ("root", "L_hip", "L_knee", "L_sole", "R_hip", "R_knee", "R_sole")
    parents = (-1, 0, 1, 2, 0, 4, 5)
    off = np.array(
        [
            [0, 1, 0],
            [0.1, 0, 0],
            [0, -0.45, 0],
            [0, -0.45, 0.05],
            [-0.1, 0, 0],
            [0, -0.45, 0],
            [0, -0.45, 0.05],
        ],
        np.float32,
    )
    f = find_feet(Skeleton(names, parents, off))
    assert (f.left_toe, f.left_ankle, f.right_toe, f.right_ankle) == (3, 2, 6, 5)
    with pytest.raises(MotionError, match="left/right joint names"):
        find_feet(Skeleton(("a", "b"), (-1, 0), np.zeros((2, 3), np.float32)))


def test_hysteresis_does_not_flicker_at_a_threshold() -> None:
    t = ContactThresholds()
    rng = np.random.default_rng(0)
    # A planted joint whose height jitters around height_on: it entered contact once and
    # must stay in contact (leaving needs height_off).
    h = t.height_on + rng.normal(0, 0.004, 200)
    v = np.full(200, 0.05)
    flags = _hysteresis(h, v, t, 1.0)
    assert flags[5:].all()
    # A joint that never gets low or slow never enters.
    assert not _hysteresis(np.full(50, 0.2), np.full(50, 3.0), t, 1.0).any()
    # Oracle: the same rule written as an explicit two-state machine.
    h = rng.uniform(0, 0.1, 300)
    v = rng.uniform(0, 1.0, 300)
    state, expect = False, []
    for hi, vi in zip(h, v, strict=True):
        if state:
            state = not (hi > t.height_off or vi > t.speed_off)
        else:
            state = hi < t.height_on and vi < t.speed_on
        expect.append(state)
    got = _hysteresis(h, v, t, 1.0)
    # The first frame may start in contact in the library (its past is unknown) — compare after.
    np.testing.assert_array_equal(got[1:], np.array(expect)[1:])


def test_contacts_need_three_frames(cmu_dir: Path) -> None:
    clip = load_clip(cmu_dir / "walk" / "07_01.bvh")
    short = Motion(clip.skeleton, clip.rotations[:2], clip.root_positions[:2], clip.fps)
    with pytest.raises(MotionError, match="at least 3 frames"):
        foot_contacts(short)
    with pytest.raises(MotionError, match="expected foot"):
        gait_cycles(clip, foot="middle")
