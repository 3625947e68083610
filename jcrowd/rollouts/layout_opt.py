"""Layout optimisation: move obstacles so a scenario's room empties fastest.

A scenario's geometry is parametrised by the numbers at a few TOML key paths of its
``[[obstacles]]`` (``obstacles[2].center[0]``, ``size[k]``, ``radius``, ``points[j][k]``;
:mod:`jcrowd.scenario.keys`), each within bounds. :func:`layout_problem` fixes everything
else, :func:`layout_setup` builds the world at one parameter vector ``θ`` on the host,
:func:`layout_objective` runs the rollout and reads the objective, and
:func:`~jcrowd.rollouts.search.projected_gradient` minimises it within the bounds.

Readings taken:

- **The navigation field is rebuilt at every outer iterate and frozen inside the gradient**:
  ``jax.grad`` reaches the walls' repulsion, slide and spacing, not people re-routing. The
  forward objective (:func:`forward_value`) rebuilds the field at each ``θ`` and is what the
  line search compares, so an accepted step lowers the true objective. The field's 0.2 m cells
  make the forward objective piecewise smooth with small steps.
- **Obstacle walls are functions of ``θ``**: the free space's boundary without the varied
  obstacles (built once) plus each varied obstacle's outline computed in JAX from ``θ``
  (a rectangle's sides, a circle's 64-gon, a polygon's edges). Per-cell wall lists are padded to
  a power of two so moving an obstacle seldom recompiles.
- **Agents** are spawned once from the scenario as written, so layouts differ only in layout.
  An agent inside a varied obstacle at some ``θ`` is an error naming the key to bound tighter.
  Only groups with a ``goal`` and no ``[[sources]]``.
- **Objectives** (minimised), from each agent's soft "out" ``o_i(t) = σ((d − D_i(x_i(t)))/τ_c)``
  within ``d`` = 1 m of its goal by walking distance, ``τ_c`` = 0.1 m: ``travel_time``, the mean
  censored exit time ``T_i = Σ_k Δt (1 − o_i(t_k))``; ``evacuation``, the soft maximum
  ``τ_E log((1/N) Σ_i exp(T_i/τ_E))``, ``τ_E`` = 1 s; ``flow``, minus ``(1/T) Σ_i o_i(T)``.
- **A jam's gradient is not the objective's slope** (:mod:`jcrowd.rollouts.rollout`, "Limits"),
  so the optimiser uses only the gradient's direction and judges every step by the forward
  objective. Where nobody queues the gradient of every objective equals central differences
  (``tests/test_optimize.py``). docs/design/rollouts.md has the measurements.

Conventions: positions ``[x, z]`` in metres, time in seconds; ``θ`` in the key paths' units.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import shapely
from jaxtyping import Array, Float

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians.navigation import (
    Navigation,
    distance_field,
    field_grid,
    field_values,
    rasterize,
)
from jcrowd.pedestrians.neighbours import grid_spec
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.pedestrians.scene import CLEARANCE_M, NAV_CELL_M
from jcrowd.pedestrians.step import Pedestrians
from jcrowd.pedestrians.world import World, wall_segments, walls_near_cells
from jcrowd.rollouts.rollout import COUNT_TEMPERATURE, RolloutParams, RolloutSetup, rollout
from jcrowd.scenario.geometry import Region
from jcrowd.scenario.keys import Varied, with_values
from jcrowd.scenario.layout import Layout, free_space, region_shape
from jcrowd.scenario.schema import Scenario
from jcrowd.scenario.spawning import spawn

__all__ = [
    "EMPTY_TEMPERATURE",
    "OBJECTIVES",
    "OUT_DEPTH",
    "LayoutProblem",
    "forward_value",
    "layout_objective",
    "layout_problem",
    "layout_setup",
    "obstacle_walls",
    "value_and_gradient",
]

OBJECTIVES = ("evacuation", "flow", "travel_time")
"""The objectives :func:`layout_objective` reads (module docstring)."""

EMPTY_TEMPERATURE = 1.0
"""``τ_E`` (s) of the soft time to empty."""

OUT_DEPTH = 1.0
"""``d`` (m): an agent within this walking distance of its goal counts as out."""

_CIRCLE_SIDES = 64  # region_shape draws a circle as a 64-gon (quad_segs=16)
_GRID_CELL_M = 1.6  # the simulator's neighbour grid cell (jcrowd.crowd.simulate)
_GRID_DENSITY = 8.0  # agents per m² a cell holds (× 1.5): queues at a door are dense


# ------------------------------------------------------------------------------ geometry


def _outline(kind: str, values: Float[Array, " P"]) -> Float[Array, "E 2 2"]:
    """The sides ``(E, 2, 2)`` of one obstacle from its numbers, laid out as :func:`_flat`
    lays them out."""
    if kind == "rect":
        c, half = values[:2], 0.5 * values[2:4]
        lo, hi = c - half, c + half
        corners = jnp.stack([lo, jnp.stack([hi[0], lo[1]]), hi, jnp.stack([lo[0], hi[1]])])
    elif kind == "circle":
        a = jnp.asarray(np.arange(_CIRCLE_SIDES) * (2 * np.pi / _CIRCLE_SIDES), values.dtype)
        corners = values[:2] + values[2] * jnp.stack([jnp.cos(a), jnp.sin(a)], axis=1)
    else:
        corners = values.reshape(-1, 2)
    return jnp.stack([corners, jnp.roll(corners, -1, axis=0)], axis=1)


def _flat(region: Region) -> np.ndarray:
    """An obstacle's numbers as one vector: rect ``[cx, cz, w, d]``, circle ``[cx, cz, r]``,
    polygon its points row by row."""
    if region.kind == "rect":
        return np.concatenate([region.center, region.size]).astype(np.float64)
    if region.kind == "circle":
        return np.asarray([*region.center, region.radius], np.float64)
    return np.asarray(region.points, np.float64).reshape(-1)


def _slot(region: Region, v: Varied) -> int:
    """Where ``v`` sits in :func:`_flat`'s vector."""
    if v.field == "points":
        return 2 * v.index[0] + v.index[1]
    return {"center": 0, "size": 2, "radius": 2}[v.field] + (v.index[0] if v.index else 0)


