"""The footprint map of a motion model and its least-squares solve.

The map (1) of :mod:`jcrowd.model.footprints`: controls ``c`` → kriging weights ``b(c)`` and
core ``K(c)`` (000 Eq. 8) → pose vectors → root path and forward kinematics → the cycle's three
footprints, written in JAX for one cycle so that it is differentiated, jit-compiled once per
model level, and solved by optimistix's Levenberg–Marquardt (:func:`solve_cycle`). The
footprints of a clip are read by :func:`cycle_footprints` (NumPy, contact detection): the same
reader serves captures, the delivered clips, and the map's fixed aligned frames.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from jcrowd.errors import MotionError
from jcrowd.kriging.universal import kriging_weights, predict_from_weights
from jcrowd.model.motion_model import MotionModel, level_pose_vectors
from jcrowd.model.posevec import decode_clip
from jcrowd.motion.clip import Motion, joint_positions, normalize_root
from jcrowd.motion.gait import find_feet, foot_contacts
from jcrowd.motion.rotation import quat_from_expmap, quat_mul, quat_rotate, yaw_quat
from jcrowd.motion.skeleton import Skeleton, forward_kinematics

__all__ = [
    "FootprintMap",
    "cycle_footprints",
    "footprint_map",
    "relative",
    "relative_batch",
    "residual",
    "solve_cycle",
    "solve_jit",
    "synthesized_footprints",
    "synthesized_jit",
]

_HI = jax.lax.Precision.HIGHEST
_ROOT_ROWS = 7  # height, velocity (2), yaw rate, tilt (3): the first rows of every pose vector


def cycle_footprints(motion: Motion) -> tuple[np.ndarray, int]:
    """The ``(3, 2)`` footprints of one gait cycle in its start frame, and the right strike frame.

    ``motion`` spans one cycle, a left heel strike at frame 0 to the next at its last frame
    (a :class:`~jcrowd.model.samples.Sample`'s motion, or a synthesized clip). It is
    root-normalised first (start above the origin facing +Z), then the footprints are the
    ankles' ``[x, z]`` at frame 0 (left), at the right heel strike and at the last frame (left)
    (the format: :mod:`jcrowd.model.footprints`). Raises :class:`~jcrowd.errors.MotionError`
    when no right heel strike lies inside the cycle.
    """
    cut = normalize_root(motion)
    contacts = foot_contacts(cut)
    strikes = contacts.right_strikes
    strikes = strikes[(strikes > 0) & (strikes < cut.num_frames - 1)]
    if strikes.size == 0:
        raise MotionError(
            f"footprints: expected a right heel strike inside the cycle (frames 1.."
            f"{cut.num_frames - 2}), found none"
        )
    right = int(strikes[0])
    pos = np.asarray(joint_positions(cut), np.float64)
    feet = contacts.feet
    rows = [pos[0, feet.left_ankle], pos[right, feet.right_ankle], pos[-1, feet.left_ankle]]
    return np.stack(rows)[:, [0, 2]], right


class FootprintMap(eqx.Module):
    """What the footprint map (1) needs of one model level, as arrays.

    Attributes:
        kriging: the level's kriging model.
        u_pose: ``(P, R_P)`` rows of ``U_P`` times the layout's element scales.
        u_time: ``(T, R_T)``.
        reference: ``(J, 4)`` joint reference rotations (row 0 unused).
        skeleton: the reference skeleton scaled to the character's height.
        height: the character's height (m), scalar.
        low, high: ``(d,)`` the model's control range.
        frames: static, the three footprints' aligned frames as ``(i0, i1, w)``.
        ankles: static, the left and right ankle joints.
    """

    kriging: Any
    u_pose: Float[Array, "P RP"]
    u_time: Float[Array, "T RT"]
    reference: Float[Array, "J 4"]
    skeleton: Skeleton
    height: Float[Array, ""]
    low: Float[Array, " d"]
    high: Float[Array, " d"]
    frames: tuple[tuple[int, int, float], ...] = eqx.field(static=True)
    ankles: tuple[int, int] = eqx.field(static=True)


def _strike_frames(model: MotionModel, level: int) -> tuple[float, float, float]:
    """Aligned frames of the opening, right and closing heel strikes.

    Read with :func:`cycle_footprints` off the cycle decoded at the samples' median controls,
    mapped to aligned time through its ΔA (:func:`~jcrowd.model.posevec.decode_clip`).

    Found at the model's default height: the decode scales every length with the height and the
    contact thresholds scale with it too, so the frames are the model's, and one compiled solve
    serves every height.
    """
    km = model.levels[level].kriging
    c0 = np.median(np.asarray(km.controls, np.float64), axis=0)
    y = level_pose_vectors(model, c0, level)
    h = model.default_height
    motion = decode_clip(y, model.layout, model.skeleton.scaled(h), h, model.fps)
    _, right = cycle_footprints(motion)
    da = np.maximum(y[:-1, model.layout.delta_a], 1e-3)
    times = np.concatenate([[0.0], np.cumsum(da)])
    aligned = np.arange(len(times), dtype=np.float64)
    last = float(motion.num_frames - 1)
    return 0.0, float(np.interp(right, times, aligned)), float(np.interp(last, times, aligned))


def footprint_map(model: MotionModel, level: int, height: float) -> FootprintMap:
    """The map (1) of ``model``'s ``level`` for a character ``height`` m tall (host code)."""
    lv = model.levels[level]
    dtype = lv.kriging.residuals.dtype
    t = lv.u_time.shape[0]
    frames = []
    for f in _strike_frames(model, level):
        i0 = min(int(np.floor(f)), t - 1)
        frames.append((i0, min(i0 + 1, t - 1), float(f - i0)))
    feet = find_feet(model.skeleton)
    scale = np.asarray(model.layout.scale, np.float64)[:, None]
    return FootprintMap(
        lv.kriging,
        jnp.asarray(lv.u_pose * scale, dtype),
        jnp.asarray(lv.u_time, dtype),
        jnp.asarray(model.layout.reference, dtype),
        jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), model.skeleton.scaled(height)),
        jnp.asarray(height, dtype),
        jnp.asarray(model.control_ranges[:, 0], dtype),
        jnp.asarray(model.control_ranges[:, 1], dtype),
        tuple(frames),
        (feet.left_ankle, feet.right_ankle),
    )


