"""Pose vectors: one gait-cycle sample on the aligned timeline as a ``(T, P)`` matrix, and back.

Per aligned frame ``t`` (DESIGN §4.5; papers 000 §3.2, 001 §3.5) the pose vector is::

    y(t) = [ root height,            1  ÷ body height
             root velocity,          2  heading frame (x left, z forward) ÷ height, per frame
             yaw rate,               1  radians per aligned frame
             root tilt,              3  exp map of the root rotation with its heading removed
             joint rotations,        3 per non-root joint: exp map relative to a reference
             ΔA ]                    1  sample frames per aligned frame (001 §3.5)

Choices, and why:

- *Velocity per aligned frame.* The root moves by ``d(t) = R(−h(t)) (p(t+1) − p(t))`` between
  aligned frames ``t`` and ``t+1`` (the last frame repeats the one before). Stored per aligned
  frame rather than per second, its sum over a cycle is the cycle's displacement — the control
  parameter — so interpolating pose vectors interpolates displacements linearly; speed in m/s is
  ``d · fps / ΔA``. Positions are divided by the sample's body height: subjects differ in size
  (the model keeps one reference skeleton; an agent is that skeleton scaled by its height).
- *Joint rotations relative to a reference.* ``e_j = log(r_j⁻¹ q_j)`` on the ``w ≥ 0`` side, with
  ``r_j`` the joint's mean rotation over the dataset (sign-aligned, normalised). Angles stay well
  below π, so the exp maps are continuous across frames and samples and nearly linear — plain
  exp maps of ``q`` jump where the angle crosses π and differ between ``q`` and ``−q``.
- *Element scales* (:class:`PoseLayout.scale`): a pose vector is divided by these before it goes
  into the tensor so the groups weigh comparably: positions by a quarter of the body height (a
  1-radian turn of a 0.25·height limb moves it as far as one unit of root motion), angles by 1,
  and ΔA by its dataset mean (relative speed change).
- *ΔA.* ``ΔA(t) = A(t+1) − A(t)`` in sample frames (``A`` maps aligned frames to fractional sample
  frames; the last entry repeats the one before), so ``A(t) = A(0) + Σ_{k<t} ΔA(k)``.

:func:`decode_pose_vectors` is the exact inverse of :func:`encode_sample` on the aligned frames
(tested to 1e-4 m); :func:`unwarp` then resamples the aligned frames onto the sample clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jcrowd.errors import MotionError
from jcrowd.motion.clip import Motion, rest_forward
from jcrowd.motion.rotation import (
    quat_canonical,
    quat_conj,
    quat_from_expmap,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_slerp,
    quat_to_expmap,
    quat_yaw,
    yaw_quat,
)
from jcrowd.motion.skeleton import Skeleton

__all__ = [
    "PoseLayout",
    "cycle_closing",
    "decode_clip",
    "decode_pose_vectors",
    "encode_sample",
    "mean_rotations",
    "sample_at",
    "unwarp",
]


@dataclass(frozen=True)
class PoseLayout:
    """Where each quantity sits in a pose vector, and the references it is relative to.

    Attributes:
        num_joints: joints of the reference skeleton (the root included).
        reference: ``(J, 4)`` per-joint reference rotations ``r_j`` (row 0 unused).
        scale: ``(P,)`` element scales (the tensor stores ``y / scale``).
    """

    num_joints: int
    reference: np.ndarray
    scale: np.ndarray

    @property
    def size(self) -> int:
        return 1 + 2 + 1 + 3 + 3 * (self.num_joints - 1) + 1

    @property
    def height(self) -> int:
        return 0

    @property
    def velocity(self) -> slice:
        return slice(1, 3)

    @property
    def yaw_rate(self) -> int:
        return 3

    @property
    def tilt(self) -> slice:
        return slice(4, 7)

    def joint(self, j: int) -> slice:
        """The exp-map elements of non-root joint ``j``."""
        return slice(7 + 3 * (j - 1), 10 + 3 * (j - 1))

    @property
    def delta_a(self) -> int:
        return self.size - 1

    def pose_rows(self) -> np.ndarray:
        """``(P,)`` bool: the elements that are poses (root height and tilt, joint rotations), not
        rates (velocity, yaw rate, ΔA). A cycle closes in these (:func:`cycle_closing`)."""
        rows = np.ones(self.size, bool)
        rows[[*range(self.size)[self.velocity], self.yaw_rate, self.delta_a]] = False
        return rows

    def joint_elements(self, joints: list[int] | tuple[int, ...]) -> np.ndarray:
        """Indices of the elements of the given non-root joints (for progressive reduction)."""
        return (
            np.concatenate([np.arange(self.size)[self.joint(j)] for j in joints])
            if joints
            else np.zeros(0, int)
        )


def sample_at(motion: Motion, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations ``(T, J, 4)`` and root positions ``(T, 3)`` at fractional ``frames``."""
    f = np.asarray(frames, np.float64)
    if f.min() < -1e-9 or f.max() > motion.num_frames - 1 + 1e-9:
        raise MotionError(
            f"pose vectors: frames must lie in [0, {motion.num_frames - 1}], found "
            f"[{f.min():.3f}, {f.max():.3f}]"
        )
    i0 = np.clip(np.floor(f).astype(int), 0, motion.num_frames - 1)
    i1 = np.minimum(i0 + 1, motion.num_frames - 1)
    a = (f - i0)[:, None]
    rot = np.asarray(motion.rotations, np.float64)
    pos = np.asarray(motion.root_positions, np.float64)
    q = quat_slerp(rot[i0], rot[i1], np.broadcast_to(a[:, None], (*rot[i0].shape[:-1], 1)))
    return q, pos[i0] * (1 - a) + pos[i1] * a


