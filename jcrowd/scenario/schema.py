"""The scenario data model: ground, groups, camera, LOD settings, model, seed and time.

The file format is documented key by key in ``examples/README.md``.
:func:`~jcrowd.scenario.parse.load_scenario` reads a file and
:func:`~jcrowd.scenario.parse.parse_scenario` builds a :class:`Scenario` from its tables;
:func:`~jcrowd.scenario.spawning.spawn` places the agents.

Conventions:

- Units are metres, seconds and radians unless a name says otherwise (``fov_deg``).
- The ground is the x–z plane, y up; a ground point is ``[x, z]``, a 3-D point ``[x, y, z]``.
- Heading θ means facing ``(sin θ, 0, cos θ)``: 0 faces +z, positive yaw turns left (towards
  +x, the walker's left when it faces +z). The camera's up is +y.
- Every bad input is a :class:`~jcrowd.errors.ScenarioError` reading
  ``file: key.path: expected …, found …`` (``file:line`` for TOML syntax). Key paths use the TOML
  names and count from 0: ``groups[2]`` is the third ``[[groups]]`` table.

The dataclasses check their own fields, types included, so a scenario built in code is as valid
as a parsed one; their errors name the TOML key relative to the object (``count: expected …``).
The parser only walks the tables (unknown and missing keys) and prefixes the file and the path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from jaxtyping import Float

from jcrowd.scenario.camera import Camera, CameraKey, camera_at
from jcrowd.scenario.check import (
    Problem,
    Raw,
    is_int,
    real,
    reals,
    require,
    value_range,
)
from jcrowd.scenario.check import points as point_list
from jcrowd.scenario.geometry import Region
from jcrowd.scenario.layout import Layout, check_layout, free_space, region_shape

__all__ = [
    "DEFAULT_THRESHOLDS_M",
    "Camera",
    "CameraKey",
    "DynamicsSettings",
    "Group",
    "LodSettings",
    "Path",
    "Scenario",
    "Source",
    "camera_at",
]

DEFAULT_THRESHOLDS_M = (30.0, 40.0, 50.0, 60.0, 80.0)
"""Default LOD distances (6 levels), after paper 000 §5.1: full detail nearer than 30 m, then a
coarser level (fewer joints, then smaller key levels) every 10 m, the last from 80 m."""

SPEED_RANGE = (0.3, 3.0)  # m/s a walker may be given
HEIGHT_RANGE = (1.0, 2.2)  # m, standing heights the model is scaled to


# ----------------------------------------------------------------------------------- data model


@dataclass(frozen=True, eq=False)
class Path:
    """Waypoints ``(K, 2)`` walked in order from the agent's spawn point; consecutive waypoints
    differ. ``loop``: after the last, head to waypoint 0 again (needs K ≥ 2); otherwise stop and
    idle at the last one."""

    waypoints: Float[np.ndarray, "K 2"]
    loop: bool = False

    def __post_init__(self) -> None:
        w = point_list(self.waypoints, "waypoints")
        require(isinstance(self.loop, bool), "loop", "true or false", self.loop)
        require(not self.loop or len(w) >= 2, "loop", "false for a single waypoint", self.loop)
        same = np.all(w[1:] == w[:-1], axis=1)
        if same.any():
            k = int(np.argmax(same)) + 1
            require(False, f"waypoints[{k}]", f"a point other than waypoints[{k - 1}]", w[k])
        if self.loop and np.all(w[0] == w[-1]):
            expected = "a point other than waypoints[0] (a looped path returns there by itself)"
            require(False, f"waypoints[{len(w) - 1}]", expected, w[-1])
        object.__setattr__(self, "waypoints", w)


@dataclass(frozen=True, eq=False)
class Group:
    """Agents that spawn together and share a path or a goal.

    Exactly one of ``path`` and ``goal``: a path is walked waypoint by waypoint; a goal means
    walk straight to one random point in the goal region, then stop and idle there.
    ``speed`` (m/s, within 0.3–3.0) and ``height`` (standing height in m, within 1.0–2.2) are
    ``(lo, hi)`` ranges each agent draws uniformly from (a single number means lo = hi).
    ``color`` RGB in [0, 1]; None takes the palette colour of the group's index.
    """

    name: str
    count: int
    spawn: Region
    path: Path | None = None
    goal: Region | None = None
    speed: tuple[float, float] = (1.1, 1.5)
    height: tuple[float, float] = (1.55, 1.9)
    color: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        put = object.__setattr__
        require(isinstance(self.name, str) and self.name, "name", "a non-empty string", self.name)
        ok = is_int(self.count) and self.count >= 0  # 0: fed only by [[sources]] (Scenario)
        require(ok, "count", "a positive integer", self.count)
        put(self, "count", int(self.count))
        if (self.path is None) == (self.goal is None):
            found = "neither" if self.path is None else "both"
            raise Problem("", f"expected exactly one of `path` and `goal`, found {found}")
        put(self, "speed", value_range(self.speed, "speed", SPEED_RANGE, "m/s"))
        put(self, "height", value_range(self.height, "height", HEIGHT_RANGE, "m"))
        if self.color is not None:
            rgb = reals(self.color, "color", "[r, g, b] in [0, 1]", 3)
            require(np.all((rgb >= 0) & (rgb <= 1)), "color", "[r, g, b] in [0, 1]", self.color)
            put(self, "color", (float(rgb[0]), float(rgb[1]), float(rgb[2])))


@dataclass(frozen=True, eq=False)
class Source:
    """Agents of group ``group`` (its path or goal, speed, height and colour) appearing over
    time: ``rate`` per second (> 0) from ``start`` (s, ≥ 0) until ``stop`` (s) or until ``count``
    have appeared, whichever comes first (neither: until the scenario ends), each at a uniform
    point of ``region`` (None: the group's spawn region). Agent ``k`` (0, 1, …) of a source
    appears at ``start + k / rate``."""

    group: str
    rate: float
    start: float = 0.0
    stop: float | None = None
    count: int | None = None
    region: Region | None = None

    def __post_init__(self) -> None:
        put = object.__setattr__
        g = self.group
        require(isinstance(g, str) and g, "group", "the name of a group", g)
        require(real(self.rate) and self.rate > 0, "rate", "agents per second > 0", self.rate)
        put(self, "rate", float(self.rate))
        require(real(self.start) and self.start >= 0, "start", "a time ≥ 0 (s)", self.start)
        put(self, "start", float(self.start))
        if self.stop is not None:
            ok = real(self.stop) and self.stop > self.start
            require(ok, "stop", f"a time after start ({self.start:g} s)", self.stop)
            put(self, "stop", float(self.stop))
        if self.count is not None:
            require(
                is_int(self.count) and self.count > 0, "count", "a positive integer", self.count
            )
            put(self, "count", int(self.count))

    def times(self, duration: float) -> Float[np.ndarray, " K"]:
        """When each of its agents appears (s), within ``[0, duration)``."""
        end = min(duration, self.stop if self.stop is not None else math.inf)
        k = max(0, math.ceil((end - self.start) * self.rate - 1e-9))
        if self.count is not None:
            k = min(k, self.count)
        return self.start + np.arange(k) / self.rate


@dataclass(frozen=True, eq=False)
class LodSettings:
    """Level-of-detail settings for the crowd step (paper 000 §5.1).

    ``thresholds_m``: increasing distances (m); an agent farther than ``thresholds_m[i]`` is at
    level i + 1 or coarser, so there are ``len(thresholds_m) + 1`` levels. ``screen`` is the
    importance that ranks agents for the capacities: ``"distance"`` to the camera or
    ``"pixels"`` of projected height; levels always come from the distance thresholds.
    ``hysteresis_m``: the margin an agent must cross beyond a threshold before it changes level
    (≥ 0, less than half the gap between thresholds). ``capacities``: per-level agent budget
    (agents beyond the last are drawn as dots and counted); None takes the crowd code's default
    budget. Levels ``≤ blend_max_level`` blend clips (−1: none does). ``min_pixels``: agents
    shorter than this on screen are not synthesized, only drawn as dots (0: none).
    ``plant_feet``: with the dynamics on, agents at levels ``≤ blend_max_level`` plant their
    stance feet and bend their legs to reach them (:mod:`jcrowd.motion.planting`).
    """

    thresholds_m: tuple[float, ...] = DEFAULT_THRESHOLDS_M
    hysteresis_m: float = 2.0
    capacities: tuple[int, ...] | None = None
    blend_max_level: int = 1
    screen: str = "distance"
    min_pixels: float = 3.0
    plant_feet: bool = True

    @property
    def num_levels(self) -> int:
        return len(self.thresholds_m) + 1

    def __post_init__(self) -> None:
        put = object.__setattr__
        expected = "increasing distances > 0 (m)"
        t = reals(self.thresholds_m, "thresholds", expected)
        require(t[0] > 0 and np.all(np.diff(t) > 0), "thresholds", expected, self.thresholds_m)
        put(self, "thresholds_m", tuple(float(v) for v in t))
        half_gap = float(np.min(np.diff(t, prepend=0.0))) / 2
        h = self.hysteresis_m
        expected = f"metres in [0, {half_gap:g}) (half the smallest gap)"
        require(real(h) and 0 <= h < half_gap, "hysteresis", expected, h)
        put(self, "hysteresis_m", float(h))
        if self.capacities is not None:
            c = self.capacities
            ok = isinstance(c, list | tuple) and len(c) == self.num_levels
            ok = ok and all(is_int(v) and v > 0 for v in c)
            require(ok, "capacities", f"{self.num_levels} positive integers (one per level)", c)
            put(self, "capacities", tuple(int(v) for v in c))
        b = self.blend_max_level
        ok = is_int(b) and -1 <= b < self.num_levels
        require(ok, "blend_max_level", f"an integer in [-1, {self.num_levels - 1}]", b)
        object.__setattr__(self, "blend_max_level", int(b))
        ok = self.screen in ("distance", "pixels")
        require(ok, "importance", '"distance" or "pixels"', self.screen)
        m = self.min_pixels
        require(real(m) and 0 <= m, "min_pixels", "a height in pixels >= 0", m)
        object.__setattr__(self, "min_pixels", float(m))
        ok = isinstance(self.plant_feet, bool)
        require(ok, "plant_feet", "true or false", self.plant_feet)


MAX_AVOID_COVER = 1.0 / 3.0
"""With ``[dynamics] avoid`` on, the share of a group's spawn region its agents' discs may cover.
Placing discs at random two radii apart (:data:`~jcrowd.scenario.spawning.SPREAD_TRIES` draws
each) starts to fail near 0.4: 320 agents of radius 0.2 m in 10 m × 10 m (cover 0.40) leave
3 touching pairs, 250 (cover 0.31) none. A third is 2.65 agents per m² at the
default radius, 6.3 at the entrance experiment's 0.13 m."""


DYNAMICS_MODELS = ("collision-free-speed", "anticipation")
"""The values of ``[dynamics] model``."""


@dataclass(frozen=True, eq=False)
class DynamicsSettings:
    """Crowd dynamics (``[dynamics]``). ``avoid``: agents avoid each other (the collision-free
    speed model drives every root; off: each walks its clips towards its waypoints as if alone).
    ``model``: ``"collision-free-speed"`` (the plain model, validated on unidirectional flows) or
    ``"anticipation"`` (people predict each other's paths a second ahead and step aside early:
    counter-flows pass; see :mod:`jcrowd.pedestrians.reaction`). ``radius``: the body disc kept
    clear around each agent (m, 0.1–0.4). ``far_every``: agents drawn coarser than the blended near
    levels, or not drawn, compute their avoidance every ``far_every`` steps, in turn (1–8; 1: every
    agent every step). ``params``: a parameters file (``jcrowd calibrate --out``; its
    ``[avoidance]`` table sets fields of :class:`~jcrowd.pedestrians.params.AvoidanceParams`, the
    rest keep their defaults; its ``[body] radius``, when it has one, is the ``radius`` unless this
    table names one); ``avoidance`` holds what it set, as ``(name, value)`` pairs."""

    avoid: bool = False
    model: str = "collision-free-speed"
    radius: float = 0.2
    far_every: int = 1
    params: str | None = None
    avoidance: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        require(isinstance(self.avoid, bool), "avoid", "true or false", self.avoid)
        require(
            self.model in DYNAMICS_MODELS,
            "model",
            " or ".join(repr(m) for m in DYNAMICS_MODELS),
            self.model,
        )
        r = self.radius
        require(real(r) and 0.1 <= r <= 0.4, "radius", "a radius in [0.1, 0.4] (m)", r)
        object.__setattr__(self, "radius", float(r))
        k = self.far_every
        ok = isinstance(k, int) and not isinstance(k, bool) and 1 <= k <= 8
        require(ok, "far_every", "an integer in [1, 8] (steps)", k)


@dataclass(frozen=True, eq=False, kw_only=True)
class Scenario:
    """A whole scenario. ``model``: absolute path of a model file, or None for the shipped model.
    ``ground`` is a rect holding every spawn region, goal region and waypoint; ``seed`` ≥ 0
    drives :func:`~jcrowd.scenario.spawning.spawn`; ``duration_s`` and ``fps`` are positive;
    ``layout`` the obstacles, walls and walkable area (:func:`~jcrowd.scenario.layout.check_layout`
    checks the groups against them)."""

    source: str = "<code>"
    model: str | None = None
    seed: int = 0
    duration_s: float
    fps: float = 30.0
    ground: Region
    groups: tuple[Group, ...]
    camera: Camera
    lod: LodSettings = field(default_factory=LodSettings)
    layout: Layout = field(default_factory=Layout)
    dynamics: DynamicsSettings = field(default_factory=DynamicsSettings)
    sources: tuple[Source, ...] = ()

    @property
    def num_agents(self) -> int:
        """Agents placed at t = 0 (sources add more over time)."""
        return sum(g.count for g in self.groups)

    def group_index(self, name: str) -> int:
        """The index of the group called ``name``."""
        return next(i for i, g in enumerate(self.groups) if g.name == name)

    def __post_init__(self) -> None:
        require(is_int(self.seed) and self.seed >= 0, "seed", "an integer ≥ 0", self.seed)
        for key, name in (("duration", "duration_s"), ("fps", "fps")):
            v = getattr(self, name)
            require(real(v) and v > 0, key, "a positive number", v)
            object.__setattr__(self, name, float(v))
        object.__setattr__(self, "seed", int(self.seed))
        require(self.ground.kind == "rect", "ground.shape", '"rect"', self.ground.kind)
        object.__setattr__(self, "groups", tuple(self.groups))
        require(self.groups, "groups", "at least one [[groups]] table", Raw("none"))
        lo, hi = self.ground.bounds()
        inside = f"inside the ground (x in [{lo[0]:g}, {hi[0]:g}], z in [{lo[1]:g}, {hi[1]:g}])"
        names: dict[str, int] = {}
        for i, g in enumerate(self.groups):
            used = names.setdefault(g.name, i)
            require(used == i, f"groups[{i}].name", f"a name not used by groups[{used}]", g.name)
            for key, region in (("spawn", g.spawn), ("goal", g.goal)):
                if region is not None:
                    a, b = region.bounds()
                    found = f"one spanning x in [{a[0]:g}, {b[0]:g}], z in [{a[1]:g}, {b[1]:g}]"
                    ok = np.all(a >= lo) and np.all(b <= hi)
                    require(ok, f"groups[{i}].{key}", f"a region {inside}", Raw(found))
            if g.path is not None:
                out = ~self.ground.contains(g.path.waypoints)
                k = int(np.argmax(out))
                key = f"groups[{i}].path.waypoints[{k}]"
                require(not out.any(), key, f"a point {inside}", g.path.waypoints[k])
        object.__setattr__(self, "sources", tuple(self.sources))
        fed: set[str] = set()
        for i, s in enumerate(self.sources):
            require(s.group in names, f"sources[{i}].group", "the name of a group", s.group)
            fed.add(s.group)
            if s.region is not None:
                a, b = s.region.bounds()
                found = f"one spanning x in [{a[0]:g}, {b[0]:g}], z in [{a[1]:g}, {b[1]:g}]"
                ok = np.all(a >= lo) and np.all(b <= hi)
                require(ok, f"sources[{i}].region", f"a region {inside}", Raw(found))
            require(
                s.start < self.duration_s,
                f"sources[{i}].start",
                f"a time before the scenario ends ({self.duration_s:g} s)",
                s.start,
            )
        for i, g in enumerate(self.groups):
            if g.count == 0:
                require(
                    g.name in fed,
                    f"groups[{i}].count",
                    "a positive integer",
                    Raw("0 (0 only for a group that [[sources]] feed)"),
                )
        if not self.layout.empty:
            require(
                self.dynamics.avoid,
                "dynamics.avoid",
                "true in a scenario with obstacles, walls or a walkable area (only the crowd "
                "dynamics route agents around them)",
                self.dynamics.avoid,
            )
            check_layout(self.ground, self.layout, self.groups, self.sources)
        if self.dynamics.avoid:
            self._check_room_to_spread()

    def _check_room_to_spread(self) -> None:
        """With avoidance on, agents start two radii apart, placed at random: each group's
        discs may cover at most :data:`MAX_AVOID_COVER` of its spawn region's free area."""
        r = self.dynamics.radius
        space = None if self.layout.empty else free_space(self.ground, self.layout)
        most = MAX_AVOID_COVER / (math.pi * r * r)  # agents per m²
        for i, g in enumerate(self.groups):
            region = region_shape(g.spawn)
            area = region.area if space is None else region.intersection(space).area
            need = g.count / most
            require(
                area >= need,
                f"groups[{i}].spawn",
                f"room for {g.count} agents two radii ({r:g} m) apart, placed at random: "
                f"their discs may cover at most a third of the free area (≥ {need:.3g} m² free, "
                f"≤ {most:.3g} per m²)",
                Raw(f"{area:.3g} m² free ({g.count / max(area, 1e-9):.3g} per m²)"),
            )
