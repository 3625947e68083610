"""Scenario layouts (jcrowd.scenario.layout): obstacles, walls, walkable area, and the checks
that name the key of a spawn region, goal or waypoint they make unusable."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from jcrowd.errors import ScenarioError
from jcrowd.scenario import Region, Wall, free_space, parse_scenario, region_shape

BASE = """\
duration = 10.0
[ground]
center = [0, 0]
size = [40, 20]
[dynamics]
avoid = true
[camera]
eye = [0, 1.7, -30]
target = [0, 1.0, 0]
"""

GROUP = """
[[groups]]
name = "g"
count = {count}
spawn = {{ shape = "rect", center = [-15, 0], size = [4, 4] }}
goal = {{ shape = "rect", center = [15, 0], size = [4, 4] }}
"""


def _parse(layout: str, count: int = 20, group: str = GROUP):
    return parse_scenario(BASE + layout + group.format(count=count), "t.toml")


def test_obstacles_walls_and_walkable_are_parsed_into_free_space():
    s = _parse(
        """
[[obstacles]]
shape = "rect"
center = [0, 5]
size = [2, 4]
[[obstacles]]
shape = "circle"
center = [5, -5]
radius = 1.0
[[walls]]
points = [[-5, -10], [-5, 0]]
thickness = 0.4
[walkable]
shape = "rect"
center = [0, 0]
size = [40, 18]
"""
    )
    assert len(s.layout.obstacles) == 2 and len(s.layout.walls) == 1
    assert s.layout.walls[0].thickness == 0.4
    space = free_space(s.ground, s.layout)
    # Closed form: the 40 × 18 walkable strip minus a 2 × 4 block, a unit disc (as a 64-gon)
    # and the wall's 0.4 m × 9.2 m inside the strip (its square end reaches 0.2 m past z = 0;
    # below z = −9 it lies outside the walkable strip).
    disc = 64 / 2 * math.sin(2 * math.pi / 64)  # the 64-gon's area, radius 1
    want = 40 * 18 - 2 * 4 - disc - 0.4 * 9.2
    assert space.area == pytest.approx(want, abs=1e-9)
    assert not space.contains(shapely.Point(0, 5)) and space.contains(shapely.Point(0, 0))


def test_a_scenario_without_layout_is_unchanged():
    s = _parse("")
    assert s.layout.empty
    assert free_space(s.ground, s.layout).area == pytest.approx(800.0)


@pytest.mark.parametrize(
    ("layout", "count", "message"),
    [
        (
            "[[walls]]\npoints = [[0, -10], [0, 10]]\nthickness = 0.0\n",
            20,
            "t.toml: walls[0].thickness: expected a thickness > 0 (m), found 0.0",
        ),
        (
            "[[walls]]\npoints = [[0, -10]]\n",
            20,
            "t.toml: walls[0].points: expected at least 2 points",
        ),
        (
            '[[obstacles]]\nshape = "polygon"\npoints = [[0, 0], [2, 2], [2, 0], [0, 2]]\n',
            20,
            "t.toml: obstacles[0].points: expected a simple polygon, found edges 0 and 2 crossing",
        ),
        (
            '[[obstacles]]\nshape = "rect"\ncenter = [-15, 0]\nsize = [5, 5]\n',
            20,
            "t.toml: groups[0].spawn: expected a region with free space (not all inside "
            "obstacles), found none",
        ),
        (
            '[[obstacles]]\nshape = "rect"\ncenter = [-15, 0.25]\nsize = [5, 3.5]\n',
            20,
            "t.toml: groups[0].spawn: expected room for 20 agents at ≤ 8 per m² (≥ 2.5 m² free), "
            "found 2 m² free (10 per m²)",
        ),
        (
            "[[walls]]\npoints = [[0, -11], [0, 11]]\n",
            20,
            "t.toml: groups[0].goal: expected a region reachable from the spawn region, found one "
            "cut off from it by obstacles or walls",
        ),
        (
            '[walkable]\nshape = "rect"\ncenter = [100, 0]\nsize = [5, 5]\n',
            20,
            "t.toml: walkable: expected a region overlapping the ground, found none",
        ),
        (
            '[[obstacles]]\nshape = "circle"\ncenter = [15, 0]\nradius = 3.0\n',
            20,
            "t.toml: groups[0].goal: expected a region with free space",
        ),
        (
            "[[walls]]\npoints = [[0, -10], [0, 10]]\nheight = 2\n",
            20,
            "t.toml: walls[0].height: unknown key; allowed keys: points, thickness",
        ),
    ],
)
def test_bad_layouts_name_the_key(layout, count, message):
    with pytest.raises(ScenarioError) as err:
        _parse(layout, count)
    assert str(err.value).startswith(message), str(err.value)


def test_obstacles_must_be_tables():
    with pytest.raises(
        ScenarioError, match=r"t.toml: obstacles: expected \[\[obstacles\]\] tables"
    ):
        parse_scenario("obstacles = 3\n" + BASE + GROUP.format(count=5), "t.toml")


def test_a_waypoint_inside_an_obstacle_or_cut_off_is_named():
    group = """
