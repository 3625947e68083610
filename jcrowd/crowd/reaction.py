"""Reaction time and anticipation: how an agent's avoidance follows from its last velocity.

The collision-free speed model itself (Tordeux, Chraibi & Seyfried 2016; Eqs. 1–4 and four
changes of ours) is :mod:`jcrowd.crowd.avoidance`, which calls the terms here when it is given
the last step's velocities (:class:`Motion`).

A fifth change of ours to the collision-free speed model, in the crowd step and the pedestrian
step (given the last velocities; without them, as in the tests against the paper's equations,
the model is the paper's):

- **A reaction time**: the velocity relaxes from the last one towards the paper's,
  ``v ← v' + (V(s(e)) e − v') min(1, Δt/τ_p)`` with ``τ_p = 0.1`` s (walls included in
  ``e``), and then walks no faster than Eqs. (2)–(3) allow along its own direction,
  ``|v| ≤ V(s(v/|v|))`` — so the collision-free bound holds for the relaxed velocity too.
  The explicit step oscillates in a dense queue — the repulsion and the desire win in turn —
  and on the Wuppertal entrance the velocity's direction turned by 116° per frame at the
  median (p99 179°), so walkers drawn on it could only skate or spin. Relaxing the direction
  alone (``e ← u(e' + (e − e') min(1, Δt/τ_p))``, 2026-12-03 a.m.) turned that into orbits:
  the direction then turns at most 30° per frame at ``τ_p = 0.1`` s while the speed along it
  stays free, and agents at the queue's edge circled at 1.34 m/s on loops of ~15 cm radius
  (14k of the run's 79k agent-frames faster than 0.2 m/s were faster than 0.8 m/s). Relaxing
  the velocity, a turn costs speed: 4.5k of 59k, the direction's change per frame at the
  median 6° (17° relaxing the direction). ``τ_p = 0.3`` s slowed the entrance to 109 s
  (measured 64.5 s), 0.5 s to 142 s; at 0.1 s see docs/crowd.md's validation table. Not the
  anticipation model's relaxation, which stays on the direction.
  Tried and dropped: keeping the direction in the desired half-plane (nobody pushed
  backwards): the entrance jammed, 64 of 75 stuck.

**Anticipation** (optional; ``[dynamics] model = "anticipation"``): the collision-free speed model
lets counter-flowing groups jam head-on (each agent's repulsion points straight back at the agent it
meets). The anticipation velocity model of Q. Xu, M. Chraibi, A. Seyfried, "Anticipation in a
velocity-based model for pedestrian dynamics", Transportation Research Part C 133 (2021) 103464
(arXiv:2107.00624), keeps the speed of Eqs. (2)–(3) and changes the direction in three phases —
perception, prediction, strategy — and relaxes it with a reaction time. We read the phases as
follows (the paper's validation is bidirectional flow and lane formation; the exact terms below are
our reading, not a transcription):

- *perception*: neighbour ``j`` counts with weight ``k_ij = max(0, e_i^0·(x_j − x_i)/‖x_j − x_i‖)``
  (in front of the desired direction; behind: 0);
- *prediction*: both keep their current velocities; ``s^a_ij`` is the smallest distance between
  the two over the next ``t_a`` seconds (closest approach, clipped to ``[0, t_a]``), ``p_ij``
  the separation ``x_i − x_j`` at that time;
- *strategy*: step sideways, perpendicular to the desired direction, to the side ``i`` is
  predicted to be on: ``e_i = u(e_i^{CSM} + Σ_j k_ij a_a exp((ℓ_ij − s^a_ij)/D_a)
  tanh((p_ij·r_i + b)/w) r_i)`` with ``r_i`` the right of ``e_i^0`` (``y`` up) and ``b`` a
  small bias to the right that breaks the tie of an exact head-on meeting (keep right), ``w``
  the width over which the side turns smoothly;
- *reaction*: ``e_i ← u(e_i^{prev} + (e_i − e_i^{prev}) min(1, Δt/τ))`` from the direction of
  the last step's velocity (when faster than 5 cm/s), ``Δt`` the time since the agent's last
  update. This relaxes the direction chosen among people, Eq. (4)'s bodies included: relaxing
  only the desired and sideways terms, with the bodies' repulsion at once, made the head-on
  test no better than the plain model (23 % clear at 45 s). The walls act at once, added after
  the relaxation (relaxed, agents pressed by a crowd slid into them: 3 agent-steps inside a
  wall in a door test).

Defaults ``t_a = 1`` s, ``a_a = 8``, ``D_a = 0.1`` m, ``τ = 0.3`` s (JuPedSim 1.4's AVM
defaults), ``b = 0.05`` m, ``w = 0.1`` m. Measured on two groups of 230 walking head-on (20 m
fronts, 1.4 /m²): 45 s after the start 56 % had walked clear past the other group, against 32 %
with the plain model; the prediction without the reaction time did worse than the plain model.
Where it falls short (``bench/pedestrians.py --model anticipation``, with the four changes
above): people step sideways in front of the Wuppertal entrance's 0.5 m gap and pass it at
0.83 /s against the measured 1.16 (the plain model: 1.14), and the wide HERMES run comes out
35 % too thin — so it is not the default (docs/crowd.md). Its HERMES speed error is 0.105 m/s
(plain: 0.138).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

if TYPE_CHECKING:
    from jcrowd.crowd.avoidance import AvoidanceParams

__all__ = ["TINY", "Motion", "react", "relax_velocity", "sideways", "unit_xz"]

_WALKING = 0.3  # m/s: a neighbour slower than this counts as partly standing (anticipation)
TINY = 1e-6
"""m: distances below this count as coincident (a direction left undefined is 0)."""


class Motion(eqx.Module):
    """What the reaction time and anticipation read (:func:`~jcrowd.crowd.avoidance.avoid`):
    the agents' own velocities of the last step ``(n, 2)``, the crowd's ``(P, 2)`` in the rows
    neighbour ids index (the same array when the agents are the crowd; ``None``: the plain
    model, whose velocity only relaxes), and the time since their last update ``dt`` (s; one,
    or one per agent)."""

    own: Float[Array, "n 2"]
    crowd: Float[Array, "P 2"] | None
    dt: Float[Array, "*n"] = eqx.field(converter=jnp.asarray)


def sideways(
    params: AvoidanceParams,
    desired: Array,
    motion: Motion,
    vj: tuple[Array, Array],
    valid: Array,
    dx: Array,
    dz: Array,
    inv: Array,
    size: Array,
) -> tuple[Array, Array]:
    """The anticipatory sideways step ``Σ_j k_ij a_a e^{(ℓ_ij − s^a_ij)/D_a} tanh(…) r_i``
    (module docstring) on ``(N, M)`` arrays; ``dx, dz`` are ``x_i − x_j``, ``vj`` the
    candidates' velocities."""
    vjx, vjz = vj
    wx, wz = motion.own[:, 0:1] - vjx, motion.own[:, 1:2] - vjz  # v_i − v_j
    w2 = wx * wx + wz * wz
    closing = -(dx * wx + dz * wz)
    t = jnp.clip(closing / jnp.maximum(w2, TINY**2), 0.0, params.anticipation_time)
    px, pz = dx + wx * t, dz + wz * t  # x_i − x_j at the closest approach
    s = _norm_xz(px, pz)
    d0x, d0z = desired[:, 0:1], desired[:, 1:2]
    rx, rz = -d0z, d0x  # the right of the desired direction (y up)
    front = jnp.maximum(0.0, -(dx * d0x + dz * d0z) * inv)  # k_ij
    # Following: a neighbour walking my way, or standing, is followed, not stepped around.
    vj_speed = _norm_xz(vjx, vjz)
    # (1 − cos)/2 of the angle between v_j and e_i^0, times min(1, ‖v_j‖/_WALKING), in one.
    front = front * (vj_speed - (vjx * d0x + vjz * d0z)) / (2 * jnp.maximum(vj_speed, _WALKING))
    strength = params.anticipation_strength * jnp.exp((size - s) / params.anticipation_range)
    side = jnp.tanh((px * rx + pz * rz + params.keep_right) / params.side_width)
    k = jnp.sum(jnp.where(valid, front * strength * side, 0.0), axis=1, keepdims=True)
    return (k * rx)[:, 0], (k * rz)[:, 0]


