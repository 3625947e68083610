"""Time warps: paths to functions, ΔA and back, inversion, self-alignment, and recovering a known
time-stretch of a captured walk."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import load_clip

from jcrowd.align import (
    AlignError,
    align_to_reference,
    dtw,
    invert_warp,
    physics_features,
    pose_features,
    resample_warp,
    sample_motion,
    time_warp,
    warp_from_increments,
    warp_increments,
)


def test_diagonal_path_is_the_identity() -> None:
    path = np.stack([np.arange(50)] * 2, axis=1)
    np.testing.assert_array_equal(time_warp(path), np.arange(50.0))
    frames = resample_warp(time_warp(path), 100)
    np.testing.assert_allclose(frames, np.linspace(0, 49, 100), atol=1e-12)
    inc = warp_increments(frames)
    np.testing.assert_allclose(inc, np.r_[0.0, np.full(99, 49 / 99)], atol=1e-12)


def test_horizontal_and_vertical_runs_are_averaged() -> None:
    # Reference frame 0 matches sample frames 0..2 (horizontal run); reference frames 1..3
    # match sample frame 3 (vertical run); then the diagonal.
    path = np.array([[0, 0], [0, 1], [0, 2], [1, 3], [2, 3], [3, 3], [4, 4], [5, 5]])
    a = time_warp(path)
    # Knots: (0, 1) from the horizontal run's mean, (2, 3) at the vertical run's middle,
    # then (4, 4), (5, 5); linear in between.
    np.testing.assert_allclose(a, [1.0, 2.0, 3.0, 3.5, 4.0, 5.0])
    assert np.all(np.diff(a) > 0)


def test_time_warp_of_random_dtw_paths_is_monotone_and_in_range() -> None:
    rng = np.random.default_rng(4)
    for n, m in [(30, 70), (70, 30), (1, 9), (9, 1), (45, 45)]:
        path = dtw(rng.normal(size=(n, 2)), rng.normal(size=(m, 2))).path
        a = time_warp(path)
        assert a.shape == (n,)
        assert np.all(np.diff(a) >= 0) and a.min() >= 0 and a.max() <= m - 1


def test_increments_integrate_back_to_the_warp() -> None:
    rng = np.random.default_rng(8)
    path = dtw(np.cumsum(rng.normal(size=(80, 3)), 0), np.cumsum(rng.normal(size=(120, 3)), 0)).path
    frames = resample_warp(time_warp(path), 100)
    inc = warp_increments(frames)
    assert inc.shape == (100,) and np.all(inc[1:] >= 0)
    # cumsum(ΔA) = A exactly up to rounding in the running sum (1e-12 frames).
    np.testing.assert_allclose(warp_from_increments(inc), frames, atol=1e-12)
    np.testing.assert_allclose(inc.sum(), frames[-1], atol=1e-12)


def test_interpolated_increments_give_an_interpolated_speed() -> None:
    # Two samples of the same motion, one 1.5 times slower: their ΔA mix gives a map whose
    # duration is the mix of the durations (what paper 001 §3.5 kriges ΔA for).
    fast = np.linspace(0, 99, 100)
    slow = 1.5 * fast
    mix = warp_from_increments(0.3 * warp_increments(fast) + 0.7 * warp_increments(slow))
    np.testing.assert_allclose(mix, 0.3 * fast + 0.7 * slow, atol=1e-12)
    # An overshooting interpolation (negative increments) is clamped to stay monotone.
    wobbly = np.r_[0.0, np.sin(np.linspace(0, 20, 99))]
    clamped = warp_from_increments(wobbly)
    assert np.all(np.diff(clamped) >= 0)
    raw = warp_from_increments(wobbly, min_increment=None)
    np.testing.assert_allclose(raw, np.cumsum(wobbly), atol=1e-12)


def test_invert_warp() -> None:
    a = np.cumsum(np.r_[0.0, np.random.default_rng(1).uniform(0.2, 2.0, 59)])
    np.testing.assert_allclose(invert_warp(a, a), np.arange(60.0), atol=1e-9)
    np.testing.assert_allclose(invert_warp(a, [-5.0, a[-1] + 5]), [0.0, 59.0])
    # A flat stretch maps to its middle.
    np.testing.assert_allclose(invert_warp(np.array([0.0, 1.0, 1.0, 1.0, 2.0]), [1.0]), [2.0])
    with pytest.raises(AlignError, match="non-decreasing"):
        invert_warp(np.array([0.0, 2.0, 1.0]), [1.0])


def test_bad_paths_are_rejected() -> None:
    with pytest.raises(AlignError, match="from \\(0, 0\\)"):
        time_warp(np.array([[1, 0], [2, 1]]))
    with pytest.raises(AlignError, match="steps"):
        time_warp(np.array([[0, 0], [2, 1]]))
    with pytest.raises(AlignError, match="\\(K, 2\\)"):
        time_warp(np.zeros((3, 3), np.int64))
    with pytest.raises(AlignError, match="num_frames"):
        resample_warp(np.arange(5.0), 1)
    with pytest.raises(AlignError, match="method"):
        align_to_reference(np.zeros((4, 2)), np.zeros((4, 2)), method="fast")  # type: ignore[arg-type]


def test_sample_motion_at_integer_frames_is_the_clip(cmu16_dir: Path) -> None:
    m = load_clip(cmu16_dir / "16_15.bvh")
    same = sample_motion(m, np.arange(m.num_frames, dtype=np.float64))
    np.testing.assert_allclose(same.rotations, m.rotations, atol=1e-6)  # float32 slerp at t=0
    np.testing.assert_allclose(same.root_positions, m.root_positions, atol=1e-6)


def test_aligning_a_clip_to_itself_is_the_identity(cmu_dir: Path, cmu16_dir: Path) -> None:
    for m in (load_clip(cmu_dir / "walk" / "07_01.bvh"), load_clip(cmu16_dir / "16_15.bvh")):
        f = pose_features(m)
        for method in ("exact", "multiscale"):
            al = align_to_reference(f, f, num_frames=100, method=method)
            np.testing.assert_allclose(al.frames, np.linspace(0, m.num_frames - 1, 100), atol=1e-9)
            assert al.result.cost == 0.0


@pytest.mark.parametrize("stretch", [1.25, 0.8])
def test_a_known_time_stretch_is_recovered(cmu_dir: Path, cmu16_dir: Path, stretch: float) -> None:
    """The reference is a walk replayed through a known monotone map ``g``; aligning the walk to
    it must give back ``A = g``."""
    for m in (load_clip(cmu_dir / "walk" / "07_01.bvh"), load_clip(cmu16_dir / "16_15.bvh")):
        big = m.fps > 60
        n = int(stretch * m.num_frames)
        s = np.linspace(0.0, 1.0, n)
        g = (m.num_frames - 1) * (s + 0.06 * np.sin(2 * np.pi * s))  # g' > 0: 1 ± 0.38
        reference = sample_motion(m, g)
        # Point clouds are tempo-free: the path is exact to the half frame DTW's integer sample
        # frames allow (measured max 0.51 frames).
        for method in ("exact", "multiscale"):
            al = align_to_reference(
                pose_features(reference), pose_features(m), num_frames=n, method=method
            )
            err = np.abs(al.frames - g)
            assert err.mean() < 0.3 and err.max() < 1.0
        # Physics features scale with tempo (acceleration by 1/stretch²), so the stretched clip's
        # features differ in size; the inner cost compares directions only. Measured at 120 fps
        # mean 0.6–0.9 and max 3.5–4.5 frames (≤ 40 ms), at 30 fps mean 0.4, max 1.7 frames.
        al = align_to_reference(
            physics_features(reference), physics_features(m), num_frames=n, metric="inner"
        )
        err = np.abs(al.frames - g)
        assert err.mean() < (1.5 if big else 0.75) and err.max() < (8.0 if big else 3.0)
