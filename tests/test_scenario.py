"""Tests for jcrowd.scenario.schema and jcrowd.scenario.spawning: the shipped examples, region
geometry (uniform sampling, point-in-polygon against a slow loop), camera interpolation, spawn
determinism and paths, and every kind of bad scenario file (message names file and key path)."""

from __future__ import annotations

import math
import re
from pathlib import Path as FilePath

import numpy as np
import pytest

from jcrowd.errors import JcrowdError, ScenarioError
from jcrowd.scenario import (
    DEFAULT_THRESHOLDS_M,
    LATERAL_JITTER_M,
    Camera,
    CameraKey,
    Group,
    LodSettings,
    Path,
    Region,
    Scenario,
    camera_at,
    load_scenario,
    parse_scenario,
    polygon_contains,
    spawn,
    triangulate,
)

EXAMPLES = FilePath(__file__).resolve().parents[1] / "examples"
EXPECTED_COUNTS = {  # what each example promises (examples/README.md)
    "plaza": (3000, 5),
    "stadium": (2000, 2),
    "procession": (580, 3),
    "city_100k": (100_000, 7),
    "entrance": (75, 1),
    "station": (0, 2),  # everyone comes from [[sources]]
    "bidirectional": (0, 2),  # the same
}

# An arrow-shaped, non-convex polygon: a 10 × 4 shaft and a head, reflex vertices at the joins.
ARROW = [[0, 0], [10, 0], [10, -3], [16, 2], [10, 7], [10, 4], [0, 4]]
ARROW_AREA = 40.0 + 0.5 * 10 * 6  # shaft + head triangle (base 10 along x = 10, height 6)

MINIMAL = """\
seed = 7
duration = 20.0
[ground]
center = [0, 0]
size = [200, 200]
[camera]
eye = [0, 1.7, -60]
target = [0, 1.0, 0]
[[groups]]
name = "walkers"
count = 50
speed = [1.1, 1.5]
spawn = { shape = "rect", center = [0, -40], size = [80, 20] }
path = { waypoints = [[0, 40], [40, 40], [40, 0]], loop = false }
[[groups]]
name = "sitters"
count = 20
spawn = { shape = "circle", center = [-50, 0], radius = 5 }
goal = { shape = "polygon", points = [[-60, 60], [-40, 60], [-50, 80]] }
"""


def _scenario(text: str = MINIMAL):
    return parse_scenario(text, "test.toml")


# ------------------------------------------------------------------------------------- examples


@pytest.mark.parametrize("name", sorted(EXPECTED_COUNTS))
def test_every_example_parses_and_spawns_inside_its_regions(name):
    scenario = load_scenario(EXAMPLES / f"{name}.toml")
    agents, groups = EXPECTED_COUNTS[name]
    assert scenario.num_agents == agents and len(scenario.groups) == groups
    assert scenario.model is None  # "default": the shipped model
    s = spawn(scenario)
    assert s.num_agents == agents
    n, k = s.waypoints.shape[:2]
    assert s.position.shape == (n, 2) and s.heading.shape == (n,) and s.color.shape == (n, 3)
    assert s.group.dtype == np.int32 and s.num_waypoints.dtype == np.int32
    assert s.waypoints.dtype == np.float64 and s.color.dtype == np.float32 and s.loop.dtype == bool
    assert np.all(scenario.ground.contains(s.position))
    assert np.all(scenario.ground.contains(s.waypoints.reshape(-1, 2)))
    for i, group in enumerate(scenario.groups):
        mine = s.group == i
        assert mine.sum() == group.count
        assert np.all(group.spawn.contains(s.position[mine]))
        assert np.all((s.speed[mine] >= group.speed[0]) & (s.speed[mine] <= group.speed[1]))
        assert np.all((s.height[mine] >= group.height[0]) & (s.height[mine] <= group.height[1]))
        if group.goal is not None:
            assert np.all(s.num_waypoints[mine] == 1) and not s.loop[mine].any()
            assert np.all(group.goal.contains(s.waypoints[mine, 0]))
    # padding repeats each agent's last real waypoint
    last = s.waypoints[np.arange(n), s.num_waypoints - 1]
    pad = np.arange(k)[None, :] >= s.num_waypoints[:, None]
    assert np.array_equal(s.waypoints[pad], np.repeat(last, k - s.num_waypoints, axis=0))


