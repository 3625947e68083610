"""Local avoidance: the collision-free speed model of A. Tordeux, M. Chraibi, A. Seyfried,
"Collision-free speed model for pedestrian dynamics", Traffic and Granular Flow '15 (Springer
2016), 225–232 (arXiv:1512.05597), a first-order model:

- Eq. (1)  ``ẋ_i = V(s_i) e_i``;
- Eq. (2)  ``V(s) = min(v0_i, max(0, (s − ℓ) / T))``, time gap ``T``, agent size ``ℓ``;
- Eq. (3)  ``s_i = min_{j ∈ J_i} ‖x_j − x_i‖`` over the neighbours ahead of ``i`` in a corridor
  of its own width: ``J_i = {j : e_i·(x_j − x_i) ≥ 0 and |e_i^⊥·(x_j − x_i)| ≤ ℓ}``;
- Eq. (4)  ``e_i = u(e_i^0 + Σ_j R(‖x_i − x_j‖) (x_i − x_j)/‖x_i − x_j‖)``,
  ``R(s) = a exp((ℓ − s)/D)``, ``u(v) = v/‖v‖``.

Readings taken as JuPedSim's implementation does: radii, ``ℓ_ij = r_i + r_j``; walls repel in
Eq. (4) like a neighbour, ``a_w exp((r_i − d)/D_w)`` along the normal from the wall's closest
point. Five changes of ours, each for a failure of the paper's model on the experiments of
``bench/pedestrians.py`` (docs/validation.md: figures; docs/design/pedestrians.md: the trials):

- **A smooth Eq. (2)**: ``V(s) = v0 x / (1 + x^n)^{1/n}``, ``x = (s − ℓ)/(v0 T)``, ``n`` = 4:
  slope ``1/T`` at contact, never above the paper's ``V`` (the collision-free bound holds),
  the paper's as ``n → ∞``; its triangular ``V`` leaves the fed HERMES corridors too thin.
- **Anisotropic repulsion**: ``j`` repels ``i`` with weight ``λ + (1 − λ)(1 + cos φ_ij)/2``,
  ``φ_ij`` between ``e_i^0`` and ``x_j − x_i``, ``λ`` = 0.3: isotropic, a crowd pressing from
  behind forms arches at a narrow exit that never break.
- **Walls in Eq. (3)**: a wall ahead within ``r_i`` of the walking line limits the speed like a
  neighbour of size 0 at its closest point (no oscillating against ``D_w``'s stiff wall).
- **Sliding along walls**: ``e^0 ← u(e^0 − w min(0, e^0·n) n)``, ``n`` the normal of the wall
  pressed into most, ``w = clip((r_i + m − d)/m, 0, 1)``, ``m`` = 0.1 m.
- **Standing where desire and repulsion cancel** (opt-in, given last velocities ``v'``): speed
  ``V(s) min(1, ‖E‖/c + ‖v'‖/v_go)``, ``E`` the sum Eq. (4) normalises (walls, anticipation's
  step included; a free walker's ``‖E‖`` is 1), ``c`` = ``stand_drive``, ``v_go`` = 2 m/s.
  Normalised, ``E`` walks at full ``V`` whichever way it tips, so a queue steps forward and
  back; with ``c`` = 0.7 the Wuppertal entrance's queue is as calm as measured, but the jammed
  HERMES corridors and the bidirectional example stand too still, so ``c`` = 0 (off) by default.

More with them: :mod:`~jcrowd.pedestrians.reaction`, :mod:`~jcrowd.pedestrians.heading`. Eq. (4)
and ``V`` are smooth; the gradient jumps where Eq. (3)'s set, the slid wall or ``min`` change.

Positions ``[x, z]`` in metres, velocities m/s; neighbours as candidate ids (``N``: none),
walls as segments ``(S, 2, 2)`` with candidate ids (``S``: none), through the grid in
:func:`~jcrowd.pedestrians.grid_avoidance.avoid_in_grid`.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.pedestrians.heading import body_speed
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.pedestrians.reaction import TINY as _TINY
from jcrowd.pedestrians.reaction import Motion, react, relax_velocity, sideways
from jcrowd.pedestrians.reaction import unit_xz as _unit_xz

__all__ = [
    "Motion",
    "approach_cap",
    "avoid",
    "avoid_one",
    "avoid_rows",
    "closest_on_segments",
    "crowd_table",
]


def closest_on_segments(
    point: Float[Array, " 2"], segments: Float[Array, "W 2 2"]
) -> Float[Array, "W 2"]:
    """The closest point of each segment ``(a, b)`` to ``point``."""
    a, b = segments[:, 0], segments[:, 1]
    ab = b - a
    t = jnp.sum((point - a) * ab, axis=-1) / jnp.maximum(jnp.sum(ab * ab, axis=-1), _TINY**2)
    return a + jnp.clip(t, 0.0, 1.0)[:, None] * ab


def _unit(v: Array) -> tuple[Array, Array]:
    """``(v/‖v‖, ‖v‖)`` along the last axis, 0 where ``‖v‖`` is below ``_TINY``."""
    norm = jnp.sqrt(jnp.sum(v * v, axis=-1, keepdims=True))
    return jnp.where(norm > _TINY, v / jnp.maximum(norm, _TINY), 0.0), norm[..., 0]


def optimal_velocity(
    params: AvoidanceParams, speed: Float[Array, "*n"], gap: Float[Array, "*n"]
) -> Float[Array, "*n"]:
    """Eq. (2) smoothed: ``V = v0 x / (1 + x^n)^{1/n}`` with ``x = (s − ℓ)/(v0 T)``, 0 at
    ``s ≤ ℓ`` (module docstring)."""
    v0 = jnp.maximum(speed, _TINY)
    # Nobody ahead (gap = +inf) gives x = 1e3 as the clip would, without dividing inf: the
    # gradient of inf / (v0 T) through the clip is inf·0 = NaN in v0 and T.
    free = gap == jnp.inf
    x = jnp.clip(jnp.where(free, 0.0, gap) / (v0 * params.time_gap), _TINY, 1e3)
    x = jnp.where(free, 1e3, x)  # and no 0**n above: its n-gradient is NaN
    v = speed * x / (1.0 + x**params.sharpness) ** (1.0 / params.sharpness)
    return jnp.where(gap > 0.0, v, 0.0)


def avoid_one(
    params: AvoidanceParams,
    position: Float[Array, " 2"],
    desired: Float[Array, " 2"],
    speed: Float[Array, ""],
    radius: Float[Array, ""],
    others: Float[Array, "M 2"],
    other_radius: Float[Array, " M"],
    other_valid: Bool[Array, " M"],
    walls: Float[Array, "W 2 2"],
    wall_valid: Bool[Array, " W"],
) -> tuple[Float[Array, " 2"], Float[Array, ""]]:
    """One agent's velocity under Eqs. (1)–(4): returns ``(velocity (2,), spacing s_i − ℓ)``.

    Args:
        position: the agent's ``[x, z]``; ``desired`` its unit desired direction ``e_i^0``;
            ``speed`` its free speed ``v0_i`` (m/s); ``radius`` its ``r_i`` (m).
        others, other_radius, other_valid: candidate neighbours (invalid rows are ignored).
        walls, wall_valid: candidate wall segments.

    The spacing is ``+inf`` when nobody is ahead in the corridor.
    """
    q = closest_on_segments(position, walls)
    wall_away, wall_dist = _unit(position - q)
    # The wall pressed into most takes the into-wall part of the desire (module docstring).
    reach = jnp.clip((radius + params.wall_slide - wall_dist) / params.wall_slide, 0.0, 1.0)
    press = jnp.where(wall_valid, reach * jnp.minimum(0.0, wall_away @ desired), 0.0)
    if walls.shape[0]:
        k = jnp.argmin(press)
        desired, _ = _unit(desired - press[k] * wall_away[k])
    away, dist = _unit(position - others)  # e_ij and s_ij
    size = radius + other_radius  # ℓ_ij
    push = jnp.where(other_valid, params.strength * jnp.exp((size - dist) / params.range), 0.0)
    push = push * _behind_weight(params, -(away @ desired))
    direction = desired + jnp.sum(push[:, None] * away, axis=0)
    wall_push = params.wall_strength * jnp.exp((radius - wall_dist) / params.wall_range)
    wall_push = jnp.where(wall_valid, wall_push, 0.0)
    direction, _ = _unit(direction + jnp.sum(wall_push[:, None] * wall_away, axis=0))
    rel = others - position
    ahead = rel @ direction >= 0.0
    lateral = jnp.abs(rel[:, 0] * direction[1] - rel[:, 1] * direction[0])
    in_corridor = other_valid & ahead & (lateral <= size)
    gap = jnp.min(jnp.where(in_corridor, dist - size, jnp.inf))
    if walls.shape[0]:
        rel_w = q - position
        w_lateral = jnp.abs(rel_w[:, 0] * direction[1] - rel_w[:, 1] * direction[0])
        w_in = wall_valid & (rel_w @ direction >= 0.0) & (w_lateral <= radius)
        gap = jnp.minimum(gap, jnp.min(jnp.where(w_in, wall_dist - radius, jnp.inf)))
    v = optimal_velocity(params, speed, gap)
    return v * direction, gap


def avoid(
    params: AvoidanceParams,
    position: Float[Array, "N 2"],
    desired: Float[Array, "N 2"],
    speed: Float[Array, " N"],
    radius: Float[Array, " N"],
    neighbours: Int[Array, "N M"],
    walls: Float[Array, "S 2 2"],
    wall_ids: Int[Array, "N W"],
    others: tuple[Array, Array] | None = None,
    motion: Motion | None = None,
    horizon: Float[Array, "*N"] | None = None,
) -> tuple[Float[Array, "N 2"], Float[Array, " N"]]:
    """Every agent's velocity (Eqs. 1–4) from its candidate neighbours and walls; with
    ``motion``, anticipating (:mod:`jcrowd.pedestrians.reaction`'s reading of Xu et al. 2021).

    ``neighbours`` holds agent ids (``N`` for none), ``wall_ids`` segment ids into ``walls``
    (``S`` for none). With ``others = (positions (P, 2), radii (P,))`` the ids index those
    instead (``P`` for none): the agents stepped here are then a block of a larger crowd, as on
    one device of several. Returns ``(velocity (N, 2), spacing (N,))``, what :func:`avoid_one`
    gives agent by agent without ``motion`` (anticipation is checked against its own oracle,
    ``tests/test_avoidance.py``). ``horizon`` (s; one, or one per agent): how long the
    velocity will be walked before the agent is updated again — its speed is then capped so
    it closes at most half the gap to any candidate (:func:`approach_cap`). Written on
    ``(N, M)`` arrays per coordinate rather than as a ``vmap`` of :func:`avoid_one` over
    ``(M, 2)`` rows: XLA:CPU vectorizes loops over one contiguous axis, and a minor axis of
    length 2 defeats that.
    """
    all_pos, all_rad = (position, radius) if others is None else others
    table = crowd_table(all_pos, all_rad, None if motion is None else motion.crowd)
    rows = table[neighbours]
    valid = neighbours < all_pos.shape[0]
    return avoid_rows(
        params, position, desired, speed, radius, rows, valid, walls, wall_ids, motion, horizon
    )


def crowd_table(
    position: Float[Array, "P 2"], radius: Float[Array, " P"], velocity: Float[Array, "P 2"] | None
) -> Float[Array, "P1 C"]:
    """The rows :func:`avoid_rows` reads per candidate, ``[x, z, r]`` (then ``vx, vz`` with
    ``velocity``), and a zero row ``P`` for "no candidate". One gather of these rows per
    candidate, not one per column: XLA:CPU recomputes the candidate ids inside every gather it
    fuses them into (measured: three column gathers took twice the time of the rest of
    :func:`avoid` at 100k agents)."""
    columns = [position, radius[:, None].astype(position.dtype)]
    if velocity is not None:
        columns.append(velocity.astype(position.dtype))
    table = jnp.concatenate(columns, axis=1)
    return jnp.concatenate([table, jnp.zeros((1, table.shape[1]), table.dtype)])


def avoid_rows(
    params: AvoidanceParams,
    position: Float[Array, "N 2"],
    desired: Float[Array, "N 2"],
    speed: Float[Array, " N"],
    radius: Float[Array, " N"],
    rows: Float[Array, "N M C"],
    valid: Bool[Array, "N M"],
    walls: Float[Array, "S 2 2"],
    wall_ids: Int[Array, "N W"],
    motion: Motion | None = None,
    horizon: Float[Array, "*N"] | None = None,
) -> tuple[Float[Array, "N 2"], Float[Array, " N"]]:
    """:func:`avoid` from the candidates' rows of :func:`crowd_table` (``valid``: a row is a
    candidate); ``motion.crowd`` is not read (the rows carry the velocities)."""
    x, z = position[:, 0], position[:, 1]
    wx, wz, winv, wd, wvalid = _wall_offsets(x, z, walls, wall_ids)
    if wall_ids.shape[1]:
        desired = _slide(params, desired, radius, wx, wz, winv, wd, wvalid)
    px, pz, pr = rows[..., 0], rows[..., 1], rows[..., 2]
    dx, dz = x[:, None] - px, z[:, None] - pz  # from j to i
    dist = jnp.sqrt(dx * dx + dz * dz)
    inv = jnp.where(dist > _TINY, 1.0 / jnp.maximum(dist, _TINY), 0.0)
    size = radius[:, None] + pr
    push = jnp.where(valid, params.strength * jnp.exp((size - dist) / params.range), 0.0) * inv
    push = push * _behind_weight(params, -(dx * desired[:, 0:1] + dz * desired[:, 1:2]) * inv)
    ex = desired[:, 0] + jnp.sum(push * dx, axis=1)
    ez = desired[:, 1] + jnp.sum(push * dz, axis=1)
    wpush = params.wall_strength * jnp.exp((radius[:, None] - wd) / params.wall_range)
    wpush = jnp.where(wvalid, wpush, 0.0) * winv
    wall_x, wall_z = jnp.sum(wpush * wx, axis=1), jnp.sum(wpush * wz, axis=1)
    if motion is not None and motion.crowd is not None:
        vj = (rows[..., 3], rows[..., 4])
        sx, sz = sideways(params, desired, motion, vj, valid, dx, dz, inv, size)
        ex, ez = ex + sx, ez + sz
    # A person whose desire and repulsion cancel stands (module docstring).
    drive = 1.0 if motion is None else _drive(params, ex + wall_x, ez + wall_z, motion.own)
    if motion is not None and motion.crowd is not None:
        # The reaction time relaxes the direction people choose; walls act at once.
        ex, ez = react(params.reaction_time, motion, *_unit_xz(ex, ez))
    ex, ez = _unit_xz(ex + wall_x, ez + wall_z)

    def spacing(ex: Array, ez: Array) -> Array:
        """Eq. (3) along ``(ex, ez)``, walls ahead as neighbours of size 0 at their closest
        points."""
        # Neighbour j relative to i is (−dx, −dz): ahead when e·(x_j − x_i) ≥ 0.
        ahead = -(dx * ex[:, None] + dz * ez[:, None]) >= 0.0
        lateral = jnp.abs(dx * ez[:, None] - dz * ex[:, None])
        gap = jnp.min(jnp.where(valid & ahead & (lateral <= size), dist - size, jnp.inf), axis=1)
        if wall_ids.shape[1]:
            w_ahead = -(wx * ex[:, None] + wz * ez[:, None]) >= 0.0
            w_lateral = jnp.abs(wx * ez[:, None] - wz * ex[:, None])
            w_in = wvalid & w_ahead & (w_lateral <= radius[:, None])
            w_gap = jnp.min(jnp.where(w_in, wd - radius[:, None], jnp.inf), axis=1)
            gap = jnp.minimum(gap, w_gap)
        return gap

    gap = spacing(ex, ez)
    v = optimal_velocity(params, speed, gap) * drive
    if motion is not None and motion.facing is not None:  # a body walks along its heading
        v = body_speed(params, ex, ez, v, motion.facing)
    if motion is not None and motion.crowd is None:  # the plain model with its reaction time
        ex, ez, v = relax_velocity(params.plain_reaction_time, motion, ex, ez, v)
        gap = spacing(ex, ez)
        v = jnp.minimum(v, optimal_velocity(params, speed, gap))
    if horizon is not None:
        ahead_j = -(dx * ex[:, None] + dz * ez[:, None]) * inv  # cos to each neighbour
        cap = approach_cap(dist - size, ahead_j, valid, horizon)
        if wall_ids.shape[1]:
            ahead_w = -(wx * ex[:, None] + wz * ez[:, None]) * winv
            wall_cap = approach_cap(2.0 * (wd - radius[:, None]), ahead_w, wvalid, horizon)
            cap = jnp.minimum(cap, wall_cap)
        v = jnp.minimum(v, cap)
    return jnp.stack([v * ex, v * ez], axis=1), gap


def approach_cap(
    gap: Float[Array, "N M"],
    cos: Float[Array, "N M"],
    valid: Bool[Array, "N M"],
    horizon: Float[Array, "*N"],
) -> Float[Array, " N"]:
    """The fastest an agent may walk for ``horizon`` seconds without being updated: at speed
    ``v`` along ``e`` it comes at most ``v·horizon·cos_j`` closer to candidate ``j``
    (``cos_j = e·(x_j − x_i)/‖x_j − x_i‖``; ``‖x_j − x_i − s e‖ ≥ ‖x_j − x_i‖ − s cos_j``), and
    it may use half of the free gap ``s_ij − ℓ_ij`` — the other half is ``j``'s, which caps
    itself the same way. So ``v ≤ min_j max(0, gap_j) / (2 horizon cos_j)`` over the
    candidates it walks towards (``cos_j > 0``); ``+inf`` when it walks towards none.

    Simulation level of detail (:attr:`~jcrowd.crowd.state.StepConfig.far_every`): a far
    agent walks its velocity for ``far_every`` steps, and two of them crossing could otherwise
    close more than their gap in between (measured on the 100k plaza: 0.84 (rᵢ + rⱼ) between
    two far agents at 1.4 m/s). Walking along a neighbour (``cos ≈ 0``) or behind one at the
    model's own speed (``V ≤ gap/T``, and ``T ≥ 2 horizon``) the cap does not bind. Walls,
    which do not move, get the whole gap (the caller passes twice it). Not smooth (a minimum
    over candidates): it is not in the differentiable path, which updates every step.
    """
    h = jnp.asarray(horizon)
    h = h[:, None] if h.ndim else h
    rate = 2.0 * h * cos
    limit = jnp.maximum(gap, 0.0) / jnp.maximum(rate, _TINY)
    return jnp.min(jnp.where(valid & (cos > 0.0), limit, jnp.inf), axis=1)


def _drive(params: AvoidanceParams, ex: Array, ez: Array, own: Array) -> Array:
    """The share of the speed the unnormalised Eq. (4) sum ``E = (ex, ez)`` leaves an agent
    whose last velocity is ``own``: ``min(1, ‖E‖/c + ‖v'‖/v_go)``, 1 with ``c`` = 0 (module
    docstring)."""
    norm = jnp.sqrt(ex * ex + ez * ez + _TINY * _TINY)
    sp = jnp.sqrt(own[:, 0] ** 2 + own[:, 1] ** 2 + _TINY * _TINY)
    share = norm / jnp.maximum(params.stand_drive, _TINY) + sp / params.go_speed
    return jnp.where(params.stand_drive > 0.0, jnp.minimum(1.0, share), 1.0)


def _behind_weight(params: AvoidanceParams, cos: Array) -> Array:
    """The anisotropy ``λ + (1 − λ)(1 + cos φ_ij)/2`` of a neighbour at bearing ``cos φ_ij``
    from the desired direction (1 straight ahead, ``λ`` straight behind)."""
    return params.anisotropy + (1.0 - params.anisotropy) * 0.5 * (1.0 + cos)


def _wall_offsets(
    x: Array, z: Array, walls: Array, wall_ids: Array
) -> tuple[Array, Array, Array, Array, Array]:
    """From each candidate wall's closest point to the agent: ``(dx, dz, 1/d, d, valid)``,
    each ``(N, W)``."""
    pad = jnp.concatenate([walls, jnp.zeros((1, 2, 2), walls.dtype)])
    ax, az = pad[:, 0, 0][wall_ids], pad[:, 0, 1][wall_ids]
    bx, bz = pad[:, 1, 0][wall_ids], pad[:, 1, 1][wall_ids]
    abx, abz = bx - ax, bz - az
    t = ((x[:, None] - ax) * abx + (z[:, None] - az) * abz) / jnp.maximum(
        abx * abx + abz * abz, _TINY**2
    )
    t = jnp.clip(t, 0.0, 1.0)
    wx, wz = x[:, None] - (ax + t * abx), z[:, None] - (az + t * abz)
    wd = jnp.sqrt(wx * wx + wz * wz)
    winv = jnp.where(wd > _TINY, 1.0 / jnp.maximum(wd, _TINY), 0.0)
    return wx, wz, winv, wd, wall_ids < walls.shape[0]


def _slide(
    params: AvoidanceParams,
    desired: Array,
    radius: Array,
    wx: Array,
    wz: Array,
    winv: Array,
    wd: Array,
    wvalid: Array,
) -> Array:
    """The desired direction slides along the wall it presses into most (module docstring):
    ``u(e^0 − w min(0, e^0·n) n)`` for the candidate wall with the most negative
    ``w min(0, e^0·n)``, ``n`` its unit normal towards the agent, ``w = clip((r + m − d)/m,
    0, 1)``."""
    nx, nz = wx * winv, wz * winv
    into = jnp.minimum(0.0, desired[:, 0:1] * nx + desired[:, 1:2] * nz)
    reach = jnp.clip((radius[:, None] + params.wall_slide - wd) / params.wall_slide, 0.0, 1.0)
    press = jnp.where(wvalid, reach * into, 0.0)
    k = jnp.argmin(press, axis=1)[:, None]
    p = jnp.take_along_axis(press, k, axis=1)[:, 0]
    ex = desired[:, 0] - p * jnp.take_along_axis(nx, k, axis=1)[:, 0]
    ez = desired[:, 1] - p * jnp.take_along_axis(nz, k, axis=1)[:, 0]
    return jnp.stack(_unit_xz(ex, ez), axis=1)