class LayoutGeometry(eqx.Module):
    """The walls as a function of ``θ``: the fixed ones and the varied obstacles' numbers.

    Attributes:
        fixed: ``(S0, 2, 2)`` the free space's boundary without the varied obstacles.
        base: per varied obstacle, its numbers at the scenario as written (:func:`_flat`).
        kinds: per varied obstacle, ``"rect"``, ``"circle"`` or ``"polygon"``.
        slots: per ``θ_j``, ``(which varied obstacle, position in its numbers)``.
    """

    fixed: Float[Array, "S0 2 2"]
    base: tuple[Float[Array, " P"], ...]
    kinds: tuple[str, ...] = eqx.field(static=True)
    slots: tuple[tuple[int, int], ...] = eqx.field(static=True)


def obstacle_walls(geometry: LayoutGeometry, theta: Float[Array, " V"]) -> Float[Array, "S 2 2"]:
    """Every wall segment at ``θ`` (m): the fixed ones, then each varied obstacle's outline;
    differentiable in ``θ``. The count ``S`` does not depend on ``θ``."""
    values = [b.astype(theta.dtype) for b in geometry.base]
    for j, (o, pos) in enumerate(geometry.slots):
        values[o] = values[o].at[pos].set(theta[j])
    parts = [geometry.fixed.astype(theta.dtype)]
    parts += [_outline(k, v) for k, v in zip(geometry.kinds, values, strict=True)]
    return jnp.concatenate(parts)


# ------------------------------------------------------------------------------ the problem


