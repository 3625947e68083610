"""A procedural walker: synthetic gait whose control parameters are known exactly.

The walker is the ground truth for gait analysis (contacts, cycles, control parameters) and the
source of the sample clip the package ships. Its design, in the conventions of DESIGN §3
(metres, seconds, radians, Y up, facing +Z at rest, left side at +X):

- The root (``Hips``) follows a circular arc at constant ``speed``; the heading turns uniformly
  by ``dyaw_per_cycle`` per gait cycle (a straight line when it is 0) and starts at 0 (+Z) at
  the origin at t = 0. The root's yaw is the path tangent exactly; its height bobs at twice the
  cycle frequency (highest in mid single support).
- Footsteps lie half a hip width to either side of the path. A foot is planted, flat and at
  ground height for the first ``STANCE_FRACTION`` of its cycle (zero world velocity), then
  swings to its next footstep along a raised parabola, leaving and landing with a small forward
  and a clear vertical speed (as a heel lands), so the contact onset is sharp. Left heel strikes
  happen at ``lead_in + k * cycle_duration`` exactly; the right foot runs half a cycle later.
- Legs are posed by analytic two-bone IK (hip → knee → ankle, knee bending forward), so forward
  kinematics reproduces the designed foot positions. The root height is the largest one (one
  constant plus the bob) at which every designed ankle position stays within 99.5 % of the leg's
  reach, found on a fine time grid that does not depend on ``fps``. Since the stance foot stays
  flat (no heel rise at push-off), the knees bend more than a person's (≈ 50° in mid-stance at
  1.3 m/s): the walker is a test oracle and a sample, not a style reference.
- The upper body adds a chest twist, a head that keeps facing the path, and arms swinging
  opposite to the legs; ``seed`` varies only these style amplitudes.

Because the path is a uniform arc and nothing on the root depends on the gait phase except its
height, the root displacement over any window of one cycle is the same in that window's start
heading frame: ``dz = (L/θ) sin θ``, ``dx = (L/θ)(1 − cos θ)`` with ``L = speed · T``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from jcrowd.errors import MotionError
from jcrowd.motion.clip import Motion
from jcrowd.motion.rotation import (
    quat_canonical,
    quat_conj,
    quat_from_axis_angle,
    quat_from_matrix,
    quat_mul,
    yaw_quat,
)
from jcrowd.motion.skeleton import Skeleton, rest_positions

__all__ = ["STANCE_FRACTION", "WalkTruth", "procedural_walk", "walker_skeleton"]

STANCE_FRACTION = 0.6
"""Share of a gait cycle each foot spends planted (the rest is swing)."""

_REACH = 0.995  # the stretched leg never exceeds this share of thigh + shank (keeps IK regular)
_BOB = 0.015  # root bob amplitude, fraction of height (≈ 5 cm peak to peak at 1.75 m)
_LIFT = 0.035  # peak foot lift in swing, fraction of height
_LIFT_OFF_SPEED = 0.2  # horizontal foot speed leaving the ground, share of the mean swing speed
_LAND_SPEED = 0.15  # horizontal foot speed at touchdown, share of the mean swing speed

# Rest skeleton in units of the character's height: (name, parent, offset). The lowest point
# (toe joint and toe tip) is at 0 and the head top at 1; proportions after Drillis & Contini.
_ANKLE, _SHANK, _THIGH, _PELVIS, _HIP_HALF = 0.039, 0.246, 0.245, 0.030, 0.050
_JOINTS: tuple[tuple[str, int, tuple[float, float, float]], ...] = (
    ("Hips", -1, (0.0, 0.0, 0.0)),
    ("LeftUpLeg", 0, (_HIP_HALF, -_PELVIS, 0.0)),
    ("LeftLeg", 1, (0.0, -_THIGH, 0.0)),
    ("LeftFoot", 2, (0.0, -_SHANK, 0.0)),
    ("LeftToe", 3, (0.0, -_ANKLE, 0.073)),
    ("RightUpLeg", 0, (-_HIP_HALF, -_PELVIS, 0.0)),
    ("RightLeg", 5, (0.0, -_THIGH, 0.0)),
    ("RightFoot", 6, (0.0, -_SHANK, 0.0)),
    ("RightToe", 7, (0.0, -_ANKLE, 0.073)),
    ("Spine", 0, (0.0, 0.060, 0.0)),
    ("Chest", 9, (0.0, 0.120, 0.0)),
    ("Neck", 10, (0.0, 0.100, 0.0)),
    ("Head", 11, (0.0, 0.050, 0.0)),
    ("LeftArm", 10, (0.105, 0.080, 0.0)),
    ("LeftForeArm", 13, (0.0, -0.186, 0.0)),
    ("LeftHand", 14, (0.0, -0.146, 0.0)),
    ("RightArm", 10, (-0.105, 0.080, 0.0)),
    ("RightForeArm", 16, (0.0, -0.186, 0.0)),
    ("RightHand", 17, (0.0, -0.146, 0.0)),
)
_ENDS: tuple[tuple[int, tuple[float, float, float]], ...] = (
    (4, (0.0, 0.0, 0.040)),  # left toe tip
    (8, (0.0, 0.0, 0.040)),  # right toe tip
    (12, (0.0, 0.110, 0.0)),  # head top
)


def walker_skeleton(height: float = 1.75) -> Skeleton:
    """The walker's 19-joint skeleton, scaled so its rest height is ``height`` metres.

    Rest height = head-top End Site minus the lowest joint or End Site (the toes). Y is up, the
    character faces +Z and its left side is at +X; limbs hang straight down at rest.
    """
    if not height > 0:
        raise MotionError(f"walker_skeleton: expected a positive height (m), found {height}")
    offsets: Any = np.array([o for _, _, o in _JOINTS], np.float64)
    end_offsets: Any = np.array([o for _, o in _ENDS], np.float64)
    names, parents = tuple(n for n, _, _ in _JOINTS), tuple(p for _, p, _ in _JOINTS)
    unit = Skeleton(names, parents, offsets, tuple(p for p, _ in _ENDS), end_offsets)
    joints, ends = rest_positions(unit)
    ys = np.concatenate([joints[:, 1], ends[:, 1]])
    factor = height / float(ends[2, 1] - ys.min())
    # NumPy leaves (Motion and Skeleton hold NumPy on the offline path, as read_bvh's do).
    offsets = np.asarray(offsets * factor, np.float32)
    end_offsets = np.asarray(end_offsets * factor, np.float32)
    return Skeleton(names, parents, offsets, unit.end_parents, end_offsets)


@dataclass(frozen=True, eq=False)
class WalkTruth:
    """The exact control parameters of a :func:`procedural_walk`, one entry per gait cycle.

    A cycle runs from one left heel strike to the next. Displacements are in the heading frame
    at the cycle's start (z forward, x to the character's left).

    Attributes:
        dx, dz: ``(C,)`` root displacement over each cycle (m).
        dyaw: ``(C,)`` heading change (rad, + = left).
        speed: ``(C,)`` root path length / duration (m/s).
        duration: ``(C,)`` seconds.
        left_strikes: ``(C + 1,)`` left heel strike times (s); cycle ``i`` spans
            ``left_strikes[i]`` to ``left_strikes[i + 1]``.
        height: character height (m).
        fps: frame rate of the clip.
        contacts: ``(F, 2)`` bool, left and right foot planted at each frame.
    """

    dx: np.ndarray
    dz: np.ndarray
    dyaw: np.ndarray
    speed: np.ndarray
    duration: np.ndarray
    left_strikes: np.ndarray
    height: float
    fps: float
    contacts: np.ndarray

    @property
    def num_cycles(self) -> int:
        return len(self.dx)

    @property
    def strike_frames(self) -> np.ndarray:
        """Frame index of each left heel strike, ``(C + 1,)`` int."""
        return np.rint(self.left_strikes * self.fps).astype(np.int64)


def procedural_walk(
    *,
    cycles: int = 3,
    speed: float = 1.3,
    dyaw_per_cycle: float = 0.0,
    cycle_duration: float = 1.1,
    height: float = 1.75,
    fps: float = 60.0,
    lead_in: float = 0.3,
    seed: int = 0,
    tail: float = 0.3,
) -> tuple[Motion, WalkTruth]:
    """A walk with known control parameters (see the module docstring for the design).

    Args:
        cycles: complete gait cycles (left strike to left strike) in the clip.
        speed: root speed along its path (m/s).
        dyaw_per_cycle: heading change per cycle (rad; + turns left, from +Z towards +X).
        cycle_duration: seconds per cycle (two steps).
        height: character height (m).
        fps: frame rate.
        lead_in: seconds of walking before the first left heel strike.
        seed: varies the upper-body style only; the control parameters stay exact.
        tail: seconds after the last left heel strike (at least 0.3 so it is detectable).

    Returns:
        ``(motion, truth)``; the motion holds NumPy float32 arrays and spans
        ``lead_in + cycles * cycle_duration + tail`` seconds.
    """
    checks = (
        (cycles >= 1, "at least one cycle", cycles),
        (speed >= 0, "a non-negative speed (m/s)", speed),
        (cycle_duration > 0, "a positive cycle duration (s)", cycle_duration),
        (fps > 0, "a positive frame rate", fps),
        (0 <= lead_in < cycle_duration, "a lead-in (s) in [0, cycle_duration)", lead_in),
        (tail >= 0.3, "a tail of at least 0.3 s", tail),
        (abs(dyaw_per_cycle) < np.pi, "|dyaw_per_cycle| < π", dyaw_per_cycle),
    )
    for ok, expected, found in checks:
        if not ok:
            raise MotionError(f"procedural_walk: expected {expected}, found {found}")
    skeleton = walker_skeleton(height)
    gait = _Gait(skeleton, speed, dyaw_per_cycle / cycle_duration, cycle_duration, lead_in)
    t = np.arange(round((lead_in + cycles * cycle_duration + tail) * fps) + 1) / fps

    rng = np.random.default_rng(seed)
    style = rng.uniform(0.85, 1.15, size=4)  # arm swing, elbow, chest twist, lean
    rotations, root = gait.pose(t, style)

    length = speed * cycle_duration
    theta = dyaw_per_cycle
    full = np.full(cycles, 1.0)
    truth = WalkTruth(
        dx=full * length * np.sin(theta / 2) * np.sinc(theta / (2 * np.pi)),
        dz=full * length * np.sinc(theta / np.pi),
        dyaw=full * theta,
        speed=full * speed,
        duration=full * cycle_duration,
        left_strikes=lead_in + cycle_duration * np.arange(cycles + 1),
        height=float(height),
        fps=float(fps),
        contacts=np.stack([gait.planted(t, 0.0), gait.planted(t, 0.5)], axis=-1),
    )
    rot32: Any = rotations.astype(np.float32)
    root32: Any = root.astype(np.float32)
    motion = Motion(skeleton, rot32, root32, float(fps))
    return motion, truth


class _Gait:
    """The walk's geometry as functions of time (NumPy float64, vectorised over frames)."""

    def __init__(
        self, skeleton: Skeleton, speed: float, omega: float, period: float, lead_in: float
    ):
        self.skeleton = skeleton
        self.speed, self.omega, self.period, self.lead_in = speed, omega, period, lead_in
        off = np.asarray(skeleton.offsets, np.float64)
        self.hip = {1.0: off[1], -1.0: off[5]}
        self.thigh, self.shank, self.ankle_height = -off[2, 1], -off[3, 1], -off[4, 1]
        joints, ends = rest_positions(skeleton)
        self.height = float(ends[2, 1] - min(joints[:, 1].min(), ends[:, 1].min()))
        self.root_height = 0.0
        self.root_height = self._fit_root_height()

    # --- path and phases -------------------------------------------------------------------
    def path(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Root ground position ``(..., 3)`` (y = 0) and heading at times ``t``."""
        psi = self.omega * t
        dist = self.speed * t
        x = dist * np.sin(psi / 2) * np.sinc(psi / (2 * np.pi))
        z = dist * np.sinc(psi / np.pi)
        return np.stack([x, np.zeros_like(x), z], axis=-1), psi

    def phase(self, t: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray]:
        """Cycle index and phase in [0, 1) of a foot whose strikes are ``offset`` cycles late."""
        u = (t - self.lead_in) / self.period - offset
        k = np.floor(u + 1e-9)  # a strike that lands on a frame counts as that frame's stance
        return k, np.clip(u - k, 0.0, 1.0)

    def planted(self, t: np.ndarray, offset: float) -> np.ndarray:
        return self.phase(t, offset)[1] < STANCE_FRACTION

    def root(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos, psi = self.path(t)
        _, phi = self.phase(t, 0.0)
        bob = _BOB * self.height * np.cos(4 * np.pi * (phi - STANCE_FRACTION / 2))
        pos[..., 1] = self.root_height + bob
        return pos, psi

    # --- feet --------------------------------------------------------------------------------
    def footstep(self, k: np.ndarray, offset: float, side: float) -> tuple[np.ndarray, np.ndarray]:
        """Ankle position and yaw of footstep ``k``: under the hip at mid-stance."""
        tc = self.lead_in + (k + offset + STANCE_FRACTION / 2) * self.period
        pos, psi = self.path(tc)
        left = np.stack([np.cos(psi), np.zeros_like(psi), -np.sin(psi)], axis=-1)
        pos = pos + self.hip[side][0] * left
        pos[..., 1] = self.ankle_height
        return pos, psi

    def foot(self, t: np.ndarray, offset: float, side: float) -> tuple[np.ndarray, np.ndarray]:
        """World ankle position ``(..., 3)`` and foot yaw of one foot at times ``t``."""
        k, phi = self.phase(t, offset)
        a, yaw_a = self.footstep(k, offset, side)
        b, yaw_b = self.footstep(k + 1, offset, side)
        s = np.clip((phi - STANCE_FRACTION) / (1 - STANCE_FRACTION), 0.0, 1.0)
        # Cubic Hermite: leaves and lands moving forward at shares of the mean swing speed.
        e = (
            3 * s**2
            - 2 * s**3
            + _LIFT_OFF_SPEED * (s**3 - 2 * s**2 + s)
            + _LAND_SPEED * (s**3 - s**2)
        )
        # A parabola: the foot rises and lands with a clear vertical speed (a sharp contact).
        lift = _LIFT * self.height * 4 * s * (1 - s)
        pos = a + (b - a) * e[..., None]
        pos[..., 1] += lift
        return pos, yaw_a + (yaw_b - yaw_a) * e

    def hip_joint(self, root: np.ndarray, psi: np.ndarray, side: float) -> np.ndarray:
        return root + _yaw_rotate(psi, self.hip[side])

    def _fit_root_height(self) -> float:
        """Largest root height constant keeping every ankle within reach over one cycle."""
        t = self.lead_in + self.period * np.linspace(0.0, 1.0, 1025)
        root, psi = self.root(t)  # root height constant 0 here: only the bob
        reach = _REACH * (self.thigh + self.shank)
        limits = []
        for offset, side in ((0.0, 1.0), (0.5, -1.0)):
            ankle, _ = self.foot(t, offset, side)
            hip = self.hip_joint(root, psi, side)
            horizontal = np.hypot(*(hip - ankle)[..., [0, 2]].T)
            if horizontal.max() >= reach:
                raise MotionError(
                    "procedural_walk: expected a stride the legs can reach (hip to ankle ≤ "
                    f"{reach:.3f} m), found {horizontal.max():.3f} m; lower the speed or the cycle "
                    "duration"
                )
            limits.append(ankle[:, 1] - hip[:, 1] + np.sqrt(reach**2 - horizontal**2))
        return float(np.min(limits))

    # --- full pose ---------------------------------------------------------------------------
    def pose(self, t: np.ndarray, style: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local rotations ``(F, J, 4)`` and root positions ``(F, 3)`` at times ``t``."""
        root, psi = self.root(t)
        _, phi = self.phase(t, 0.0)
        q = np.zeros((len(t), self.skeleton.num_joints, 4))
        q[..., 0] = 1.0
        q_root = yaw_quat(psi)
        q[:, 0] = q_root
        for offset, side, j in ((0.0, 1.0, 1), (0.5, -1.0, 5)):
            ankle, foot_yaw = self.foot(t, offset, side)
            hip = self.hip_joint(root, psi, side)
            pole = np.stack(
                [np.sin(psi) + np.sin(foot_yaw), 0 * psi, np.cos(psi) + np.cos(foot_yaw)], -1
            )
            g_thigh, g_shank = _two_bone_ik(hip, ankle, pole, self.thigh, self.shank)
            g_foot = yaw_quat(foot_yaw)
            q[:, j] = quat_mul(quat_conj(q_root), g_thigh)
            q[:, j + 1] = quat_mul(quat_conj(g_thigh), g_shank)
            q[:, j + 2] = quat_mul(quat_conj(g_shank), g_foot)
        swing = 2 * np.pi * phi
        arm, elbow, twist, lean = style * np.array([0.30, 0.25, 0.07, 0.05])
        x_axis, z_axis = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
        q[:, 9] = quat_from_axis_angle(x_axis, lean + 0 * psi)
        q[:, 10] = yaw_quat(twist * np.cos(swing))  # right shoulder forward at left strike
        q[:, 11] = quat_mul(
            yaw_quat(-twist * np.cos(swing)), quat_from_axis_angle(x_axis, -lean + 0 * psi)
        )
        for side, j in ((1.0, 13), (-1.0, 16)):
            back = side * arm * np.cos(swing)  # + rotates the hanging arm backwards
            abduct = quat_from_axis_angle(z_axis, side * 0.08 + 0 * psi)
            q[:, j] = quat_mul(abduct, quat_from_axis_angle(x_axis, back))
            bend = elbow * (1.2 - side * 0.5 * np.cos(swing))  # bends most while swinging forward
            q[:, j + 1] = quat_from_axis_angle(x_axis, -bend)
        q[:, 1:] = quat_canonical(q[:, 1:])
        return q, root


def _yaw_rotate(psi: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate the fixed vector ``v`` by yaw ``psi`` (about +Y), ``(..., 3)``."""
    c, s = np.cos(psi), np.sin(psi)
    return np.stack(
        [c * v[0] + s * v[2], np.broadcast_to(v[1], psi.shape), -s * v[0] + c * v[2]], -1
    )


def _two_bone_ik(
    hip: np.ndarray, ankle: np.ndarray, pole: np.ndarray, l1: float, l2: float
) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations (quaternions) of thigh and shank placing the ankle at ``ankle``.

    Both bones hang along -Y at rest and bend about their local X axis. The knee lies in the
    plane of hip, ankle and ``pole`` (a forward direction), on the pole's side.
    """
    d = ankle - hip
    dist = np.linalg.norm(d, axis=-1, keepdims=True)
    u = d / dist
    dist = np.minimum(dist, (l1 + l2) * (1 - 1e-9))
    w = pole - np.sum(pole * u, -1, keepdims=True) * u
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    along = (l1**2 - l2**2 + dist**2) / (2 * dist)
    knee = hip + along * u + np.sqrt(np.maximum(l1**2 - along**2, 0.0)) * w
    axis_x = np.cross(w, u)  # the hinge: the character's left when standing
    axis_x /= np.linalg.norm(axis_x, axis=-1, keepdims=True)

    def frame(top: np.ndarray, bottom: np.ndarray) -> np.ndarray:
        y = top - bottom
        y /= np.linalg.norm(y, axis=-1, keepdims=True)
        z = np.cross(axis_x, y)
        return quat_from_matrix(np.stack([axis_x, y, z], axis=-1))

    # The shank frame is built from the IK knee, so its -Y bone ends exactly at the target
    # whenever the target is in reach.
    return frame(hip, knee), frame(knee, hip + d)
