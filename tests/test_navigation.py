"""Navigation fields (jcrowd.pedestrians.navigation) against exact shortest paths.

Oracle: the exact geodesic distance around polygonal obstacles is the shortest path in the
visibility graph of the target and the obstacles' corners (a path bends only at corners); it is
computed here with Dijkstra (heapq) and shapely's line-of-sight tests, independently of the grid
and of fast marching.
"""

from __future__ import annotations

import heapq

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians import (
    UNREACHABLE,
    Navigation,
    desired_directions,
    distance_field,
    field_grid,
    field_values,
    rasterize,
)


def _geodesic(points, target, obstacles, room):
    """Exact shortest distance from each point to ``target`` around ``obstacles`` (polygons),
    inside the rectangle ``room`` = (x0, z0, x1, z1)."""
    frame = shapely.box(-100, -100, 100, 100).difference(shapely.box(*room))
    blocked = shapely.unary_union([*obstacles, frame])
    # Corners pushed out by a hair so a path along an edge is not "inside" the obstacle.
    corners = [
        np.asarray(c) + 1e-6 * np.sign(np.asarray(c) - np.asarray(o.centroid.coords[0]))
        for o in obstacles
        for c in list(o.exterior.coords)[:-1]
    ]
    nodes = [np.asarray(target, float), *corners]

    def visible(a, b):
        return not shapely.LineString([a, b]).crosses(blocked) and not shapely.LineString(
            [a, b]
        ).within(blocked)

    dist = {0: 0.0}
    heap = [(0.0, 0)]
    done = set()
    while heap:
        d, i = heapq.heappop(heap)
        if i in done:
            continue
        done.add(i)
        for j in range(len(nodes)):
            if j not in done and visible(nodes[i], nodes[j]):
                nd = d + float(np.linalg.norm(nodes[i] - nodes[j]))
                if nd < dist.get(j, np.inf):
                    dist[j] = nd
                    heapq.heappush(heap, (nd, j))
    out = []
    for p in points:
        best = np.inf
        for i, node in enumerate(nodes):
            if i in dist and visible(p, node):
                best = min(best, dist[i] + float(np.linalg.norm(p - node)))
        out.append(best)
    return np.array(out)


def _nav(lo, hi, target_point, obstacles, cell=0.25, target_radius=0.3):
    grid = field_grid(lo, hi, cell)
    area = shapely.box(*lo, *hi)
    walkable = rasterize(grid, area.difference(shapely.unary_union(obstacles)))
    target = rasterize(grid, shapely.Point(target_point).buffer(target_radius))
    return grid, walkable, distance_field(grid, walkable, target)


def test_open_ground_is_euclidean_within_one_cell():
    grid, _, field = _nav((0.0, 0.0), (20.0, 12.0), (5.0, 6.0), [])
    x, z = grid.centres()
    exact = np.hypot(x - 5.0, z - 6.0) - 0.3  # distance to the target disc
    inside = (x > 0) & (x < 20) & (z > 0) & (z < 12)
    err = np.abs(field - exact)[inside]
    assert err.max() < grid.cell, err.max()  # the bar: within one cell


@pytest.mark.parametrize("offset", [0.0, 0.11])
@pytest.mark.parametrize("cell", [0.25, 0.2])
def test_around_a_wall_with_a_door_equals_the_visibility_graph(cell, offset):
    """A 0.5 m thick wall across the room with a 1.2 m door, shifted by ``offset`` against the
    grid; 40 points behind it."""
    lo, hi, target = (0.0, 0.0), (16.0, 10.0), (8.0, 8.5)
    z0, x0 = 4.75 + offset, 11.0 + offset
    wall = [shapely.box(0.0, z0, x0, z0 + 0.5), shapely.box(x0 + 1.2, z0, 16.0, z0 + 0.5)]
    grid, _, field = _nav(lo, hi, target, wall, cell)
    rng = np.random.default_rng(0)
    pts = rng.uniform((0.5, 0.5), (15.5, 4.0), (40, 2))  # all behind the wall
    exact = _geodesic(pts, target, wall, (*lo, *hi)) - 0.3
    nav = Navigation(jnp.asarray(field)[None], grid)
    at = (jnp.zeros(len(pts), jnp.int32), jnp.asarray(pts[:, 0]), jnp.asarray(pts[:, 1]))
    err = np.asarray(field_values(nav, *at)) - exact
    # Never shorter than the exact path by more than 0.3 cell (the target disc's raster), and
    # longer by at most 2.5 cells: the raster moves each wall face by up to half a cell and
    # fast marching's one-sided update next to an obstacle overestimates a path that grazes a
    # wall at a shallow angle (measured up to 2.3 cells at 0.2 m with this wall 0.11 m off the
    # grid; 1.2 cells at 0.25 m aligned). Paths in the open are within one cell (test above).
    assert err.min() > -0.3 * cell and err.max() < 2.5 * cell, (err.min(), err.max())
    assert (exact - np.hypot(*(pts - target).T) > 1.0).mean() > 0.5  # premise: real detours


def test_directions_point_along_the_shortest_path():
    """In the open, straight at the target; behind the wall, towards the door."""
    lo, hi, target = (0.0, 0.0), (16.0, 10.0), (8.0, 8.5)
    wall = [shapely.box(0.0, 4.75, 11.0, 5.25), shapely.box(12.2, 4.75, 16.0, 5.25)]
    grid, _, field = _nav(lo, hi, target, wall)
    nav = Navigation(jnp.asarray(field)[None], grid)
    pts = np.array([[3.0, 8.0], [14.0, 9.0], [2.0, 2.0], [9.0, 1.0]])
    e = np.asarray(desired_directions(nav, jnp.zeros(4, jnp.int32), jnp.asarray(pts)))
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-5)
    # First two see the target: the direction is the unit vector to it, within 5°.
    to_target = (np.array(target) - pts[:2]) / np.linalg.norm(np.array(target) - pts[:2], axis=1)[
        :, None
    ]
    assert (np.sum(e[:2] * to_target, axis=1) > np.cos(np.radians(5))).all()
    # Behind the wall: towards the door's near corner (11.0, 4.75), within 10°.
    corner = np.array([11.0, 4.75])
    to_door = (corner - pts[2:]) / np.linalg.norm(corner - pts[2:], axis=1)[:, None]
    assert (np.sum(e[2:] * to_door, axis=1) > np.cos(np.radians(10))).all()


