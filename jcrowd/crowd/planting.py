"""Planted feet for walkers the simulation moves: each stance foot stays where it landed, the
leg bending to reach it (two-bone IK), and lets go over the swing that follows.

With the crowd dynamics on, the root walks the simulated path, smooth and straight, while the
decoded legs (level 0 keeps 30 of the 100 aligned frames in its time mode, which smooths the
heel strike) slide their stance foot by 2–3 times what the captures' own feet slide
(``bench/follow.py``). Moving the root to lock the foot, as the step does without the dynamics,
would move it off the simulated position; production crowd tools pin the foot and solve the
leg instead, and so does :func:`plant_feet`, on the points of agents drawn at the near levels
(``≤ blend_max_level``) when :attr:`~jcrowd.crowd.state.StepConfig.plant_feet` is set. It is
off by default: a foot held off its decoded place snaps back when its agent leaves the near
levels (nothing plants the coarse levels), and a walker slowing to stand, its phase playing on
while its root hardly moves, holds its feet up to :data:`MAX_SLIP` off the standing pose.

**Stance** is a static window of the aligned phase per foot: it opens at the foot's heel strike
(:attr:`~jcrowd.crowd.clips.CrowdModel.double_support`: the left heel strikes where the left
ankle is furthest ahead) and lasts :data:`STANCE_SHARE` of the cycle. Every clip is aligned to
one reference cycle, so the window holds for every clip of the model. Our reading of the
stance length: 60 % of the gait cycle at walking speeds (Perry & Burnfield, *Gait Analysis*,
2010, ch. 1), so both windows hold a phase at each double support, and a standing walker (its
phase waiting at a double-support phase) has both feet planted.

**The pin** (per foot, world ``x, z``): at the stance's first frame the foot's planted joint
(the lower of ankle and toe, heel down then toe down, as :func:`jcrowd.model.foot_skate`
measures) is pinned where it is; in later frames the foot is moved horizontally by
``δ = pin − planted joint`` (``|δ|`` at most :data:`MAX_SLIP` times the skeleton scale: beyond
it the foot slides). When the planted joint changes from ankle to toe the pin moves to the toe
plus ``δ``, so ``δ`` is continuous. At the stance's end ``δ`` is kept and eases to 0 over the
first :data:`RELEASE_SHARE` of the swing (smoothstep), a lifted foot catching up with its
decoded path.

**The leg** (hip, knee, ankle, in the points): the ankle and everything below it move by
``δ``; the knee is placed so that thigh and shin keep their lengths, in the plane of the hip,
the new ankle and the decoded knee (the closed-form two-bone solution: with ``d`` the
hip–ankle distance, the knee sits ``a = (l₁² − l₂² + d²) / 2d`` along the hip–ankle line and
``√(l₁² − a²)`` off it, towards the decoded knee, leaning towards the toe by
:data:`POLE_WEIGHT` so a straight leg keeps its knee in front). An ankle out of reach is put
at full reach along the hip–ankle line.

State: per agent and foot the pin (or the release offset over the swing), whether the foot
was planted in the last frame and whether its toe is the planted joint: 20 bytes. Agents not
drawn at a near level have no pins: their state is reset each frame, and a foot planted when
an agent comes near starts where it is.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from jcrowd.pedestrians.heading import smoothstep

__all__ = [
    "MAX_SLIP",
    "RELEASE_SHARE",
    "STANCE_SHARE",
    "Legs",
    "leg_chains",
    "plant_feet",
    "plant_sequence",
    "reach",
]

STANCE_SHARE = 0.6
"""The share of the gait cycle a foot is planted for (from its heel strike)."""

RELEASE_SHARE = 0.5
"""The share of the swing over which a released foot eases back to its decoded path."""

MAX_SLIP = 0.1
"""The farthest a planted foot is held from its decoded place, per metre of skeleton scale."""

POLE_WEIGHT = 0.05
"""How far (per thigh length) the knee's bend leans towards the toe: where the decoded knee sits
further than this off the hip–ankle line, it decides the bend's side."""

Legs = tuple[tuple[int, int, int, int, tuple[int, ...]], ...]
"""Per foot (left, right): hip, knee, ankle, toe point indices and the ankle's descendants (the
ankle included)."""


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
    their lengths, the knee bending towards where it was and the toe (module docstring)."""
    l1 = jnp.linalg.norm(knee - hip)
    l2 = jnp.linalg.norm(ankle - knee)
    d_vec = target - hip
    d = jnp.maximum(jnp.linalg.norm(d_vec), 1e-9)
    u = d_vec / d
    d = jnp.clip(d, jnp.abs(l1 - l2) + 1e-6, (l1 + l2) * (1.0 - 1e-6))
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
) -> tuple[Array, Array, Array, Array]:
    """One agent's points with its stance feet planted, and its new ``(pin, on, toe)``.

    ``stance_start``: each foot's heel-strike phase (aligned frames); ``last``: the cycle's
    length in aligned frames; ``tau``: the phase the points are decoded at; ``scale``: the
    skeleton's scale (m). ``pin``: per foot ``(x, z)``, the pin while planted, the release
    offset while swinging; ``on``: planted in the last frame; ``toe``: the pin is the toe's.
    """
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
        held = held * jnp.minimum(1.0, MAX_SLIP * scale / jnp.maximum(n, 1e-9))
        release = jnp.where(on[f], held, pin[f])  # the offset kept over the swing
        delta = jnp.where(
            stance,
            jnp.where(on[f], held, 0.0),
            release * (1.0 - smoothstep(swing)),
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


def plant_sequence(
    legs: Legs,
    stance_start: tuple[float, float],
    last: float,
    points: Float[Array, "F P 3"],
    tau: Float[Array, " F"],
    scale: Float[Array, ""],
) -> Float[Array, "F P 3"]:
    """One agent's frames with its feet planted as the step plants them frame by frame (from no
    pins): for a walker re-synthesized off line, drawn at a near level throughout."""

    def one(carry: tuple[Array, Array, Array], x: tuple[Array, Array]) -> tuple[Any, Array]:
        p, t = x
        out, *feet = plant_feet(legs, stance_start, last, p, t, scale, *carry)
        return tuple(feet), out

    start = (jnp.zeros((2, 2), points.dtype), jnp.zeros(2, bool), jnp.zeros(2, bool))
    _, out = jax.lax.scan(one, start, (points, tau))
    return out
