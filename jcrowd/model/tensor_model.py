"""The motion-tensor model: from a folder of BVH captures to multi-level reduced tensors.

The first half of the fit (DESIGN §4 steps 1–7; papers 000 §3.2, §4.1–4.3 and 004 §2–3):

1. clips → gait-cycle samples at the model rate, mirrored (:mod:`jcrowd.model.samples`);
2. the joint order for levels from joint importance summed over the dataset (paper 003 Eq. 3,
   :mod:`jcrowd.simplify`);
3. every sample aligned by DTW to a reference sample on pose features divided by body height
   (:mod:`jcrowd.align`), its warp resampled to ``T`` frames;
4. pose vectors (:mod:`jcrowd.model.posevec`), scaled per element, stacked into ``M ∈ R^{P×T×S}``;
5. key levels by the greedy search of 000 §4.2 (:mod:`jcrowd.tensor.keylevels`); key level ``l``
   also keeps only the most important joints (000 §4.3): the pose elements of the others are not
   synthesized and those joints stay at their reference (dataset-mean) rotation, which is the
   tensor model's key posture.

The reference sample is the medoid of the samples under the DTW-free pose distance of their
time-normalised feature curves (the sample the others are closest to), so no sample has to warp
far. :func:`build_tensor_model` is pure (no files); :mod:`jcrowd.io.tensor_file` saves and loads
the result.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from jcrowd.align import align_to_reference, pose_features
from jcrowd.errors import DataError
from jcrowd.model.posevec import PoseLayout, decode_pose_vectors, encode_sample, mean_rotations
from jcrowd.model.samples import CONTROL_NAMES, Sample, gait_samples, reference_skeleton
from jcrowd.motion.clip import Clip, resample
from jcrowd.motion.rotation import quat_rotate, yaw_quat
from jcrowd.motion.skeleton import Skeleton, forward_kinematics
from jcrowd.simplify import elimination_order, joint_counts, joint_importance, pair_safe_counts
from jcrowd.tensor.algebra import Tucker, reconstruct
from jcrowd.tensor.keylevels import StorageReport, key_levels, tucker_storage

__all__ = [
    "TensorLevel",
    "TensorModel",
    "TensorModelConfig",
    "build_tensor_model",
    "level_errors",
    "reconstruct_level",
    "root_frame_positions",
    "storage",
]


@dataclass(frozen=True)
class TensorModelConfig:
    """Settings of the tensor fit.

    Attributes:
        frames: ``T``, aligned frames per sample (000 §5: 100).
        fps: model rate the clips are resampled to.
        mirror: add mirrored samples (on for walks).
        key_levels: ``N`` key levels.
        max_ranks, min_ranks: ``(R_P, R_T, R_S)`` of the finest and coarsest key levels.
            ``None``: ``(max(40, P/2), 30, 0.8·S)`` and 7×7×9, capped at the tensor's size.
            Paper 000 §5.1 used 40×40×60 for 186 samples of one gait class; the shared CMU
            walks are more varied (curved, backward and sideways steps), so the sample mode
            needs more rank, while a 100-frame cycle's time mode needs less
            (``bench/tensor.py`` reports each key level's joint error).
        dtw: ``"multiscale"`` or ``"exact"``.
    """

    frames: int = 100
    fps: float = 60.0
    mirror: bool = True
    key_levels: int = 6
    max_ranks: tuple[int, int, int] | None = None
    min_ranks: tuple[int, int, int] | None = None
    dtw: Literal["multiscale", "exact"] = "multiscale"


@dataclass(frozen=True)
class TensorLevel:
    """One key level: the reduced tensor and the joints it synthesizes."""

    tucker: Tucker
    joints: tuple[int, ...]
    mse: float


@dataclass(frozen=True)
class TensorModel:
    """Everything the kriging fit and the crowd step need from the tensor half.

    Attributes:
        skeleton: the reference skeleton for a 1 m tall character (scale by height).
        layout: pose-vector layout (references and element scales).
        order: joint elimination order (least important first).
        levels: key levels, finest first.
        controls: ``(S, 5)`` every sample's :data:`~jcrowd.model.samples.CONTROL_NAMES`.
        groups: ``(S,)`` clip index per sample (a clip and its mirror share one).
        sources: clip path per group.
        mirrored: ``(S,)`` whether each sample is a mirror image.
        tensor: ``(P, T, S)`` the scaled motion tensor the levels approximate.
    """

    config: TensorModelConfig
    skeleton: Skeleton
    layout: PoseLayout
    order: tuple[int, ...]
    levels: tuple[TensorLevel, ...]
    controls: np.ndarray
    groups: np.ndarray
    sources: tuple[str, ...]
    mirrored: np.ndarray
    tensor: np.ndarray = field(repr=False)

    @property
    def heights(self) -> np.ndarray:
        return self.controls[:, CONTROL_NAMES.index("height")]


def _features(sample: Sample) -> np.ndarray:
    return pose_features(sample.motion) / sample.height


def _medoid(features: list[np.ndarray], frames: int) -> int:
    """Index of the sample whose uniformly time-normalised features are closest to all others."""
    curves = []
    for f in features:
        t = np.linspace(0, len(f) - 1, frames)
        curves.append(
            np.stack([np.interp(t, np.arange(len(f)), f[:, k]) for k in range(f.shape[1])], 1)
        )
    x = np.stack(curves).reshape(len(curves), -1)
    sq = np.sum(x * x, axis=1)
    d = sq[:, None] + sq[None, :] - 2 * x @ x.T
    return int(np.argmin(np.maximum(d, 0).sum(axis=1)))


def _scale(layout: PoseLayout, delta_a_mean: float, frames: int) -> np.ndarray:
    """Element scales (the tensor stores ``y / scale``) so the groups weigh comparably.

    Angles (tilt, joints) are the unit: 1 rad. A root height error of a quarter body height moves
    the body as far as 1 rad turns a quarter-height limb, so heights get 0.25. Velocity and yaw
    rate are per aligned frame and their errors add up over the ``T`` frames of a cycle, so they
    get 0.25/T and 1/T: a per-frame error worth one unit then shifts the cycle's end by a quarter
    height or a radian. ΔA is divided by its dataset mean (a relative change of speed).
    """
    s = np.ones(layout.size)
    s[layout.height] = 0.25
    s[layout.velocity] = 0.25 / frames
    s[layout.yaw_rate] = 1.0 / frames
    s[layout.delta_a] = delta_a_mean
    return s


def build_tensor_model(
    clips: Sequence[Clip], config: TensorModelConfig = TensorModelConfig()
) -> TensorModel:
    """Fit the tensor half of a motion model from a dataset's clips (module docstring)."""
    samples = gait_samples(clips, fps=config.fps, mirrored=config.mirror)
    if len(samples) < 2:
        raise DataError(
            f"tensor model: expected at least 2 gait-cycle samples, found {len(samples)}"
        )
    skel = reference_skeleton(samples)
    order = elimination_order(
        skel, joint_importance([resample(c.motion, config.fps) for c in clips])
    )
    feats = [_features(s) for s in samples]
    ref = _medoid(feats, config.frames)
    warps = [
        align_to_reference(feats[ref], f, num_frames=config.frames, method=config.dtw).frames
        for f in feats
    ]
    base = PoseLayout(
        skel.num_joints,
        mean_rotations([np.asarray(s.motion.rotations) for s in samples]),
        np.ones(1),
    )
    raw = np.stack(
        [encode_sample(s.motion, w, base, s.height) for s, w in zip(samples, warps, strict=True)]
    )
    scale = _scale(base, float(raw[:, :, base.delta_a].mean()), config.frames)
    layout = PoseLayout(skel.num_joints, base.reference, scale)
    tensor = np.transpose(raw / scale, (2, 1, 0))  # (P, T, S)
    p, t, s = tensor.shape
    max_r = config.max_ranks or (
        min(p, max(40, round(p / 2))),
        min(t, 30),
        max(min(s, 9), round(0.8 * s)),
    )
    min_r = config.min_ranks or (min(7, max_r[0]), min(7, max_r[1]), min(9, max_r[2]))
    kl = key_levels(tensor, config.key_levels, max_r, min_r)
    # Mirrored pairs are kept or frozen together at every level (issue 21).
    counts = pair_safe_counts(skel, order, joint_counts(skel.num_joints, config.key_levels))
    levels = tuple(
        TensorLevel(level.tucker, _kept(order, skel.num_joints, count), level.mse)
        for level, count in zip(kl.levels, counts, strict=True)
    )
    controls = np.stack([smp.controls() for smp in samples])
    groups = np.array([smp.group for smp in samples], np.int32)
    sources = tuple(c.path for c in clips)
    mirrored = np.array([smp.mirrored for smp in samples])
    return TensorModel(
        config, skel, layout, order, levels, controls, groups, sources, mirrored, tensor
    )


def _kept(order: tuple[int, ...], num_joints: int, count: int) -> tuple[int, ...]:
    frozen = set(order[: num_joints - count])
    return tuple(j for j in range(num_joints) if j not in frozen)


def reconstruct_level(model: TensorModel, level: int) -> np.ndarray:
    """Unscaled pose vectors ``(S, T, P)`` of every sample at a key level (joint reduction too)."""
    lv = model.levels[level]
    y = np.transpose(reconstruct(lv.tucker), (2, 1, 0)) * model.layout.scale
    dropped = [j for j in range(1, model.skeleton.num_joints) if j not in lv.joints]
    y[:, :, model.layout.joint_elements(dropped)] = 0.0  # the reference rotation
    return y


def level_errors(model: TensorModel, level: int) -> tuple[float, float]:
    """Mean joint position error in the root frame, and mean end-of-cycle root error (m)."""
    truth = np.transpose(model.tensor, (2, 1, 0)) * model.layout.scale
    approx = reconstruct_level(model, level)
    joint_err, root_err = [], []
    for s in range(truth.shape[0]):
        h = float(model.heights[s])
        a = root_frame_positions(truth[s], model, h)
        b = root_frame_positions(approx[s], model, h)
        joint_err.append(np.linalg.norm(a[0] - b[0], axis=-1).mean())
        root_err.append(np.linalg.norm(a[1] - b[1]))
    return float(np.mean(joint_err)), float(np.mean(root_err))


def root_frame_positions(
    y: np.ndarray, model: TensorModel, height: float
) -> tuple[np.ndarray, np.ndarray]:
    """Decoded joint positions relative to the root in its heading frame ``(T, J-1, 3)``, and the
    root's position at the last aligned frame (the cycle's displacement), for pose vectors ``y``.
    """
    skel = model.skeleton.scaled(height)
    motion, _ = decode_pose_vectors(y, model.layout, skel, height, model.config.fps)
    _, pos = forward_kinematics(
        motion.skeleton,
        np.asarray(motion.rotations, np.float64),
        np.asarray(motion.root_positions, np.float64),
    )
    yaw = np.concatenate([[0.0], np.cumsum(y[:-1, model.layout.yaw_rate])])
    rel = quat_rotate(yaw_quat(-yaw)[:, None], pos[:, 1:] - pos[:, :1])
    return rel, pos[-1, 0]


def storage(model: TensorModel, itemsize: int = 4) -> StorageReport:
    """Bytes per key level and in total vs raw samples and a matrix-PCA model (000 §5.1).

    The PCA model is the smallest one whose error on the scaled tensor is at most level 0's.
    """
    return tucker_storage(
        model.tensor, [lv.tucker for lv in model.levels], model.levels[0].mse, itemsize=itemsize
    )