def mean_rotations(rotation_sets: list[np.ndarray]) -> np.ndarray:
    """Per-joint mean rotation ``(J, 4)`` of ``(F, J, 4)`` arrays (sign-aligned, normalised)."""
    allq = np.concatenate([np.asarray(r, np.float64) for r in rotation_sets])
    first = allq[0]
    signs = np.where(np.sum(allq * first, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    mean = (allq * signs).mean(axis=0)
    # A second pass aligns to the mean itself (the first frame may be an outlier).
    signs = np.where(np.sum(allq * mean, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return quat_normalize((allq * signs).mean(axis=0))


def encode_sample(
    motion: Motion, frames: np.ndarray, layout: PoseLayout, height: float
) -> np.ndarray:
    """Pose vectors ``(T, P)`` (unscaled) of ``motion`` at fractional sample ``frames`` ``(T,)``."""
    t = len(frames)
    if t < 2 or np.any(np.diff(frames) < 0):
        raise MotionError("pose vectors: expected at least 2 non-decreasing aligned frames")
    rot, pos = sample_at(motion, frames)
    fwd = rest_forward(motion.skeleton)
    yaw = np.unwrap(np.asarray(quat_yaw(rot[:, 0], fwd), np.float64))
    y = np.zeros((t, layout.size))
    y[:, layout.height] = pos[:, 1] / height
    step = np.diff(pos, axis=0)
    step = np.concatenate([step, step[-1:]])
    local = quat_rotate(yaw_quat(-yaw), step)
    y[:, layout.velocity] = local[:, [0, 2]] / height
    dyaw = np.diff(yaw)
    y[:, layout.yaw_rate] = np.concatenate([dyaw, dyaw[-1:]])
    tilt = quat_mul(yaw_quat(-yaw), rot[:, 0])
    y[:, layout.tilt] = quat_to_expmap(tilt)
    ref = np.asarray(layout.reference, np.float64)
    rel = quat_canonical(quat_mul(quat_conj(ref[None, 1:]), rot[:, 1:]))
    y[:, 7 : 7 + 3 * (layout.num_joints - 1)] = quat_to_expmap(rel).reshape(t, -1)
    da = np.diff(frames)
    y[:, layout.delta_a] = np.concatenate([da, da[-1:]])
    return y


def decode_pose_vectors(
    y: np.ndarray, layout: PoseLayout, skeleton: Skeleton, height: float, fps: float
) -> tuple[Motion, np.ndarray]:
    """A clip on the aligned timeline (one frame per pose vector) and its sample-frame times.

    The root starts above the origin facing +Z (heading 0) and integrates the stored velocity
    and yaw rate; ``skeleton`` should be the reference skeleton scaled to ``height``.

    Returns:
        ``(motion with T frames, A (T,) fractional sample frames of each aligned frame)``;
        :func:`unwarp` resamples it onto the sample clock.
    """
    y = np.asarray(y, np.float64)
    t = y.shape[0]
    yaw = np.concatenate([[0.0], np.cumsum(y[:-1, layout.yaw_rate])])
    vel = np.zeros((t, 3))
    vel[:, [0, 2]] = y[:, layout.velocity] * height
    steps = quat_rotate(yaw_quat(yaw), vel)
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum(steps[:-1], axis=0)])
    pos[:, 1] = y[:, layout.height] * height
    root = quat_mul(yaw_quat(yaw), quat_from_expmap(y[:, layout.tilt]))
    ref = np.asarray(layout.reference, np.float64)
    e = y[:, 7 : 7 + 3 * (layout.num_joints - 1)].reshape(t, -1, 3)
    joints = quat_mul(ref[None, 1:], quat_from_expmap(e))
    rot = np.concatenate([root[:, None], joints], axis=1)
    a = np.concatenate([[0.0], np.cumsum(y[:-1, layout.delta_a])])
    return Motion(skeleton, quat_normalize(rot).astype(np.float32), pos.astype(np.float32), fps), a


def unwarp(motion: Motion, times: np.ndarray) -> Motion:
    """Resample an aligned-time clip onto integer sample frames ``0 .. floor(times[-1])``.

    ``times`` ``(T,)`` non-decreasing: the sample frame of each aligned frame (from
    :func:`decode_pose_vectors`). This is the inverse time-warp of 001 §3.5.
    """
    times = np.asarray(times, np.float64) - float(times[0])
    if np.any(np.diff(times) <= 0):
        raise MotionError("unwarp: expected strictly increasing times (every ΔA > 0)")
    n = int(np.floor(times[-1] + 1e-9)) + 1
    aligned = np.interp(
        np.arange(n, dtype=np.float64), times, np.arange(len(times), dtype=np.float64)
    )
    rot, pos = sample_at(motion, aligned)
    return Motion(motion.skeleton, rot.astype(np.float32), pos.astype(np.float32), motion.fps)


def decode_clip(
    y: np.ndarray, layout: PoseLayout, skeleton: Skeleton, height: float, fps: float
) -> Motion:
    """Scaled aligned pose vectors ``(T, P)`` of a *predicted* cycle → a clip on the model clock.

    Predicted time steps ΔA are floored at 1e-3 (a kriged or truncated ΔA can dip to 0 or
    below, which would stop or reverse time), then :func:`decode_pose_vectors` and
    :func:`unwarp`.
    """
    y = np.array(y, np.float64)
    y[:, layout.delta_a] = np.maximum(y[:, layout.delta_a], 1e-3)
    motion, times = decode_pose_vectors(y, layout, skeleton, height, fps)
    return unwarp(motion, times)


def cycle_closing(u_time: np.ndarray) -> np.ndarray:
    """``d = Ũ_T[T−1] − Ũ_T[0]`` ``(R_T,)``: what a clip's time basis moves between the cycle's
    first and last aligned frame.

    A clip's pose at the last aligned frame is the next cycle's first pose in the capture, but
    the kriged cycles do not close (the captured cycles are not periodic: at level 0 the pose
    rows differ by up to 0.9 rad between the two ends of the default model's samples). Synthesis
    closes them in the pose rows (:meth:`PoseLayout.pose_rows`) by a linear ramp,
    ``y(τ) − (τ / (T−1)) · (U_P K d)``, so a cycle hands over to the next without a jump; the rate
    rows keep their values, so stride and cycle duration do not change. The ramp moves a pose by
    at most its own non-closure, spread over the cycle.
    """
    u = np.asarray(u_time, np.float64)
    return u[-1] - u[0]
