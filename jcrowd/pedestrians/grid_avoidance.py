"""The avoidance model evaluated through the neighbour grid, reading only as many candidates as
each agent has (:func:`avoid_in_grid`).

:func:`jcrowd.pedestrians.avoidance.avoid` takes a fixed number of candidate ids per agent. In a
crowd most agents have few neighbours and a few have many, so the step reads candidates in tiers
(:data:`CANDIDATE_TIERS`): everyone with the first tier's count, then only the agents that
filled it with the next, in the smallest bucket of agents that holds them
(:data:`BUCKET_DIVISORS`). The crowd is read in the grid's cell order
(:class:`~jcrowd.pedestrians.neighbours.CellList`), so a candidate is one read.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from functools import partial

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.indexing import first_true
from jcrowd.pedestrians.avoidance import avoid_rows, crowd_table
from jcrowd.pedestrians.neighbours import CellList, GridSpec, near_places
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.pedestrians.reaction import Motion

__all__ = ["BUCKET_DIVISORS", "CANDIDATE_TIERS", "avoid_in_grid"]

CANDIDATE_TIERS = (8, 32)
"""Candidates read per agent, tier by tier (:func:`avoid_in_grid`): an agent whose 3 × 3 cells
hold fewer others than a tier's count has them all there; a denser one moves on to the next
tier, and past the last to nine full cells."""

BUCKET_DIVISORS = (64, 8)
"""The agents moving on to a tier are evaluated in the smallest bucket of ``N / d`` agents
(at least 64) that holds them all, else all ``N`` agents are (one branch runs)."""


def avoid_in_grid(
    params: AvoidanceParams,
    grid: GridSpec,
    cells: CellList,
    position: Float[Array, "n 2"],
    desired: Float[Array, "n 2"],
    speed: Float[Array, " n"],
    radius: Float[Array, " n"],
    alive: Bool[Array, " n"],
    others: tuple[Array, Array],
    rows: Int[Array, " n"],
    walls: Float[Array, "S 2 2"],
    wall_ids: Int[Array, "n W"],
    motion: Motion | None = None,
    horizon: Float[Array, "*n"] | None = None,
) -> Float[Array, "n 2"]:
    """:func:`avoid` for agents whose neighbours are the crowd in ``cells``, reading only as
    many candidates as each agent has. Agents not alive get velocity 0. With ``motion``
    (``crowd`` in the rows of ``others``) the agents anticipate.

    ``others = (positions (P, 2), radii (P,))`` is the crowd ``cells`` was filled from and
    ``rows`` the agents' own ids in it (they are not their own neighbours). The crowd is read
    in cell order (:class:`~jcrowd.pedestrians.neighbours.CellList`), so a candidate is one read.
    Everyone is first evaluated with the first :data:`CANDIDATE_TIERS` ``[0]`` candidates; an
    agent with that many or more is evaluated again with the next tier's count (the last tier
    holds nine full cells), in the smallest bucket of :data:`BUCKET_DIVISORS` that holds all
    such agents, or all agents at that tier when none does (one branch runs). ``horizon``:
    as :func:`~jcrowd.pedestrians.avoidance.avoid`'s (the speed cap of agents updated only every
    few steps). Same
    velocities as :func:`avoid` with :func:`~jcrowd.pedestrians.neighbours.candidates`, but for the
    order of the sums.
    """
    n = position.shape[0]
    pos, rad = others
    # The crowd's rows in cell order, then the "no candidate" row: places index it directly.
    table = crowd_table(pos, rad, None if motion is None else motion.crowd)
    table = table[jnp.concatenate([cells.order, jnp.full((1,), pos.shape[0], jnp.int32)])]
    none = cells.order.shape[0]  # the place past the last: no candidate
    own = cells.place[rows]

    def velocities(sel: Array, near: Array) -> Array:
        moving = None if motion is None else motion.rows(sel)
        h = None if horizon is None else (horizon[sel] if jnp.ndim(horizon) else horizon)
        v, _ = avoid_rows(
            params,
            position[sel],
            desired[sel],
            speed[sel],
            radius[sel],
            table[near],
            near < none,
            walls,
            wall_ids[sel],
            moving,
            h,
        )
        return v

    tiers = [k for k in CANDIDATE_TIERS if k < 9 * grid.capacity] + [9 * grid.capacity]
    near, count = near_places(grid, cells, position, tiers[0], own)
    velocity = velocities(jnp.arange(n, dtype=jnp.int32), near)
    for below, k in itertools.pairwise(tiers):
        dense = alive & (count >= below)
        velocity = _next_tier(grid, cells, position, own, dense, k, velocities, velocity)
    return jnp.where(alive[:, None], velocity, 0.0)


def _next_tier(
    grid: GridSpec,
    cells: CellList,
    position: Array,
    own: Array,
    dense: Array,
    k: int,
    velocities: Callable[[Array, Array], Array],
    velocity: Array,
) -> Array:
    """The velocities with the ``dense`` agents evaluated again with ``k`` candidates, in the
    smallest bucket of :data:`BUCKET_DIVISORS` that holds them, else all agents (one branch
    runs)."""
    n = position.shape[0]
    buckets = sorted({min(n, max(64, n // d)) for d in BUCKET_DIVISORS})
    n_dense = jnp.sum(dense, dtype=jnp.int32)

    def keep(velocity: Array) -> Array:
        return velocity

    def in_bucket(velocity: Array, *, b: int) -> Array:
        idx = first_true(dense, b, n)
        safe = jnp.where(idx < n, idx, 0)
        full, _ = near_places(grid, cells, position[safe], k, own[safe])
        return velocity.at[idx].set(velocities(safe, full), mode="drop")

    def all_agents(velocity: Array) -> Array:
        full, _ = near_places(grid, cells, position, k, own)
        return velocities(jnp.arange(n, dtype=jnp.int32), full)

    branches: list[Callable[[Array], Array]] = [
        keep,
        *(partial(in_bucket, b=b) for b in buckets),
        all_agents,
    ]
    larger = sum((n_dense > b).astype(jnp.int32) for b in buckets)
    which = jnp.where(n_dense == 0, 0, 1 + larger)
    return jax.lax.switch(which, branches, velocity)
