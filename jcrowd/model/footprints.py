"""Footprints → controls: the controls whose synthesized cycle plants the feet where asked.

Paper 001 §5.3 (Fig. 12) drives a gait by "the footprints of both feet as 4D control
parameters": its samples are kriged over the footprints themselves. jcrowd's models are kriged
over the cycle's root displacement and turn ``(dx, dz, dyaw)`` (:mod:`jcrowd.model.motion_model`),
so a footprint query is answered the other way round (issue 22, item 4): per gait cycle, solve
for the controls ``c`` whose synthesized cycle puts its planted feet on the given footprints,

    min_c  ‖F(c) − F*‖²,   F(c) = footprints of FK(decode(U_P K(c) U_Tᵀ))       (1)

by Levenberg–Marquardt (optimistix) through the kriging weights ``b(c)`` (000 Eq. 8), the
pose-vector decode and forward kinematics, all differentiated by JAX. The *forward rule* it is
compared with takes the controls from the footprints' displacement alone (below).

Footprint format (readings taken, stated):

- A cycle is the model's sample: two steps from a left heel strike to the next
  (:mod:`jcrowd.motion.gait`). Its footprints are ``(3, 2)``: the ``[x, z]`` (m) of the left
  foot at the opening heel strike, the right foot at its heel strike, and the left foot at the
  closing heel strike — paper 001's two footprints plus the foot the cycle stands on at its start.
- A foot's footprint is its ankle joint (the heel; :func:`jcrowd.motion.gait.find_feet` picks
  it by name on any skeleton) at that foot's heel strike, the onset of its contact
  (:func:`jcrowd.motion.gait.foot_contacts`). A heel strike puts the heel down first, so the
  ankle is the planted joint there (the lower of ankle and toe, as in
  :mod:`jcrowd.motion.footlock`).
- Only the footprints' positions *relative to the opening left footprint* are matched: the cycle
  stands on that foot when it starts, so the controls place the right and closing left
  footprints from it. Where the root stands over the opening footprint is the model's posture
  at the strike, which no control of a cycle moves; a chain of cycles hands the closing left
  foot on as the next cycle's opening one.
- Frames. With ``heading=None`` every cycle's footprints are in its own start frame: heading
  +Z at the opening strike, x to the character's left (as the controls, DESIGN §3); cycles are
  independent. With ``heading=θ`` the footprints are world positions, cycle 0 starts facing
  ``θ`` (radians, + = left of +Z), and cycle ``k + 1`` starts facing where cycle ``k``'s
  *synthesized* clip ends (cycle by cycle, forward); rotating and translating every footprint
  and ``θ`` together leaves the controls unchanged.

The synthesized footprints ``F(c)`` are read from the decoded cycle at fixed *aligned* frames:
0 (the opening strike: every sample starts there), the right strike and the closing strike,
found once per model and level by running the contact detector on the cycle synthesized at the
samples' median controls and mapping its frames to aligned time through the decoded ΔA. Cycles
are time-aligned by DTW, so a strike sits at about the same aligned frame for every control.
Between aligned frames the pose vector and root path are interpolated linearly. What the solver
matches is therefore the model's own cycle, without foot locking (which moves the root).

Forward rule (reading of "controls from the footprints' displacement alone"): ``(dx, dz)`` is
the left foot's displacement over the cycle, closing minus opening footprint, in the start
frame — for a periodic gait the root moves as the foot does — and ``dyaw = 2·atan2(dx, dz)``,
the turn of a constant-curvature path whose chord is that displacement (the crowd's clip rule,
:mod:`jcrowd.crowd.clips`, uses the same relation the other way). It ignores the right
footprint and the foot's offset from the root, which turns with the body. Other controls
(``speed``) take the samples' median; ``height`` the character's height.

Every query is clamped to the model's control range before kriging, as
:func:`~jcrowd.model.motion_model.synthesize_clip` does; inside the solve the clamp is part of
(1), so a coordinate pressed against its bound stays there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from jcrowd.errors import KrigingError, MotionError
from jcrowd.kriging.universal import kriging_weights, predict_from_weights
from jcrowd.model.motion_model import MotionModel, level_pose_vectors, synthesize_clip
from jcrowd.model.posevec import decode_clip
from jcrowd.motion.clip import Motion, joint_positions, normalize_root
from jcrowd.motion.gait import find_feet, foot_contacts
from jcrowd.motion.rotation import quat_from_expmap, quat_mul, quat_rotate, yaw_quat
from jcrowd.motion.skeleton import Skeleton, forward_kinematics

__all__ = [
    "FootprintControls",
    "controls_for_footprints",
    "cycle_footprints",
    "footprint_errors",
    "footprints_for_controls",
    "forward_rule_controls",
]

_HI = jax.lax.Precision.HIGHEST
_ROOT_ROWS = 7  # height, velocity (2), yaw rate, tilt (3): the first rows of every pose vector


@dataclass(frozen=True)
class FootprintControls:
    """Solved and forward-rule controls for a run of cycles.

    Attributes:
        controls: ``(N, d)`` the solved controls (in the model's range), in
            ``model.control_names`` order.
        forward: ``(N, d)`` the forward rule's controls (clamped to the range).
        error_m: ``(N,)`` mean distance (m) of the right and closing left footprints of the
            model's cycle at ``controls`` from the asked ones, relative to the opening footprint
            (the objective (1) as distances).
        forward_error_m: ``(N,)`` the same at ``forward``.
        headings: ``(N,)`` each cycle's start heading (radians; 0 without ``heading``).
        converged: ``(N,)`` whether Levenberg–Marquardt met its tolerance within its steps.
        steps: ``(N,)`` Levenberg–Marquardt steps taken.
    """

    controls: np.ndarray
    forward: np.ndarray
    error_m: np.ndarray
    forward_error_m: np.ndarray
    headings: np.ndarray
    converged: np.ndarray
    steps: np.ndarray


def cycle_footprints(motion: Motion) -> tuple[np.ndarray, int]:
    """The ``(3, 2)`` footprints of one gait cycle in its start frame, and the right strike frame.

    ``motion`` spans one cycle, a left heel strike at frame 0 to the next at its last frame
    (a :class:`~jcrowd.model.samples.Sample`'s motion, or a synthesized clip). It is
    root-normalised first (start above the origin facing +Z), then the footprints are the
    ankles' ``[x, z]`` at frame 0 (left), at the right heel strike and at the last frame (left),
    module doc. Raises :class:`~jcrowd.errors.MotionError` when no right heel strike lies
    inside the cycle.
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


class _Cycle(eqx.Module):
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
    """Aligned frames of the opening, right and closing heel strikes (module doc).

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


def _cycle(model: MotionModel, level: int, height: float) -> _Cycle:
    lv = model.levels[level]
    dtype = lv.kriging.residuals.dtype
    t = lv.u_time.shape[0]
    frames = []
    for f in _strike_frames(model, level):
        i0 = min(int(np.floor(f)), t - 1)
        frames.append((i0, min(i0 + 1, t - 1), float(f - i0)))
    feet = find_feet(model.skeleton)
    scale = np.asarray(model.layout.scale, np.float64)[:, None]
    return _Cycle(
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


def _synthesized(cyc: _Cycle, c: Float[Array, " d"]) -> tuple[Array, Array]:
    """Footprints ``(3, 2)`` of the model's cycle at controls ``c``, and its closing heading.

    The map (1): kriged core → root rows over every aligned frame (the root path integrates
    them, as :func:`~jcrowd.model.posevec.decode_pose_vectors` does) → full pose vectors at the
    three footprint frames → forward kinematics → ankles.
    """
    q = jnp.clip(c, cyc.low, cyc.high)
    core = predict_from_weights(cyc.kriging, q, kriging_weights(cyc.kriging, q)[0])
    core = core.astype(cyc.u_pose.dtype)
    root = jnp.matmul(
        jnp.matmul(cyc.u_pose[:_ROOT_ROWS], core, precision=_HI), cyc.u_time.T, precision=_HI
    ).T
    yaw = jnp.concatenate([jnp.zeros((1,), root.dtype), jnp.cumsum(root[:-1, 3])])
    vel = root[:, 1:3] * cyc.height
    vel3 = jnp.stack([vel[:, 0], jnp.zeros_like(vel[:, 0]), vel[:, 1]], axis=-1)
    steps = quat_rotate(yaw_quat(yaw), vel3)
    path = jnp.concatenate([jnp.zeros((1, 3), root.dtype), jnp.cumsum(steps[:-1], axis=0)])
    i0 = np.array([f[0] for f in cyc.frames])
    i1 = np.array([f[1] for f in cyc.frames])
    w = jnp.asarray([f[2] for f in cyc.frames], root.dtype)[:, None]
    w_time = cyc.u_time[i0] * (1 - w) + cyc.u_time[i1] * w
    y = jnp.matmul(jnp.matmul(cyc.u_pose, core, precision=_HI), w_time.T, precision=_HI).T
    yaw_f = yaw[i0] * (1 - w[:, 0]) + yaw[i1] * w[:, 0]
    pos = path[i0] * (1 - w) + path[i1] * w
    pos = pos.at[:, 1].set(y[:, 0] * cyc.height)
    rot_root = quat_mul(yaw_quat(yaw_f), quat_from_expmap(y[:, 4:7]))
    e = y[:, _ROOT_ROWS : _ROOT_ROWS + 3 * (cyc.reference.shape[0] - 1)].reshape(3, -1, 3)
    joints = quat_mul(cyc.reference[None, 1:], quat_from_expmap(e))
    rot = jnp.concatenate([rot_root[:, None], joints], axis=1)
    _, p = forward_kinematics(cyc.skeleton, rot, pos)
    left, right = cyc.ankles
    feet = jnp.stack([p[0, left], p[1, right], p[2, left]])
    return feet[:, jnp.array([0, 2])], yaw_f[2]


def _relative(fp: Array) -> Array:
    """The right and closing left footprints minus the opening one, ``(2, 2)``."""
    return fp[1:] - fp[:1]


def _residual(u: Array, args: tuple[_Cycle, Array, Array, Array]) -> Array:
    cyc, target, fixed, free = args
    km = cyc.kriging
    c = jnp.where(free, u * km.control_scale + km.control_mean, fixed)
    return (_relative(_synthesized(cyc, c)[0]) - target).reshape(-1)


def _solve_one(
    cyc: _Cycle, target: Array, c0: Array, free: Array, max_steps: int
) -> tuple[Array, Array, Array]:
    """Solve (1) for one cycle from ``c0``; returns controls, converged flag and steps."""
    km = cyc.kriging
    u0 = (c0 - km.control_mean) / km.control_scale
    # Controls in the kriging's normalised units (each about unit spread), so one tolerance
    # fits metres and radians; footprints in metres, solved to ~0.1 mm.
    solver: optx.LevenbergMarquardt = optx.LevenbergMarquardt(rtol=1e-4, atol=1e-4)
    sol: optx.Solution = optx.least_squares(
        _residual, solver, u0, args=(cyc, target, c0, free), max_steps=max_steps, throw=False
    )
    c = jnp.clip(
        jnp.where(free, sol.value * km.control_scale + km.control_mean, c0), cyc.low, cyc.high
    )
    return c, jnp.asarray(sol.result == optx.RESULTS.successful), sol.stats["num_steps"]


# One compiled solve per (model level, dtype), called cycle by cycle: a vmap over cycles compiled
# for ~3x longer (20 s vs 7 s for cmu16 on 2 cores) and every new N would compile again.
_solve_jit = eqx.filter_jit(_solve_one)
_synthesized_jit = eqx.filter_jit(_synthesized)


def _rotate(xz: np.ndarray, angle: float) -> np.ndarray:
    """``[x, z]`` rows turned by ``angle`` about +Y (+ turns +z towards +x)."""
    s, c = np.sin(angle), np.cos(angle)
    return np.stack([c * xz[..., 0] + s * xz[..., 1], -s * xz[..., 0] + c * xz[..., 1]], axis=-1)


def forward_rule_controls(
    model: MotionModel, footprints: np.ndarray, *, height: float | None = None
) -> np.ndarray:
    """The forward rule's controls ``(N, d)`` for start-frame footprints ``(N, 3, 2)`` (module doc).

    Clamped to the model's range, as synthesis clamps them.
    """
    fp = _check_footprints(footprints)
    h = _height(model, height)
    d = fp[:, 2] - fp[:, 0]
    values = {
        "dx": d[:, 0],
        "dz": d[:, 1],
        "dyaw": 2.0 * np.arctan2(d[:, 0], d[:, 1]),
        "height": np.full(len(fp), h),
    }
    median = np.median(np.asarray(model.levels[0].kriging.controls, np.float64), axis=0)
    cols = [
        values.get(name, np.full(len(fp), median[k])) for k, name in enumerate(model.control_names)
    ]
    c = np.stack(cols, axis=-1)
    return np.clip(c, model.control_ranges[:, 0], model.control_ranges[:, 1])


def footprints_for_controls(
    model: MotionModel,
    controls: np.ndarray,
    level: int = 0,
    *,
    height: float | None = None,
    heading: float | None = None,
    origin: np.ndarray | None = None,
) -> np.ndarray:
    """The model's footprints ``(N, 3, 2)`` for controls ``(N, d)`` — the map (1), chained.

    Without ``heading``: every cycle in its own start frame (root above the origin facing +Z).
    With ``heading`` (and ``origin``, the first opening footprint in the world, default 0): the
    cycles follow each other as :func:`controls_for_footprints` chains them — each starts with
    its left foot on the previous cycle's closing footprint, facing where that cycle ended.
    """
    _check_level(model, level)
    c = np.asarray(controls, np.float64)
    if c.ndim != 2 or c.shape[1] != len(model.control_names) or not np.all(np.isfinite(c)):
        raise KrigingError(
            f"footprints: expected finite controls of shape (N, {len(model.control_names)}) "
            f"{model.control_names}, found shape {c.shape}"
        )
    cyc = _cycle(model, level, _height(model, height))
    out: list[np.ndarray] = []
    theta = 0.0 if heading is None else float(heading)
    at = np.zeros(2) if origin is None else np.asarray(origin, np.float64).reshape(2)
    for row in c:
        got, end = _synthesized_jit(cyc, jnp.asarray(row, cyc.u_pose.dtype))
        fp = np.asarray(got, np.float64)
        if heading is None:
            out.append(fp)
            continue
        world = at + _rotate(fp - fp[0], theta)
        out.append(world)
        at, theta = world[2], theta + float(end)
    return np.stack(out)


def controls_for_footprints(
    model: MotionModel,
    footprints: np.ndarray,
    level: int = 0,
    *,
    height: float | None = None,
    heading: float | None = None,
    max_steps: int = 64,
) -> FootprintControls:
    """Controls per cycle whose synthesized cycle plants the feet on ``footprints`` (module doc).

    Args:
        model: a fitted model kriged over ``dx`` and ``dz`` (and usually ``dyaw``).
        footprints: ``(N, 3, 2)`` per cycle the ``[x, z]`` (m) of the opening left, the right and
            the closing left footprint; in each cycle's start frame, or in the world with
            ``heading``.
        level: the model level whose cycle is matched.
        height: the character's height (m); default as in
            :func:`~jcrowd.model.motion_model.synthesize_clip`. A ``height`` control is held at it.
        heading: ``None`` (each cycle in its own start frame, cycles independent) or cycle 0's
            start heading in the world (radians; each cycle starts where the last one ended).
        max_steps: Levenberg–Marquardt steps per cycle.

    Returns:
        :class:`FootprintControls`: the solution (1), started from and compared with the forward
        rule. Paper 001 §5.3 (Fig. 12), issue 22.
    """
    _check_level(model, level)
    fp = _check_footprints(footprints)
    for name in ("dx", "dz"):
        if name not in model.control_names:
            raise KrigingError(
                f"footprints: expected a model kriged over dx and dz, found controls "
                f"{model.control_names}"
            )
    if heading is not None and not np.isfinite(heading):
        raise KrigingError(f"footprints: expected a finite heading (radians), found {heading}")
    h = _height(model, height)
    cyc = _cycle(model, level, h)
    dtype = cyc.u_pose.dtype
    free = jnp.asarray([n != "height" for n in model.control_names])
    rows, fwd_rows, flags, counts, starts = [], [], [], [], []
    theta = 0.0 if heading is None else float(heading)
    for cycle in fp:
        # Start frame of this cycle: its own (no heading), or where the previous one ended.
        local = _rotate(cycle - cycle[0], -theta)
        start = forward_rule_controls(model, local[None], height=h)[0]
        target = jnp.asarray(local[1:] - local[:1], dtype)
        c, ok, steps = _solve_jit(cyc, target, jnp.asarray(start, dtype), free, max_steps)
        rows.append(np.asarray(c, np.float64))
        fwd_rows.append(start)
        flags.append(bool(ok))
        counts.append(int(steps))
        starts.append(theta)
        if heading is not None:
            theta += float(_synthesized_jit(cyc, c)[1])
    solved, forward, headings = np.stack(rows), np.stack(fwd_rows), np.array(starts)
    local_all = np.stack([_rotate(f - f[0], -t) for f, t in zip(fp, headings, strict=True)])
    return FootprintControls(
        solved,
        forward,
        _errors(cyc, solved, local_all),
        _errors(cyc, forward, local_all),
        headings,
        np.array(flags, bool),
        np.array(counts, np.int64),
    )


@eqx.filter_jit
def _relative_batch(cyc: _Cycle, controls: Array) -> Array:
    return jax.vmap(lambda c: _relative(_synthesized(cyc, c)[0]))(controls)


def footprint_errors(
    model: MotionModel,
    controls: np.ndarray,
    footprints: np.ndarray,
    level: int = 0,
    *,
    height: float | None = None,
) -> np.ndarray:
    """Planted-foot error (m) per cycle of the *delivered* clips at ``controls`` ``(N, d)``.

    Each cycle is synthesized as the user gets it (:func:`synthesize_clip`: decode, unwarp to
    the model clock, no foot locking) and its footprints are read the way a capture's are
    (:func:`cycle_footprints`: contact detection, ankle at each heel strike); the error is the
    mean distance of its right and closing left footprints from the asked start-frame
    ``footprints`` ``(N, 3, 2)``, both relative to their opening left footprint. Independent of
    the solver's fixed aligned frames and interpolation.
    """
    fp = _check_footprints(footprints)
    c = np.asarray(controls, np.float64)
    if c.shape != (len(fp), len(model.control_names)):
        raise KrigingError(
            f"footprint errors: expected controls of shape ({len(fp)}, "
            f"{len(model.control_names)}) for {len(fp)} cycles, found {c.shape}"
        )
    out = []
    for row, want in zip(c, fp, strict=True):
        got, _ = cycle_footprints(synthesize_clip(model, row.tolist(), level, height=height))
        miss = (got[1:] - got[:1]) - (want[1:] - want[:1])
        out.append(float(np.linalg.norm(miss, axis=-1).mean()))
    return np.array(out)


def _errors(cyc: _Cycle, controls: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Mean footprint distance (m) of the model's cycles at ``controls`` from ``local``."""
    got = _relative_batch(cyc, jnp.asarray(controls, cyc.u_pose.dtype))
    want = local[:, 1:] - local[:, :1]
    return np.linalg.norm(np.asarray(got, np.float64) - want, axis=-1).mean(axis=-1)


def _check_level(model: MotionModel, level: int) -> None:
    if not 0 <= level < len(model.levels):
        raise KrigingError(
            f"footprints: expected a level in 0..{len(model.levels) - 1}, found {level}"
        )


def _height(model: MotionModel, height: float | None) -> float:
    if height is None:
        return model.default_height
    if not np.isfinite(height) or height <= 0:
        raise KrigingError(f"footprints: expected a positive finite height (m), found {height}")
    return float(height)


def _check_footprints(footprints: Any) -> np.ndarray:
    fp = np.asarray(footprints, np.float64)
    if fp.ndim != 3 or fp.shape[1:] != (3, 2) or len(fp) == 0:
        raise KrigingError(
            "footprints: expected shape (N, 3, 2) — per cycle [x, z] of the opening left, the "
            f"right and the closing left footprint, N >= 1 — found {fp.shape}"
        )
    bad = np.argwhere(~np.isfinite(fp))
    if bad.size:
        raise KrigingError(
            f"footprints: expected finite [x, z], found {fp[tuple(bad[0])]} at cycle "
            f"{bad[0][0]}, footprint {bad[0][1]}"
        )
    return fp