@dataclass(frozen=True, eq=False)
class LayoutProblem:
    """What stays fixed while ``θ`` moves (host side; built by :func:`layout_problem`).

    Attributes:
        scenario: the scenario as written.
        varied: the varied numbers, in ``θ``'s order.
        objective: one of :data:`OBJECTIVES`.
        peds: the agents at ``t = 0`` (spawned once).
        geometry: the walls as a function of ``θ`` (its ``fixed`` and ``base`` as built).
        steps, dt: the time grid (the scenario's duration and fps).
        avoidance: the avoidance model's parameters.
        depth: ``d`` (m) of the "out" indicator.
        adjoint_decay: ``γ`` of the rollout's truncated backpropagation (1: exact gradient;
            :class:`~jcrowd.rollouts.rollout.RolloutSetup`).
    """

    scenario: Scenario
    varied: tuple[Varied, ...]
    objective: str
    peds: Pedestrians
    geometry: LayoutGeometry
    steps: int
    dt: float
    avoidance: AvoidanceParams
    depth: float = OUT_DEPTH
    adjoint_decay: float = 1.0

    @property
    def lower(self) -> np.ndarray:
        return np.asarray([v.lower for v in self.varied])

    @property
    def upper(self) -> np.ndarray:
        return np.asarray([v.upper for v in self.varied])

    @property
    def start(self) -> np.ndarray:
        """``θ`` of the scenario as written."""
        obstacles = self.scenario.layout.obstacles
        return np.asarray(
            [_flat(obstacles[v.obstacle])[_slot(obstacles[v.obstacle], v)] for v in self.varied]
        )


def layout_problem(
    scenario: Scenario,
    varied: Sequence[Varied],
    objective: str,
    *,
    avoidance: AvoidanceParams | None = None,
    steps: int | None = None,
    depth: float = OUT_DEPTH,
    adjoint_decay: float = 1.0,
    dtype: Any = jnp.float32,
) -> LayoutProblem:
    """Fix a scenario's crowd, time grid and fixed walls for optimising ``varied``.

    Raises:
        JcrowdError: an unknown objective, no or repeated varied keys, groups with a path,
            ``[[sources]]``, avoidance off, or ``steps`` below 1.
    """
    src = scenario.source
    if objective not in OBJECTIVES:
        raise JcrowdError(
            f"optimize: expected an objective in {', '.join(OBJECTIVES)}, found {objective!r}"
        )
    keys = [v.key for v in varied]
    if not keys or len(set(keys)) != len(keys):
        raise JcrowdError(f"{src}: expected one or more distinct keys to vary, found {keys}")
    bad = [f"groups[{i}]" for i, g in enumerate(scenario.groups) if g.goal is None]
    if bad:
        raise JcrowdError(
            f"{src}: {bad[0]}: expected a group with a goal (the optimiser rolls "
            "out agents walking to their goal and leaving), found a path"
        )
    if scenario.sources:
        raise JcrowdError(
            f"{src}: sources: expected no [[sources]] (the optimiser's crowd is "
            f"the one spawned at t = 0), found {len(scenario.sources)}"
        )
    if not scenario.dynamics.avoid:
        raise JcrowdError(f"{src}: dynamics.avoid: expected true, found false")
    steps = round(scenario.duration_s * scenario.fps) if steps is None else steps
    if steps < 1:
        raise JcrowdError(f"optimize: expected at least one step, found {steps}")
    sp = spawn(scenario)
    n = sp.num_agents
    peds = Pedestrians(
        jnp.asarray(sp.position, dtype),
        jnp.asarray(sp.group, jnp.int32),  # one field per group: its goal
        jnp.asarray(sp.speed, dtype),
        jnp.full(n, scenario.dynamics.radius, dtype),
        jnp.ones(n, bool),
        jnp.zeros((n, 2), dtype),
        scenario.dynamics.model == "anticipation",
    )
    moved = sorted({v.obstacle for v in varied})
    obstacles = scenario.layout.obstacles
    kept = tuple(o for i, o in enumerate(obstacles) if i not in moved)
    rest = Layout(kept, scenario.layout.walls, scenario.layout.walkable)
    geometry = LayoutGeometry(
        jnp.asarray(wall_segments(free_space(scenario.ground, rest))),
        tuple(jnp.asarray(_flat(obstacles[i]), dtype) for i in moved),
        tuple(obstacles[i].kind for i in moved),
        tuple((moved.index(v.obstacle), _slot(obstacles[v.obstacle], v)) for v in varied),
    )
    return LayoutProblem(
        scenario,
        tuple(varied),
        objective,
        peds,
        geometry,
        steps,
        1.0 / scenario.fps,
        AvoidanceParams() if avoidance is None else avoidance,
        depth,
        adjoint_decay,
    )


