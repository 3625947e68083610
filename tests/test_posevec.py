"""Pose vectors: encode → decode is exact on aligned frames, on both skeletons; unwarp inverts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jcrowd.errors import MotionError
from jcrowd.io import read_bvh
from jcrowd.model import (
    PoseLayout,
    decode_pose_vectors,
    encode_sample,
    mean_rotations,
    sample_at,
    unwarp,
)
from jcrowd.motion import (
    Motion,
    character_height,
    drop_tpose_frames,
    gait_cycles,
    joint_positions,
    normalize_root,
    slice_frames,
)


def _cycle(path: Path, index: int = 0) -> tuple[Motion, float]:
    m, _ = drop_tpose_frames(read_bvh(path))
    c = gait_cycles(m)[index]
    return slice_frames(m, c.start, c.end + 1), character_height(m.skeleton)


def _layout(m: Motion) -> PoseLayout:
    return PoseLayout(m.skeleton.num_joints, mean_rotations([np.asarray(m.rotations)]), np.ones(1))


def _warp(n: int, t: int = 100) -> np.ndarray:
    """A smooth monotone (not uniform) map from t aligned frames onto [0, n-1]."""
    u = np.linspace(0.0, 1.0, t)
    return (n - 1) * (u + 0.05 * np.sin(np.pi * u))


@pytest.mark.parametrize("which", ["cmu", "cmu16"])
def test_encode_decode_is_exact_on_aligned_frames(
    which: str, cmu_dir: Path, cmu16_dir: Path
) -> None:
    path = cmu_dir / "walk" / "07_03.bvh" if which == "cmu" else cmu16_dir / "16_17.bvh"
    cyc, height = _cycle(path, 1 if which == "cmu16" else 0)  # 16_17's 2nd cycle turns 89°
    layout = _layout(cyc)
    frames = _warp(cyc.num_frames)
    y = encode_sample(cyc, frames, layout, height)
    assert y.shape == (100, layout.size)
    assert layout.size == 4 + 3 * cyc.skeleton.num_joints + 1
    decoded, times = decode_pose_vectors(y, layout, cyc.skeleton, height, cyc.fps)
    rot, pos = sample_at(cyc, frames)
    truth = normalize_root(
        Motion(cyc.skeleton, rot.astype(np.float32), pos.astype(np.float32), cyc.fps)
    )
    # float32 clips 1-2 m from the origin: ~1e-7 m per operation; 1e-4 m is the bound.
    err = np.abs(np.asarray(joint_positions(truth)) - np.asarray(joint_positions(decoded))).max()
    assert err < 1e-4
    np.testing.assert_allclose(times, frames - frames[0], atol=1e-9)
    # The yaw-rate sum is the cycle's heading change; the velocity sum its displacement.
    assert np.sum(y[:-1, layout.yaw_rate]) == pytest.approx(
        np.unwrap(np.arctan2(*_fwd(truth)))[-1], abs=1e-5
    )


def _fwd(m: Motion) -> tuple[np.ndarray, np.ndarray]:
    from jcrowd.motion import quat_rotate, rest_forward

    f = quat_rotate(np.asarray(m.rotations[:, 0], np.float64), rest_forward(m.skeleton)[None])
    return f[:, 0], f[:, 2]


def test_unwarp_of_the_identity_warp_is_the_clip(cmu16_dir: Path) -> None:
    cyc, height = _cycle(cmu16_dir / "16_15.bvh")
    layout = _layout(cyc)
    frames = np.arange(cyc.num_frames, dtype=np.float64)
    decoded, times = decode_pose_vectors(
        encode_sample(cyc, frames, layout, height), layout, cyc.skeleton, height, cyc.fps
    )
    back = unwarp(decoded, times)
    assert back.num_frames == cyc.num_frames
    err = np.abs(
        np.asarray(joint_positions(back)) - np.asarray(joint_positions(normalize_root(cyc)))
    ).max()
    assert err < 1e-4  # same frames, no interpolation: float32 round-off only


def test_unwarp_of_a_dense_warp_is_close(cmu16_dir: Path) -> None:
    cyc, height = _cycle(cmu16_dir / "16_15.bvh")
    layout = _layout(cyc)
    frames = _warp(cyc.num_frames, 400)  # 400 aligned frames for ~35 sample frames
    decoded, times = decode_pose_vectors(
        encode_sample(cyc, frames, layout, height), layout, cyc.skeleton, height, cyc.fps
    )
    back = unwarp(decoded, times)
    err = np.abs(
        np.asarray(joint_positions(back)) - np.asarray(joint_positions(normalize_root(cyc)))
    )
    # Two linear/slerp interpolations of a 30 fps capture: a few millimetres at the hands.
    assert err.max() < 5e-3


def test_height_normalisation(cmu16_dir: Path) -> None:
    cyc, height = _cycle(cmu16_dir / "16_15.bvh")
    layout = _layout(cyc)
    frames = _warp(cyc.num_frames)
    big = Motion(
        cyc.skeleton.scaled(1.5), cyc.rotations, np.asarray(cyc.root_positions) * 1.5, cyc.fps
    )
    # A 1.5× larger person doing the same motion has the same pose vectors (positions ÷ height).
    np.testing.assert_allclose(
        encode_sample(big, frames, layout, 1.5 * height),
        encode_sample(cyc, frames, layout, height),
        atol=1e-5,
    )


def test_bad_frames_are_rejected(cmu16_dir: Path) -> None:
    cyc, height = _cycle(cmu16_dir / "16_15.bvh")
    layout = _layout(cyc)
    with pytest.raises(MotionError, match="frames must lie in"):
        encode_sample(cyc, np.array([0.0, cyc.num_frames + 3.0]), layout, height)
    with pytest.raises(MotionError, match="non-decreasing"):
        encode_sample(cyc, np.array([3.0, 1.0]), layout, height)
    dec, _ = decode_pose_vectors(
        encode_sample(cyc, _warp(cyc.num_frames), layout, height),
        layout,
        cyc.skeleton,
        height,
        cyc.fps,
    )
    with pytest.raises(MotionError, match="strictly increasing"):
        unwarp(dec, np.zeros(dec.num_frames))


def test_joint_elements_index_the_joint_blocks() -> None:
    layout = PoseLayout(5, np.tile([1.0, 0, 0, 0], (5, 1)), np.ones(1))
    np.testing.assert_array_equal(layout.joint_elements([1, 3]), [7, 8, 9, 13, 14, 15])
    assert layout.delta_a == layout.size - 1 == 7 + 12
