"""Foot locking: planted feet stop sliding; poses in the root frame and heights are unchanged."""

from __future__ import annotations

import numpy as np

from jcrowd.model import foot_skate
from jcrowd.motion import Motion, joint_positions, lock_feet, procedural_walk


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