[[groups]]
name = "g"
count = {count}
spawn = {{ shape = "rect", center = [-15, 0], size = [4, 4] }}
path = {{ waypoints = [[-5, 0], [15, 0]] }}
"""
    with pytest.raises(
        ScenarioError, match=r"groups\[0\]\.path\.waypoints\[0\]: expected a point "
    ):
        _parse('[[obstacles]]\nshape = "circle"\ncenter = [-5, 0]\nradius = 1.0\n', group=group)
    wall = "[[walls]]\npoints = [[5, -11], [5, 11]]\n"
    with pytest.raises(ScenarioError, match=r"waypoints\[1\]: expected a point reachable"):
        _parse(wall, group=group)


def test_a_door_in_a_wall_keeps_the_goal_reachable():
    wall = "[[walls]]\npoints = [[0, -11], [0, -1]]\n[[walls]]\npoints = [[0, 1], [0, 11]]\n"
    space = free_space(_parse(wall).ground, _parse(wall).layout)
    assert space.geom_type == "Polygon"  # one piece: the 2 m door joins the two halves


def test_wall_shape_is_the_polyline_widened_by_its_thickness():
    w = Wall(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]]), thickness=0.5)
    # An L with square ends and a mitred corner is the union of two rectangles: the first leg
    # 4.5 × 0.5 (ends extended by 0.25), the second 0.5 × 3.5, sharing a 0.5 × 0.5 square.
    assert w.shape().area == pytest.approx(4.5 * 0.5 + 0.5 * 3.5 - 0.5 * 0.5, abs=1e-9)
    assert w.shape().contains(shapely.Point(2.0, 0.2)) and not w.shape().contains(
        shapely.Point(2.0, 0.3)
    )


def test_regions_convert_to_the_same_shape():
    r = Region.polygon([[0, 0], [4, 0], [4, 3]])
    assert region_shape(r).area == pytest.approx(6.0)
    assert region_shape(Region.rect([1, 1], [2, 4])).bounds == (0.0, -1.0, 2.0, 3.0)


def test_agents_spawn_only_in_free_space():
    """A pillar covering most of the spawn square: every agent starts outside it, and the
    agents still fill the free L-shaped remainder (both of its arms)."""
    from jcrowd.scenario import spawn

    s = _parse('[[obstacles]]\nshape = "rect"\ncenter = [-14.5, 0.5]\nsize = [3, 3]\n', count=12)
    pos = spawn(s).position
    pillar = shapely.box(-16.0, -1.0, -13.0, 2.0)
    assert not shapely.contains_xy(pillar, pos[:, 0], pos[:, 1]).any()
    assert (pos[:, 0] < -16.0).any() and (pos[:, 1] < -1.0).any()
