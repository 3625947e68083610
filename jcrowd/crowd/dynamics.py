"""Pedestrian dynamics on the ground plane: navigation, neighbours, avoidance, exits, one step.

The simulation is the authority on where people are (DESIGN §5b). One step, for every agent at
once and with static shapes: the desired direction down its target's distance field
(:mod:`jcrowd.crowd.navigation`), its candidate neighbours from the cell grid
(:mod:`jcrowd.crowd.neighbours`) and its candidate walls from a per-cell wall list built on the
host, the collision-free speed model's velocity (:mod:`jcrowd.crowd.avoidance`), an explicit
Euler step ``x ← x + v·dt`` (the model is first order), and removal of agents that reached their
target (its field is at most ``exit_depth`` there: inside the target region).

:func:`build_world` turns geometry — a walkable polygon, obstacles and targets as shapely
geometries — into the arrays the step reads (:class:`World`); it runs once, on the host.
Walls are the boundary segments of the walkable area (holes included).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import shapely
from jaxtyping import Array, Bool, Float, Int

from jcrowd.crowd.avoidance import AvoidanceParams, Motion
from jcrowd.crowd.blocking import OneStepAtATime
from jcrowd.crowd.grid_avoidance import avoid_in_grid
from jcrowd.crowd.navigation import (
    Navigation,
    desired_directions,
    distance_field,
    field_grid,
    field_values,
    rasterize,
)
from jcrowd.crowd.neighbours import GridSpec, cell_index, cell_list, grid_spec
from jcrowd.errors import JcrowdError

__all__ = [
    "Pedestrians",
    "StepInfo",
    "World",
    "build_world",
    "pedestrian_step",
    "split_pedestrian_step",
    "wall_segments",
    "walls_near_cells",
]

WALL_REACH_M = 0.8
"""Walls farther than this from an agent are not candidates: a wall at ``r + 0.4`` m repels by
``a_w·e^{−20}`` with the default ``D_w = 0.02`` m, nothing against a desire of 1."""


class World(eqx.Module):
    """What the step reads of the scene (arrays) and the static shapes it was built with.

    Attributes:
        nav: the distance fields, one per target.
        walls: ``(S, 2, 2)`` wall segments ``[[x, z], [x, z]]``.
        cell_walls: ``(cells, W)`` segment ids near each neighbour-grid cell (``S``: none).
        grid: the neighbour grid's static shape.
        exit_depth: an agent whose target field is at most this (m) has arrived and leaves.
    """

    nav: Navigation
    walls: Float[Array, "S 2 2"]
    cell_walls: Int[Array, "C W"]
    grid: GridSpec = eqx.field(static=True)
    exit_depth: float = eqx.field(static=True, default=0.0)


class Pedestrians(eqx.Module):
    """Agents of the dynamics (leading axis: agents; a fixed-size pool, ``alive`` marks who is
    in the scene).

    Attributes:
        position: ``(N, 2)`` ``[x, z]`` m.
        target: ``(N,)`` index of the distance field the agent walks down.
        speed: ``(N,)`` free walking speed ``v0`` (m/s).
        radius: ``(N,)`` m.
        alive: ``(N,)``.
        velocity: ``(N, 2)`` the last step's velocity (m/s); with it the velocity (plain)
            or the direction (anticipating) relaxes over the reaction time and, with
            ``anticipate``, agents anticipate (:mod:`jcrowd.crowd.reaction`); without it
            (``None``) the collision-free speed model of the paper steps them, without a
            reaction time.
        anticipate: with ``velocity``, the anticipation model (else the plain one).
    """

    position: Float[Array, "N 2"]
    target: Int[Array, " N"]
    speed: Float[Array, " N"]
    radius: Float[Array, " N"]
    alive: Bool[Array, " N"]
    velocity: Float[Array, "N 2"] | None = None
    anticipate: bool = eqx.field(static=True, default=True)


class StepInfo(eqx.Module):
    """What one step reports: ``velocity (N, 2)`` (0 for agents not alive), ``arrived (N,)``
    (left the scene this step), ``overflow`` (agents the neighbour grid could not store)."""

    velocity: Float[Array, "N 2"]
    arrived: Bool[Array, " N"]
    overflow: Int[Array, ""]


def pedestrian_step(
    params: AvoidanceParams,
    world: World,
    peds: Pedestrians,
    dt: Float[Array, ""] | float,
    gather: Callable[[Array], Array] | None = None,
    ids: Array | None = None,
) -> tuple[Pedestrians, StepInfo]:
    """Advance every alive agent by ``dt`` seconds (navigation → neighbours → avoidance).

    ``gather`` and ``ids``: on one device of several (:func:`split_pedestrian_step`), how the
    block sees the whole crowd: ``gather`` maps the block's ``(n, c)`` rows to the crowd's
    ``(N, c)``, ``ids`` are the block's rows in it.
    """
    desired = desired_directions(world.nav, peds.target, peds.position)
    columns = [peds.position, peds.radius[:, None], peds.alive[:, None].astype(peds.radius.dtype)]
    anticipating = peds.velocity is not None and peds.anticipate
    if peds.velocity is not None and peds.anticipate:
        columns.append(peds.velocity)
    mine = jnp.concatenate(columns, axis=1)
    every = mine if gather is None else gather(mine)
    pos, rad, live = every[:, :2], every[:, 2], every[:, 3] > 0.5
    motion = None
    if peds.velocity is not None:
        crowd_v = every[:, 4:6] if anticipating else None
        motion = Motion(peds.velocity, crowd_v, jnp.asarray(dt))
    rows = jnp.arange(peds.position.shape[0], dtype=jnp.int32) if ids is None else ids
    cells = cell_list(world.grid, pos, live)
    velocity = avoid_in_grid(
        params,
        world.grid,
        cells,
        peds.position,
        desired,
        peds.speed,
        peds.radius,
        peds.alive,
        (pos, rad),
        rows,
        world.walls,
        world.cell_walls[cell_index(world.grid, peds.position)],
        motion,
    )
    position = peds.position + velocity * dt
    depth = field_values(world.nav, peds.target, position[:, 0], position[:, 1])
    arrived = peds.alive & (depth <= world.exit_depth)
    info = StepInfo(velocity, arrived, cells.overflow)
    moved = eqx.tree_at(lambda p: (p.position, p.alive), peds, (position, peds.alive & ~arrived))
    if peds.velocity is not None:
        moved = eqx.tree_at(lambda p: p.velocity, moved, velocity)
    return moved, info


def split_pedestrian_step(devices: Sequence[Any] | None = None) -> Any:
    """:func:`pedestrian_step` with the agents split over ``devices`` (default: all), in
    contiguous blocks (the agent count must divide by their number).

    ``(params, world, peds, dt) → (peds, info)`` as the plain step, compiled. Each device steps
    its own block; neighbours live on every device, so each all-gathers the crowd's positions,
    radii and alive flags (16 bytes per agent; 24 with velocities, when agents anticipate) and
    fills the whole grid. The call returns once
    every device is done (:class:`~jcrowd.crowd.blocking.OneStepAtATime`).
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


