"""The pedestrian step: one explicit step of the 2-D crowd model for every agent at once.

The simulation is the authority on where people are (DESIGN §5b). One step, with static
shapes: each agent's desired direction — down its target's distance field
(:mod:`jcrowd.pedestrians.navigation`), or straight at its own goal point inside its target and
in a world without fields — its candidate neighbours from the cell grid
(:mod:`jcrowd.pedestrians.neighbours`) and its candidate walls from the world's per-cell wall
lists, the collision-free speed model's velocity with the reaction time or anticipation when
the last velocities are given (:mod:`jcrowd.pedestrians.avoidance`,
:mod:`jcrowd.pedestrians.reaction`), the explicit Euler step ``x ← x + v·dt`` (the model is
first order), and removal of agents that reached their target (its field at most
``exit_depth``: inside the target region).

This is the one implementation of the model: the animated crowd step (:mod:`jcrowd.crowd`),
the differentiable rollouts (:mod:`jcrowd.rollouts`) and ``bench/pedestrians.py`` all call
:func:`pedestrian_step`. Two options serve the animated crowd: ``due`` updates only some rows
(simulation level of detail: far agents in turn, the others keep their last velocity) and
``elapsed`` gives each agent the time since its last update. Agents with a heading turn it
every step (:mod:`jcrowd.pedestrians.heading`). Split over devices each device
steps its own block of agents but sees the whole crowd as neighbours (``gather``, ``ids``;
:func:`split_pedestrian_step`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians.blocking import OneStepAtATime
from jcrowd.pedestrians.grid_avoidance import avoid_in_grid
from jcrowd.pedestrians.heading import facing, turn_heading
from jcrowd.pedestrians.navigation import desired_directions, field_values
from jcrowd.pedestrians.neighbours import cell_index, cell_list
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.pedestrians.reaction import Motion
from jcrowd.pedestrians.world import World

__all__ = ["Pedestrians", "StepInfo", "pedestrian_step", "split_pedestrian_step"]


class Pedestrians(eqx.Module):
    """Agents of the pedestrian model (leading axis: agents; a fixed-size pool, ``alive`` marks
    who is in the world).

    Attributes:
        position: ``(N, 2)`` ``[x, z]`` m.
        target: ``(N,)`` index of the distance field the agent walks down.
        speed: ``(N,)`` free walking speed ``v0`` (m/s).
        radius: ``(N,)`` m.
        alive: ``(N,)``.
        velocity: ``(N, 2)`` the last step's velocity (m/s); with it the velocity (plain)
            or the direction (anticipating) relaxes over the reaction time and, with
            ``anticipate``, agents anticipate (:mod:`jcrowd.pedestrians.reaction`); without it
            (``None``) the collision-free speed model of the paper steps them, without a
            reaction time.
        anticipate: with ``velocity``, the anticipation model (else the plain one).
        goal: ``(N, 2)`` a point each agent walks straight at once inside its target, and
            everywhere in a world without fields (``None``: down the fields all the way).
        heading: ``(N,)`` the way each body faces (rad, facing ``(sin θ, cos θ)``; needs
            ``velocity``): it turns towards the walking or, when slow, the desired direction
            at a bounded rate, and with ``back_share`` < 1 people walk mostly along it
            (:mod:`jcrowd.pedestrians.heading`); ``None``: no body.
    """

    position: Float[Array, "N 2"]
    target: Int[Array, " N"]
    speed: Float[Array, " N"]
    radius: Float[Array, " N"]
    alive: Bool[Array, " N"]
    velocity: Float[Array, "N 2"] | None = None
    anticipate: bool = eqx.field(static=True, default=True)
    goal: Float[Array, "N 2"] | None = None
    heading: Float[Array, " N"] | None = None


class StepInfo(eqx.Module):
    """What one step reports: ``velocity (N, 2)`` (0 for agents not alive), ``arrived (N,)``
    (left the world this step), ``overflow`` (agents the neighbour grid could not store)."""

    velocity: Float[Array, "N 2"]
    arrived: Bool[Array, " N"]
    overflow: Int[Array, ""]


def _desired(world: World, position: Array, target: Array, goal: Array | None) -> Array:
    """Unit desired directions ``(n, 2)``: down the target's field; straight at ``goal`` inside
    the target (field ≤ 0) and in a world without fields."""
    if goal is None:
        if world.nav is None:
            raise JcrowdError(
                "pedestrian_step: expected goals (Pedestrians.goal) in a world without "
                "navigation fields, found none"
            )
        return desired_directions(world.nav, target, position)
    dx, dz = goal[:, 0] - position[:, 0], goal[:, 1] - position[:, 1]
    norm = jnp.sqrt(dx * dx + dz * dz)
    straight = jnp.stack([dx, dz], axis=1) / jnp.maximum(norm, 1e-6)[:, None]
    straight = jnp.where((norm > 1e-6)[:, None], straight, 0.0)
    if world.nav is None:
        return straight
    inside = field_values(world.nav, target, position[:, 0], position[:, 1]) <= 0.0
    return jnp.where(inside[:, None], straight, desired_directions(world.nav, target, position))


def _velocity(
    params: AvoidanceParams,
    world: World,
    peds: Pedestrians,
    dt: Array | float,
    gather: Callable[[Array], Array] | None,
    ids: Array | None,
    due: Array | None,
    elapsed: Array | None,
) -> tuple[Array, Array, Array | None]:
    """Every agent's velocity ``(N, 2)`` this step, the neighbour grid's overflow and, with a
    heading, every agent's desired direction ``(N, 2)``."""
    n = peds.position.shape[0]
    anticipating = peds.velocity is not None and peds.anticipate
    alive_f = peds.alive[:, None].astype(peds.radius.dtype)
    columns = [peds.position, peds.radius[:, None], alive_f]
    if peds.velocity is not None and peds.anticipate:
        columns.append(peds.velocity)
    mine = jnp.concatenate(columns, axis=1)
    every = mine if gather is None else gather(mine)
    pos, rad, live = every[:, :2], every[:, 2], every[:, 3] > 0.5
    cells = cell_list(world.grid, pos, live)
    since = jnp.asarray(dt) if elapsed is None else elapsed
    if due is not None:
        since = jnp.broadcast_to(jnp.asarray(since, peds.radius.dtype), (n,))
    motion, everyone = None, None
    if peds.velocity is not None:
        face = None if peds.heading is None else facing(peds.heading)
        motion = Motion(peds.velocity, every[:, 4:6] if anticipating else None, since, face)
    if peds.heading is not None:  # the heading turns every step, towards it when slow
        everyone = _desired(world, peds.position, peds.target, peds.goal)
    rows = jnp.arange(n, dtype=jnp.int32) if ids is None else ids
    position, target, goal = peds.position, peds.target, peds.goal
    speed, radius, moving = peds.speed, peds.radius, peds.alive
    desired = everyone
    horizon = None
    if due is not None:  # only these rows are computed; padding (n) is nobody
        sel = jnp.where(due < n, due, 0)
        moving = peds.alive[sel] & (due < n)
        position, target, speed, radius, rows = (
            a[sel] for a in (position, target, speed, radius, rows)
        )
        goal = None if goal is None else goal[sel]
        desired = None if everyone is None else everyone[sel]
        horizon = since[sel]
        if motion is not None:
            motion = motion.rows(sel)
    if desired is None:
        desired = _desired(world, position, target, goal)
    if world.cell_walls is None:
        wall_ids = jnp.zeros((position.shape[0], 1), jnp.int32)
    else:
        wall_ids = world.cell_walls[cell_index(world.grid, position)]
    velocity = avoid_in_grid(
        params,
        world.grid,
        cells,
        position,
        desired,
        speed,
        radius,
        moving,
        (pos, rad),
        rows,
        world.walls,
        wall_ids,
        motion,
        horizon,
    )
    if due is not None:  # the rows not due keep their last velocity
        last = jnp.zeros_like(peds.position) if peds.velocity is None else peds.velocity
        velocity = jnp.where(peds.alive[:, None], last.at[due].set(velocity, mode="drop"), 0.0)
    return velocity, cells.overflow, everyone