class LayoutSetup(eqx.Module):
    """One outer iterate's world (fields and wall lists at ``θ``) and what the objective reads."""

    rollout: RolloutSetup
    geometry: LayoutGeometry
    avoidance: AvoidanceParams
    objective: str = eqx.field(static=True)
    depth: float = eqx.field(static=True)


def layout_setup(problem: LayoutProblem, theta: Sequence[float] | np.ndarray) -> LayoutSetup:
    """Build the world at ``θ`` on the host: free space, one field per group's goal, the
    neighbour grid's wall lists (module docstring).

    Raises:
        JcrowdError: ``θ`` outside the bounds, an agent inside a varied obstacle, or a layout
            the scenario's checks refuse.
    """
    theta = np.asarray(theta, np.float64)
    src = problem.scenario.source
    for v, x in zip(problem.varied, theta, strict=True):
        if not v.lower - 1e-9 <= x <= v.upper + 1e-9:
            raise JcrowdError(
                f"{src}: {v.key}: expected a value in [{v.lower:g}, {v.upper:g}], found {x:g}"
            )
    scenario = with_values(problem.scenario, problem.varied, theta)
    space = free_space(scenario.ground, scenario.layout)
    fg = field_grid(
        np.asarray(problem.geometry.fixed).reshape(-1, 2).min(0),
        np.asarray(problem.geometry.fixed).reshape(-1, 2).max(0),
        NAV_CELL_M,
    )
    free = rasterize(fg, space)
    fields = []
    for i, g in enumerate(scenario.groups):
        try:
            goal = rasterize(fg, region_shape(g.goal).intersection(space))  # type: ignore[arg-type]
            fields.append(distance_field(fg, free, goal, clearance=CLEARANCE_M))
        except JcrowdError as err:
            raise JcrowdError(
                f"{src}: groups[{i}].goal: {err} (at {_show(problem, theta)})"
            ) from None
    xz = np.asarray(problem.peds.position, np.float64)
    for v in problem.varied:
        # An agent's disc touching the obstacle (radius as spawned, m).
        shape = region_shape(scenario.layout.obstacles[v.obstacle]).buffer(
            float(np.max(np.asarray(problem.peds.radius)))
        )
        inside = np.asarray(shapely.contains_xy(shape, xz[:, 0], xz[:, 1]))
        if inside.any():
            raise JcrowdError(
                f"{src}: {v.key}: expected bounds keeping obstacles[{v.obstacle}] off the agents, "
                f"found agent {int(np.argmax(inside))} inside it at {_show(problem, theta)}"
            )
    walls = np.asarray(obstacle_walls(problem.geometry, jnp.asarray(theta)), np.float32)
    lo, hi = scenario.ground.bounds()
    m = _GRID_CELL_M
    spec = grid_spec((lo[0] - m, lo[1] - m), (hi[0] + m, hi[1] + m), m, max_density=_GRID_DENSITY)
    near = walls_near_cells(spec, walls)
    width = 1 << max(0, near.shape[1] - 1).bit_length()  # padded: fewer distinct shapes
    near = np.pad(near, ((0, 0), (0, width - near.shape[1])), constant_values=len(walls))
    dtype = problem.peds.speed.dtype
    world = World(
        Navigation(jnp.asarray(np.stack(fields), dtype), fg),
        jnp.asarray(walls, dtype),
        jnp.asarray(near),
        spec,
    )
    setup = RolloutSetup(
        world, problem.peds, steps=problem.steps, dt=problem.dt, adjoint_decay=problem.adjoint_decay
    )
    return LayoutSetup(setup, problem.geometry, problem.avoidance, problem.objective, problem.depth)