def wall_segments(walkable: shapely.Geometry) -> np.ndarray:
    """The boundary segments ``(S, 2, 2)`` of a walkable area (outer rings and holes)."""
    segs = []
    for poly in getattr(walkable, "geoms", [walkable]):
        for ring in [poly.exterior, *poly.interiors]:
            xy = np.asarray(ring.coords)
            segs.append(np.stack([xy[:-1], xy[1:]], axis=1))
    return np.concatenate(segs).astype(np.float32) if segs else np.zeros((0, 2, 2), np.float32)


def walls_near_cells(grid: GridSpec, walls: np.ndarray) -> np.ndarray:
    """Per cell, the ids of the segments within ``WALL_REACH_M`` of the cell (host, STRtree)."""
    s = len(walls)
    lines = shapely.linestrings(walls) if s else np.array([], object)
    tree = shapely.STRtree(lines)
    x0 = grid.origin[0] + np.arange(grid.shape[0]) * grid.cell
    z0 = grid.origin[1] + np.arange(grid.shape[1]) * grid.cell
    gx, gz = np.meshgrid(x0, z0, indexing="ij")
    boxes = shapely.box(
        gx.ravel() - WALL_REACH_M,
        gz.ravel() - WALL_REACH_M,
        gx.ravel() + grid.cell + WALL_REACH_M,
        gz.ravel() + grid.cell + WALL_REACH_M,
    )
    cell_idx, seg_idx = tree.query(boxes, predicate="intersects") if s else (np.zeros(0, int),) * 2
    counts = np.bincount(cell_idx, minlength=grid.num_cells)
    width = max(1, int(counts.max()) if len(counts) else 1)
    out = np.full((grid.num_cells, width), s, np.int32)
    order = np.argsort(cell_idx, kind="stable")
    cell_idx, seg_idx = cell_idx[order], seg_idx[order]
    start = np.searchsorted(cell_idx, cell_idx, side="left")
    out[cell_idx, np.arange(len(cell_idx)) - start] = seg_idx
    return out


def build_world(
    walkable: shapely.Geometry,
    targets: Sequence[shapely.Geometry],
    *,
    nav_cell: float = 0.2,
    grid_cell: float = 2.0,
    max_density: float = 8.0,
    clearance: float = 0.5,
) -> World:
    """The arrays of a scene: one distance field per target, walls, the neighbour grid.

    Args:
        walkable: where agents may be (a polygon or multipolygon, obstacles as holes).
        targets: regions agents walk to (each must overlap the walkable area).
        nav_cell: navigation grid cell (m, ≤ 0.25).
        grid_cell: neighbour grid cell (m): at least the avoidance's reach.
        max_density: agents per m² the neighbour grid's cells are sized for (with headroom).
        clearance: how far paths keep off walls where there is room (m; see
            :func:`~jcrowd.crowd.navigation.distance_field`).

    Raises:
        JcrowdError: an empty walkable area or a target that covers no walkable cell (named by
            its index).
    """
    if walkable.is_empty or not walkable.area > 0:
        raise JcrowdError("world: expected a walkable area, found none")
    lo, hi = walkable.bounds[:2], walkable.bounds[2:]
    fg = field_grid(lo, hi, nav_cell)
    free = rasterize(fg, walkable)
    fields = []
    for i, t in enumerate(targets):
        try:
            fields.append(distance_field(fg, free, rasterize(fg, t), clearance=clearance))
        except JcrowdError as err:
            raise JcrowdError(f"world: target {i}: {err}") from None
    walls = wall_segments(walkable)
    margin = (grid_cell, grid_cell)
    spec = grid_spec(
        (lo[0] - margin[0], lo[1] - margin[1]),
        (hi[0] + margin[0], hi[1] + margin[1]),
        grid_cell,
        max_density=max_density,
    )
    nav = Navigation(jnp.asarray(np.stack(fields)), fg)
    return World(nav, jnp.asarray(walls), jnp.asarray(walls_near_cells(spec, walls)), spec)
