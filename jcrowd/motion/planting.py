"""Planted feet for walkers the simulation moves: each stance foot stays where it landed, the
leg bending to reach it (two-bone IK), and lets go over the swing that follows.

With the crowd dynamics on, the root walks the simulated path while the decoded legs slide their
stance foot by 2–3 times what the captures' own feet slide (``bench/follow.py``). Moving the
root to lock the foot would move it off the simulated position; production crowd tools pin the
foot and solve the leg instead, and so does :func:`plant_feet`, for agents drawn at the near
levels (``≤ blend_max_level``; :attr:`~jcrowd.crowd.state.StepConfig.plant_feet`). An agent
leaving them eases from its planted pose, and ``jcrowd export`` writes the planting as joint
rotations (:func:`planted_rotations`).

**Stance** is a static window of the aligned phase per foot: it opens at the foot's heel strike
(:attr:`~jcrowd.crowd.clips.CrowdModel.double_support`) and lasts :data:`STANCE_SHARE` of the
cycle, which holds for every clip (all are aligned to one reference cycle). Our reading of the
stance length: 60 % of the gait cycle at walking speeds (Perry & Burnfield, *Gait Analysis*,
2010, ch. 1), so a standing walker (its phase waiting at a double support) has both feet down.

**The pin** (per foot, world ``x, z``): at the stance's first frame the foot's planted joint
(the lower of ankle and toe, as :func:`jcrowd.model.foot_skate` measures) is pinned where it
is; later the foot is moved horizontally by ``δ = pin − planted joint`` (``|δ|`` at most
:data:`MAX_SLIP` times the skeleton scale: beyond it the foot slides). When the planted joint
changes from ankle to toe the pin moves to the toe plus ``δ``, so ``δ`` is continuous. After
the stance ``δ`` eases to 0 over the first :data:`RELEASE_SHARE` of the swing (smoothstep).

**The leg**: the ankle and everything below it move by ``δ``; the knee is placed so that thigh
and shin keep their lengths, in the plane of the hip, the new ankle and the decoded knee (the
closed-form two-bone solution, with the reach softened near a straight leg: :func:`reach`).

State: per agent and foot the pin (or the release offset), whether the foot was planted in the
last frame and whether its toe is the planted joint: 20 bytes. Agents neither drawn at a near
level nor easing from one have no pins; a foot planted when an agent comes near starts where
it is.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from jcrowd.motion.rotation import quat_inv, quat_mul, quat_rotate

__all__ = [
    "MAX_SLIP",
    "RELEASE_SHARE",
    "SEQUENCE_BLOCK",
    "SOFT_REACH",
    "STANCE_SHARE",
    "STEPPING_HOLD",
    "Legs",
    "leg_chains",
    "plant_feet",
    "plant_sequence",
    "planted_rotations",
    "reach",
    "warp_stride",
]

STANCE_SHARE = 0.6
"""The share of the gait cycle a foot is planted for (from its heel strike)."""

RELEASE_SHARE = 0.5
"""The share of the swing over which a released foot eases back to its decoded path."""

MAX_SLIP = 0.1
"""The farthest a planted foot is held from its decoded place, per metre of skeleton scale."""

STEPPING_HOLD = 0.25
"""With the stride warped below 1 (:func:`warp_stride`) a planted foot is held up to
``MAX_SLIP / max(stride, STEPPING_HOLD)``: four times as far standing or turning on the spot,
where the body turns over a planted foot until the next step re-plants it (a turn of 60° swings
a decoded toe 20 cm from the hip by 20 cm)."""

POLE_WEIGHT = 0.05
"""How far (per thigh length) the knee's bend leans towards the toe: where the decoded knee sits
further than this off the hip–ankle line, it decides the bend's side."""

SOFT_REACH = 0.1
"""The share of the leg's full reach (thigh + shin) over which the reach is softened: a target
that far or further from full reach is approached exponentially (:func:`reach`)."""

Legs = tuple[tuple[int, int, int, int, tuple[int, ...]], ...]
"""Per foot (left, right): hip, knee, ankle, toe point indices and the ankle's descendants (the
ankle included)."""


def _smoothstep(x: Array) -> Array:
    """``3x² − 2x³`` on ``x`` clipped to ``[0, 1]``."""
    c = jnp.clip(x, 0.0, 1.0)
    return c * c * (3.0 - 2.0 * c)


