"""MotionModel: kriged cores reproduce the samples; synthesized clips walk as asked; bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jcrowd.errors import KrigingError
from jcrowd.io import load_dataset
from jcrowd.kriging import predict
from jcrowd.model import (
    MotionModel,
    TensorModel,
    build_tensor_model,
    clamp_controls,
    evaluate_captures,
    fit_motion_model,
    foot_skate,
    level_cores,
    level_pose_vectors,
    reconstruct_level,
    synthesize_clip,
)


@pytest.fixture(scope="module")
def fitted(cmu16_tensor: TensorModel) -> tuple[TensorModel, MotionModel]:
    return cmu16_tensor, fit_motion_model(cmu16_tensor)


def test_kriging_interpolates_the_samples(fitted: tuple[TensorModel, MotionModel]) -> None:
    tensor, model = fitted
    c = tensor.controls[:, :3]
    for level in (0, len(model.levels) - 1):
        ours = level_pose_vectors(model, c, level)
        truth = reconstruct_level(tensor, level)
        # Kriging is exact at the samples (one-hot weights); the rest is float32 round-off of
        # cores ~1e2 through two basis products: 1e-4 of the pose vectors' scale.
        scale = np.abs(truth).max()
        assert np.abs(ours - truth).max() < 1e-4 * scale


def test_synthesized_cycle_moves_by_its_controls(fitted: tuple[TensorModel, MotionModel]) -> None:
    tensor, model = fitted
    s = int(np.argmax(np.abs(tensor.controls[:, 2])))  # the sharpest turn
    dx, dz, dyaw = tensor.controls[s, :3]
    clip = synthesize_clip(model, [dx, dz, dyaw], 0, height=float(tensor.heights[s]))
    assert clip.fps == model.fps
    root = np.asarray(clip.root_positions)
    assert np.abs(root[0, [0, 2]]).max() < 1e-6
    # The clip ends within one model frame of the cycle's end; level 0 reconstructs the root
    # path to a few cm (bench/tensor.py): 8 cm is the bound for x and z.
    assert root[-1, 0] == pytest.approx(dx, abs=0.08)
    assert root[-1, 2] == pytest.approx(dz, abs=0.08)


def test_between_samples_the_clip_is_in_between(fitted: tuple[TensorModel, MotionModel]) -> None:
    _, model = fitted
    straight = synthesize_clip(model, [0.1, 1.3, 0.0], 0)
    left = synthesize_clip(model, [0.3, 1.0, 1.2], 0)
    # A left turn ends to the left (+x) of a straight walk, and shorter in z.
    assert np.asarray(left.root_positions)[-1, 0] > np.asarray(straight.root_positions)[-1, 0]
    assert np.asarray(left.root_positions)[-1, 2] < np.asarray(straight.root_positions)[-1, 2]


def test_bad_input(fitted: tuple[TensorModel, MotionModel]) -> None:
    tensor, model = fitted
    with pytest.raises(KrigingError, match="expected 3 finite controls"):
        synthesize_clip(model, [0.1, 1.0], 0)
    with pytest.raises(KrigingError, match="expected 3 finite controls"):
        synthesize_clip(model, [0.1, float("nan"), 0.0], 0)
    with pytest.raises(KrigingError, match="expected a level in"):
        synthesize_clip(model, [0.1, 1.0, 0.0], 99)
    with pytest.raises(KrigingError, match="expected names from"):
        fit_motion_model(tensor, ("dx", "wobble"))


def test_clamp_controls_keeps_inside_and_projects_outside() -> None:
    ranges = np.array([[-1.0, 1.0], [0.5, 2.0]])
    inside = np.array([[0.3, 1.0], [-1.0, 2.0]])
    np.testing.assert_array_equal(clamp_controls(inside, ranges), inside)
    got = clamp_controls(np.array([[5.0, -3.0], [-9.0, 1.5]]), ranges)
    np.testing.assert_array_equal(got, [[1.0, 0.5], [-1.0, 1.5]])


def test_queries_outside_the_range_are_clamped(fitted: tuple[TensorModel, MotionModel]) -> None:
    _, model = fitted
    lo, hi = model.control_ranges[:, 0], model.control_ranges[:, 1]
    far = hi + 10 * (hi - lo)  # far outside: the linear trend alone would be huge here
    got = level_pose_vectors(model, far, 0)
    np.testing.assert_array_equal(got, level_pose_vectors(model, hi, 0))
    # Unclamped, the hyperplane trend extrapolates: the same query without the clamp differs.
    raw = np.asarray(predict(model.levels[0].kriging, far.astype(np.float32)))
    assert np.abs(raw - level_cores(model, hi, 0)).max() > 1.0


def test_baselines_reproduce_the_samples(fitted: tuple[TensorModel, MotionModel]) -> None:
    """RBF and nearest refitted from the model's own samples are exact at those samples."""
    tensor, model = fitted
    c = tensor.controls[:6, :3]
    kriged = level_cores(model, c, 0, "kriging")
    scale = np.abs(kriged).max()
    for method in ("rbf", "nearest"):
        # Both interpolate exactly; 1e-4 of the cores' scale is float32 round-off of the
        # trend + residual reconstruction and of the RBF solve.
        np.testing.assert_allclose(level_cores(model, c, 0, method), kriged, atol=1e-4 * scale)
    # Between samples the three differ (a test that could not fail otherwise).
    mid = (c[:1] + c[1:2]) / 2
    assert np.abs(level_cores(model, mid, 0, "nearest") - level_cores(model, mid, 0)).max() > 1e-3
    with pytest.raises(KrigingError, match="method: expected one of"):
        level_cores(model, c, 0, "spline")


