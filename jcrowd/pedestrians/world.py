"""The world the pedestrian step walks in: navigation fields, walls and the neighbour grid.

:class:`World` holds the arrays the step reads of a place — one distance field per target
(:mod:`jcrowd.pedestrians.navigation`), the walls as segments with a per-cell list of the walls
near each neighbour-grid cell (built on the host with an STRtree), and the neighbour grid's
static shape (:mod:`jcrowd.pedestrians.neighbours`). :func:`build_world` makes one from shapely
geometry (a walkable polygon, obstacles as its holes, targets as regions); a scenario's layout
becomes one in :mod:`jcrowd.pedestrians.scene`; :func:`open_world` is a place with no walls and
no fields, where agents walk straight at their goals. Walls are the boundary segments of the
walkable area, holes included. Everything here runs once, on the host.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import shapely
from jaxtyping import Array, Float, Int

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians.navigation import Navigation, distance_field, field_grid, rasterize
from jcrowd.pedestrians.neighbours import GridSpec, grid_spec

__all__ = [
    "WALL_REACH_M",
    "World",
    "build_world",
    "open_world",
    "wall_segments",
    "walls_near_cells",
]

WALL_REACH_M = 0.8
"""Walls farther than this from an agent are not candidates: a wall at ``r + 0.4`` m repels by
``a_w·e^{−20}`` with the default ``D_w = 0.02`` m, nothing against a desire of 1."""


class World(eqx.Module):
    """What the pedestrian step reads of a place (arrays) and the static shapes it was built with.

    Attributes:
        nav: the distance fields, one per target (``None``: no fields; agents walk straight at
            their goals, :class:`~jcrowd.pedestrians.step.Pedestrians`).
        walls: ``(S, 2, 2)`` wall segments ``[[x, z], [x, z]]``.
        cell_walls: ``(cells, W)`` segment ids near each neighbour-grid cell (``S``: none);
            ``None`` with no walls.
        grid: the neighbour grid's static shape.
        exit_depth: an agent whose target field is at most this (m) has arrived and leaves.
    """

    nav: Navigation | None
    walls: Float[Array, "S 2 2"]
    cell_walls: Int[Array, "C W"] | None
    grid: GridSpec = eqx.field(static=True)
    exit_depth: float = eqx.field(static=True, default=0.0)


def open_world(grid: GridSpec) -> World:
    """A place without walls or navigation fields, over ``grid``."""
    return World(None, jnp.zeros((0, 2, 2), jnp.float32), None, grid)


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
    """The arrays of a place: one distance field per target, walls, the neighbour grid.

    Args:
        walkable: where agents may be (a polygon or multipolygon, obstacles as holes).
        targets: regions agents walk to (each must overlap the walkable area).
        nav_cell: navigation grid cell (m, ≤ 0.25).
        grid_cell: neighbour grid cell (m): at least the avoidance's reach.
        max_density: agents per m² the neighbour grid's cells are sized for (with headroom).
        clearance: how far paths keep off walls where there is room (m; see
            :func:`~jcrowd.pedestrians.navigation.distance_field`).

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
