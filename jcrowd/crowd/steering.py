"""The crowd step's dynamics stage: where each agent walks, avoiding the others (DESIGN §5b).

With :attr:`~jcrowd.crowd.state.StepConfig.avoid` on, the simulation is the authority on
where people are: each alive agent's velocity comes from the collision-free speed model,
anticipating with :attr:`~jcrowd.crowd.state.StepConfig.anticipate`
(:mod:`jcrowd.crowd.avoidance`) — its desired direction straight towards its current waypoint
(or, with a layout, down the waypoint's navigation field: :mod:`jcrowd.crowd.scene`; the
scene's walls then repel too), its free speed, and its neighbours from the cell grid
(:mod:`jcrowd.crowd.neighbours`) — and its root moves by ``v·dt``. The body turns towards the
velocity at most :data:`TURN_RATE` rad/s (a walker turns its whole body over about a step, not
in one frame), and the next gait cycle is chosen from the velocity (:func:`aim_point`), so the
clips follow the simulated path.

With the crowd split over devices each device steps its own block of agents, but neighbours
live on every device: ``gather`` assembles the whole crowd's positions, radii and alive flags
(an all-gather of ``(N, 4)`` floats: 16 MB at 1M agents; ``(N, 6)``, 24 MB, when agents
anticipate: their velocities too) and every device fills the same grid
from them. ``ids`` are the block's agents' rows in the gathered arrays.
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.crowd.avoidance import AvoidanceParams, Motion
from jcrowd.crowd.grid_avoidance import avoid_in_grid
from jcrowd.crowd.navigation import desired_directions, field_values
from jcrowd.crowd.neighbours import GridSpec, cell_index, cell_list
from jcrowd.crowd.scene import Scene
from jcrowd.crowd.state import CrowdState
from jcrowd.motion.fastmath import sincos

__all__ = [
    "TURN_RATE",
    "aim_point",
    "current_field",
    "due_rows",
    "steer",
    "turn_towards",
    "waypoint_xz",
]

TURN_RATE = 3.0
"""Largest body turn rate (rad/s) when the heading follows the velocity."""

TURN_FULL_SPEED = 0.8
"""From this speed (m/s) up the body turns at up to :data:`TURN_RATE` (:func:`turn_towards`)."""

TURN_SLOW_SHARE = 0.1
"""The share of :data:`TURN_RATE` a walker keeps however slowly it moves."""

SELECT_WAYPOINTS = 8
"""Up to this many waypoints per agent, the current one is picked by selects (vectorized);
longer lists are gathered."""


def waypoint_xz(waypoints: Float[Array, "N K 2"], wp: Int[Array, " N"]) -> tuple[Array, Array]:
    """The ``(x, z)`` of each agent's waypoint ``wp``."""
    k = waypoints.shape[1]
    if k > SELECT_WAYPOINTS:
        row = jnp.take_along_axis(waypoints, wp[:, None, None], axis=1)[:, 0]
        return row[:, 0], row[:, 1]
    tx, tz = waypoints[:, 0, 0], waypoints[:, 0, 1]
    for j in range(1, k):
        tx = jnp.where(wp == j, waypoints[:, j, 0], tx)
        tz = jnp.where(wp == j, waypoints[:, j, 1], tz)
    return tx, tz


def current_field(state: CrowdState) -> Int[Array, " N"]:
    """Each agent's navigation field for its current waypoint (−1: none)."""
    return jnp.take_along_axis(state.field, state.waypoint[:, None], axis=1)[:, 0]


