"""Foot locking: planted feet stop sliding; poses in the root frame and heights are unchanged."""

from __future__ import annotations

import numpy as np

from jcrowd.model import foot_skate
from jcrowd.motion import Motion, joint_positions, lock_feet, planted_slides, procedural_walk


def test_a_sliding_walk_is_locked_and_a_planted_one_left_alone() -> None:
    walk, _ = procedural_walk(cycles=2, speed=1.3, seed=0)
    # The walker plants its feet exactly; the contact detector also counts a frame or two of
    # landing, so the measured slide is ~1e-4 m/frame — a quarter of a capture's own ~2e-3.
    assert foot_skate(walk) < 5e-4
    locked = lock_feet(walk)
    # Locking it moves the root by at most the landing frames' slide, summed over the clip.
    assert np.abs(np.asarray(locked.root_positions) - np.asarray(walk.root_positions)).max() < 0.02
    # Make it skate: the root runs 10 % fast, so planted feet drag backwards in the world.
    root = np.asarray(walk.root_positions, np.float64).copy()
    root[:, [0, 2]] *= 1.1
    skating = Motion(walk.skeleton, walk.rotations, root.astype(np.float32), walk.fps)
    assert foot_skate(skating) > 0.1 / 60  # ~13 cm/s of slide at 60 fps
    fixed = lock_feet(skating)
    assert foot_skate(fixed) < 0.1 * foot_skate(skating)
    # Only the root's horizontal path changes: heights and the pose relative to the root stay.
    a, b = np.asarray(joint_positions(skating)), np.asarray(joint_positions(fixed))
    np.testing.assert_allclose(a[..., 1], b[..., 1], atol=1e-5)
    np.testing.assert_allclose(a - a[:, :1], b - b[:, :1], atol=1e-4)


# --- Against the walker's known contacts --------------------------------------------------------
# The oracle below never calls ``foot_contacts`` (which ``lock_feet`` and ``foot_skate`` share):
# the planted feet come from ``WalkTruth.contacts``, and the expected root step is the rule of the
# module docstring written as a plain loop. The detector finds the walker's contacts up to two
# frames late at a landing and one at a lift-off (measured), so only frame pairs whose truth flags
# hold for ``_MARGIN`` frames on either side are checked.
_MARGIN = 2
_OVERSPEED = 1.3  # the root runs 30 % fast: a planted foot drags backwards by 0.3 × the speed
_FEET = (("LeftFoot", "LeftToe"), ("RightFoot", "RightToe"))


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (w, x, y, z) quaternions, in NumPy (builds inputs only)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def _axis_quat(axis: int, angle: np.ndarray) -> np.ndarray:
    q = np.zeros((*np.shape(angle), 4))
    q[..., 0], q[..., 1 + axis] = np.cos(angle / 2), np.sin(angle / 2)
    return q


def _skating_walk(
    *, dyaw: float = 0.0, wiggle: bool = False, pitch: float = 0.0
) -> tuple[Motion, np.ndarray]:
    """A 1 m/s walk whose root runs 30 % fast, and the walker's true contacts ``(F, 2)``.

    ``wiggle`` swings each foot about its vertical axis (left ±0.15 rad over 0.6 s, right
    ±0.10 rad over 0.45 s), so a planted foot's toe slides differently from its ankle and the two
    feet slide differently from each other; ``pitch`` (rad, about the foot's X axis) tilts both
    feet for the whole clip (negative raises the toe). The ankles' paths are untouched.
    """
    # 1 m/s: a planted foot then slides at 0.3 m/s, under the detector's 0.35 m/s entry speed.
    walk, truth = procedural_walk(cycles=3, speed=1.0, dyaw_per_cycle=dyaw, seed=0)
    rot = np.asarray(walk.rotations, np.float64).copy()
    t = np.arange(walk.num_frames) / walk.fps
    names = walk.skeleton.names
    for (ankle, _), amp, period in zip(_FEET, (0.15, 0.10), (0.6, 0.45), strict=True):
        j = names.index(ankle)
        yaw = amp * np.sin(2 * np.pi * t / period) if wiggle else 0 * t
        rot[:, j] = _quat_mul(
            rot[:, j], _quat_mul(_axis_quat(1, yaw), _axis_quat(0, pitch + 0 * t))
        )
    root = np.asarray(walk.root_positions, np.float64).copy()
    root[:, [0, 2]] *= _OVERSPEED
    skating = Motion(walk.skeleton, rot.astype(np.float32), root.astype(np.float32), walk.fps)
    return skating, truth.contacts


