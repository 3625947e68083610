"""``MotionModel``: the reduced motion tensor with universal kriging of its cores, per level.

The second half of the fit (DESIGN §4 steps 8–9; papers 000 §3.3, 001 §3–4). For key level
``l`` with Tucker model ``M ≈ Z̃ ×1 U_P ×2 U_T ×3 U_S``, sample ``i``'s core is
``K_i = Z̃ ×3 u_{S,i}`` (an ``R_P × R_T`` matrix), and a new motion for control parameters
``c`` has the core ``K(c) = K_m(c) + Σ_i b_i(c) K_{r,i}`` (000 Eq. 8, :mod:`jcrowd.kriging`),
so its pose vectors are ``Y(c) = U_P K(c) U_Tᵀ`` (000 Eq. 4 over all aligned frames).

Controls default to ``(dx, dz, dyaw)`` — the cycle's displacement and turn (000 §5 uses the 2-D
displacement plus the character's height; a single-subject dataset has no height to vary). The
kriging model normalises them so the control space is isotropic (001 §6). One variogram,
fitted on the finest level's cores, serves every level, so the kriging weights ``b(c)`` of a
clip are the same at every level (what lets a crowd agent keep them across LOD changes).
A synthesized clip is the reference skeleton scaled to ``height``. :func:`synthesize_clip` is
pure; fitting runs NumPy/JAX on arrays.

Queries outside the sampled control range are clamped to it, control by control
(:func:`clamp_controls`), before kriging: the hyperplane trend ``K_m(c)`` is a least-squares fit
*inside* the samples, and extrapolating it is unreliable (on ``cmu/walk`` the backward/sideways take
``09_12`` left out lies outside the straight walks' range; ``bench/repro_001.py`` reports the
leave-one-clip-out error with and without clamping). The crowd step clamps the same way. The
reliability ρ is still reported at the requested controls, so a caller sees how far out it asked.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from jcrowd.errors import KrigingError
from jcrowd.kriging.rbf import fit_rbf, predict_nearest, predict_rbf
from jcrowd.kriging.system import trend_basis
from jcrowd.kriging.universal import KrigingModel, fit_kriging, predict, reliability
from jcrowd.model.posevec import PoseLayout, decode_clip
from jcrowd.model.samples import CONTROL_NAMES
from jcrowd.model.tensor_model import TensorModel
from jcrowd.motion import footlock
from jcrowd.motion.clip import Motion
from jcrowd.motion.skeleton import Skeleton
from jcrowd.tensor.algebra import mode_product

__all__ = [
    "METHODS",
    "MotionLevel",
    "MotionModel",
    "clamp_controls",
    "fit_motion_model",
    "level_cores",
    "level_pose_vectors",
    "model_reliability",
    "sample_cores",
    "synthesize_clip",
]


@dataclass(frozen=True)
class MotionLevel:
    """One accuracy level: bases, the kriged cores and the joints it synthesizes.

    Attributes:
        u_pose: ``(P, R_P)`` with the rows of dropped joints' elements zeroed (000 §4.3).
        u_time: ``(T, R_T)``.
        kriging: kriging of the ``(S, R_P, R_T)`` sample cores over the controls.
        joints: joints synthesized (the others stay at their reference rotation).
    """

    u_pose: np.ndarray
    u_time: np.ndarray
    kriging: KrigingModel
    joints: tuple[int, ...]


@dataclass(frozen=True)
class MotionModel:
    """A fitted motion model: per level bases + kriging, plus what decoding needs.

    Attributes:
        skeleton: reference skeleton for a 1 m tall character.
        layout: pose-vector layout (references, element scales).
        control_names: the kriged controls, e.g. ``("dx", "dz", "dyaw")``.
        control_ranges: ``(d, 2)`` min/max of the samples' controls.
        levels: finest first.
        fps: the model rate of synthesized clips.
        default_height: height (m) used when ``height`` is not a control.
        body_height: the standing height of the body drawn on the skeleton, per metre of the
            skeleton (its rest joints and End Sites span 1 m). Agents' heights are statures:
            the crowd step scales the skeleton by ``height / body_height``, so the drawn body,
            not its joints, is ``height`` tall. Loading a model file binds the shipped body and
            measures it (:func:`jcrowd.io.with_body_height`); 1.0 (the joints span the height)
            for a model that has no body bound, such as one just fitted in memory.
    """

    skeleton: Skeleton
    layout: PoseLayout
    control_names: tuple[str, ...]
    control_ranges: np.ndarray
    levels: tuple[MotionLevel, ...]
    fps: float
    default_height: float
    body_height: float = 1.0


def sample_cores(tucker_core: np.ndarray, u_samples: np.ndarray) -> np.ndarray:
    """``K_i = Z̃ ×3 u_{S,i}`` for every sample: ``(S, R_P, R_T)`` (000 §3.3)."""
    return np.moveaxis(mode_product(tucker_core, u_samples, 2), 2, 0)


def fit_motion_model(
    tensor: TensorModel,
    controls: Sequence[str] = ("dx", "dz", "dyaw"),
    *,
    samples: np.ndarray | None = None,
) -> MotionModel:
    """Krige every key level's sample cores over ``controls`` (optionally a subset of samples)."""
    unknown = [c for c in controls if c not in CONTROL_NAMES]
    if unknown:
        raise KrigingError(f"controls: expected names from {CONTROL_NAMES}, found {unknown}")
    idx = [CONTROL_NAMES.index(c) for c in controls]
    rows = np.arange(len(tensor.controls)) if samples is None else np.asarray(samples)
    c = tensor.controls[rows][:, idx]
    levels: list[MotionLevel] = []
    for lv in tensor.levels:
        u_p, u_t, u_s = lv.tucker.factors
        cores = sample_cores(lv.tucker.core, u_s[rows])
        dropped = [j for j in range(1, tensor.skeleton.num_joints) if j not in lv.joints]
        u_p = np.array(u_p, np.float64)
        u_p[tensor.layout.joint_elements(dropped)] = 0.0
        # One variogram for the whole model, fitted on the finest level: the kriging weights
        # b(c) then agree at every level (Γ is the same up to the sill, and b is invariant to
        # scaling Γ), so a crowd agent stores b once per clip and changes level for free.
        shared = levels[0].kriging.variogram if levels else None
        levels.append(MotionLevel(u_p, np.asarray(u_t), fit_kriging(c, cores, shared), lv.joints))
    ranges = np.stack([c.min(axis=0), c.max(axis=0)], axis=1)
    return MotionModel(
        tensor.skeleton,
        tensor.layout,
        tuple(controls),
        ranges,
        tuple(levels),
        tensor.config.fps,
        float(np.median(tensor.heights)),
    )