def steer(
    grid: GridSpec,
    x: Array,
    z: Array,
    tx: Array,
    tz: Array,
    speed: Array,
    radius: Array,
    alive: Array,
    gather: Callable[[Array], Array] | None = None,
    ids: Array | None = None,
    scene: Scene | None = None,
    field: Array | None = None,
    due: Array | None = None,
    previous: tuple[Array, Array] | None = None,
    anticipate: bool = False,
    dt: Array | float = 1 / 30,
    params: AvoidanceParams | None = None,
) -> tuple[Array, Array, Array]:
    """Velocity ``(vx, vz)`` (m/s) of each agent walking to ``(tx, tz)``, and the grid overflow.

    Agents not alive get velocity 0 and are nobody's neighbour. Without ``gather`` the arrays
    are the whole crowd; with it they are one block, ``gather`` maps a block's ``(n, c)`` array
    to the whole crowd's ``(N, c)`` and ``ids`` are the block's rows in it. With a ``scene``
    and each agent's ``field`` the desired direction runs down that field until the agent is
    inside its target (then straight at ``(tx, tz)``), and the scene's walls repel.

    ``due`` (simulation level of detail): the rows whose velocity is computed this step, a
    fixed-size index array (``n`` pads it); the others keep their ``previous`` velocity
    ``(vx, vz)``. Every agent is still everyone's neighbour at its current position. An agent
    computed here walks its velocity until its next update, ``dt`` s (one per agent), so its
    speed is capped to close at most half its gap to any neighbour in that time
    (:func:`~jcrowd.crowd.avoidance.approach_cap`).

    ``anticipate``: agents predict their neighbours' paths from the ``previous`` velocities
    (which the gather then also carries: 24 bytes per agent instead of 16) and relax their
    direction over the reaction time, by the ``dt`` s since their last update (a scalar, or
    one per agent: far agents updating every k steps relax by k steps at a time;
    :mod:`jcrowd.crowd.avoidance`).

    ``params``: the avoidance model's parameters (default: its defaults).
    """
    n = x.shape[0]
    px, pz = (jnp.zeros(n, x.dtype), jnp.zeros(n, x.dtype)) if previous is None else previous
    columns = [x, z, radius, alive.astype(x.dtype)] + ([px, pz] if anticipate else [])
    mine = jnp.stack(columns, axis=1)
    every = mine if gather is None else gather(mine)
    pos, rad, live = every[:, :2], every[:, 2], every[:, 3] > 0.5
    rows = jnp.arange(n, dtype=jnp.int32) if ids is None else ids
    cells = cell_list(grid, pos, live)
    motion = None
    if previous is not None:  # over the reaction time, from the last velocities
        elapsed = jnp.broadcast_to(jnp.asarray(dt, x.dtype), (n,))
        crowd_v = every[:, 4:6] if anticipate else None
        motion = Motion(jnp.stack([px, pz], axis=1), crowd_v, elapsed)
    horizon = None
    if due is not None:
        sel = jnp.where(due < n, due, 0)
        in_sel = alive[sel] & (due < n)
        x, z, tx, tz, speed, radius, rows = (a[sel] for a in (x, z, tx, tz, speed, radius, rows))
        field = None if field is None else field[sel]
        horizon = jnp.broadcast_to(jnp.asarray(dt, x.dtype), (n,))[sel]
        if motion is not None:
            motion = Motion(motion.own[sel], motion.crowd, motion.dt[sel])
    else:
        in_sel = alive
    dx, dz = tx - x, tz - z
    norm = jnp.sqrt(dx * dx + dz * dz)
    desired = jnp.stack([dx, dz], axis=1) / jnp.maximum(norm, 1e-6)[:, None]
    desired = jnp.where((norm > 1e-6)[:, None], desired, 0.0)
    if scene is not None and field is not None:
        here_xz = jnp.stack([x, z], axis=1)
        inside = field_values(scene.nav, field, x, z) <= 0.0
        down = desired_directions(scene.nav, field, here_xz)
        desired = jnp.where(inside[:, None], desired, down)
    here = jnp.stack([x, z], axis=1)
    if scene is None:
        walls, wall_ids = jnp.zeros((0, 2, 2), x.dtype), jnp.zeros((x.shape[0], 1), jnp.int32)
    else:
        walls, wall_ids = scene.walls, scene.cell_walls[cell_index(grid, here)]
    velocity = avoid_in_grid(
        AvoidanceParams() if params is None else params,
        grid,
        cells,
        here,
        desired,
        speed,
        radius,
        in_sel,
        (pos, rad),
        rows,
        walls,
        wall_ids,
        motion,
        horizon,
    )
    vx, vz = velocity[:, 0], velocity[:, 1]
    if due is not None:
        vx = jnp.where(alive, px.at[due].set(vx, mode="drop"), 0.0)
        vz = jnp.where(alive, pz.at[due].set(vz, mode="drop"), 0.0)
    return vx, vz, cells.overflow


def due_rows(
    near: Bool[Array, " N"], clock: Float[Array, " N"], dt: Array, every: int, size: int
) -> Int[Array, " size"]:
    """The rows whose avoidance runs this step when far agents update every ``every`` steps:
    every ``near`` agent, and the others in turn — row ``i`` when ``(tick + i) mod every = 0``
    with ``tick = round(clock / dt)`` (each step a different ``1 / every`` of them). Returns
    ``size`` row ids, padded with ``N``; ``size`` must hold the near agents plus
    ``⌈N / every⌉``."""
    n = near.shape[0]
    tick = jnp.round(clock / dt).astype(jnp.int32)
    turn = jnp.remainder(tick + jnp.arange(n, dtype=jnp.int32), every) == 0
    (rows,) = jnp.nonzero(near | turn, size=size, fill_value=n)
    return rows.astype(jnp.int32)


def turn_towards(heading: Array, vx: Array, vz: Array, dt: Array, min_speed: float = 0.05) -> Array:
    """The heading turned towards the velocity's direction by at most ``TURN_RATE·dt`` times
    ``clip(speed / TURN_FULL_SPEED, TURN_SLOW_SHARE, 1)`` (unchanged while the agent is slower
    than ``min_speed`` m/s).

    A slow walker turns slowly: in a dense queue the simulated velocity's direction swings from
    step to step as neighbours push, and a body chasing it at the full rate swings its planted
    foot round (measured on the entrance run: the heading turned more than 2° in 80 % of the
    planted-foot frames, most of them at 0.1–0.5 m/s); people shuffling in a queue sidestep
    rather than turn.
    """
    want = jnp.arctan2(vx, vz)  # heading θ faces (sin θ, cos θ)
    diff = jnp.remainder(want - heading + jnp.pi, 2 * jnp.pi) - jnp.pi
    speed = jnp.sqrt(vx * vx + vz * vz)
    limit = TURN_RATE * dt * jnp.clip(speed / TURN_FULL_SPEED, TURN_SLOW_SHARE, 1.0)
    turn = jnp.clip(diff, -limit, limit)
    moving = vx * vx + vz * vz > min_speed * min_speed
    return jnp.where(moving, heading + turn, heading)


def aim_point(
    x: Array, z: Array, vx: Array, vz: Array, heading: Array, ahead_s: float
) -> Float[Array, "N 2"]:
    """Where an agent is heading ``ahead_s`` seconds from now at its velocity: the target its
    next gait cycle aims at. A standing agent aims straight ahead by a hand's breadth (its
    cycle then walks as slowly as the model allows)."""
    s, c = sincos(heading)
    px = jnp.where(vx * vx + vz * vz > 1e-4, x + vx * ahead_s, x + 0.1 * s)
    pz = jnp.where(vx * vx + vz * vz > 1e-4, z + vz * ahead_s, z + 0.1 * c)
    return jnp.stack([px, pz], axis=1)