def leg_chains(parents: tuple[int, ...], feet: tuple[int, int, int, int]) -> Legs:
    """The two legs' point indices from the points' parents and the feet (left ankle, left toe,
    right ankle, right toe)."""
    par = np.asarray(parents)
    out = []
    for ankle, toe in ((feet[0], feet[1]), (feet[2], feet[3])):
        knee = int(par[ankle])
        hip = int(par[knee])
        below = [ankle]
        for p in range(len(par)):
            q = p
            while q >= 0 and q != ankle:
                q = int(par[q])
            if q == ankle and p != ankle:
                below.append(p)
        out.append((hip, knee, ankle, toe, tuple(below)))
    return tuple(out)


def reach(
    hip: Float[Array, " 3"],
    knee: Float[Array, " 3"],
    ankle: Float[Array, " 3"],
    toe: Float[Array, " 3"],
    target: Array,
) -> tuple[Array, Array]:
    """Two-bone IK: the knee and ankle for an ankle wanted at ``target``, thigh and shin keeping
    their lengths ``l₁, l₂``.

    With ``d`` the hip–target distance the knee sits ``a = (l₁² − l₂² + d²) / 2d`` along the
    hip–target line and ``√(l₁² − a²)`` off it, towards the decoded knee, leaning towards the
    toe by :data:`POLE_WEIGHT` so a straight leg keeps its knee in front.

    **Soft reach.** Near full reach ``L = l₁ + l₂`` the knee's offset changes without bound per
    unit of ``d`` (``∝ √(L − d)``): clamped at ``L``, a target 1 mm further swings a nearly
    straight knee by over a centimetre, and two levels of detail whose hips differ by a
    centimetre draw knees several apart. Beyond ``s = max((1 − SOFT_REACH)·L, d₀)`` (``d₀`` the
    decoded hip–ankle distance) ``d`` is softened as game rigs' "soft IK" does:
    ``d' = s + (L − s)(1 − exp(−(d − s)/(L − s)))``, approaching full reach without getting
    there, so the knee straightens no faster than the target moves. Taking ``d₀`` into ``s``
    leaves the decoded leg as it is when the foot needs no moving (``d = d₀``): captured legs
    spend much of the stance beyond 0.9 L (median 0.97 L on ``cmu16``), and softening from
    0.9 L alone would bend them all. The ankle then stops short of the target on its line.
    """
    l1 = jnp.linalg.norm(knee - hip)
    l2 = jnp.linalg.norm(ankle - knee)
    d_vec = target - hip
    d = jnp.maximum(jnp.linalg.norm(d_vec), 1e-9)
    u = d_vec / d
    full = l1 + l2
    start = jnp.maximum(full * (1.0 - SOFT_REACH), jnp.linalg.norm(ankle - hip))
    soft = jnp.maximum(full - start, 1e-9)
    d = jnp.where(d > start, start + soft * (1.0 - jnp.exp(-(d - start) / soft)), d)
    d = jnp.clip(d, jnp.abs(l1 - l2) + 1e-6, full * (1.0 - 1e-6))
    a = (l1 * l1 - l2 * l2 + d * d) / (2.0 * d)
    off = jnp.sqrt(jnp.maximum(l1 * l1 - a * a, 0.0))
    # The knee bends towards where it was, and over the toes where the leg is nearly straight
    # (the decoded knee then says little about the bend's side, and noise would flip it).
    # The side is taken off the decoded hip–ankle line, then made square to the new one.
    u0 = (ankle - hip) / jnp.maximum(jnp.linalg.norm(ankle - hip), 1e-9)
    side = (knee - hip) - jnp.dot(knee - hip, u0) * u0
    foot = toe - ankle
    pole = side + POLE_WEIGHT * l1 * foot / jnp.maximum(jnp.linalg.norm(foot), 1e-9)
    bend = pole - jnp.dot(pole, u) * u
    bn = jnp.linalg.norm(bend)
    bend = jnp.where(bn > 1e-9, bend / jnp.maximum(bn, 1e-9), 0.0)
    return hip + a * u + off * bend, hip + d * u


