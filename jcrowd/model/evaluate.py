"""Leave-one-clip-out cross-validation of motion prediction: kriging vs RBF vs nearest sample.

Every gait cycle of a clip, and its mirror, leaves together (sibling cycles of one take are
near-duplicates and would flatter every method). For each left-out clip the remaining samples'
level-``l`` cores ``K_i`` are interpolated over the controls by universal kriging
(:mod:`jcrowd.kriging`), by the "verbs and adverbs" RBF (Rose et al.) and by the nearest sample
(and, as ``per_pose`` and ``per_element``, paper 001's kriging of the whole unreduced aligned
motions with one variogram, or one per pose element),
and the predicted pose vectors ``U_P K(c) U_Tᵀ`` are compared with the left-out sample's own
(the tensor's data): mean joint position error in the root frame and end-of-cycle root
displacement error (m), averaged over the left-out samples.

Choices, stated: the tensor bases (HOOI on all samples) and the kriging variogram (fitted once on
all samples) are shared by the folds — refitting them per fold would cost a full fit per clip;
both leak equally into all three methods, so the comparison stays fair. RBF and nearest see
the same normalised controls as kriging. Every method is asked at the left-out controls clamped
to the training samples' range, control by control, as the model and the crowd ask
(:func:`jcrowd.model.motion_model.clamp_controls`): on ``cmu/walk`` the backward/sideways take
``09_12`` lies outside the straight walks' range, and unclamped, its linear trend extrapolates
far enough to put kriging behind nearest sample over all folds (``bench/repro_001.py`` reports
the error with and without clamping).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jcrowd.errors import DataError
from jcrowd.kriging.rbf import fit_rbf, predict_nearest, predict_rbf
from jcrowd.kriging.universal import fit_kriging, kriging_variance, normalise_controls, predict
from jcrowd.kriging.variogram_fit import VariogramFit
from jcrowd.model.motion_model import (
    MotionModel,
    clamp_controls,
    model_reliability,
    sample_cores,
    synthesize_clip,
)
from jcrowd.model.posevec import decode_clip
from jcrowd.model.samples import CONTROL_NAMES, gait_samples
from jcrowd.model.tensor_model import TensorModel, root_frame_positions
from jcrowd.motion.clip import Clip, Motion
from jcrowd.motion.footlock import lock_feet, planted_slides

__all__ = ["ALL_CV_METHODS", "CV_METHODS", "evaluate_captures", "foot_skate", "leave_one_clip_out"]

CV_METHODS = ("kriging", "per_pose", "rbf", "nearest")
ALL_CV_METHODS = (*CV_METHODS, "per_element")


def leave_one_clip_out(
    tensor: TensorModel,
    controls: Sequence[str] = ("dx", "dz", "dyaw"),
    *,
    level: int = 0,
    methods: Sequence[str] = CV_METHODS,
    skate: bool = False,
) -> dict[str, dict[str, float]]:
    """``{method: {"joint_m", "max_joint_m", "root_m"}}`` over every left-out clip (module doc).

    ``kriging`` also gets ``z_rms``: each left-out sample's core-space error ‖K* − K‖_F divided
    by the standard deviation the model predicts for it (√ of the kriging variance, which
    includes the nugget: an unseen capture's own variation), root-mean-squared. The errors
    are vectors, so a z-score is a norm and is never negative; reading taken for "the
    standard deviation of the z-scores": their RMS about 0, which is 1 when the predicted
    variance equals the expected squared error (as the standard deviation of signed scalar
    z-scores is). Below 1 the model is over-cautious, above 1 over-confident.

    ``joint_m`` is the mean over left-out samples of their mean joint error, ``max_joint_m`` the
    mean of their per-sample maximum. With ``skate``, every method also gets ``skate_cm`` (foot
    skate of the decoded prediction after foot locking, what jcrowd delivers) and
    ``skate_raw_cm`` (before), and a ``"captures"`` entry holds the samples' own ``skate_cm``
    (their aligned data decoded the same way, so all figures are at the model rate).
    """
    data = _shared_data(tensor, controls, level, methods)
    errors: dict[str, list[tuple[float, ...]]] = {m: [] for m in methods}
    z_scores: list[float] = []
    for group in np.unique(tensor.groups):
        out = tensor.groups == group
        train = ~out
        if np.count_nonzero(train) < data.c_norm.shape[1] + 2:
            continue
        c_train = data.c_norm[train]
        box = np.stack([c_train.min(axis=0), c_train.max(axis=0)], axis=1)
        q = jnp.asarray(clamp_controls(data.c_norm[out], box), jnp.float32)
        ys, z = _core_predictions(data, train, out, q, methods)
        z_scores.extend(z)
        ys.update(_motion_predictions(data, train, q, methods))
        for method, y in ys.items():
            errors[method].extend(_sample_errors(tensor, data.truth, y, out, skate))
    return _summary(tensor, data.truth, errors, z_scores, skate)


@dataclass(frozen=True)
class _SharedData:
    """What every fold shares (module doc: bases and variograms are fitted on all samples).

    ``c_norm`` ``(S, d)`` normalised controls; ``cores`` ``(S, R_P, R_T)``; ``motions``
    ``(S, T, P)`` whole aligned motions and ``truth`` the same scaled; ``u_p``, ``u_t`` the
    level's pose and time bases; the variograms of the methods asked for (else ``None``, ``[]``).
    """

    c_norm: np.ndarray
    cores: np.ndarray
    motions: np.ndarray
    truth: np.ndarray
    u_p: np.ndarray
    u_t: np.ndarray
    scale: np.ndarray
    variogram: VariogramFit
    pose_variogram: VariogramFit | None
    element_variograms: list[VariogramFit]


def _shared_data(
    tensor: TensorModel, controls: Sequence[str], level: int, methods: Sequence[str]
) -> _SharedData:
    """The level's cores and bases, the normalised controls and the variograms, fitted once."""
    lv = tensor.levels[level]
    u_p, u_t, u_s = lv.tucker.factors
    cores = sample_cores(lv.tucker.core, u_s)
    idx = [CONTROL_NAMES.index(c) for c in controls]
    c_all = tensor.controls[:, idx]
    c_norm, _, _ = normalise_controls(c_all)
    # Normalise once, so the variogram fitted on all samples keeps its units in every fold.
    variogram = fit_kriging(c_norm, cores, normalise=False).variogram
    truth = np.transpose(tensor.tensor, (2, 1, 0)) * tensor.layout.scale
    # Paper 001's per-pose kriging: whole aligned motions (every frame's pose vector, ΔA
    # included, scaled), not the reduced cores, with one variogram over whole-motion distances.
    motions = np.transpose(tensor.tensor, (2, 1, 0))
    pose_variogram, element_variograms = None, []
    if "per_pose" in methods:
        pose_variogram = fit_kriging(c_norm, motions, normalise=False).variogram
    if "per_element" in methods:
        # Paper 001 §3.2 kriges each pose element separately. Reading taken: one variogram per
        # element over its whole aligned trajectory (P variograms), not one per element *and*
        # frame (P·T = 6200 fits per fold on cmu16); the paper found per-element no better than
        # per-pose anyway (its Table 1), so this is the affordable form of the baseline.
        element_variograms = [
            fit_kriging(c_norm, motions[:, :, k], normalise=False).variogram
            for k in range(motions.shape[2])
        ]
    return _SharedData(
        c_norm,
        cores,
        motions,
        truth,
        u_p,
        u_t,
        tensor.layout.scale,
        variogram,
        pose_variogram,
        element_variograms,
    )


def _core_predictions(
    data: _SharedData, train: np.ndarray, out: np.ndarray, q: jax.Array, methods: Sequence[str]
) -> tuple[dict[str, np.ndarray], list[float]]:
    """Kriging, RBF and nearest sample of the cores at ``q``, decoded to scaled pose vectors
    ``(n_out, T, P)``, and the kriging z-scores of the left-out samples."""
    c_train, k_train = data.c_norm[train], data.cores[train]
    preds: dict[str, np.ndarray] = {}
    z_scores: list[float] = []
    if "kriging" in methods:
        km = fit_kriging(c_train, k_train, data.variogram, normalise=False)
        preds["kriging"] = np.asarray(predict(km, q))
        # Calibration: the core-space error against the std the model predicts for an
        # unseen capture there (kriging variance: signal, the capture's nugget, the mean).
        miss = (preds["kriging"] - data.cores[out]).reshape(int(np.count_nonzero(out)), -1)
        sd = np.sqrt(np.maximum(np.asarray(kriging_variance(km, q), np.float64), 1e-30))
        z_scores.extend((np.linalg.norm(miss, axis=1) / sd).tolist())
    if "rbf" in methods:
        rm = fit_rbf(c_train, k_train)
        preds["rbf"] = np.asarray(predict_rbf(rm, q))
    if "nearest" in methods:
        preds["nearest"] = np.asarray(predict_nearest(c_train, k_train, q))
    ys = {
        m: np.einsum("pr,srt,ut->sup", data.u_p, np.asarray(k, np.float64), data.u_t) * data.scale
        for m, k in preds.items()
    }
    return ys, z_scores


def _motion_predictions(
    data: _SharedData, train: np.ndarray, q: jax.Array, methods: Sequence[str]
) -> dict[str, np.ndarray]:
    """Paper 001's kriging of whole aligned motions at ``q`` (per pose, per element), scaled."""
    c_train, m_train = data.c_norm[train], data.motions[train]
    ys: dict[str, np.ndarray] = {}
    if "per_pose" in methods:
        pm = fit_kriging(c_train, m_train, data.pose_variogram, normalise=False)
        got = np.asarray(predict(pm, q), np.float64)
        ys["per_pose"] = got * data.scale
    if "per_element" in methods:
        cols = [
            np.asarray(
                predict(fit_kriging(c_train, m_train[:, :, k], v, normalise=False), q),
                np.float64,
            )
            for k, v in enumerate(data.element_variograms)
        ]
        ys["per_element"] = np.stack(cols, axis=-1) * data.scale
    return ys


def _sample_errors(
    tensor: TensorModel, truth: np.ndarray, y: np.ndarray, out: np.ndarray, skate: bool
) -> list[tuple[float, ...]]:
    """Per left-out sample: mean and max joint error and root error (m) of the prediction
    ``y`` in the root frame; with ``skate``, its foot skate (cm) after and before locking."""
    rows = []
    for j, s in enumerate(np.nonzero(out)[0]):
        h = float(tensor.heights[s])
        a = root_frame_positions(truth[s], tensor, h)
        b = root_frame_positions(y[j], tensor, h)
        dist = np.linalg.norm(a[0] - b[0], axis=-1)
        row = [float(dist.mean()), float(dist.max()), float(np.linalg.norm(a[1] - b[1]))]
        if skate:
            raw = _decoded(tensor, y[j], h)
            row += [100 * foot_skate(lock_feet(raw)), 100 * foot_skate(raw)]
        rows.append(tuple(row))
    return rows


def _summary(
    tensor: TensorModel,
    truth: np.ndarray,
    errors: dict[str, list[tuple[float, ...]]],
    z_scores: list[float],
    skate: bool,
) -> dict[str, dict[str, float]]:
    """Each method's errors averaged over the left-out samples, kriging's ``z_rms`` and, with
    ``skate``, the captures' own foot skate."""
    keys = ("joint_m", "max_joint_m", "root_m", "skate_cm", "skate_raw_cm")
    result = {
        m: dict(zip(keys, np.mean(v, axis=0).tolist(), strict=False)) for m, v in errors.items()
    }
    if z_scores:
        result["kriging"]["z_rms"] = float(np.sqrt(np.mean(np.square(z_scores))))
    if skate:
        own = [
            100 * foot_skate(_decoded(tensor, truth[s], float(tensor.heights[s])))
            for s in range(len(truth))
        ]
        result["captures"] = {"skate_cm": float(np.mean(own))}
    return result


def _decoded(tensor: TensorModel, y: np.ndarray, height: float) -> Motion:
    """Scaled aligned pose vectors ``(T, P)`` decoded and unwarped to the model clock."""
    return decode_clip(y, tensor.layout, tensor.skeleton.scaled(height), height, tensor.config.fps)


def foot_skate(motion: Motion) -> float:
    """Mean horizontal slide (m per frame) of a foot in contact, over both feet.

    On every contact frame (:func:`jcrowd.motion.gait.foot_contacts`) the foot's planted joint is
    the lower of its ankle and toe (heel down, then toe down); its horizontal displacement to the
    next frame is the slide. A perfect plant slides 0; a capture's own value (marker noise, the
    heel-to-toe roll) is the reference to compare a synthesized clip with, at the same frame rate.
    """
    slides = [np.linalg.norm(step, axis=-1) for _, step in planted_slides(motion)]
    every = np.concatenate(slides)
    return float(every.mean()) if every.size else 0.0


def evaluate_captures(
    model: MotionModel,
    clips: Sequence[Clip],
    *,
    level: int = 0,
    method: str = "kriging",
    foot_lock: bool = True,
) -> list[dict[str, Any]]:
    """Predict every left-started gait cycle of ``clips`` and compare with the capture.

    Per cycle: its controls, the model's reliability there, mean/max joint position error in the
    root frame after DTW time alignment (pose features ÷ height), and foot skate
    (:func:`foot_skate`) of the prediction (``skate_pred_cm``), of the decoded motion before
    foot locking (``skate_raw_cm``) and of the capture (``skate_true_cm``). The clips must use
    the model's skeleton (joint names).

    The prediction is what jcrowd delivers: with ``foot_lock`` (the default, as in the crowd
    step and ``jcrowd export``) planted feet are locked (:func:`jcrowd.motion.footlock.lock_feet`).
    Why the raw decode slides: the time mode keeps ``R_T`` = 30 of 100 aligned frames, which
    smooths the heel strike, and a time mode wide enough to keep it would make every core
    several times larger; locking costs a few flops per agent-frame instead
    (``bench/kriging.py`` reports skate before and after locking beside the captures').
    """
    from jcrowd.align import align_to_reference, pose_features

    names = model.skeleton.names
    out = []
    for sample in gait_samples(clips, fps=model.fps, mirrored=False):
        if sample.motion.skeleton.names != names:
            raise DataError(
                f"{sample.source}: expected the model's skeleton (joints {list(names)}), found "
                f"{list(sample.motion.skeleton.names)}"
            )
        c = sample.controls(model.control_names)
        raw = synthesize_clip(model, c.tolist(), level, height=sample.height, method=method)
        pred = lock_feet(raw) if foot_lock else raw
        fp = pose_features(pred) / sample.height
        fs = pose_features(sample.motion) / sample.height
        warp = align_to_reference(
            fs, fp, num_frames=sample.motion.num_frames, method="exact"
        ).frames
        a = pose_features(sample.motion).reshape(sample.motion.num_frames, -1, 3)
        b_all = pose_features(pred).reshape(pred.num_frames, -1, 3)
        i0 = np.clip(np.floor(warp).astype(int), 0, pred.num_frames - 1)
        i1 = np.minimum(i0 + 1, pred.num_frames - 1)
        w = (warp - i0)[:, None, None]
        b = b_all[i0] * (1 - w) + b_all[i1] * w
        err = np.linalg.norm(a - b, axis=-1)
        out.append(
            {
                "file": sample.source,
                "start": sample.cycle.start,
                "c": c.tolist(),
                "reliability": float(model_reliability(model, c[None], level)[0]),
                "mean_error_m": float(err.mean()),
                "max_error_m": float(err.max()),
                "skate_pred_cm": 100 * foot_skate(pred),
                "skate_raw_cm": 100 * foot_skate(raw),
                "skate_true_cm": 100 * foot_skate(sample.motion),
            }
        )
    return out