def test_foot_lock_in_synthesize_and_eval(
    fitted: tuple[TensorModel, MotionModel], cmu16_dir: Path
) -> None:
    tensor, model = fitted
    c = tensor.controls[0, :3].tolist()
    raw = synthesize_clip(model, c, 0)
    locked = synthesize_clip(model, c, 0, lock_feet=True)
    # Locking pins planted feet: the slide drops well below the raw decode's (0.5 cm/frame).
    assert foot_skate(locked) < 0.5 * foot_skate(raw)
    clips = load_dataset(cmu16_dir)[:1]
    for method in ("kriging", "nearest"):
        cycles = evaluate_captures(model, clips, method=method)
        assert cycles and all(c["skate_pred_cm"] <= c["skate_raw_cm"] for c in cycles)
        unlocked = evaluate_captures(model, clips, method=method, foot_lock=False)
        assert [c["skate_pred_cm"] for c in unlocked] == [c["skate_raw_cm"] for c in unlocked]


def test_kriging_beats_rbf_and_nearest_on_the_walker() -> None:
    """Ground truth from the procedural walker: a 4×5 grid of speeds and turns, 2 cycles each."""
    from jcrowd.model import TensorModelConfig, leave_one_clip_out
    from jcrowd.motion import Clip, procedural_walk

    grid = [(v, y) for v in (1.0, 1.25, 1.5, 1.75) for y in (-0.6, -0.3, 0.0, 0.3, 0.6)]
    clips = []
    for i, (speed, dyaw) in enumerate(grid):
        motion, _ = procedural_walk(cycles=2, speed=speed, dyaw_per_cycle=dyaw, seed=i)
        clips.append(Clip(f"walker_{i}", motion, 0, None, None, None))
    tensor = build_tensor_model(clips, TensorModelConfig(key_levels=2, mirror=False))
    cv = leave_one_clip_out(tensor, skate=True)  # every held-out clip's controls are new
    # Measured: kriging 0.60 / 3.1 cm, RBF 0.76 / 5.0 cm, nearest 2.2 / 25 cm (joint / root).
    assert cv["kriging"]["joint_m"] < cv["rbf"]["joint_m"] < cv["nearest"]["joint_m"]
    assert cv["kriging"]["root_m"] < cv["rbf"]["root_m"] < cv["nearest"]["root_m"]
    # Paper 001's per-pose kriging of whole motions beats the nearest sample too.
    assert cv["per_pose"]["joint_m"] < cv["nearest"]["joint_m"]
    for method in ("kriging", "per_pose", "rbf", "nearest"):
        r = cv[method]
        assert r["joint_m"] < r["max_joint_m"]
        # Locking can only pin planted feet; 1e-6 cm allows for the float32 decode.
        assert 0.0 <= r["skate_cm"] <= r["skate_raw_cm"] + 1e-6
    assert cv["captures"]["skate_cm"] > 0.0
