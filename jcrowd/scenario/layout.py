"""Where people can walk: obstacles, walls and an optional walkable area, and their checks.

A scenario's layout (TOML: ``[[obstacles]]``, ``[[walls]]``, ``[walkable]``; keys documented in
``examples/README.md``) takes space away from the ground: an obstacle is a region (rect, circle
or simple polygon: a building, a pillar, a barrier), a wall a polyline with a thickness, and
everything outside ``walkable`` (when given) is obstacle too. :func:`free_space` is what remains,
a shapely geometry — possibly several pieces; agents walk inside it and the crowd dynamics
route around the rest.

:func:`check_layout` checks a scenario's groups against it, naming the key: a spawn region with
no free space, a spawn region too small for its agents at a sane density (above
:data:`MAX_SPAWN_DENSITY`), waypoints or a goal inside an obstacle, and a goal or waypoint that
cannot be reached from the spawn region (they lie in different pieces of the free space).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from jaxtyping import Float

from jcrowd.scenario.check import Problem, Raw, real, require
from jcrowd.scenario.check import points as point_list
from jcrowd.scenario.geometry import Region

__all__ = [
    "MAX_SPAWN_DENSITY",
    "Layout",
    "Wall",
    "blocked_space",
    "check_layout",
    "free_space",
    "region_shape",
]

MAX_SPAWN_DENSITY = 8.0
"""Agents per m² of free spawn area beyond which a group is refused (denser than any measured
crowd's average; the densest measured in the shared data is 9.3 /m² at one instant)."""


def region_shape(region: Region) -> shapely.Geometry:
    """A region as a shapely polygon (a circle as a 64-gon)."""
    if region.kind == "rect":
        lo, hi = region.bounds()
        return shapely.box(lo[0], lo[1], hi[0], hi[1])
    if region.kind == "circle":
        return shapely.Point(*region.center).buffer(region.radius, quad_segs=16)
    return shapely.Polygon(region.points)


@dataclass(frozen=True, eq=False)
class Wall:
    """A wall along a polyline: ``points`` ``(K ≥ 2, 2)`` ``[x, z]`` (m, consecutive points
    distinct), ``thickness`` (m, > 0) centred on the line, with square ends."""

    points: Float[np.ndarray, "K 2"]
    thickness: float = 0.2

    def __post_init__(self) -> None:
        p = point_list(self.points, "points")
        require(len(p) >= 2, "points", "at least 2 points [x, z]", self.points)
        same = np.all(p[1:] == p[:-1], axis=1)
        if same.any():
            k = int(np.argmax(same)) + 1
            require(False, f"points[{k}]", f"a point other than points[{k - 1}]", p[k])
        t = self.thickness
        require(real(t) and t > 0, "thickness", "a thickness > 0 (m)", t)
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "thickness", float(t))

    def shape(self) -> shapely.Geometry:
        line = shapely.LineString(self.points)
        return line.buffer(self.thickness / 2, cap_style="square", join_style="mitre")


@dataclass(frozen=True, eq=False)
class Layout:
    """Obstacles, walls and the walkable area (None: the whole ground) of a scenario."""

    obstacles: tuple[Region, ...] = ()
    walls: tuple[Wall, ...] = ()
    walkable: Region | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "walls", tuple(self.walls))

    @property
    def empty(self) -> bool:
        return not self.obstacles and not self.walls and self.walkable is None


def free_space(ground: Region, layout: Layout) -> shapely.Geometry:
    """The ground (within ``walkable``) minus every obstacle and wall."""
    space = region_shape(ground)
    if layout.walkable is not None:
        space = space.intersection(region_shape(layout.walkable))
    blocked = [region_shape(o) for o in layout.obstacles] + [w.shape() for w in layout.walls]
    if blocked:
        space = space.difference(shapely.unary_union(blocked))
    return space


def blocked_space(ground: Region, layout: Layout) -> shapely.Geometry:
    """What of the ground is not free: obstacles, walls and the ground outside ``walkable``
    (what a renderer draws as solid)."""
    return region_shape(ground).difference(free_space(ground, layout))


def _pieces(space: shapely.Geometry) -> list[shapely.Geometry]:
    return [g for g in getattr(space, "geoms", [space]) if not g.is_empty and g.area > 0]


def check_layout(ground: Region, layout: Layout, groups: Sequence, sources: Sequence = ()) -> None:
    """Check every group against the free space (keys relative to the scenario's top level).

    Raises:
        Problem: the first problem, e.g. ``groups[1].spawn: expected a region with free space
            (not all inside obstacles), found none``.
    """
    if layout.walkable is not None:
        inside = region_shape(ground).intersection(region_shape(layout.walkable))
        require(inside.area > 0, "walkable", "a region overlapping the ground", Raw("none"))
    space = free_space(ground, layout)
    pieces = _pieces(space)
    for i, src in enumerate(sources):
        if src.region is not None:
            free = region_shape(src.region).intersection(space)
            require(
                free.area > 0,
                f"sources[{i}].region",
                "a region with free space (not all inside obstacles)",
                Raw("none"),
            )
    for i, g in enumerate(groups):
        spawn = region_shape(g.spawn).intersection(space)
        key = f"groups[{i}].spawn"
        free = "a region with free space (not all inside obstacles)"
        require(spawn.area > 0, key, free, Raw("none"))
        density = g.count / spawn.area
        require(
            density <= MAX_SPAWN_DENSITY,
            key,
            f"room for {g.count} agents at ≤ {MAX_SPAWN_DENSITY:g} per m² "
            f"(≥ {g.count / MAX_SPAWN_DENSITY:.3g} m² free)",
            Raw(f"{spawn.area:.3g} m² free ({density:.3g} per m²)"),
        )
        starts = {k for k, piece in enumerate(pieces) if piece.intersects(spawn)}
        if g.path is not None:
            for k, w in enumerate(g.path.waypoints):
                at = f"groups[{i}].path.waypoints[{k}]"
                point = shapely.Point(*w)
                require(space.covers(point), at, "a point outside obstacles and walls", w)
                reach = {j for j, piece in enumerate(pieces) if piece.covers(point)}
                if not reach & starts:
                    raise Problem(
                        at,
                        "expected a point reachable from the spawn region, found "
                        "one cut off from it by obstacles or walls",
                    )
        if g.goal is not None:
            goal = region_shape(g.goal).intersection(space)
            at = f"groups[{i}].goal"
            require(goal.area > 0, at, free, Raw("none"))
            reach = {j for j, piece in enumerate(pieces) if piece.intersects(goal)}
            if not reach & starts:
                raise Problem(
                    at,
                    "expected a region reachable from the spawn region, found one "
                    "cut off from it by obstacles or walls",
                )