def test_example_details_the_readme_promises():
    procession = load_scenario(EXAMPLES / "procession.toml")
    assert len(procession.camera.keys) == 3 and all(g.path.loop for g in procession.groups)
    stadium = load_scenario(EXAMPLES / "stadium.toml")
    assert stadium.lod.capacities == (300, 400, 500, 600, 800, 2000)
    assert {g.spawn.kind for g in stadium.groups} == {"rect", "polygon"}
    plaza = load_scenario(EXAMPLES / "plaza.toml")
    assert plaza.duration_s == 20.0 and plaza.camera.keys[0].eye[1] == 10.0
    assert plaza.lod.thresholds_m == DEFAULT_THRESHOLDS_M and plaza.lod.screen == "distance"
    assert load_scenario(EXAMPLES / "city_100k.toml").lod.screen == "pixels"


# ------------------------------------------------------------------------------------- regions


def _slow_ray_cast(polygon, point) -> bool:
    """Count crossings of a ray from ``point`` towards +x, one edge at a time."""
    x, z = point
    inside = False
    for i in range(len(polygon)):
        (x1, z1), (x2, z2) = polygon[i], polygon[(i + 1) % len(polygon)]
        if (z1 > z) != (z2 > z):
            x_cross = x1 + (z - z1) * (x2 - x1) / (z2 - z1)
            if x < x_cross:
                inside = not inside
    return inside


def test_polygon_contains_agrees_with_a_slow_ray_casting_loop():
    rng = np.random.default_rng(0)
    region = Region.polygon(ARROW)
    points = rng.uniform([-2, -5], [18, 9], size=(3000, 2))
    slow = np.array([_slow_ray_cast(ARROW, p) for p in points])
    assert np.array_equal(region.contains(points), slow)
    assert 0.2 < slow.mean() < 0.6  # both answers occur
    assert np.array_equal(polygon_contains(np.array(ARROW[::-1], float), points), slow)


def test_triangulation_covers_the_polygon():
    tris = triangulate(np.array(ARROW, float))
    (ax, az), (bx, bz) = (tris[:, 1] - tris[:, 0]).T, (tris[:, 2] - tris[:, 0]).T
    area = 0.5 * np.abs(ax * bz - az * bx)
    assert len(tris) == len(ARROW) - 2
    np.testing.assert_allclose(area.sum(), ARROW_AREA, rtol=1e-12)
    assert Region.polygon(ARROW).area == pytest.approx(ARROW_AREA, rel=1e-12)


def _within_binomial(hits: int, n: int, p: float, sigmas: float = 5.0) -> bool:
    # A count of n draws with probability p has sd √(n p (1 − p)); 5 sd fails a correct sampler
    # with probability < 1e-6 per check, while a sampler biased by 1 % of the area is caught.
    return abs(hits - n * p) <= sigmas * math.sqrt(n * p * (1 - p))


def test_polygon_sampling_is_uniform():
    n = 200_000
    region = Region.polygon(ARROW)
    points = region.sample(np.random.default_rng(1), n)
    assert points.shape == (n, 2) and np.all(region.contains(points))
    # sub-rectangles lying inside the arrow: shaft parts, across the reflex joins, in the head
    for (x0, z0), (x1, z1) in [
        ((0, 0), (5, 4)),
        ((5, 1), (10, 3)),
        ((8, 0), (12, 4)),
        ((10, 0), (13, 4)),
        ((11, 1), (13, 3)),
    ]:
        inside = (points[:, 0] >= x0) & (points[:, 0] < x1)
        inside &= (points[:, 1] >= z0) & (points[:, 1] < z1)
        p = (x1 - x0) * (z1 - z0) / ARROW_AREA
        assert _within_binomial(int(inside.sum()), n, p), ((x0, z0), (x1, z1))


