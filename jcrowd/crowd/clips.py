"""Clip scheduling: the next gait cycle's control parameters from an agent's path (000 §5.2).

When an agent passes the middle of its current cycle it chooses the next one, so near agents
can blend it in over the second half (:mod:`jcrowd.crowd.stepping`). The choice, for one agent:

1. Predict where the current cycle ends: its start pose moved by the cycle's own controls
   ``(dx, dz, dyaw)`` (in the heading frame at the cycle start: z forward, x left, + yaw left).
2. Aim at the current waypoint from there: the turn ``dyaw`` is the bearing of the waypoint,
   clamped to the model's range, so a 90° corner is walked as the captures walk it (the default
   model covers about ±90° per cycle) instead of by rotating the root.
3. A turning cycle's displacement is the chord of an arc: stride ``L`` (speed × the model's
   median cycle duration) at half the turn, ``(dx, dz) = L (sin(dyaw/2), cos(dyaw/2))``.
4. Clamp into the model's control box, and where the kriging reliability ρ (001 App. B) falls
   below a threshold, take the average of the kriged clip and the nearest sample's own clip
   (the reliable region is not convex, so a box alone does not keep the prediction
   trustworthy). Reading taken for "prefer the reliable region" (000 §5.2 / the issue): the
   mixing vector is ``(a(c) + a(s_n)) / 2``, so the core is ``(K(c) + K_n) / 2`` — half a
   captured cycle — and its controls ``(c + s_n) / 2``. Kriging at the halfway controls instead
   would need a second kriging solve per choice; this needs one.

Controls named ``speed`` or ``height`` (if the model has them) take the agent's own values.
:func:`next_clip` is written for one agent (the slow, obvious version: the test oracle);
:func:`next_clips` is the same choice for many agents at once with the kriging in matrix form
(one GEMM per operator instead of a matrix-vector product per agent). The crowd step calls
:func:`next_clips_lod`: agents it synthesizes get that kriged choice; agents it does not
(culled, or dots) keep their aimed controls — their root path is the same — but play the
nearest captured cycle instead of a kriged one, which needs no kriging solve. Their pose is
not drawn; if one comes into detail mid-cycle it plays a real captured cycle until its next
choice (at most one cycle), which is kriged.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from jcrowd.crowd.synthesis import (
    Decoders,
    build_decoders,
    clip_core,
    clip_weights,
    coeffs_at,
    level_points,
    point_parents,
    pose_from_coeffs,
)
from jcrowd.errors import KrigingError
from jcrowd.indexing import first_true
from jcrowd.kriging.universal import reliability_one, weights_and_reliability
from jcrowd.model.motion_model import MotionModel
from jcrowd.motion.fastmath import sincos
from jcrowd.motion.gait import find_feet
from jcrowd.motion.planting import Legs, leg_chains

__all__ = [
    "CrowdModel",
    "build_crowd_model",
    "choose_controls",
    "local_to_world",
    "next_clip",
    "next_clips",
    "next_clips_lod",
]


class CrowdModel(eqx.Module):
    """A motion model prepared for the crowd step.

    Attributes:
        decoders: per-level decoders and the shared kriging.
        lo, hi: ``(d,)`` control box (the samples' range).
        sample_controls: ``(S, d)`` the samples' controls (for the reliability fallback).
        duration: ``(A,)`` cycle duration in model frames as a linear function of a clip's
            mixing vector (Σ ΔA over the aligned frames, 001 §3.5).
        cycle_seconds: the samples' median cycle duration (s).
        shortest_cycle_seconds: the samples' shortest cycle duration (s): at most one cycle per
            agent ends in this long, which bounds the clip choices a step must make.
        index: static positions of ``dx, dz, dyaw, speed, height`` in the controls (-1: absent).
        feet: left ankle, left toe, right ankle, right toe joints (for foot locking).
        double_support: static aligned phases where both feet are planted, one per step of the
            cycle (:func:`double_support_phases`): a walker that stops waits at one of them.
        body_height: the model's drawn body height per metre of skeleton
            (:attr:`~jcrowd.model.motion_model.MotionModel.body_height`): an agent's stature
            is its skeleton scale ``state.height`` times this.
        legs: per foot the hip, knee, ankle and toe points and the ankle's descendants
            (:func:`jcrowd.motion.planting.leg_chains`, for planting the feet).
    """

    decoders: Decoders
    lo: Float[Array, " d"]
    hi: Float[Array, " d"]
    sample_controls: Float[Array, "S d"]
    duration: Float[Array, " A"]
    cycle_seconds: float = eqx.field(static=True)
    shortest_cycle_seconds: float = eqx.field(static=True)
    index: tuple[int, int, int, int, int] = eqx.field(static=True)
    feet: tuple[int, int, int, int] = eqx.field(static=True)
    double_support: tuple[float, ...] = eqx.field(static=True, default=())
    body_height: float = eqx.field(static=True, default=1.0)
    legs: Legs = eqx.field(static=True, default=())

    @property
    def frames(self) -> int:
        return self.decoders.frames


def build_crowd_model(model: MotionModel) -> CrowdModel:
    """Prepare ``model`` for the step; it must krige over ``dx``, ``dz`` and ``dyaw``."""
    names = model.control_names
    missing = [c for c in ("dx", "dz", "dyaw") if c not in names]
    if missing:
        raise KrigingError(
            f"crowd: the model must krige over dx, dz and dyaw to follow paths, found {names}"
        )
    index = tuple(names.index(c) if c in names else -1 for c in ("dx", "dz", "dyaw"))
    index += tuple(names.index(c) if c in names else -1 for c in ("speed", "height"))
    dec = build_decoders(model)
    lv = dec.levels[0]
    cores = np.asarray(lv.mix_cores(), np.float64).reshape(-1, *lv.ranks)
    delta_a = np.einsum(
        "r,ars,ts->ta", np.asarray(lv.u_pose)[-1], cores, np.asarray(lv.u_time, np.float64)
    )
    duration = delta_a[:-1].sum(axis=0)  # frames 0..T-2 advance the clock (posevec decode)
    k = dec.kriging
    samples = np.asarray(k.controls)
    s = len(samples)
    basis = (samples - np.asarray(k.control_mean)) / np.asarray(k.control_scale)
    per_sample = duration[:s] + duration[s] + basis @ duration[s + 1 :]
    cycle_seconds = float(np.median(per_sample) / model.fps)
    ranges = np.asarray(model.control_ranges, np.float32)
    feet = find_feet(model.skeleton)
    foot_joints = (feet.left_ankle, feet.left_toe, feet.right_ankle, feet.right_toe)
    mean_clip = eqx.filter_jit(clip_weights)(dec, jnp.asarray(samples.mean(axis=0), jnp.float32))
    return CrowdModel(
        dec,
        jnp.asarray(ranges[:, 0]),
        jnp.asarray(ranges[:, 1]),
        jnp.asarray(samples, jnp.float32),
        jnp.asarray(duration, jnp.float32),
        cycle_seconds,
        float(np.min(per_sample) / model.fps),
        index,  # type: ignore[arg-type]
        foot_joints,
        double_support_phases(dec, mean_clip, foot_joints),
        float(model.body_height),
        leg_chains(point_parents(model), foot_joints),
    )


def double_support_phases(
    dec: Decoders, mix: Float[Array, " A"], feet: tuple[int, int, int, int]
) -> tuple[float, float]:
    """The two aligned phases of the clip with mixing vector ``mix`` (level 0) where its ankles
    are furthest apart along the walking direction, one foot ahead, then the other: the heel
    strikes, when both feet are on the ground. (Foot heights tell double support less well:
    a decoded clip's lowest foot joint wanders by ±1 cm for a 1 m character, a seventh of its
    swing clearance.) Every clip is aligned to one reference cycle (DTW), so the phases hold
    for the model's other clips."""
    lv = dec.levels[0]
    last = dec.frames - 1
    core = clip_core(lv, mix)
    zero = jnp.zeros(2, jnp.float32)

    def points(tau: Array) -> Array:
        y = pose_from_coeffs(lv, coeffs_at(lv, core, tau))
        return level_points(lv, y, zero, jnp.float32(0.0), jnp.float32(1.0))

    # One compiled program: eager, the decode and FK ran as ~330 small compiles (10 s).
    pts = np.asarray(jax.jit(jax.vmap(points))(jnp.arange(last, dtype=jnp.float32)))
    apart = pts[:, feet[0], 2] - pts[:, feet[2], 2]  # heading 0 faces +z
    return float(np.argmax(apart)), float(np.argmin(apart))


def local_to_world(v: Float[Array, "... 2"], heading: Float[Array, ...]) -> Array:
    """Rotate ``(x, z)`` from a heading frame (z forward, x left) into the world."""
    s, c = sincos(heading)
    return jnp.stack([v[..., 0] * c + v[..., 1] * s, -v[..., 0] * s + v[..., 1] * c], axis=-1)


def _aim(
    cm: CrowdModel,
    position: Float[Array, " 2"],
    heading: Float[Array, ""],
    target: Float[Array, " 2"],
    speed: Float[Array, ""],
    height: Float[Array, ""],
) -> Float[Array, " d"]:
    """Steps 2–4 of the module doc up to the box clamp (no reliability pull), one agent."""
    ix, iz, iyaw, ispeed, iheight = cm.index
    left, fwd = local_to_world(target - position, -heading)  # the target in the heading frame
    turn = jnp.clip(jnp.arctan2(left, fwd), cm.lo[iyaw], cm.hi[iyaw])
    stride = speed * cm.cycle_seconds
    c = (cm.lo + cm.hi) / 2
    sin, cos = sincos(turn / 2)
    c = c.at[ix].set(stride * sin).at[iz].set(stride * cos)
    c = c.at[iyaw].set(turn)
    if ispeed >= 0:
        c = c.at[ispeed].set(speed)
    if iheight >= 0:
        c = c.at[iheight].set(height)
    return jnp.clip(c, cm.lo, cm.hi)


def choose_controls(
    cm: CrowdModel,
    position: Float[Array, " 2"],
    heading: Float[Array, ""],
    target: Float[Array, " 2"],
    speed: Float[Array, ""],
    height: Float[Array, ""],
    min_reliability: float,
) -> Float[Array, " d"]:
    """Controls of a cycle starting at ``(position, heading)`` that walks towards ``target``."""
    return _choose(cm, position, heading, target, speed, height, min_reliability)[0]


def _choose(
    cm: CrowdModel,
    position: Float[Array, " 2"],
    heading: Float[Array, ""],
    target: Float[Array, " 2"],
    speed: Float[Array, ""],
    height: Float[Array, ""],
    min_reliability: float,
) -> tuple[Array, Array]:
    """``(controls, mixing vector)`` of the next clip, one agent (module doc, step 4)."""
    c = _aim(cm, position, heading, target, speed, height)
    k = cm.decoders.kriging
    d2 = jnp.sum(((cm.sample_controls - c) / k.control_scale) ** 2, axis=1)
    n = jnp.argmin(d2)
    a = clip_weights(cm.decoders, c)
    a_n = clip_weights(cm.decoders, cm.sample_controls[n])
    pull = reliability_one(k, c) < min_reliability
    return (
        jnp.where(pull, 0.5 * (c + cm.sample_controls[n]), c),
        jnp.where(pull, 0.5 * (a + a_n), a),
    )


def next_clip(
    cm: CrowdModel,
    origin: Float[Array, " 3"],
    control: Float[Array, " d"],
    target: Float[Array, " 2"],
    speed: Float[Array, ""],
    height: Float[Array, ""],
    min_reliability: float,
) -> tuple[Array, Array, Array]:
    """The next cycle for an agent whose current cycle started at ``origin = (x, z, heading)``.

    Returns ``(controls (d,), mixing vector a (A,), duration in model frames)``.
    """
    ix, iz, iyaw = cm.index[:3]
    end = origin[:2] + local_to_world(jnp.stack([control[ix], control[iz]]), origin[2])
    c, a = _choose(cm, end, origin[2] + control[iyaw], target, speed, height, min_reliability)
    return c, a, jnp.dot(a, cm.duration)


def _aimed_rows(
    cm: CrowdModel,
    origin: Float[Array, "M 3"],
    control: Float[Array, "M d"],
    target: Float[Array, "M 2"],
    speed: Float[Array, " M"],
    height: Float[Array, " M"],
) -> Float[Array, "M d"]:
    """Steps 1–4 of the module doc up to the box clamp, for ``M`` agents."""
    ix, iz, iyaw = cm.index[:3]
    end = origin[:, :2] + local_to_world(control[:, [ix, iz]], origin[:, 2])
    return jax.vmap(lambda e, h, t, s, ht: _aim(cm, e, h, t, s, ht))(
        end, origin[:, 2] + control[:, iyaw], target, speed, height
    )


def _nearest_rows(cm: CrowdModel, c: Float[Array, "M d"]) -> Array:
    """Index of the nearest sample (scaled controls) of each row."""
    k = cm.decoders.kriging
    # Squared scaled distances to every sample, summed per control column (see
    # jcrowd.kriging.universal._terms_matrix on why not a (M, S, d) broadcast).
    steps = [
        (cm.sample_controls[None, :, j] - c[:, j, None]) / k.control_scale[j]
        for j in range(c.shape[1])
    ]
    d2 = steps[0] * steps[0]
    for step in steps[1:]:
        d2 = d2 + step * step
    # First index of the row minimum, as two single-operand reductions: XLA:CPU does not
    # vectorize argmin's paired (value, index) reduction.
    s = d2.shape[1]
    first = jnp.where(d2 == d2.min(axis=1, keepdims=True), jnp.arange(s)[None, :], s)
    return jnp.minimum(first.min(axis=1), s - 1)


def _sample_rows(cm: CrowdModel, n: Array) -> Float[Array, "M A"]:
    """Mixing vectors of the samples ``n``' own clips: one-hot weights (kriging interpolates
    the samples), then the trend basis at the sample's controls."""
    k = cm.decoders.kriging
    x_n = (cm.sample_controls[n] - k.control_mean) / k.control_scale
    one = jnp.ones((n.shape[0], 1), x_n.dtype)
    return jnp.concatenate([jax.nn.one_hot(n, k.num_samples, dtype=x_n.dtype), one, x_n], axis=1)


def _kriged_rows(
    cm: CrowdModel, c: Float[Array, "M d"], n: Array, min_reliability: float
) -> tuple[Array, Array]:
    """Step 4's kriged clip with its reliability pull towards the nearest sample ``n``."""
    k = cm.decoders.kriging
    b, rho = weights_and_reliability(k, c)
    pull = (rho < min_reliability)[:, None]
    x = (c - k.control_mean) / k.control_scale
    a = jnp.concatenate([b, jnp.ones((c.shape[0], 1), c.dtype), x], axis=1)
    a = jnp.where(pull, 0.5 * (a + _sample_rows(cm, n)), a)
    return jnp.where(pull, 0.5 * (c + cm.sample_controls[n]), c), a


def next_clips(
    cm: CrowdModel,
    origin: Float[Array, "M 3"],
    control: Float[Array, "M d"],
    target: Float[Array, "M 2"],
    speed: Float[Array, " M"],
    height: Float[Array, " M"],
    min_reliability: float,
) -> tuple[Array, Array, Array]:
    """:func:`next_clip` for ``M`` agents at once, the kriging as matrix products.

    Returns ``(controls (M, d), mixing vectors (M, A), durations (M,))``.
    """
    c = _aimed_rows(cm, origin, control, target, speed, height)
    c, a = _kriged_rows(cm, c, _nearest_rows(cm, c), min_reliability)
    return c, a, a @ cm.duration


def next_clips_lod(
    cm: CrowdModel,
    origin: Float[Array, "M 3"],
    control: Float[Array, "M d"],
    target: Float[Array, "M 2"],
    speed: Float[Array, " M"],
    height: Float[Array, " M"],
    min_reliability: float,
    krige: Bool[Array, " M"],
    budget: int,
) -> tuple[Array, Array, Array, Bool[Array, " M"]]:
    """:func:`next_clips` where only the rows ``krige`` are kriged (at most ``budget`` of them).

    The other rows — agents the step does not synthesize — keep their aimed controls (so their
    root still walks straight at the waypoint) and play the nearest sample's own captured
    cycle, without a kriging solve: their pose is not drawn, and 000 §4.3 computes only the
    root "in an invisible area". In a large crowd most agents choosing a clip in a step are
    not synthesized (culled, or dots), so kriging only the synthesized ones spends the solves
    where a pose is drawn.

    Returns ``(controls, mixing vectors, durations, done)``; ``done`` is False for ``krige``
    rows beyond the budget (their choice waits).
    """
    c = _aimed_rows(cm, origin, control, target, speed, height)
    n = _nearest_rows(cm, c)
    m = c.shape[0]
    k = first_true(krige, min(budget, m), m)
    ks = jnp.minimum(k, m - 1)
    c_k, a_k = _kriged_rows(cm, c[ks], n[ks], min_reliability)
    a = _sample_rows(cm, n).at[k].set(a_k, mode="drop")
    c = c.at[k].set(c_k, mode="drop")
    done = ~krige | jnp.zeros(m, bool).at[k].set(True, mode="drop")
    return c, a, a @ cm.duration, done