def pedestrian_step(
    params: AvoidanceParams,
    world: World,
    peds: Pedestrians,
    dt: Float[Array, ""] | float,
    gather: Callable[[Array], Array] | None = None,
    ids: Array | None = None,
    due: Int[Array, " D"] | None = None,
    elapsed: Float[Array, "*N"] | None = None,
) -> tuple[Pedestrians, StepInfo]:
    """Advance every alive agent by ``dt`` seconds (navigation → neighbours → avoidance).

    Args:
        params: the model's parameters.
        world: fields, walls and the neighbour grid.
        peds: the agents.
        dt: the step (s).
        gather, ids: on one device of several (:func:`split_pedestrian_step`), how the block
            sees the whole crowd: ``gather`` maps the block's ``(n, c)`` rows to the crowd's
            ``(N, c)``, ``ids`` are the block's rows in it.
        due: the rows whose velocity is computed this step, a fixed-size index array padded
            with ``N``; the others keep their last ``velocity``. Everyone is still everyone's
            neighbour. A computed agent walks its velocity until its next update, ``elapsed``
            s, so its speed is capped to close at most half its gap to any neighbour in that
            time (:func:`~jcrowd.pedestrians.avoidance.approach_cap`).
        elapsed: the time (s) since each agent's last update, over which its velocity or
            direction relaxes (default ``dt``).

    Returns:
        The agents moved (``alive`` false for those that arrived; ``velocity`` updated when
        given) and the step's :class:`StepInfo`.
    """
    if peds.heading is not None and peds.velocity is None:
        raise JcrowdError(
            "pedestrian_step: expected the last velocities (Pedestrians.velocity) with a "
            "heading, found none"
        )
    velocity, overflow, desired = _velocity(params, world, peds, dt, gather, ids, due, elapsed)
    position = peds.position + velocity * dt
    arrived = jnp.zeros_like(peds.alive)
    if world.nav is not None:
        depth = field_values(world.nav, peds.target, position[:, 0], position[:, 1])
        arrived = peds.alive & (depth <= world.exit_depth)
    info = StepInfo(velocity, arrived, overflow)
    moved = eqx.tree_at(lambda p: (p.position, p.alive), peds, (position, peds.alive & ~arrived))
    if peds.velocity is not None:
        moved = eqx.tree_at(lambda p: p.velocity, moved, velocity)
    if peds.heading is not None and desired is not None:
        turned = turn_heading(params, peds.heading, velocity, desired, dt)
        heading = jnp.where(peds.alive, turned, peds.heading)
        moved = eqx.tree_at(lambda p: p.heading, moved, heading)
    return moved, info