def _show(problem: LayoutProblem, theta: np.ndarray) -> str:
    return ", ".join(f"{v.key} = {x:g}" for v, x in zip(problem.varied, theta, strict=True))


# ------------------------------------------------------------------------------ objectives


def layout_objective(theta: Float[Array, " V"], setup: LayoutSetup) -> tuple[Array, Array]:
    """The objective at ``θ`` (minimised; module docstring) and the neighbour grid's overflow
    (0: the run is the model's). Differentiable in ``θ`` with the world held at its iterate."""
    walls = obstacle_walls(setup.geometry, theta)
    peds = setup.rollout.peds
    params = RolloutParams(
        setup.avoidance,
        peds.speed.astype(theta.dtype),
        walls,
        jnp.zeros((0,), theta.dtype),
        jnp.ones((), theta.dtype),
    )
    traj = rollout(params, setup.rollout)
    x = traj.position.astype(theta.dtype)
    nav = cast(Navigation, setup.rollout.world.nav)  # layout_setup builds the fields
    depth = field_values(nav, peds.target, x[..., 0], x[..., 1])
    out = jax.nn.sigmoid((setup.depth - depth.astype(theta.dtype)) / COUNT_TEMPERATURE)
    dt = setup.rollout.dt
    if setup.objective == "flow":
        value = -jnp.sum(out[-1]) / (setup.rollout.steps * dt)
    else:
        exit_time = dt * jnp.sum(traj.entered[:-1] * (1.0 - out[:-1]), axis=0)  # (N,)
        if setup.objective == "travel_time":
            value = jnp.mean(exit_time)
        else:
            n = exit_time.shape[0]
            value = EMPTY_TEMPERATURE * (
                jax.nn.logsumexp(exit_time / EMPTY_TEMPERATURE) - math.log(n)
            )
    return value, traj.overflow


_forward = jax.jit(layout_objective)
_value_and_grad = jax.jit(jax.value_and_grad(layout_objective, has_aux=True))


def _checked(problem: LayoutProblem, theta: np.ndarray, overflow: Any) -> None:
    if int(overflow) > 0:
        raise JcrowdError(
            f"{problem.scenario.source}: expected the neighbour grid to hold the crowd, found "
            f"{int(overflow)} agents over its capacity at {_show(problem, theta)}"
        )


def forward_value(problem: LayoutProblem, theta: Sequence[float] | np.ndarray) -> float:
    """The objective at ``θ`` with the world rebuilt there: one forward simulation."""
    x = np.asarray(theta, np.float64)
    setup = layout_setup(problem, x)
    value, overflow = _forward(jnp.asarray(x, problem.peds.speed.dtype), setup)
    _checked(problem, x, overflow)
    return float(value)


def value_and_gradient(
    problem: LayoutProblem, theta: Sequence[float] | np.ndarray
) -> tuple[float, np.ndarray]:
    """The objective and its gradient at ``θ`` (world rebuilt at ``θ``, then frozen)."""
    x = np.asarray(theta, np.float64)
    setup = layout_setup(problem, x)
    (value, overflow), grad = _value_and_grad(jnp.asarray(x, problem.peds.speed.dtype), setup)
    _checked(problem, x, overflow)
    return float(value), np.asarray(grad, np.float64)