def test_rect_and_circle_sampling_are_uniform():
    n = 100_000
    rng = np.random.default_rng(2)
    circle = Region.circle([3, -4], 10)
    p = circle.sample(rng, n)
    assert np.all(circle.contains(p))
    r = np.linalg.norm(p - [3, -4], axis=1)
    assert _within_binomial(int((r < 5).sum()), n, 0.25)  # inner disc: a quarter of the area
    right = p[:, 0] > 3
    assert _within_binomial(int(right.sum()), n, 0.5)
    rect = Region.rect([1, 2], [4, 8])
    q = rect.sample(rng, n)
    assert np.all(rect.contains(q)) and _within_binomial(int((q[:, 1] < 0).sum()), n, 0.25)
    lo, hi = rect.bounds()
    assert np.array_equal(lo, [-1, -2]) and np.array_equal(hi, [3, 6])


def test_regions_built_in_code_check_themselves():
    with pytest.raises(ScenarioError, match=r"radius: expected a radius > 0"):
        Region.circle([0, 0], 0.0)
    with pytest.raises(ScenarioError, match=r"size: expected \[width, depth\] both > 0"):
        Region.rect([0, 0], [1, -1])
    with pytest.raises(ScenarioError, match=r"points: expected a simple polygon"):
        Region.polygon([[0, 0], [2, 2], [2, 0], [0, 2]])  # a bow tie
    with pytest.raises(ScenarioError, match=r"last point repeating points\[0\]"):
        Region.polygon([[0, 0], [2, 0], [2, 2], [0, 0]])
    with pytest.raises(ScenarioError, match=r'shape: expected "rect", "circle" or "polygon"'):
        Region("square")


def test_a_scenario_built_in_code_is_checked_like_a_parsed_one():
    camera = Camera((CameraKey(0.0, np.array([0, 1.7, -50.0]), np.array([0, 1.0, 0.0])),))
    walkers = Group("walkers", 100, Region.rect([0, 0], [10, 10]), goal=Region.circle([0, 30], 2))
    ground = Region.rect([0, 0], [100, 100])
    scenario = Scenario(duration_s=5, ground=ground, groups=(walkers,), camera=camera)
    assert scenario.fps == 30.0 and scenario.lod.num_levels == 6 and scenario.model is None
    assert spawn(scenario).num_agents == 100
    with pytest.raises(
        ScenarioError, match=r"expected exactly one of `path` and `goal`, found neither"
    ):
        Group("idle", 3, Region.rect([0, 0], [1, 1]))
    with pytest.raises(
        ScenarioError, match=r"waypoints\[1\]: expected a point other than waypoints\[0\]"
    ):
        Path(np.array([[0.0, 0.0], [0.0, 0.0]]))
    with pytest.raises(ScenarioError, match=r"hysteresis: expected metres in \[0, 5\)"):
        LodSettings(hysteresis_m=6.0)
    far_goal = Group("far", 1, Region.rect([0, 0], [1, 1]), goal=Region.circle([0, 60], 1))
    with pytest.raises(ScenarioError, match=r"^groups\[0\]\.goal: expected a region inside"):
        Scenario(duration_s=5, ground=ground, groups=(far_goal,), camera=camera)


# --------------------------------------------------------------------------------------- camera


