"""A scenario's layout as a :class:`~jcrowd.pedestrians.world.World`: fields per waypoint, walls.

With obstacles, walls or a walkable area (:mod:`jcrowd.scenario.layout`) an agent walks down a
distance field (:mod:`jcrowd.pedestrians.navigation`) to its waypoint's *target*, and the
collision-free speed model keeps it off the walls (:mod:`jcrowd.pedestrians.avoidance`, Eq. 4's
wall term). :func:`build_scene` runs once, on the host, when a scenario is prepared:

- Targets. A path waypoint's target is the disc of radius ``reach`` (the distance at which the
  step counts a waypoint as reached, :attr:`~jcrowd.crowd.state.StepConfig.reach`) round the
  group's waypoint, cut to the free space and to the piece of it that holds the waypoint (a
  wall crossing the disc leaves its far side out). A goal's target is the goal region cut to
  the free space. One field per group and waypoint; agents' own waypoints (offset sideways by
  up to ``LATERAL_JITTER_M`` from the group's) share it.
- Inside its target (field ≤ 0) an agent heads straight at its own waypoint; outside, down the
  field. A waypoint counts as reached on entering its target (a goal region is thus an exit),
  so a waypoint behind a thin wall within ``reach`` is not reached through the wall.
- Walls: the free space's boundary segments; per neighbour-grid cell the segments within
  :data:`~jcrowd.pedestrians.world.WALL_REACH_M` of it.

Memory: the fields are ``targets × cells × 4`` bytes over the free space's bounding box at
:data:`NAV_CELL_M` cells (6 targets over 100 m × 100 m: 6 MB). A layout whose fields would
exceed :data:`MAX_FIELD_BYTES` is refused. A scenario without a layout builds no fields: its
agents walk straight at their waypoints (:func:`~jcrowd.pedestrians.world.open_world`).
"""

from __future__ import annotations

from typing import cast

import jax.numpy as jnp
import numpy as np
import shapely
from jaxtyping import Int

from jcrowd.errors import JcrowdError, ScenarioError
from jcrowd.pedestrians.navigation import Navigation, distance_field, field_grid, rasterize
from jcrowd.pedestrians.neighbours import GridSpec
from jcrowd.pedestrians.world import World, wall_segments, walls_near_cells
from jcrowd.scenario.geometry import Region
from jcrowd.scenario.layout import free_space, region_shape
from jcrowd.scenario.schema import Scenario
from jcrowd.scenario.spawning import Spawn

__all__ = [
    "CLEARANCE_M",
    "MAX_FIELD_BYTES",
    "NAV_CELL_M",
    "build_scene",
    "field_ids",
    "scene_bytes",
]

NAV_CELL_M = 0.2
"""Navigation grid cell (m): under the 0.25 m the door widths of the shared experiments (0.5 m
and up) need to be at least two cells wide."""

MAX_FIELD_BYTES = 2 * 1024**3
"""Largest navigation fields (bytes) a scenario may ask for."""

CLEARANCE_M = 0.5
"""Paths keep this far off walls where there is room (:func:`distance_field`)."""


def _piece_holding(area: shapely.Geometry, point: shapely.Point) -> shapely.Geometry:
    """The polygon of ``area`` that covers ``point`` (the nearest one if none does)."""
    pieces = [g for g in getattr(area, "geoms", [area]) if g.area > 0]
    if not pieces:
        return area
    return min(pieces, key=lambda g: g.distance(point))


def _targets(scenario: Scenario, space: shapely.Geometry, reach: float) -> list[list[tuple]]:
    """Per group, per waypoint: ``(key, target geometry)``."""
    out = []
    for i, g in enumerate(scenario.groups):
        if g.path is None:
            goal = region_shape(cast(Region, g.goal)).intersection(space)
            out.append([(f"groups[{i}].goal", goal)])
            continue
        row = []
        for k, w in enumerate(g.path.waypoints):
            point = shapely.Point(*w)
            disc = point.buffer(reach, quad_segs=16).intersection(space)
            row.append((f"groups[{i}].path.waypoints[{k}]", _piece_holding(disc, point)))
        out.append(row)
    return out


def scene_bytes(scenario: Scenario) -> int:
    """Bytes the scenario's navigation fields take (0 without a layout)."""
    if scenario.layout.empty:
        return 0
    space = free_space(scenario.ground, scenario.layout)
    x0, z0, x1, z1 = space.bounds
    cells = field_grid((x0, z0), (x1, z1), NAV_CELL_M).shape
    targets = sum(1 if g.path is None else len(g.path.waypoints) for g in scenario.groups)
    return targets * cells[0] * cells[1] * 4


def field_ids(scenario: Scenario, sp: Spawn) -> Int[np.ndarray, "N K"]:
    """Each agent's field per waypoint: fields are numbered group by group, one per goal or path
    waypoint (as :func:`build_scene` builds them); rows padded with the last waypoint's."""
    sizes = [1 if g.path is None else len(g.path.waypoints) for g in scenario.groups]
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    k = sp.waypoints.shape[1]
    step = np.minimum(np.arange(k)[None, :], np.maximum(sp.num_waypoints, 1)[:, None] - 1)
    return (first[sp.group][:, None] + step).astype(np.int32)


def build_scene(
    scenario: Scenario, sp: Spawn, grid: GridSpec, reach: float
) -> tuple[World, Int[np.ndarray, "N K"]]:
    """The layout as a :class:`~jcrowd.pedestrians.world.World` over the step's neighbour
    ``grid``, and each agent's field per waypoint ``(N, K)`` (padded like the spawn's
    waypoints, with the last one).

    Raises:
        ScenarioError: fields larger than :data:`MAX_FIELD_BYTES`, or a target the navigation
            grid cannot reach (named by its key path).
    """
    size = scene_bytes(scenario)
    if size > MAX_FIELD_BYTES:
        raise ScenarioError(
            f"{scenario.source}: obstacles/walls/walkable: expected navigation fields of at most "
            f"{MAX_FIELD_BYTES / 1024**3:.0f} GiB (targets × cells × 4 bytes at "
            f"{NAV_CELL_M} m cells), found {size / 1024**3:.1f} GiB; use fewer waypoints or a "
            "smaller walkable area"
        )
    space = free_space(scenario.ground, scenario.layout)
    x0, z0, x1, z1 = space.bounds
    fg = field_grid((x0, z0), (x1, z1), NAV_CELL_M)
    free = rasterize(fg, space)
    fields: list[np.ndarray] = []
    for row in _targets(scenario, space, reach):
        for key, target in row:
            try:
                goal = rasterize(fg, target)
                fields.append(distance_field(fg, free, goal, clearance=CLEARANCE_M))
            except JcrowdError as err:
                raise ScenarioError(f"{scenario.source}: {key}: {err}") from None
    ids = field_ids(scenario, sp)
    walls = wall_segments(space)
    world = World(
        Navigation(jnp.asarray(np.stack(fields)), fg),
        jnp.asarray(walls),
        jnp.asarray(walls_near_cells(grid, walls)),
        grid,
    )
    return world, ids
