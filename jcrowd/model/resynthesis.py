"""One agent of a recorded run as a full-detail :class:`~jcrowd.motion.clip.Motion` (for BVH
export).

A recording made with ``jcrowd run --record all`` holds, per step and agent, the root position
and heading, the phase τ, the current and next clip's controls and whether a next clip was
chosen. That is enough to re-synthesize the agent at level 0 whatever level it was drawn at:
the pose vector at each step is the kriged clip at τ (000 Eqs. 4–5, 8), blended with the next
clip over the second half of the cycle and closed over the cycle
(:func:`jcrowd.model.posevec.cycle_closing`) exactly as :mod:`jcrowd.crowd.stepping` blends near
agents, and the root is put where the run put it. Every joint of the model's skeleton is
written (joints a level drops keep their reference rotation), the skeleton scaled by the agent's
recorded height (its stature) over the model's ``body_height``, as the step scales it.
"""

from __future__ import annotations

from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from jcrowd.errors import JcrowdError
from jcrowd.kriging.universal import predict
from jcrowd.model.motion_model import MotionModel
from jcrowd.model.posevec import cycle_closing
from jcrowd.motion.clip import Motion, joint_positions
from jcrowd.motion.gait import find_feet
from jcrowd.motion.planting import leg_chains, plant_sequence, planted_rotations
from jcrowd.motion.rotation import quat_from_expmap, quat_mul, quat_normalize, yaw_quat
from jcrowd.motion.skeleton import forward_kinematics

__all__ = ["RECORD_KEYS", "agent_motion", "heel_strikes"]

RECORD_KEYS = ("position", "heading", "tau", "control", "control_next", "has_next", "height")


