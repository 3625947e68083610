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
   synthesized and those joints stay at their reference rotation;
6. (``level_fit="refit"``, the default) paper 003 in the levels: the reference rotations are the
   dataset's key posture (003 Eq. 2 over the aligned frames of every sample), and each coarse
   level's kept joints are refitted sample by sample and frame by frame so that the whole body
   keeps its shape with the dropped joints frozen (:mod:`jcrowd.model.level_refit`); that
   level's Tucker model is then HOOI of the refitted tensor at the level's ranks, warm-started
   from the key level. ``level_fit="freeze"`` is the simpler fit: dataset-mean references and
   the captured rotations of the kept joints (``bench/tensor.py`` reports both).

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
from jcrowd.model.level_refit import refit_kept_rotations
from jcrowd.model.posevec import (
    PoseLayout,
    decode_pose_vectors,
    encode_sample,
    mean_rotations,
    sample_at,
)
from jcrowd.model.samples import CONTROL_NAMES, Sample, gait_samples, reference_skeleton
from jcrowd.motion.clip import Clip, Motion, resample
from jcrowd.motion.rotation import (
    quat_canonical,
    quat_conj,
    quat_from_expmap,
    quat_mul,
    quat_rotate,
    quat_to_expmap,
    yaw_quat,
)
from jcrowd.motion.skeleton import Skeleton, forward_kinematics
from jcrowd.simplify import elimination_order, joint_counts, joint_importance, pair_safe_counts
from jcrowd.simplify.analysis import analyse_motion, key_posture
from jcrowd.tensor.algebra import Tucker, hooi, mean_squared_error, reconstruct
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
        level_fit: ``"refit"`` (003's key posture and refit in every coarse level) or
            ``"freeze"`` (mean references, kept joints as captured); module docstring, step 6.
    """

    frames: int = 100
    fps: float = 60.0
    mirror: bool = True
    key_levels: int = 6
    max_ranks: tuple[int, int, int] | None = None
    min_ranks: tuple[int, int, int] | None = None
    dtw: Literal["multiscale", "exact"] = "multiscale"
    level_fit: Literal["refit", "freeze"] = "refit"


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
    if config.level_fit not in ("refit", "freeze"):
        raise DataError(
            f"tensor model: level_fit: expected 'refit' or 'freeze', found {config.level_fit!r}"
        )
    if config.level_fit == "refit":
        aligned = [sample_at(s.motion, w)[0] for s, w in zip(samples, warps, strict=True)]
        reference = dataset_key_posture(skel, np.concatenate(aligned))
    else:
        reference = mean_rotations([np.asarray(s.motion.rotations) for s in samples])
    base = PoseLayout(skel.num_joints, reference, np.ones(1))
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
    controls_h = np.array([smp.height for smp in samples])
    # Mirrored pairs are kept or frozen together at every level.
    counts = pair_safe_counts(skel, order, joint_counts(skel.num_joints, config.key_levels))
    truth = (  # the samples' own root-frame joints, which the refitted levels are judged by
        _root_frames(np.transpose(tensor, (2, 1, 0)) * layout.scale, layout, skel, controls_h)
        if config.level_fit != "freeze"
        else []
    )
    levels = []
    for level, count in zip(kl.levels, counts, strict=True):
        kept = _kept(order, skel.num_joints, count)
        frozen = TensorLevel(level.tucker, kept, level.mse)
        if config.level_fit == "freeze" or count == skel.num_joints:
            levels.append(frozen)
            continue
        refitted = refit_level(raw, layout, skel, kept, level.tucker)
        # Keep whichever reproduces the samples' whole bodies better (module docstring, 6).
        errors = [_body_error(truth, lv, layout, skel, controls_h) for lv in (frozen, refitted)]
        levels.append(refitted if errors[1] < errors[0] else frozen)
    controls = np.stack([smp.controls() for smp in samples])
    groups = np.array([smp.group for smp in samples], np.int32)
    sources = tuple(c.path for c in clips)
    mirrored = np.array([smp.mirrored for smp in samples])
    return TensorModel(
        config, skel, layout, order, tuple(levels), controls, groups, sources, mirrored, tensor
    )


def lever_weights(layout: PoseLayout, skeleton: Skeleton) -> np.ndarray:
    """Per pose element, how far turning it moves the body: rms lever arm ÷ a quarter height.

    For a joint's three elements (the root's tilt for the root) the lever is the root mean
    square, over every joint and End Site of the rest pose, of its distance from the joint when
    the joint is its strict ancestor (0 otherwise), for the unit-height skeleton; ÷ 0.25 matches
    :func:`_scale`'s unit (1 rad of a quarter-height limb). A leaf joint moves only its End
    Site; a floor of 0.05 keeps every element in the fit. Root height, velocity, yaw rate and
    ΔA keep weight 1. Weighted so, the Frobenius error HOOI minimises approximates the
    whole-body position error to first order (rotation errors times their lever arms).
    """
    j = skeleton.num_joints
    identity = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (j, 1))
    _, pos = forward_kinematics(skeleton, identity, np.zeros(3))
    end_offsets = np.asarray(skeleton.end_offsets_or_empty(), np.float64).reshape(-1, 3)
    ends = pos[list(skeleton.end_parents)] + end_offsets if len(end_offsets) else np.zeros((0, 3))
    points = np.concatenate([pos, ends])
    # The joint each point rotates with first: a joint's parent, an End Site's joint.
    first = [skeleton.parents[k] for k in range(j)] + list(skeleton.end_parents)
    ancestors = np.zeros((j, len(points)), bool)
    for k, a in enumerate(first):
        while a >= 0:
            ancestors[a, k] = True
            a = skeleton.parents[a]
    arms = np.sum((points[None] - pos[:, None]) ** 2, axis=-1) * ancestors
    lever = np.sqrt(arms.sum(axis=1) / max(len(points) - 1, 1)) / 0.25
    w = np.ones(layout.size)
    for joint in range(j):
        w[layout.tilt if joint == 0 else layout.joint(joint)] = max(float(lever[joint]), 0.05)
    return w


def refit_level(
    raw: np.ndarray, layout: PoseLayout, skeleton: Skeleton, kept: tuple[int, ...], start: Tucker
) -> TensorLevel:
    """A coarse level from the refitted samples (module docstring, step 6).

    HOOI at ``start``'s ranks, warm-started from it, of the refitted tensor with every element
    weighted by :func:`lever_weights`; the weights are divided back out of ``U_P`` (its columns
    are then no longer orthonormal, which decoding does not need). ``mse`` is that of the
    level's own (unweighted, refitted) tensor.
    """
    y = refit_pose_vectors(raw, layout, skeleton, kept) / layout.scale
    tensor = np.transpose(y, (2, 1, 0))
    w = lever_weights(layout, skeleton)[:, None, None]
    res = hooi(tensor * w, start.ranks, init=start, throw=False)
    u_p, u_t, u_s = res.tucker.factors
    tucker = Tucker(res.core, (np.asarray(u_p) / w[:, :, 0], u_t, u_s))
    return TensorLevel(tucker, kept, mean_squared_error(tensor, reconstruct(tucker)))


def _root_frames(
    y: np.ndarray, layout: PoseLayout, skeleton: Skeleton, heights: np.ndarray
) -> list[np.ndarray]:
    """Each sample's joint positions in its root frame (:func:`_root_frame`) from unscaled pose
    vectors ``(S, T, P)``."""
    return [_root_frame(y[s], layout, skeleton, float(heights[s]))[0] for s in range(len(y))]


def _body_error(
    truth: list[np.ndarray],
    level: TensorLevel,
    layout: PoseLayout,
    skeleton: Skeleton,
    heights: np.ndarray,
) -> float:
    """Mean whole-body joint error in the root frame of a level's reconstruction (m), against
    the samples' own root-frame joints ``truth`` (:func:`_root_frames` of the tensor)."""
    approx = np.transpose(reconstruct(level.tucker), (2, 1, 0)) * layout.scale
    dropped = [j for j in range(1, skeleton.num_joints) if j not in level.joints]
    approx[:, :, layout.joint_elements(dropped)] = 0.0
    err = [
        np.linalg.norm(a - b, axis=-1).mean()
        for a, b in zip(truth, _root_frames(approx, layout, skeleton, heights), strict=True)
    ]
    return float(np.mean(err))


