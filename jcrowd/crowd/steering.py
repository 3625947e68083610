"""The crowd step's dynamics stage and the body that follows it (DESIGN §5b).

With :attr:`~jcrowd.crowd.state.StepConfig.avoid` on, the simulation is the authority on
where people are: :func:`walk` calls the pedestrian step (:mod:`jcrowd.pedestrians`) for each
alive agent — towards its current waypoint, down the waypoint's navigation field in a layout,
among its neighbours — and the root moves by ``v·dt``. The body faces the step's heading
(:mod:`jcrowd.pedestrians.heading`: towards the walking direction, the waypoint's when standing
or shuffling, at a bounded turn rate), and the next gait cycle is chosen from the velocity
(:func:`aim_point`), so the clips follow the simulated path.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.crowd.state import CrowdState, StepConfig
from jcrowd.indexing import first_true
from jcrowd.motion.fastmath import sincos
from jcrowd.pedestrians.neighbours import GridSpec
from jcrowd.pedestrians.step import Pedestrians, pedestrian_step
from jcrowd.pedestrians.world import World, open_world

__all__ = [
    "aim_point",
    "current_field",
    "due_rows",
    "walk",
    "waypoint_xz",
]

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


def walk(
    config: StepConfig,
    world: World | None,
    state: CrowdState,
    near: Bool[Array, " N"],
    dt: Array,
    gather: Callable[[Array], Array] | None = None,
    ids: Array | None = None,
) -> tuple[Array, Array, Array, Array]:
    """The crowd step's dynamics stage: each agent's velocity ``(vx, vz)`` this step, its body
    heading after the step and the neighbour grid's overflow, from
    :func:`~jcrowd.pedestrians.step.pedestrian_step` (the heading turns towards the walking
    direction, or the waypoint's when slow: :mod:`jcrowd.pedestrians.heading`).

    The agents walk towards their current waypoint (down its field in a ``world`` with a
    layout, straight at it without one: :func:`~jcrowd.pedestrians.world.open_world`) with
    their last velocities, so the velocity relaxes over the reaction time and, with
    ``config.anticipate``, they anticipate. With ``config.far_every > 1`` only the ``near``
    agents and every ``far_every``-th far one are computed this step (:func:`due_rows`); a far
    agent relaxes by ``far_every`` steps at a time. ``gather``, ``ids``: on one device of
    several, how the block sees the whole crowd.
    """
    grid = cast(GridSpec, config.grid)  # StepConfig.check requires it with avoid
    place = open_world(grid) if world is None else world
    due, elapsed = None, None
    if config.far_every > 1:  # simulation LOD: far agents in turn
        n = state.num_agents
        near_slots = sum(config.capacities[: config.blend_max_level + 1])
        size = min(n, -(-n // config.far_every) + near_slots)
        due = due_rows(near, state.clock, dt, config.far_every, size)
        elapsed = jnp.where(near, dt, dt * config.far_every)  # since the last update
    tx, tz = waypoint_xz(state.waypoints, state.waypoint)
    peds = Pedestrians(
        position=jnp.stack([state.x, state.z], axis=1),
        target=current_field(state),
        speed=state.speed,
        radius=state.radius,
        alive=state.alive,
        velocity=jnp.stack([state.vx, state.vz], axis=1),
        goal=jnp.stack([tx, tz], axis=1),
        anticipate=config.anticipate,
        heading=state.heading,
    )
    params = config.avoidance_params()
    moved, info = pedestrian_step(params, place, peds, dt, gather, ids, due, elapsed)
    heading = cast(Array, moved.heading)
    return info.velocity[:, 0], info.velocity[:, 1], heading, info.overflow


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
    rows = first_true(near | turn, size, n)
    return rows.astype(jnp.int32)


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