def react(tau: Array, motion: Motion, ex: Array, ez: Array) -> tuple[Array, Array]:
    """The direction relaxed from the last step's: ``u(e' + (e − e') min(1, Δt/τ))``."""
    vx, vz = motion.own[:, 0], motion.own[:, 1]
    sp = _norm_xz(vx, vz)
    moving = sp > 0.05
    px = jnp.where(moving, vx / jnp.maximum(sp, TINY), ex)
    pz = jnp.where(moving, vz / jnp.maximum(sp, TINY), ez)
    rate = jnp.minimum(1.0, motion.dt / tau)
    return unit_xz(px + (ex - px) * rate, pz + (ez - pz) * rate)


def relax_velocity(
    tau: Array, motion: Motion, ex: Array, ez: Array, v: Array
) -> tuple[Array, Array, Array]:
    """The velocity ``v·e`` relaxed from the last step's: ``v' + (v e − v') min(1, Δt/τ)``,
    as its unit direction and speed."""
    rate = jnp.minimum(1.0, motion.dt / tau)
    rx = motion.own[:, 0] + (v * ex - motion.own[:, 0]) * rate
    rz = motion.own[:, 1] + (v * ez - motion.own[:, 1]) * rate
    ux, uz = unit_xz(rx, rz)
    return ux, uz, _norm_xz(rx, rz)


def unit_xz(ex: Array, ez: Array) -> tuple[Array, Array]:
    """``(ex, ez)`` scaled to unit length, 0 where it is shorter than ``TINY``."""
    norm = _norm_xz(ex, ez)
    ok = norm > TINY
    return (
        jnp.where(ok, ex / jnp.maximum(norm, TINY), 0.0),
        jnp.where(ok, ez / jnp.maximum(norm, TINY), 0.0),
    )


def _norm_xz(ex: Array, ez: Array) -> Array:
    """``√(ex² + ez²)``, whose gradient at 0 is 0: ``jnp.sqrt``'s is infinite there, and times
    a zero cotangent (an agent standing, or one that left) it is NaN in every gradient."""
    sq = ex * ex + ez * ez
    nonzero = sq > 0.0
    return jnp.where(nonzero, jnp.sqrt(jnp.where(nonzero, sq, 1.0)), 0.0)
