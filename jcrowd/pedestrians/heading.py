"""A body heading in the pedestrian step: which way each person faces, and what it may do to
the velocity.

The collision-free speed model has no body: its velocity's direction is all there is, so every
push from a neighbour turns the person. With a heading per agent (``Pedestrians.heading``, an
angle θ facing ``(sin θ, cos θ)`` in ``(x, z)``, the crowd's convention) the step turns it
every step and may bind the velocity to it; the reading is ours, after crowd tools that keep
heading and velocity apart (Unreal's Mass crowds face the move target when standing, Houdini's
crowd solver bounds the turn rate) and pedestrian models with an orientation (Xu, Chraibi &
Seyfried 2021; Farina et al. 2017):

1. **The heading turns** towards ``t = u(w v̂ + (1 − w) e⁰)``, ``w = S(‖v‖/v_walk)``, ``S`` the
   smoothstep: a walking person faces where they go, a standing or shuffling one their desired
   direction (goal or field) — a jostle in a queue does not turn the body. It relaxes over
   ``τ_h`` and turns at most ``ω (s + (1 − s) w)`` rad/s: ``θ ← θ + clip(Δ min(1, Δt/τ_h),
   ±ω (s + (1 − s) w) Δt)``, ``Δ`` the wrapped angle to ``t``. Willems et al. (Sci. Rep. 2020)
   measured the walking direction following the body's with about 100 ms delay; ``τ_h`` =
   0.1 s, ``ω`` = 3 rad/s, ``v_walk`` = 0.5 m/s. A standing body turns at ``s`` = 0.4 of that:
   its feet stay planted while it turns, so a faster turn slides them.
2. **Walking mostly along the heading** (``back_share`` ``b`` < 1): the model's speed ``V``
   (Eq. 2) is scaled by ``f = b + (1 − b) ((1 + cos φ)/2)²``, ``φ`` between the chosen
   direction and the heading: 1 ahead, ``(1 + 3b)/4`` to the side, ``b`` straight back; only
   lowered, so the collision-free bound holds. Off by default (``b`` = 1): on the Wuppertal
   entrance ``b`` = 0.25 halves the queue's moving frames but cuts the flow by a sixth, below
   the measurement's band; what calms the queue is the avoidance's standing rule
   (:mod:`jcrowd.pedestrians.avoidance`; docs/design/pedestrians.md).

Rule 2 acts where the model's velocity is chosen (with the last velocities,
:class:`~jcrowd.pedestrians.reaction.Motion`), before the plain model's reaction time relaxes
it. Smoothness: ``f`` is smooth; the turn's bound is a clip, so the heading's gradient is cut
while a turn is rate-limited, and the wrap of ``Δ`` jumps when the target is straight behind.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from jcrowd.pedestrians.params import AvoidanceParams

__all__ = ["body_speed", "facing", "smoothstep", "turn_heading"]

_TINY = 1e-6


def smoothstep(x: Array) -> Array:
    """``S(x) = 3x² − 2x³`` on ``x`` clipped to ``[0, 1]``: 0 below 0, 1 above 1, C¹."""
    c = jnp.clip(x, 0.0, 1.0)
    return c * c * (3.0 - 2.0 * c)


def facing(heading: Float[Array, " N"]) -> Float[Array, "N 2"]:
    """The unit direction ``(sin θ, cos θ)`` a heading θ faces."""
    return jnp.stack([jnp.sin(heading), jnp.cos(heading)], axis=1)


def body_speed(
    params: AvoidanceParams,
    ex: Float[Array, " N"],
    ez: Float[Array, " N"],
    v: Float[Array, " N"],
    face: Float[Array, "N 2"],
) -> Float[Array, " N"]:
    """Rule 2 (module docstring): the speed ``v`` along the unit ``(ex, ez)`` scaled by the
    share a body facing ``face`` keeps in that direction."""
    cos = ex * face[:, 0] + ez * face[:, 1]
    half = 0.5 * (1.0 + cos)
    return v * (params.back_share + (1.0 - params.back_share) * half * half)


def turn_heading(
    params: AvoidanceParams,
    heading: Float[Array, " N"],
    velocity: Float[Array, "N 2"],
    desired: Float[Array, "N 2"],
    dt: Float[Array, "*N"] | float,
) -> Float[Array, " N"]:
    """Rule 1 (module docstring): the heading turned towards the walking direction, or the
    desired one when slow, relaxed over ``heading_time`` and at most ``turn_rate·dt`` (a share
    ``stand_turn_share`` of it standing). Kept
    where neither direction is defined (a person standing with nowhere to go)."""
    vx, vz = velocity[:, 0], velocity[:, 1]
    sq = vx * vx + vz * vz
    moving = sq > _TINY * _TINY
    speed = jnp.sqrt(jnp.where(moving, sq, 1.0))
    w = jnp.where(moving, smoothstep(speed / params.walk_speed), 0.0)
    tx = w * jnp.where(moving, vx / speed, 0.0) + (1.0 - w) * desired[:, 0]
    tz = w * jnp.where(moving, vz / speed, 0.0) + (1.0 - w) * desired[:, 1]
    has = tx * tx + tz * tz > _TINY * _TINY
    want = jnp.arctan2(jnp.where(has, tx, 0.0), jnp.where(has, tz, 1.0))
    diff = jnp.remainder(want - heading + jnp.pi, 2.0 * jnp.pi) - jnp.pi
    dt = jnp.asarray(dt, heading.dtype)
    share = params.stand_turn_share + (1.0 - params.stand_turn_share) * w
    limit = params.turn_rate * share * dt
    turn = jnp.clip(diff * jnp.minimum(1.0, dt / params.heading_time), -limit, limit)
    return jnp.where(has, heading + turn, heading)