def test_enclosed_cells_are_unreachable_and_obstacles_continue_the_field():
    lo, hi = (0.0, 0.0), (10.0, 10.0)
    ring = shapely.box(5.0, 5.0, 9.0, 9.0).difference(shapely.box(5.5, 5.5, 8.5, 8.5))
    grid, walkable, field = _nav(lo, hi, (2.0, 2.0), [ring])
    x, z = grid.centres()
    inner = (x > 5.6) & (x < 8.4) & (z > 5.6) & (z < 8.4)
    assert (field[inner] == UNREACHABLE).all()
    # The first obstacle cells next to walkable ones: finite, above their walkable neighbours.
    edge = ~walkable & (x > 5.0) & (x < 5.3) & (z > 6.0) & (z < 8.0)
    assert edge.any() and (field[edge] < UNREACHABLE).all()
    assert (field[edge] > field[np.roll(edge, -1, axis=0)]).all()


def test_a_target_in_an_obstacle_is_an_error():
    grid = field_grid((0.0, 0.0), (4.0, 4.0), 0.25)
    walkable = np.zeros(grid.shape, bool)
    with pytest.raises(JcrowdError, match="covers no walkable cell"):
        distance_field(grid, walkable, np.ones(grid.shape, bool))
    with pytest.raises(JcrowdError, match="cell size"):
        field_grid((0.0, 0.0), (4.0, 4.0), 0.5)


def test_jit_equals_eager_and_batched_equals_one_by_one():
    grid, _, field = _nav((0.0, 0.0), (10.0, 10.0), (5.0, 5.0), [shapely.box(6, 2, 7, 8)])
    fields = np.stack([field, field[::-1]])
    nav = Navigation(jnp.asarray(fields), grid)
    rng = np.random.default_rng(1)
    pts = jnp.asarray(rng.uniform(0.5, 9.5, (30, 2)), jnp.float32)
    which = jnp.asarray(rng.integers(0, 2, 30), jnp.int32)
    eager = desired_directions(nav, which, pts)
    # Unit vectors from differences of ~10 m float32 values over half a cell: a few 1e-6.
    np.testing.assert_allclose(
        np.asarray(jax.jit(desired_directions)(nav, which, pts)), np.asarray(eager), atol=1e-5
    )
    for i in range(0, 30, 7):
        one = desired_directions(nav, which[i : i + 1], pts[i : i + 1])
        np.testing.assert_allclose(np.asarray(one[0]), np.asarray(eager[i]), atol=1e-5)


def test_clearance_keeps_paths_off_walls_and_through_narrow_gaps():
    """With clearance the field is a travel time that slows near walls: in the open it is the
    distance; the way through a 0.5 m gap stays open; the direction past a corner bends away
    from it where the distance field's direction grazes it."""
    lo, hi, target = (0.0, 0.0), (10.0, 10.0), (5.0, 9.0)
    wall = [shapely.box(0.0, 4.8, 4.75, 5.2), shapely.box(5.25, 4.8, 10.0, 5.2)]  # 0.5 m gap
    grid = field_grid(lo, hi, 0.2)
    area = shapely.box(*lo, *hi).difference(shapely.unary_union(wall))
    walkable, goal = rasterize(grid, area), rasterize(grid, shapely.Point(target).buffer(0.3))
    plain = distance_field(grid, walkable, goal)
    slow = distance_field(grid, walkable, goal, clearance=0.5)
    x, z = grid.centres()
    below = walkable & (z < 4.0)
    assert (slow[below] < UNREACHABLE).all()  # the gap is still passable
    assert (slow[below] > plain[below]).all()  # and costs more than its length
    # Far from every wall (here: above the wall, more than 0.5 m from it and the border), the
    # travel time grows exactly like the distance (same gradient): compare differences.
    open_ = walkable & (z > 6.0) & (z < 9.3) & (x > 0.8) & (x < 9.2)
    ref = open_ & (np.abs(x - 5.0) < 0.11) & (np.abs(z - 7.1) < 0.11)
    d_plain = plain[open_] - plain[ref][0]
    d_slow = slow[open_] - slow[ref][0]
    assert np.abs(d_plain - d_slow).max() < 0.3  # m over up to 5 m: slow cells near the border
    # Beside the wall's underside, heading for the gap: the distance field's direction grazes
    # the wall and aims at the gap's corner; with clearance it first moves off the wall (−z)
    # and, next to the gap, aims at its middle (x = 5) rather than its corner (4.75, 4.8).
    navs = [Navigation(jnp.asarray(f)[None], grid) for f in (plain, slow)]
    at = jnp.asarray([[3.0, 4.55], [4.6, 4.6]], jnp.float32)
    e_plain, e_slow = (np.asarray(desired_directions(n, jnp.zeros(2, jnp.int32), at)) for n in navs)
    assert e_plain[0, 1] > 0.0 > e_slow[0, 1] + 0.5  # measured 0.19 vs −0.86
    assert e_slow[1, 0] > e_plain[1, 0] + 0.1  # measured 0.99 vs 0.77