def plant_feet(
    legs: Legs,
    stance_start: tuple[float, float],
    last: float,
    points: Float[Array, "P 3"],
    tau: Float[Array, ""],
    scale: Float[Array, ""],
    pin: Float[Array, "2 2"],
    on: Bool[Array, " 2"],
    toe: Bool[Array, " 2"],
    heading: Float[Array, ""] | None = None,
    stride: Float[Array, ""] | float = 1.0,
) -> tuple[Array, Array, Array, Array]:
    """One agent's points with its stance feet planted, and its new ``(pin, on, toe)``.

    ``stance_start``: each foot's heel-strike phase (aligned frames); ``last``: the cycle's
    length in aligned frames; ``tau``: the phase the points are decoded at; ``scale``: the
    skeleton's scale (m). ``pin``: per foot ``(x, z)``, the pin while planted, the release
    offset while swinging; ``on``: planted in the last frame; ``toe``: the pin is the toe's.
    ``heading`` and ``stride``: the stride warp (:func:`warp_stride`; none without a heading).
    """
    if heading is not None:
        points = warp_stride(legs, points, heading, stride)
    # A foot stepping on the spot is held further: the body turns above it.
    cap = MAX_SLIP * scale / jnp.maximum(jnp.asarray(stride, points.dtype), STEPPING_HOLD)
    length = STANCE_SHARE * last
    pins, ons, toes = [], [], []
    for f, (hip, knee, ankle, toe_j, below) in enumerate(legs):
        into = jnp.remainder(tau - stance_start[f], last)
        stance = into < length
        swing = jnp.clip((into - length) / (RELEASE_SHARE * (last - length)), 0.0, 1.0)
        low_toe = points[toe_j, 1] < points[ankle, 1]
        xz = jnp.array([0, 2])
        flagged = jnp.where(toe[f], points[toe_j, xz], points[ankle, xz])
        held = pin[f] - flagged
        n = jnp.linalg.norm(held)
        held = held * jnp.minimum(1.0, cap / jnp.maximum(n, 1e-9))
        release = jnp.where(on[f], held, pin[f])  # the offset kept over the swing
        delta = jnp.where(
            stance,
            jnp.where(on[f], held, 0.0),
            release * (1.0 - _smoothstep(swing)),
        )
        lowest = jnp.where(low_toe, points[toe_j, xz], points[ankle, xz])
        pins.append(jnp.where(stance, lowest + delta, release))
        ons.append(stance)
        toes.append(low_toe)
        target = points[ankle] + jnp.stack([delta[0], 0.0, delta[1]])
        new_knee, new_ankle = reach(points[hip], points[knee], points[ankle], points[toe_j], target)
        shift = new_ankle - points[ankle]
        idx = np.asarray(below)
        points = points.at[idx].add(shift).at[knee].set(new_knee)
    return points, jnp.stack(pins), jnp.stack(ons), jnp.stack(toes)


def warp_stride(
    legs: Legs, points: Float[Array, "P 3"], heading: Float[Array, ""], stride: Array | float
) -> Float[Array, "P 3"]:
    """The decoded feet moved along the body's forward ``(sin θ, 0, cos θ)`` so that each
    ankle's forward offset from its hip is ``stride`` times the decoded one (the ankle and the
    points below it shift together; the knee is left to :func:`reach`): 1 keeps the decoded
    walk, 0 puts the feet under the hips — a walker stepping on the spot, as one turning in
    place does, or one standing."""
    fwd = jnp.stack([jnp.sin(heading), 0.0, jnp.cos(heading)]).astype(points.dtype)
    keep = 1.0 - jnp.asarray(stride, points.dtype)
    moved = jnp.zeros_like(points)
    for hip, _, ankle, _, below in legs:
        ahead = jnp.dot(points[ankle] - points[hip], fwd)
        # A constant mask, not a scatter: the step warps every synthesized agent, and a
        # scatter per agent costs more on XLA:CPU than the multiply-add over all points.
        mask = np.zeros((points.shape[0], 1), np.float32)
        mask[np.asarray(below)] = 1.0
        moved = moved + jnp.asarray(mask, points.dtype) * (-keep * ahead * fwd)
    return points + moved


SEQUENCE_BLOCK = 256
""":func:`plant_sequence` pads a clip to a multiple of this many frames, so clips of any length
share a few compiled programs (one per length would fill memory over a crowd's agents)."""