def test_camera_at_interpolates_linearly_and_holds_at_the_ends():
    keys = (
        CameraKey(1.0, np.array([0.0, 2.0, -10.0]), np.array([0.0, 1.0, 0.0])),
        CameraKey(5.0, np.array([8.0, 6.0, -10.0]), np.array([4.0, 1.0, 0.0])),
        CameraKey(7.0, np.array([8.0, 6.0, 10.0]), np.array([4.0, 1.0, 20.0])),
    )
    camera = Camera(keys)
    eye, target = camera_at(camera, 2.0)  # a quarter of the way from key 0 to key 1
    np.testing.assert_allclose(eye, [2.0, 3.0, -10.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(target, [1.0, 1.0, 0.0], rtol=0, atol=1e-12)
    eye, target = camera_at(camera, 6.0)  # midway from key 1 to key 2
    np.testing.assert_allclose(eye, [8.0, 6.0, 0.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(target, [4.0, 1.0, 10.0], rtol=0, atol=1e-12)
    for t, key in ((-3.0, keys[0]), (1.0, keys[0]), (7.0, keys[2]), (100.0, keys[2])):
        eye, target = camera_at(camera, t)
        assert np.array_equal(eye, key.eye) and np.array_equal(target, key.target)
    fixed = _scenario().camera  # defaults: 60° vertical fov, 1280 × 720
    assert len(fixed.keys) == 1 and fixed.fov_deg == 60.0
    assert (fixed.width, fixed.height, fixed.near, fixed.far) == (1280, 720, 0.1, 1000.0)
    assert np.array_equal(camera_at(fixed, 12.0)[0], [0, 1.7, -60])


# ---------------------------------------------------------------------------------------- spawn


def _same(a, b) -> bool:
    return all(
        np.array_equal(getattr(a, f), getattr(b, f))
        for f in ("position", "heading", "group", "height", "speed", "waypoints", "loop", "color")
    )


def test_spawn_is_deterministic_in_the_seed():
    a, b = spawn(_scenario()), spawn(_scenario())
    assert _same(a, b)
    c = spawn(_scenario(MINIMAL.replace("seed = 7", "seed = 8")))
    assert not np.any(np.all(a.position == c.position, axis=1))
    # each group has its own stream: growing one group leaves the other's agents in place
    d = spawn(_scenario(MINIMAL.replace("count = 20", "count = 30")))
    assert np.array_equal(a.position[a.group == 0], d.position[d.group == 0])


def test_spawn_headings_face_the_first_waypoint():
    s = spawn(_scenario())
    facing = np.stack([np.sin(s.heading), np.cos(s.heading)], axis=1)
    to_first = s.waypoints[:, 0] - s.position
    to_first /= np.linalg.norm(to_first, axis=1, keepdims=True)
    np.testing.assert_allclose(facing, to_first, rtol=0, atol=1e-12)


def test_path_copies_are_parallel_offsets_of_at_most_a_metre():
    scenario = _scenario()
    s = spawn(scenario)
    w = scenario.groups[0].path.waypoints  # legs +x then −z: a right-angle corner
    mine = s.waypoints[s.group == 0]
    assert np.all(s.num_waypoints[s.group == 0] == 3)
    # signed distance to the left of each leg, at both of its ends
    offsets = []
    for k in range(len(w) - 1):
        d = (w[k + 1] - w[k]) / np.linalg.norm(w[k + 1] - w[k])
        left = np.array([d[1], -d[0]])
        offsets.append((mine[:, k : k + 2] - w[k : k + 2]) @ left)
    # (n, 4): leg 0's far end and both ends of leg 1 sit at one distance (the mitre at the
    # corner); leg 0's near end also depends on the agent's approach from its spawn point
    offsets = np.concatenate(offsets, axis=1)[:, 1:]
    np.testing.assert_allclose(offsets, offsets[:, :1].repeat(3, axis=1), rtol=0, atol=1e-12)
    assert np.all(np.abs(offsets) <= LATERAL_JITTER_M) and offsets[:, 0].std() > 0.3


def test_looped_paths_are_joined_at_the_nearest_leg_and_kept_in_the_ground():
    text = MINIMAL.replace(
        "path = { waypoints = [[0, 40], [40, 40], [40, 0]], loop = false }",
        "path = { waypoints = [[-100, -100], [100, -100], [100, 100], [-100, 100]], loop = true }",
    ).replace("center = [0, -40], size = [80, 20]", "center = [0, 95], size = [100, 4]")
    scenario = _scenario(text)
    s = spawn(scenario)
    mine = s.group == 0
    assert np.all(s.loop[mine]) and np.all(s.num_waypoints[mine] == 4)
    # spawned along the north leg (waypoint 2 → 3), every agent first heads for waypoint 3
    assert np.all(np.abs(s.waypoints[mine, 0] - [-100, 100]) <= LATERAL_JITTER_M * 2)
    assert np.all(np.abs(s.waypoints[mine, 1] - [-100, -100]) <= LATERAL_JITTER_M * 2)
    # waypoints on the ground's edge: offsets outwards are clipped back onto it
    assert np.all(scenario.ground.contains(s.waypoints.reshape(-1, 2)))
    assert np.any(s.waypoints[mine] == -100) and np.any(np.abs(s.waypoints[mine]) < 100)


def test_model_paths_resolve_against_the_scenario_folder(tmp_path):
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "mine.jcm").write_bytes(b"")
    file = tmp_path / "s.toml"
    file.write_text('model = "models/mine.jcm"\n' + MINIMAL)
    assert load_scenario(file).model == str((tmp_path / "models" / "mine.jcm").resolve())
    file.write_text('model = "default"\n' + MINIMAL)
    assert load_scenario(file).model is None


# -------------------------------------------------------------------------------- bad scenarios

CAMERA_KEYS = """\
[[camera.keys]]
time = 2.0
eye = [0, 2, -60]
target = [0, 1, 0]
[[camera.keys]]
time = 2.0
eye = [5, 2, -60]
target = [0, 1, 0]"""
INSIDE = r"expected a point inside the ground \(x in \[-100, 100\], z in \[-100, 100\]\)"

# (what is wrong, text replaced in MINIMAL, its replacement, message after "file: ")
# One bad-scenario case per line reads as a table, hence `# fmt: skip` below (a formatter
# directive, not a skipped test).
BAD = [
    ("unknown top-level key", "seed = 7", "seed = 7\ncolour = 1",
     r"colour: unknown key; allowed keys: model, seed, duration"),
    ("unknown group key", 'name = "walkers"', 'name = "walkers"\ncolour = [1, 0, 0]',
     r"groups\[0\]\.colour: unknown key; allowed keys: name, count, spawn"),
    ("negative count", "count = 50", "count = -3",
     r"groups\[0\]\.count: expected a positive integer, found -3"),
    ("zero count", "count = 20", "count = 0",
     r"groups\[1\]\.count: expected a positive integer, found 0"),
    ("fractional count", "count = 50", "count = 2.5",
     r"groups\[0\]\.count: expected a positive integer, found 2\.5"),
    ("boolean count", "count = 50", "count = true",
     r"groups\[0\]\.count: expected a positive integer, found true"),
    ("zero size", "size = [80, 20]", "size = [80, 0]",
     r"groups\[0\]\.spawn\.size: expected \[width, depth\] both > 0 \(m\), found \[80, 0\]"),
    ("zero radius", "radius = 5", "radius = 0",
     r"groups\[1\]\.spawn\.radius: expected a radius > 0 \(m\), found 0"),
    ("negative radius", "radius = 5", "radius = -2.5",
     r"groups\[1\]\.spawn\.radius: expected a radius > 0 \(m\), found -2\.5"),
    ("collinear polygon", "[[-60, 60], [-40, 60], [-50, 80]]", "[[-60, 60], [-50, 60], [-40, 60]]",
     r"groups\[1\]\.goal\.points: expected points spanning an area, found them all on one line"),
    ("waypoint outside the ground", "[40, 0]]", "[40, 130]]",
     rf"groups\[0\]\.path\.waypoints\[2\]: {INSIDE}, found \[40\.0, 130\.0\]"),
    ("spawn outside the ground", "center = [-50, 0]", "center = [-98, 0]",
     r"groups\[1\]\.spawn: expected a region inside the ground .*, "
     r"found one spanning x in \[-103, -93\]"),
    ("goal outside the ground", "[-50, 80]]", "[-50, 101]]",
     r"groups\[1\]\.goal: expected a region inside the ground"),
    ("missing model file", "seed = 7", 'model = "nowhere/none.jcm"\nseed = 7',
     r'model: expected an existing model file, found "nowhere/none\.jcm"'),
    ("reversed speed", "speed = [1.1, 1.5]", "speed = [1.5, 1.1]",
     r"groups\[0\]\.speed: expected \[lo, hi\] m/s with 0\.3 ≤ lo ≤ hi ≤ 3\.0, "
     r"found \[1\.5, 1\.1\]"),
    ("speed out of range", "speed = [1.1, 1.5]", "speed = [1.1, 4.0]",
     r"groups\[0\]\.speed: expected \[lo, hi\] m/s"),
    ("camera keys not increasing", "eye = [0, 1.7, -60]\ntarget = [0, 1.0, 0]", CAMERA_KEYS,
     r"camera\.keys\[1\]\.time: expected a time after keys\[0\]\.time = 2\.0, found 2\.0"),
    ("fixed and keyed camera", "target = [0, 1.0, 0]", "target = [0, 1.0, 0]\n" + CAMERA_KEYS,
     r"camera: expected eye and target \(fixed\) or \[\[camera\.keys\]\], found both"),
    ("vertical camera", "target = [0, 1.0, 0]", "target = [0, 1.0, -60]",
     r"camera\.target: expected a point off the vertical through eye"),
    ("odd image width", "target = [0, 1.0, 0]", "target = [0, 1.0, 0]\nwidth = 1279",
     r"camera\.width: expected a positive even number of pixels, found 1279"),
    ("misspelt [[groups]]", "[[groups]]", "[[crowd]]",
     r"crowd: unknown key"),
    ("both path and goal", "goal = {", 'path = { waypoints = [[0, 0]] }\ngoal = {',
     r"groups\[1\]: expected exactly one of `path` and `goal`, found both"),
    ("string where a number goes", "center = [0, -40]", 'center = [0, "south"]',
     r'groups\[0\]\.spawn\.center: expected \[x, z\] \(m\), found \[0, "south"\]'),
    ("unknown shape", 'shape = "circle"', 'shape = "disc"',
     r'groups\[1\]\.spawn\.shape: expected "rect", "circle" or "polygon", found "disc"'),
    ("circle with a size", "radius = 5", "radius = 5, size = [1, 1]",
     r"groups\[1\]\.spawn\.size: unknown key; allowed keys: shape, center, radius"),
    ("duplicate group names", 'name = "sitters"', 'name = "walkers"',
     r'groups\[1\]\.name: expected a name not used by groups\[0\], found "walkers"'),
    ("zero lod capacity", "[[groups]]", "[lod]\ncapacities = [9, 9, 9, 9, 9, 0]\n[[groups]]",
     r"lod\.capacities: expected 6 positive integers \(one per level\), found \[9, 9, 9, 9, 9, 0"),
    ("negative min_pixels", "[[groups]]", "[lod]\nmin_pixels = -1\n[[groups]]",
     r"lod\.min_pixels: expected a height in pixels >= 0, found -1"),
    ("plant_feet not a switch", "[[groups]]", "[lod]\nplant_feet = 1\n[[groups]]",
     r"lod\.plant_feet: expected true or false, found 1"),
    ("lod thresholds not increasing", "[[groups]]", "[lod]\nthresholds = [30, 20]\n[[groups]]",
     r"lod\.thresholds: expected increasing distances > 0 \(m\), found \[30, 20\]"),
    ("negative seed", "seed = 7", "seed = -1",
     r"seed: expected an integer ≥ 0, found -1"),
    ("zero duration", "duration = 20.0", "duration = 0",
     r"duration: expected a positive number, found 0"),
]  # fmt: skip


@pytest.mark.parametrize(("old", "new", "message"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_scenarios_name_the_file_and_the_key_path(tmp_path, old, new, message):
    assert old in MINIMAL  # the edit applies
    file = tmp_path / "bad.toml"
    file.write_text(MINIMAL.replace(old, new, 1))
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(file))}: {message}"):
        load_scenario(file)


def test_missing_required_key_groups(tmp_path):
    file = tmp_path / "nogroups.toml"
    file.write_text(MINIMAL[: MINIMAL.index("[[groups]]")])
    with pytest.raises(
        ScenarioError, match=rf"^{re.escape(str(file))}: groups: expected a value, found nothing"
    ):
        load_scenario(file)


def test_toml_syntax_errors_give_the_line(tmp_path):
    file = tmp_path / "syntax.toml"
    file.write_text(MINIMAL.replace("size = [200, 200]", "size = [200, 200"))  # line 5
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(file))}:\d+: invalid TOML: "):
        load_scenario(file)
    file.write_text(MINIMAL.replace("duration = 20.0", "duration = = 20.0"))  # line 2
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(file))}:2: invalid TOML: .*column"):
        load_scenario(file)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(ScenarioError, match=r"nope\.toml: expected a scenario file, found no such"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ScenarioError, match=r"expected a scenario file, found a folder"):
        load_scenario(tmp_path)
    binary = tmp_path / "latin1.toml"
    binary.write_bytes(b"seed = 7\n# caf\xe9\n")
    with pytest.raises(ScenarioError, match=r"latin1\.toml:2: expected UTF-8 text"):
        load_scenario(binary)


def test_scenario_errors_are_jcrowd_value_errors():
    with pytest.raises(JcrowdError):
        _scenario(MINIMAL.replace("count = 50", "count = -3"))
    assert issubclass(ScenarioError, ValueError)