def _pose_vectors(model: MotionModel, c: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Scaled level-0 pose vectors ``(F, P)`` for per-frame controls ``(F, d)`` and phases."""
    lv = model.levels[0]
    cores = np.asarray(predict(lv.kriging, jnp.asarray(c, jnp.float32)), np.float64)
    last = lv.u_time.shape[0] - 1
    t = np.clip(tau, 0.0, last)
    i0 = np.minimum(np.floor(t).astype(int), last - 1)
    frac = (t - i0)[:, None]
    w = lv.u_time[i0] * (1 - frac) + lv.u_time[i0 + 1] * frac  # 000 Eq. 5
    g = np.einsum("frs,fs->fr", cores, w)
    # The cycle closed in its pose rows as the step closes it (posevec.cycle_closing).
    ramp = (t / last)[:, None] * (cores @ cycle_closing(lv.u_time))
    rows = model.layout.pose_rows()
    return (g @ lv.u_pose.T - rows * (ramp @ lv.u_pose.T)) * model.layout.scale


def agent_motion(
    model: MotionModel, recording: Mapping[str, np.ndarray], agent: int, plant: bool = False
) -> Motion:
    """The recorded ``agent`` re-synthesized at full detail, at the run's frame rate; with
    ``plant``, its feet planted as the crowd step plants a near agent's
    (:mod:`jcrowd.motion.planting`; the recording's run had the dynamics on)."""
    missing = [k for k in RECORD_KEYS if k not in recording]
    if missing:
        raise JcrowdError(f"export: expected a recording made with --record all, missing {missing}")
    n = recording["position"].shape[1]
    if not 0 <= agent < n:
        raise JcrowdError(f"export: expected an agent id in 0..{n - 1}, found {agent}")
    tau = np.asarray(recording["tau"][:, agent], np.float64)
    y = _pose_vectors(model, recording["control"][:, agent], tau)
    y_next = _pose_vectors(model, recording["control_next"][:, agent], tau)
    half = (model.levels[0].u_time.shape[0] - 1) / 2
    x = np.clip((tau - half) / half, 0.0, 1.0)
    s = np.where(recording["has_next"][:, agent], x * x * (3 - 2 * x), 0.0)[:, None]
    y = y + s * (y_next - y)
    height = float(recording["height"][agent]) / model.body_height  # the skeleton's scale
    heading = np.asarray(recording["heading"][:, agent], np.float64)
    xz = np.asarray(recording["position"][:, agent], np.float64)
    fps = float(recording["fps"]) if "fps" in recording else 30.0
    motion = _motion(model, y, heading, xz, height, fps)
    if not plant:
        return motion
    # The stride warp the step drew the agent with (recordings without it: none).
    stride = recording["stride"][:, agent] if "stride" in recording else None
    return _planted(model, motion, tau, height, heading, stride)


def _motion(
    model: MotionModel,
    y: np.ndarray,
    heading: np.ndarray,
    xz: np.ndarray,
    height: float,
    fps: float,
) -> Motion:
    """A clip from scaled pose vectors ``(F, P)``, headings, root ``(x, z)`` and the skeleton's
    scale."""
    layout, j = model.layout, model.layout.num_joints
    root = quat_mul(yaw_quat(heading), quat_from_expmap(y[:, layout.tilt]))
    e = y[:, 7 : 7 + 3 * (j - 1)].reshape(len(y), j - 1, 3)
    joints = quat_mul(np.asarray(layout.reference, np.float64)[None, 1:], quat_from_expmap(e))
    rot = quat_normalize(np.concatenate([root[:, None], joints], axis=1))
    pos = np.stack([xz[:, 0], y[:, layout.height] * height, xz[:, 1]], axis=1)
    return Motion(
        model.skeleton.scaled(height), rot.astype(np.float32), pos.astype(np.float32), fps
    )


def heel_strikes(model: MotionModel) -> tuple[float, float]:
    """The aligned phases of the left and the right heel strike: where the left ankle, then
    the right, is furthest ahead in the model's mean clip at level 0 (as the crowd step finds
    its double-support phases, :func:`jcrowd.crowd.clips.double_support_phases`)."""
    last = model.levels[0].u_time.shape[0] - 1
    c = np.asarray(model.levels[0].kriging.controls, np.float64).mean(axis=0)
    tau = np.arange(last, dtype=np.float64)
    y = _pose_vectors(model, np.repeat(c[None], last, axis=0), tau)
    zero = np.zeros(last)
    pos = np.asarray(joint_positions(_motion(model, y, zero, np.zeros((last, 2)), 1.0, 30.0)))
    feet = find_feet(model.skeleton)
    apart = pos[:, feet.left_ankle, 2] - pos[:, feet.right_ankle, 2]  # heading 0 faces +z
    return float(np.argmax(apart)), float(np.argmin(apart))


def _planted(
    model: MotionModel,
    motion: Motion,
    tau: np.ndarray,
    scale: float,
    heading: np.ndarray | None = None,
    stride: np.ndarray | None = None,
) -> Motion:
    """``motion`` with its feet planted frame by frame from no pins
    (:func:`jcrowd.motion.planting.plant_sequence`, with the stride warp when ``stride`` is
    given), written back as joint rotations."""
    skel = motion.skeleton
    feet = find_feet(skel)
    legs = leg_chains(
        skel.parents, (feet.left_ankle, feet.left_toe, feet.right_ankle, feet.right_toe)
    )
    world, before = (
        np.asarray(a, np.float64)
        for a in forward_kinematics(skel, motion.rotations, motion.root_positions)
    )
    last = float(model.levels[0].u_time.shape[0] - 1)
    after = plant_sequence(
        legs,
        heel_strikes(model),
        last,
        jnp.asarray(before, jnp.float32),
        jnp.asarray(tau, jnp.float32),
        jnp.float32(scale),
        None if stride is None else jnp.asarray(heading, jnp.float32),
        None if stride is None else jnp.asarray(stride, jnp.float32),
    )
    rot = planted_rotations(
        skel.parents,
        legs,
        np.asarray(motion.rotations, np.float64),
        world,
        before,
        np.asarray(after, np.float64),
    )
    return Motion(skel, quat_normalize(rot).astype(np.float32), motion.root_positions, motion.fps)