def plant_sequence(
    legs: Legs,
    stance_start: tuple[float, float],
    last: float,
    points: Float[Array, "F P 3"],
    tau: Float[Array, " F"],
    scale: Float[Array, ""],
    heading: Float[Array, " F"] | None = None,
    stride: Float[Array, " F"] | None = None,
) -> Float[Array, "F P 3"]:
    """One agent's frames with its feet planted as the step plants them frame by frame (from no
    pins): for a walker re-synthesized off line, drawn at a near level throughout. ``heading``
    and ``stride``: per frame, the stride warp (:func:`warp_stride`; none when not given)."""
    f = points.shape[0]
    size = -(-f // SEQUENCE_BLOCK) * SEQUENCE_BLOCK

    def padded(a: Array) -> Array:
        # Frames repeated past the end: the scan is causal, so they change nothing before it.
        return jnp.concatenate([a, jnp.repeat(a[-1:], size - f, axis=0)])

    ones = jnp.ones(f, points.dtype)
    warp = (
        ones * 0.0 if heading is None else jnp.asarray(heading, points.dtype),
        ones if stride is None else jnp.asarray(stride, points.dtype),
    )
    xs = (padded(points), padded(jnp.asarray(tau)), *map(padded, warp))
    return _plant_scan(legs, stance_start, last, *xs, jnp.asarray(scale))[:f]


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _plant_scan(
    legs: Legs,
    stance_start: tuple[float, float],
    last: float,
    points: Array,
    tau: Array,
    heading: Array,
    stride: Array,
    scale: Array,
) -> Array:
    """:func:`plant_sequence` over a padded clip: one ``lax.scan`` of :func:`plant_feet`."""

    def one(carry: tuple[Array, Array, Array], x: tuple[Array, ...]) -> tuple[Any, Array]:
        p, t, h, k = x
        out, *feet = plant_feet(legs, stance_start, last, p, t, scale, *carry, h, k)
        return tuple(feet), out

    start = (jnp.zeros((2, 2), points.dtype), jnp.zeros(2, bool), jnp.zeros(2, bool))
    _, out = jax.lax.scan(one, start, (points, tau, heading, stride))
    return out


def _least_rotation(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` turning directions ``u`` onto ``v`` about ``u × v`` (the least
    rotation; ``u`` and ``v`` never opposite here: a bone turned by a few degrees)."""
    u = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-12)
    v = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
    q = np.concatenate([1.0 + np.sum(u * v, axis=-1, keepdims=True), np.cross(u, v)], axis=-1)
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)


def planted_rotations(
    parents: tuple[int, ...],
    legs: Legs,
    local: Float[np.ndarray, "F J 4"],
    world: Float[np.ndarray, "F J 4"],
    before: Float[np.ndarray, "F J 3"],
    after: Float[np.ndarray, "F J 3"],
) -> np.ndarray:
    """Local joint rotations whose forward kinematics put the legs where :func:`plant_feet` put
    their points (``before`` → ``after``, joint positions), for writing a planted walker as a
    clip. Per leg: the hip joint turns its thigh onto the new knee and the knee its shin onto
    the new ankle (the least rotations, keeping each bone's twist); the ankle keeps its world
    rotation (the foot was moved, not turned), so everything below it follows unchanged.
    ``local`` and ``world``: the clip's local and global rotations (scalar-first)."""
    out = np.array(local, np.float64, copy=True)
    for hip, knee, ankle, _, _ in legs:
        r_hip = quat_mul(
            _least_rotation(before[:, knee] - before[:, hip], after[:, knee] - after[:, hip]),
            world[:, hip],
        )
        parent = parents[hip]
        out[:, hip] = r_hip if parent < 0 else quat_mul(quat_inv(world[:, parent]), r_hip)
        r_knee = quat_mul(r_hip, local[:, knee])
        shin = quat_rotate(quat_inv(world[:, knee]), before[:, ankle] - before[:, knee])
        turn = _least_rotation(quat_rotate(r_knee, shin), after[:, ankle] - after[:, knee])
        r_knee = quat_mul(turn, r_knee)
        out[:, knee] = quat_mul(quat_inv(r_hip), r_knee)
        out[:, ankle] = quat_mul(quat_inv(r_knee), world[:, ankle])
    return out