def synthesized_footprints(fmap: FootprintMap, c: Float[Array, " d"]) -> tuple[Array, Array]:
    """Footprints ``(3, 2)`` of the model's cycle at controls ``c``, and its closing heading.

    The map (1): kriged core → root rows over every aligned frame (the root path integrates
    them, as :func:`~jcrowd.model.posevec.decode_pose_vectors` does) → full pose vectors at the
    three footprint frames → forward kinematics → ankles.
    """
    q = jnp.clip(c, fmap.low, fmap.high)
    core = predict_from_weights(fmap.kriging, q, kriging_weights(fmap.kriging, q)[0])
    core = core.astype(fmap.u_pose.dtype)
    root = jnp.matmul(
        jnp.matmul(fmap.u_pose[:_ROOT_ROWS], core, precision=_HI), fmap.u_time.T, precision=_HI
    ).T
    yaw = jnp.concatenate([jnp.zeros((1,), root.dtype), jnp.cumsum(root[:-1, 3])])
    vel = root[:, 1:3] * fmap.height
    vel3 = jnp.stack([vel[:, 0], jnp.zeros_like(vel[:, 0]), vel[:, 1]], axis=-1)
    steps = quat_rotate(yaw_quat(yaw), vel3)
    path = jnp.concatenate([jnp.zeros((1, 3), root.dtype), jnp.cumsum(steps[:-1], axis=0)])
    i0 = np.array([f[0] for f in fmap.frames])
    i1 = np.array([f[1] for f in fmap.frames])
    w = jnp.asarray([f[2] for f in fmap.frames], root.dtype)[:, None]
    w_time = fmap.u_time[i0] * (1 - w) + fmap.u_time[i1] * w
    y = jnp.matmul(jnp.matmul(fmap.u_pose, core, precision=_HI), w_time.T, precision=_HI).T
    yaw_f = yaw[i0] * (1 - w[:, 0]) + yaw[i1] * w[:, 0]
    pos = path[i0] * (1 - w) + path[i1] * w
    pos = pos.at[:, 1].set(y[:, 0] * fmap.height)
    rot_root = quat_mul(yaw_quat(yaw_f), quat_from_expmap(y[:, 4:7]))
    e = y[:, _ROOT_ROWS : _ROOT_ROWS + 3 * (fmap.reference.shape[0] - 1)].reshape(3, -1, 3)
    joints = quat_mul(fmap.reference[None, 1:], quat_from_expmap(e))
    rot = jnp.concatenate([rot_root[:, None], joints], axis=1)
    _, p = forward_kinematics(fmap.skeleton, rot, pos)
    left, right = fmap.ankles
    feet = jnp.stack([p[0, left], p[1, right], p[2, left]])
    return feet[:, jnp.array([0, 2])], yaw_f[2]


def relative(fp: Array) -> Array:
    """The right and closing left footprints minus the opening one, ``(2, 2)``."""
    return fp[1:] - fp[:1]


def residual(u: Array, args: tuple[FootprintMap, Array, Array, Array]) -> Array:
    """``(4,)`` relative footprints at normalised controls ``u`` minus ``target`` ``(2, 2)``.

    ``args = (map, target, fixed, free)``: controls not ``free`` (``height``) keep ``fixed``.
    """
    fmap, target, fixed, free = args
    km = fmap.kriging
    c = jnp.where(free, u * km.control_scale + km.control_mean, fixed)
    return (relative(synthesized_footprints(fmap, c)[0]) - target).reshape(-1)


def solve_cycle(
    fmap: FootprintMap, target: Array, c0: Array, free: Array, max_steps: int
) -> tuple[Array, Array, Array]:
    """Solve (1) for one cycle from ``c0``; returns controls, converged flag and steps."""
    km = fmap.kriging
    u0 = (c0 - km.control_mean) / km.control_scale
    # Controls in the kriging's normalised units (each about unit spread), so one tolerance
    # fits metres and radians; footprints in metres, solved to ~0.1 mm.
    solver: optx.LevenbergMarquardt = optx.LevenbergMarquardt(rtol=1e-4, atol=1e-4)
    sol: optx.Solution = optx.least_squares(
        residual, solver, u0, args=(fmap, target, c0, free), max_steps=max_steps, throw=False
    )
    c = jnp.clip(
        jnp.where(free, sol.value * km.control_scale + km.control_mean, c0), fmap.low, fmap.high
    )
    return c, jnp.asarray(sol.result == optx.RESULTS.successful), sol.stats["num_steps"]


# One compiled solve per (model level, dtype), called cycle by cycle: a vmap over cycles compiled
# for ~3x longer (20 s vs 7 s for cmu16 on 2 cores) and every new N would compile again.
solve_jit = eqx.filter_jit(solve_cycle)
synthesized_jit = eqx.filter_jit(synthesized_footprints)


@eqx.filter_jit
def relative_batch(fmap: FootprintMap, controls: Array) -> Array:
    return jax.vmap(lambda c: relative(synthesized_footprints(fmap, c)[0]))(controls)
