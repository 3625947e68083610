"""Reaction time and anticipation: how an agent's avoidance follows from its last velocity.

The collision-free speed model (:mod:`jcrowd.pedestrians.avoidance`) calls the terms here when
it is given the last step's velocities (:class:`Motion`); without them the model is the paper's.

**A reaction time** (a fifth change of ours): the velocity relaxes from the last one towards
the model's, ``v ← v' + (V(s(e)) e − v') min(1, Δt/τ_p)``, ``τ_p`` = 0.1 s (walls included in
``e``), and then walks no faster than Eqs. (2)–(3) allow along its own direction,
``|v| ≤ V(s(v/|v|))``, so the collision-free bound still holds. The explicit step otherwise
oscillates in a dense queue — repulsion and desire win in turn — and a body drawn on that
velocity could only skate or spin. Relaxing the velocity, not only its direction, makes a turn
cost speed, so agents at a queue's edge do not circle at walking speed (docs/design/
pedestrians.md has the measurements and the alternatives).

**Anticipation** (``[dynamics] model = "anticipation"``): the anticipation velocity model of
Q. Xu, M. Chraibi, A. Seyfried, "Anticipation in a velocity-based model for pedestrian
dynamics", Transportation Research Part C 133 (2021) 103464 (arXiv:2107.00624), keeps the speed
of Eqs. (2)–(3) and changes the direction in three phases; our reading of them (the paper's
validation is bidirectional flow and lane formation; the terms are a reading, not a
transcription):

- *perception*: neighbour ``j`` counts with ``k_ij = max(0, e_i^0·(x_j − x_i)/‖x_j − x_i‖)``,
  less when it walks my way or stands (it is followed, not stepped around);
- *prediction*: both keep their velocities; ``s^a_ij`` is their closest distance over the next
  ``t_a`` seconds and ``p_ij`` their separation then;
- *strategy*: step sideways, to the side ``i`` is predicted on: ``e_i = u(e_i^{CSM} + Σ_j k_ij
  a_a exp((ℓ_ij − s^a_ij)/D_a) tanh((p_ij·r_i + b)/w) r_i)``, ``r_i`` the right of ``e_i^0``,
  ``b`` a keep-right bias (``i`` steps right unless it is predicted more than ``b`` to the
  left of ``j``), ``w`` the turn's width;
- *reaction*: ``e_i ← u(e_i^{prev} + (e_i − e_i^{prev}) min(1, Δt/τ))`` from the last
  velocity's direction, ``Δt`` the time since the agent's last update, over the direction
  chosen among people (bodies' repulsion included); walls act at once, after it.

Defaults ``t_a`` = 1 s, ``a_a`` = 8, ``D_a`` = 0.1 m, ``τ`` = 0.3 s (JuPedSim 1.4's), ``b`` =
0.1 m (a lane rule: with 0.05 m the mouths of ``examples/bidirectional.toml`` jam, with 0.2 m
wide head-on fronts pass slower; docs/design/pedestrians.md), ``w`` = 0.1 m. Counter-flowing
groups pass where the plain model jams head-on; in front of a narrow gap people step sideways
and pass it slower than measured, so it is not the default (``bench/pedestrians.py --model
anticipation``; docs/validation.md).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from jcrowd.pedestrians.params import AvoidanceParams

__all__ = ["TINY", "Motion", "react", "relax_velocity", "sideways", "unit_xz"]

_WALKING = 0.3  # m/s: a neighbour slower than this counts as partly standing (anticipation)
TINY = 1e-6
"""m: distances below this count as coincident (a direction left undefined is 0)."""


class Motion(eqx.Module):
    """What the reaction time and anticipation read (:func:`~jcrowd.pedestrians.avoidance.avoid`):
    the agents' own velocities of the last step ``(n, 2)``, the crowd's ``(P, 2)`` in the rows
    neighbour ids index (the same array when the agents are the crowd; ``None``: the plain
    model, whose velocity only relaxes), the time since their last update ``dt`` (s; one,
    or one per agent) and, for agents with a heading, the unit direction each faces
    ``(n, 2)`` (:mod:`jcrowd.pedestrians.heading`)."""

    own: Float[Array, "n 2"]
    crowd: Float[Array, "P 2"] | None
    dt: Float[Array, "*n"] = eqx.field(converter=jnp.asarray)
    facing: Float[Array, "n 2"] | None = None

    def rows(self, sel: Array) -> Motion:
        """The same for the agents ``sel`` (``crowd`` is everyone's and stays whole)."""
        dt = self.dt[sel] if self.dt.ndim else self.dt
        face = None if self.facing is None else self.facing[sel]
        return Motion(self.own[sel], self.crowd, dt, face)


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