def split_pedestrian_step(devices: Sequence[Any] | None = None) -> Any:
    """:func:`pedestrian_step` with the agents split over ``devices`` (default: all), in
    contiguous blocks (the agent count must divide by their number).

    ``(params, world, peds, dt) → (peds, info)`` as the plain step, compiled. Each device steps
    its own block; neighbours live on every device, so each all-gathers the crowd's positions,
    radii and alive flags (16 bytes per agent; 24 with velocities, when agents anticipate) and
    fills the whole grid. The call returns once every device is done
    (:class:`~jcrowd.pedestrians.blocking.OneStepAtATime`).
    """
    import jax
    from jax import shard_map
    from jax.sharding import Mesh
    from jax.sharding import PartitionSpec as P

    devs = list(jax.devices() if devices is None else devices)
    mesh = Mesh(np.array(devs), ("agents",))

    def local(
        params: AvoidanceParams, world: World, peds: Pedestrians, dt: Array
    ) -> tuple[Pedestrians, StepInfo]:
        n_local = peds.position.shape[0]
        rows = jax.lax.axis_index("agents") * n_local + jnp.arange(n_local, dtype=jnp.int32)

        def gather(block: Array) -> Array:
            return jax.lax.all_gather(block, "agents", tiled=True)

        return pedestrian_step(params, world, peds, dt, gather, rows)

    agents, same = P("agents"), P()
    mapped = shard_map(
        local,
        mesh=mesh,
        in_specs=(same, same, agents, same),
        # Every device fills the same grid: its overflow count is already the crowd's.
        out_specs=(agents, StepInfo(agents, agents, same)),  # type: ignore[arg-type]
        check_vma=False,
    )
    return OneStepAtATime(jax.jit(mapped))