def _steady_pairs(contacts: np.ndarray) -> np.ndarray:
    """Frames ``i`` whose truth flags are the same over ``i - _MARGIN .. i + 1 + _MARGIN``."""
    f = len(contacts)
    keep = [
        i
        for i in range(_MARGIN, f - 1 - _MARGIN)
        if (contacts[i - _MARGIN : i + 2 + _MARGIN] == contacts[i]).all()
    ]
    return np.array(keep, np.int64)


def test_single_support_planted_foot_stays_put_after_locking() -> None:
    """In single support (walker truth) the planted foot stops sliding once locked.

    Guards against a correction that is missing, has the wrong sign or lands on the wrong axes.
    """
    skating, contacts = _skating_walk(dyaw=0.5)  # turning: the slide has both x and z parts
    before = np.asarray(joint_positions(skating), np.float64)
    after = np.asarray(joint_positions(lock_feet(skating)), np.float64)
    names = skating.skeleton.names
    pairs = _steady_pairs(contacts)
    single = pairs[contacts[pairs].sum(axis=1) == 1]
    assert len(single) > 40  # premise: plenty of single-support frames are checked
    for i in single:
        side = int(np.argmax(contacts[i]))
        for name in _FEET[side]:
            j = names.index(name)
            # Premise: unlocked, the planted foot drags 0.3 m/s / 60 fps = 5 mm per frame.
            assert np.hypot(*(before[i + 1, j] - before[i, j])[[0, 2]]) > 4e-3
            # Locked, it stays to 1 mm per frame: a fifth of the slide, and far above the
            # float32 rounding (~1e-6 m) of an exact lock.
            assert np.hypot(*(after[i + 1, j] - after[i, j])[[0, 2]]) < 1e-3, (i, name)


def test_the_lower_of_ankle_and_toe_is_pinned() -> None:
    """With the toe below the ankle, then above it, the lower joint is the one pinned.

    The feet turn about their vertical axes while planted, so the toe moves relative to the
    ankle and pinning one leaves the other sliding. Guards against pinning the higher joint.
    """
    # Flat feet (the toe 6.8 cm below the ankle), then feet pitched 1 rad toe-up (the toe 7 cm
    # above it); the planted joint is named by height alone, as the module docstring states.
    for pitch, toe_lower in ((0.0, True), (-1.0, False)):
        skating, contacts = _skating_walk(wiggle=True, pitch=pitch)
        before = np.asarray(joint_positions(skating), np.float64)
        after = np.asarray(joint_positions(lock_feet(skating)), np.float64)
        names = skating.skeleton.names
        pairs = _steady_pairs(contacts)
        single = pairs[contacts[pairs].sum(axis=1) == 1]
        assert len(single) > 100  # premise: plenty of single-support frames are checked
        turns, slides = [], []
        for i in single:
            side = int(np.argmax(contacts[i]))
            ankle, toe = (names.index(n) for n in _FEET[side])
            low, high = (toe, ankle) if toe_lower else (ankle, toe)
            # Premise: the heights differ clearly (≥ 2 cm), with the expected joint lower.
            assert before[i, low, 1] + 0.02 < before[i, high, 1]
            rel = before[:, toe, [0, 2]] - before[:, ankle, [0, 2]]
            turns.append(np.linalg.norm(rel[i + 1] - rel[i]))
            slides.append(np.linalg.norm(after[i + 1, low, [0, 2]] - after[i, low, [0, 2]]))
        # Premise: the toe moves up to ~3 mm per frame relative to the ankle, so pinning the
        # wrong joint leaves the lower one sliding by that much.
        assert max(turns) > 2e-3
        # The lower joint is pinned exactly: to float32 rounding of positions up to 5 m from the
        # origin (ulp ~5e-7 m), with 40× headroom; the bug's slide is 100× larger.
        assert max(slides) < 2e-5, (pitch, max(slides))