def clamp_controls(c: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Controls ``(..., d)`` clamped, control by control, to ``ranges`` ``(d, 2)`` (module doc)."""
    return np.clip(np.asarray(c, np.float64), ranges[:, 0], ranges[:, 1])


METHODS = ("kriging", "rbf", "nearest")
"""Ways to predict a core: the model's kriging, or the baselines refitted on its samples."""


def _sample_cores(km: KrigingModel) -> tuple[np.ndarray, np.ndarray]:
    """Normalised sample controls and their cores, rebuilt as a kriging model's trend + residual."""
    c = (np.asarray(km.controls, np.float64) - np.asarray(km.control_mean, np.float64)) / (
        np.asarray(km.control_scale, np.float64)
    )
    values = trend_basis(c) @ np.asarray(km.trend, np.float64) + np.asarray(km.residuals)
    return c, values.reshape((len(c), *km.value_shape))


def level_cores(
    model: MotionModel, c: np.ndarray, level: int = 0, method: str = "kriging"
) -> np.ndarray:
    """Cores ``(..., R_P, R_T)`` for controls ``(..., d)``, clamped to the model's range first.

    ``method``: ``"kriging"`` (the model), ``"rbf"`` (verbs-and-adverbs RBF) or ``"nearest"``
    (nearest sample), the baselines fitted on the same samples in the same normalised controls.
    """
    if method not in METHODS:
        raise KrigingError(f"method: expected one of {METHODS}, found {method!r}")
    km = model.levels[level].kriging
    q = clamp_controls(c, model.control_ranges)
    if method == "kriging":
        return np.asarray(predict(km, jnp.asarray(q, jnp.float32)), np.float64)
    cs, values = _sample_cores(km)
    qn = jnp.asarray(
        (q - np.asarray(km.control_mean, np.float64)) / np.asarray(km.control_scale, np.float64),
        jnp.float32,
    )
    if method == "rbf":
        return np.asarray(predict_rbf(fit_rbf(cs, values), qn), np.float64)
    return np.asarray(predict_nearest(cs, values, qn), np.float64)


def level_pose_vectors(
    model: MotionModel, c: np.ndarray, level: int = 0, method: str = "kriging"
) -> np.ndarray:
    """Unscaled pose vectors ``(..., T, P)`` for controls ``(..., d)`` at a level (batched).

    The controls are clamped to the model's range first (:func:`clamp_controls`); ``method`` as
    in :func:`level_cores`.
    """
    lv = model.levels[level]
    cores = level_cores(model, c, level, method)
    y = np.einsum("pr,...rs,ts->...tp", lv.u_pose, cores, lv.u_time)
    return y * model.layout.scale


def model_reliability(model: MotionModel, c: np.ndarray, level: int = 0) -> np.ndarray:
    """ρ(c) (001 App. B) of the level's kriging at ``(..., d)`` controls."""
    return np.asarray(reliability(model.levels[level].kriging, jnp.asarray(c, jnp.float32)))


def synthesize_clip(
    model: MotionModel,
    c: Sequence[float],
    level: int = 0,
    *,
    height: float | None = None,
    lock_feet: bool = False,
    method: str = "kriging",
) -> Motion:
    """One gait cycle for controls ``c`` at ``level``, on the model's clock (``model.fps``).

    Starts above the origin facing +Z; the skeleton is the reference scaled to ``height``
    (default: the control named ``height`` if kriged, else the model's default height).
    ``lock_feet`` applies :func:`jcrowd.motion.footlock.lock_feet` (planted feet stop sliding; the
    root's path shifts by a few cm per cycle).
    Controls outside the model's range are clamped to it (module doc); ``method`` picks kriging
    or a baseline (:func:`level_cores`).
    """
    q = np.asarray(c, np.float64)
    if q.shape != (len(model.control_names),) or not np.all(np.isfinite(q)):
        raise KrigingError(
            f"synthesize: expected {len(model.control_names)} finite controls "
            f"{model.control_names}, found {q.tolist()}"
        )
    if not 0 <= level < len(model.levels):
        raise KrigingError(
            f"synthesize: expected a level in 0..{len(model.levels) - 1}, found {level}"
        )
    if height is None:
        names = model.control_names
        height = float(q[names.index("height")]) if "height" in names else model.default_height
    y = level_pose_vectors(model, q, level, method)
    motion = decode_clip(y, model.layout, model.skeleton.scaled(height), height, model.fps)
    return footlock.lock_feet(motion) if lock_feet else motion
