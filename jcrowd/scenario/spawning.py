"""Where a scenario's agents start: :func:`spawn` places every group's agents and paths.

Conventions (shared with :mod:`jcrowd.scenario.schema`): the ground is the x–z plane, y up; a point
on it is ``[x, z]`` in metres. Heading θ (radians, in (−π, π]) means facing ``(sin θ, 0, cos θ)``:
θ = 0 faces +z and a positive yaw turns the walker to its left, towards +x (facing +z with y up,
+x is on the left, as in :mod:`jcrowd.motion.gait`). The left of heading θ is ``(cos θ, −sin θ)`` in
x–z. A positive lateral offset moves a path to its walker's left.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
import shapely
from jaxtyping import Bool, Float, Int

from jcrowd.scenario.geometry import Region
from jcrowd.scenario.layout import free_space
from jcrowd.scenario.schema import Scenario

__all__ = ["LATERAL_JITTER_M", "Spawn", "spawn", "spawn_empty", "spawn_sources"]

LATERAL_JITTER_M = 1.0
"""Largest lateral offset of an agent's copy of its group's path (metres)."""

# A mitred offset vertex moves by |offset| / cos(turn / 2); beyond a 120° turn that factor (2)
# is capped so a sharp corner does not throw the vertex far away.
_MAX_MITER = 2.0

# Group colours when a group gives none: distinct hues, cycled by group index.
_PALETTE = np.array(
    [
        [0.90, 0.30, 0.20],
        [0.20, 0.50, 0.90],
        [0.95, 0.75, 0.20],
        [0.30, 0.70, 0.40],
        [0.60, 0.40, 0.80],
        [0.95, 0.55, 0.75],
        [0.40, 0.80, 0.85],
        [0.55, 0.45, 0.35],
    ],
    np.float32,
)


def _left_of(d: np.ndarray) -> np.ndarray:
    """Unit left normals of directions ``d`` (..., 2); zero where ``d`` is zero."""
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    return np.stack([d[..., 1], -d[..., 0]], axis=-1) / np.maximum(length, 1e-300)


def _offset_waypoints(
    waypoints: np.ndarray, loop: bool, offsets: np.ndarray, starts: np.ndarray
) -> np.ndarray:
    """Each agent's copy of a path, moved ``offsets[i]`` metres to its walker's left.

    Vertices are mitred so each leg stays ``|offset|`` from the original leg (capped at
    ``_MAX_MITER·|offset|`` at corners sharper than 120°). On an open path the leg into
    waypoint 0 is the agent's own approach from ``starts``, so agents coming from a wide spawn
    region keep their sideways spacing onto the first leg. Returns ``(n, K, 2)``.
    """
    n, k = len(starts), len(waypoints)
    leg = np.roll(waypoints, -1, axis=0) - waypoints  # leg k leaves waypoint k
    legs = _left_of(leg if loop else leg[:-1])
    if loop:
        n_in = np.broadcast_to(np.roll(legs, 1, axis=0), (n, k, 2))
        n_out = np.broadcast_to(legs, (n, k, 2))
    else:
        approach = _left_of(waypoints[None, 0] - starts)[:, None, :]
        n_out = np.broadcast_to(np.concatenate([legs, legs[-1:]]) if k > 1 else approach, (n, k, 2))
        # an agent spawned on waypoint 0 has no approach: its first leg stands in for it
        approach = np.where(np.any(approach != 0, axis=-1, keepdims=True), approach, n_out[:, :1])
        n_in = np.concatenate([approach, np.broadcast_to(legs[None], (n, k - 1, 2))], axis=1)
    bis = n_in + n_out  # |bis| = 2 cos(turn / 2)
    norm = np.linalg.norm(bis, axis=-1, keepdims=True)
    safe = np.maximum(norm, 1e-12)
    miter = np.where(
        norm >= 2.0 / _MAX_MITER,
        2.0 * bis / safe**2,
        np.where(norm > 1e-9, _MAX_MITER * bis / safe, n_in),
    )
    return waypoints[None] + offsets[:, None, None] * miter


def _sample_free(
    region: Region, rng: np.random.Generator, n: int, free: shapely.Geometry | None
) -> np.ndarray:
    """``n`` points uniform over the part of ``region`` inside ``free`` (rejection sampling;
    :func:`~jcrowd.scenario.layout.check_layout` made sure that part has area)."""
    if free is None:
        return region.sample(rng, n)
    shapely.prepare(free)
    kept: list[np.ndarray] = [np.zeros((0, 2))]
    count = 0
    while count < n:
        p = region.sample(rng, max(2 * (n - count), 16))
        p = p[shapely.contains_xy(free, p[:, 0], p[:, 1])]
        kept.append(p)
        count += len(p)
    return np.concatenate(kept)[:n]


SPREAD_TRIES = 50
"""Draws per agent before a start position that touches another agent's disc is accepted."""