def test_double_support_steps_the_root_back_by_the_mean_slide() -> None:
    """The root step equals its step less the mean slide of the feet planted (walker truth).

    The expected step is computed by a plain loop over the truth contacts: each planted foot's
    lower joint's horizontal slide, averaged over the planted feet. The two feet turn at
    different rates, so in double support their slides differ. Guards against summing the
    slides of both feet instead of averaging (and against using one foot's slide only).
    """
    skating, contacts = _skating_walk(wiggle=True)
    pos = np.asarray(joint_positions(skating), np.float64)
    root = np.asarray(skating.root_positions, np.float64)
    locked = np.asarray(lock_feet(skating).root_positions, np.float64)
    names = skating.skeleton.names
    pairs = _steady_pairs(contacts)
    double = 0
    for i in pairs:
        slides = []
        for side, (ankle_name, toe_name) in enumerate(_FEET):
            if not (contacts[i, side] and contacts[i + 1, side]):
                continue
            ankle, toe = names.index(ankle_name), names.index(toe_name)
            low = ankle if pos[i, ankle, 1] <= pos[i, toe, 1] else toe
            slides.append(pos[i + 1, low, [0, 2]] - pos[i, low, [0, 2]])
        assert slides, i  # the walker always has a foot down (each is planted 60 % of a cycle)
        if len(slides) == 2:
            double += 1
            # Premise: the feet's slides differ (measured 0.4–6 mm), so the mean is 10× the
            # tolerance away from either foot's own slide; each is ~5 mm per frame.
            assert np.linalg.norm(slides[0] - slides[1]) > 3e-4
            assert min(np.linalg.norm(s) for s in slides) > 3e-3
        expected = root[i + 1, [0, 2]] - root[i, [0, 2]] - np.mean(slides, axis=0)
        # float32 rounding of root positions up to 5 m (ulp ~5e-7 m) and of the joints' FK,
        # with 40× headroom; summing two ~5 mm slides instead of averaging is off by ~5 mm.
        np.testing.assert_allclose(
            locked[i + 1, [0, 2]] - locked[i, [0, 2]], expected, rtol=0, atol=2e-5, err_msg=f"{i}"
        )
        # Heights are left alone.
        assert locked[i, 1] == root[i, 1]
    assert double >= 10  # premise: double-support frames are among those checked


def test_planted_slides_are_the_lower_joints_steps_on_truly_planted_frames() -> None:
    """``planted_slides`` (shared by ``lock_feet`` and ``foot_skate``) against the walker's truth.

    On every steady frame where the truth plants a foot, that foot's entry holds the frame, and
    its step is the lower of ankle and toe moving to the next frame, computed here in NumPy.
    Guards against the helper reporting the wrong frames, joint or axes for either foot.
    """
    skating, contacts = _skating_walk(wiggle=True)
    pos = np.asarray(joint_positions(skating), np.float64)
    names = skating.skeleton.names
    found = planted_slides(skating)
    assert len(found) == 2
    checked = 0
    for i in _steady_pairs(contacts):
        for side, (frames, steps) in enumerate(found):
            if not contacts[i, side]:
                continue
            ankle, toe = (names.index(n) for n in _FEET[side])
            low = ankle if pos[i, ankle, 1] <= pos[i, toe, 1] else toe
            k = np.searchsorted(frames, i)
            assert k < len(frames) and frames[k] == i, (i, side)  # detected as planted
            # Same float64 positions on both sides: only summation order differs.
            np.testing.assert_allclose(
                steps[k], pos[i + 1, low, [0, 2]] - pos[i, low, [0, 2]], atol=1e-12
            )
            checked += 1
    assert checked > 150  # premise: both feet, single and double support