_KEY_FRAMES = 1024
"""At most this many aligned frames, evenly spread over all samples, pick the key posture (the
posture error of Eq. 1 is compared between every pair of them)."""


def dataset_key_posture(skeleton: Skeleton, rotations: np.ndarray) -> np.ndarray:
    """003 Eq. 2 over a dataset: per joint, its rotation at the frame of least summed error.

    ``rotations`` ``(F, J, 4)`` are the samples' aligned frames one after another; at most
    :data:`_KEY_FRAMES` of them, evenly spaced, are compared. Each joint's key frame is the
    one with the smallest sum of 003's posture error to all the others, so the key posture is
    made of captured rotations (003 §4.2: it "doesn't violate human constraint").
    """
    rot = np.asarray(rotations, np.float64)
    pick = np.unique(np.linspace(0, len(rot) - 1, min(len(rot), _KEY_FRAMES)).round().astype(int))
    frames = Motion(
        skeleton, rot[pick].astype(np.float32), np.zeros((len(pick), 3), np.float32), 1.0
    )
    return key_posture(frames, analyse_motion(frames).key_frames).astype(np.float64)


def refit_pose_vectors(
    raw: np.ndarray, layout: PoseLayout, skeleton: Skeleton, kept: tuple[int, ...]
) -> np.ndarray:
    """Unscaled pose vectors ``(S, T, P)`` of a level: joints not in ``kept`` at the reference
    (the key posture), the kept joints and the root's tilt refitted so every joint of the full
    skeleton stays where the sample has it (:func:`~jcrowd.model.level_refit.refit_kept_rotations`).
    The root's height, velocity, yaw rate and ΔA are the sample's.
    """
    s, t, _ = raw.shape
    j = layout.num_joints
    ref = np.asarray(layout.reference, np.float64)
    tilt = quat_from_expmap(raw[:, :, layout.tilt])
    e = raw[:, :, 7 : 7 + 3 * (j - 1)].reshape(s, t, j - 1, 3)
    joints = quat_mul(ref[None, None, 1:], quat_from_expmap(e))
    rot = np.concatenate([tilt[:, :, None], joints], axis=2).reshape(s * t, j, 4)
    out = refit_kept_rotations(skeleton, rot, kept, ref).astype(np.float64).reshape(s, t, j, 4)
    y = np.array(raw, np.float64)
    y[:, :, layout.tilt] = quat_to_expmap(out[:, :, 0])
    rel = quat_canonical(quat_mul(quat_conj(ref[None, None, 1:]), out[:, :, 1:]))
    y[:, :, 7 : 7 + 3 * (j - 1)] = quat_to_expmap(rel).reshape(s, t, -1)
    return y


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
    return _root_frame(y, model.layout, model.skeleton, height)


def _root_frame(
    y: np.ndarray, layout: PoseLayout, skeleton: Skeleton, height: float
) -> tuple[np.ndarray, np.ndarray]:
    motion, _ = decode_pose_vectors(y, layout, skeleton.scaled(height), height, 1.0)
    _, pos = forward_kinematics(
        motion.skeleton,
        np.asarray(motion.rotations, np.float64),
        np.asarray(motion.root_positions, np.float64),
    )
    yaw = np.concatenate([[0.0], np.cumsum(y[:-1, layout.yaw_rate])])
    rel = quat_rotate(yaw_quat(-yaw)[:, None], pos[:, 1:] - pos[:, :1])
    return rel, pos[-1, 0]


def storage(model: TensorModel, itemsize: int = 4) -> StorageReport:
    """Bytes per key level and in total vs raw samples and a matrix-PCA model (000 §5.1).

    The PCA model is the smallest one whose error on the scaled tensor is at most level 0's.
    """
    return tucker_storage(
        model.tensor, [lv.tucker for lv in model.levels], model.levels[0].mse, itemsize=itemsize
    )