def _spread(
    region: Region,
    rng: np.random.Generator,
    n: int,
    free: shapely.Geometry | None,
    gap: float,
    placed: dict[tuple[int, int], list[np.ndarray]],
) -> np.ndarray:
    """``n`` start positions in ``region`` at least ``gap`` from each other and from the
    positions in ``placed`` (a hash of ``gap``-sized cells, updated), as :func:`spawn` says."""
    out = np.empty((n, 2))
    pool, k = np.empty((0, 2)), 0
    for i in range(n):
        for _ in range(SPREAD_TRIES):
            if k == len(pool):
                pool, k = _sample_free(region, rng, 64, free), 0
            p, k = pool[k], k + 1
            cx, cz = int(p[0] // gap), int(p[1] // gap)
            near = [
                q
                for dx in (-1, 0, 1)
                for dz in (-1, 0, 1)
                for q in placed.get((cx + dx, cz + dz), ())
            ]
            if not near or np.min(np.sum((np.asarray(near) - p) ** 2, axis=1)) >= gap * gap:
                break
        out[i] = p
        placed.setdefault((cx, cz), []).append(p)
    return out


def _loop_entry(waypoints: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per point, the waypoint that ends the loop leg nearest to it (where it joins the loop)."""
    a = waypoints
    d = np.roll(waypoints, -1, axis=0) - a  # leg k: waypoint k → k + 1 (mod K)
    rel = points[:, None, :] - a[None]
    t = np.clip(np.sum(rel * d, axis=-1) / np.sum(d * d, axis=-1), 0.0, 1.0)
    gap = np.linalg.norm(rel - t[..., None] * d, axis=-1)
    return (np.argmin(gap, axis=1) + 1) % len(waypoints)


@dataclass(frozen=True, eq=False)
class Spawn:
    """The crowd at t = 0, agents of group 0 first (NumPy, host side).

    Attributes:
        position: ``(N, 2)`` root ``[x, z]`` on the ground (m).
        heading: ``(N,)`` radians; facing ``(sin θ, 0, cos θ)``, towards the first waypoint.
        group: ``(N,)`` int32 index into ``scenario.groups``.
        height: ``(N,)`` standing height (m).
        speed: ``(N,)`` preferred walking speed (m/s).
        waypoints: ``(N, K, 2)`` float64, each agent's path, padded with its last waypoint; K is
            the longest path in the scenario (1 for goal-only scenarios).
        num_waypoints: ``(N,)`` int32, how many rows of ``waypoints`` are real.
        loop: ``(N,)`` bool; after its last waypoint a looping agent heads to waypoint 0 again, a
            non-looping one stops and idles there (goal agents never loop).
        color: ``(N, 3)`` float32 RGB in [0, 1], the group's colour.
    """

    position: Float[np.ndarray, "N 2"]
    heading: Float[np.ndarray, " N"]
    group: Int[np.ndarray, " N"]
    height: Float[np.ndarray, " N"]
    speed: Float[np.ndarray, " N"]
    waypoints: Float[np.ndarray, "N K 2"]
    num_waypoints: Int[np.ndarray, " N"]
    loop: Bool[np.ndarray, " N"]
    color: Float[np.ndarray, "N 3"]

    @property
    def num_agents(self) -> int:
        return len(self.position)


def spawn(scenario: Scenario) -> Spawn:
    """Place every agent of ``scenario``: deterministic from ``scenario.seed``.

    Each group draws from its own stream (``SeedSequence(seed).spawn``), so changing one group
    leaves the others' agents where they were. Per agent, uniformly: position in the spawn region,
    speed and height in the group's ranges; then a goal agent gets one waypoint uniform in the goal
    region (it walks there and idles), and a path agent gets the group's waypoints offset
    sideways by a uniform lateral offset in ``[−LATERAL_JITTER_M, LATERAL_JITTER_M]`` (so a group
    does not walk in single file), clipped to the ground. An open path is walked from its first
    waypoint; a looped path is joined at the end of the leg nearest the spawn point (its
    waypoints rotated so that one comes first), so agents spread over a loop do not all walk to
    waypoint 0 first. Initial headings face each agent's first waypoint.

    With ``[dynamics] avoid`` on, agents start at least two radii apart (their discs do not
    overlap): each position is drawn again, up to :data:`SPREAD_TRIES` times, while it falls
    within that distance of an agent placed before it (earlier groups first), then kept as
    drawn — in a region packed close to the limit a few may start touching, and the dynamics
    push them apart within the first steps.
    """
    groups = scenario.groups
    free = None if scenario.layout.empty else free_space(scenario.ground, scenario.layout)
    gap = 2 * scenario.dynamics.radius if scenario.dynamics.avoid else 0.0
    placed: dict[tuple[int, int], list[np.ndarray]] = {}
    streams = np.random.SeedSequence(scenario.seed).spawn(len(groups))
    parts: list[tuple[np.ndarray, ...]] = []
    for index, (group, stream) in enumerate(zip(groups, streams, strict=True)):
        rng = np.random.default_rng(stream)
        n = group.count
        if gap > 0:
            position = _spread(group.spawn, rng, n, free, gap, placed)
        else:
            position = _sample_free(group.spawn, rng, n, free)
        parts.append(_agents(scenario, index, rng, position))
    columns = [np.concatenate(column) for column in zip(*parts, strict=True)]
    return Spawn(*columns)


def _agents(
    scenario: Scenario, index: int, rng: np.random.Generator, position: np.ndarray
) -> tuple[np.ndarray, ...]:
    """The columns of :class:`Spawn` for agents of group ``index`` starting at ``position``:
    speed, height and path (or goal point) drawn from ``rng`` as :func:`spawn` says."""
    group = scenario.groups[index]
    n = len(position)
    lo, hi = scenario.ground.bounds()
    k_max = max(1 if g.path is None else len(g.path.waypoints) for g in scenario.groups)
    speed = rng.uniform(group.speed[0], group.speed[1], size=n)
    height = rng.uniform(group.height[0], group.height[1], size=n)
    if group.path is None:  # Group's check makes sure it then has a goal
        goal = cast("Region", group.goal)
        waypoints, loop = goal.sample(rng, n)[:, None, :], False
    else:
        offsets = rng.uniform(-LATERAL_JITTER_M, LATERAL_JITTER_M, size=n)
        base = group.path.waypoints
        moved = np.clip(_offset_waypoints(base, group.path.loop, offsets, position), lo, hi)
        if group.path.loop:  # each agent joins the loop where it is nearest, walking on
            order = (_loop_entry(base, position)[:, None] + np.arange(len(base))) % len(base)
            moved = np.take_along_axis(moved, order[..., None], axis=1)
        waypoints, loop = moved, group.path.loop
    to_first = waypoints[:, 0] - position
    k = waypoints.shape[1]
    pad = np.repeat(waypoints[:, -1:], k_max - k, axis=1)
    color = _PALETTE[index % len(_PALETTE)] if group.color is None else group.color
    return (
        position,
        np.arctan2(to_first[:, 0], to_first[:, 1]),
        np.full(n, index, np.int32),
        height,
        speed,
        np.concatenate([waypoints, pad], axis=1),
        np.full(n, k, np.int32),
        np.full(n, loop, bool),
        np.broadcast_to(np.asarray(color, np.float32), (n, 3)),
    )


def spawn_sources(scenario: Scenario) -> tuple[Spawn, Float[np.ndarray, " R"]]:
    """Every agent the scenario's ``[[sources]]`` will add, and when (s), in order of appearance.

    Each source draws from its own stream (after the groups' streams, so adding a source does
    not move the agents placed at t = 0): positions uniform over its region's free part (no
    spacing: an agent may appear touching one already there, and the dynamics push them apart),
    then speed, height and path as the group's agents at t = 0 (:func:`spawn`).
    """
    groups, sources = scenario.groups, scenario.sources
    free = None if scenario.layout.empty else free_space(scenario.ground, scenario.layout)
    streams = np.random.SeedSequence(scenario.seed).spawn(len(groups) + len(sources))
    parts, times = [], []
    for src, stream in zip(sources, streams[len(groups) :], strict=True):
        rng = np.random.default_rng(stream)
        index = scenario.group_index(src.group)
        t = src.times(scenario.duration_s)
        region = src.region if src.region is not None else groups[index].spawn
        position = _sample_free(region, rng, len(t), free)
        parts.append(_agents(scenario, index, rng, position))
        times.append(t)
    if not parts:
        empty = spawn_empty(scenario)
        return empty, np.zeros(0)
    columns = [np.concatenate(column) for column in zip(*parts, strict=True)]
    when = np.concatenate(times)
    order = np.argsort(when, kind="stable")
    return Spawn(*(c[order] for c in columns)), when[order]


def spawn_empty(scenario: Scenario) -> Spawn:
    """A :class:`Spawn` of no agents, shaped like the scenario's."""
    k_max = max(1 if g.path is None else len(g.path.waypoints) for g in scenario.groups)
    return Spawn(
        np.zeros((0, 2)),
        np.zeros(0),
        np.zeros(0, np.int32),
        np.zeros(0),
        np.zeros(0),
        np.zeros((0, k_max, 2)),
        np.zeros(0, np.int32),
        np.zeros(0, bool),
        np.zeros((0, 3), np.float32),
    )
