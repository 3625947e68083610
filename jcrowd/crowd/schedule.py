"""Clip scheduling in the crowd step: waypoints, the next gait cycle, and the hand-over.

Part 4 of :mod:`jcrowd.crowd.stepping`'s step (paper 000 §5.2): an agent reaching its waypoint
heads for the next (or leaves the crowd at the end of an open path); half way through a cycle it
chooses the next one — kriged for agents being synthesized, the nearest captured cycle for the
rest (:func:`jcrowd.crowd.clips.next_clips_lod`), at most ``refresh`` per step — aiming at its
waypoint, or with the crowd dynamics on, along its simulated velocity
(:func:`jcrowd.crowd.steering.aim_point`); at the cycle's end the next clip takes over.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import jax.numpy as jnp
from jaxtyping import Array, Bool

from jcrowd.crowd.clips import CrowdModel, next_clips_lod
from jcrowd.crowd.state import CrowdState, StepConfig
from jcrowd.crowd.steering import aim_point, current_field, waypoint_xz
from jcrowd.indexing import first_true
from jcrowd.pedestrians.navigation import field_values
from jcrowd.pedestrians.world import World

__all__ = ["PASS_REACH", "schedule"]

PASS_REACH = 2.0
"""With avoidance, a waypoint within this many reaches also counts as passed once the agent is
past it along the next leg: a crowd converging on one point otherwise packs round it, the agents
in front walking on towards the next waypoint against those still arriving."""


def _waypoints(config: StepConfig, state: CrowdState, world: World | None) -> tuple[Array, Array]:
    """Each agent's waypoint after this step, and who is still alive: a waypoint within
    ``reach`` (with avoidance, also one passed along the next leg within ``PASS_REACH``
    reaches; in a layout, on entering its target) is reached; past the last of an open path
    the agent leaves."""
    tx, tz = waypoint_xz(state.waypoints, state.waypoint)
    d2 = (tx - state.x) ** 2 + (tz - state.z) ** 2
    near = d2 < config.reach**2
    if config.avoid:  # in a crowd: also passed once past it along the next leg, near it
        nxt = state.waypoint + 1
        has_next = (nxt < state.num_waypoints) | state.loop
        nx, nz = waypoint_xz(state.waypoints, jnp.where(nxt < state.num_waypoints, nxt, 0))
        past = (state.x - tx) * (nx - tx) + (state.z - tz) * (nz - tz) > 0.0
        near = near | (has_next & past & (d2 < (PASS_REACH * config.reach) ** 2))
    if world is not None and world.nav is not None:  # on entering the target (goal: exit)
        near = field_values(world.nav, current_field(state), state.x, state.z) <= 0.0
    reached = state.alive & near
    wp = state.waypoint + reached.astype(jnp.int32)
    done = wp >= state.num_waypoints
    wp = jnp.where(done & state.loop, 0, jnp.minimum(wp, state.num_waypoints - 1))
    return wp, state.alive & ~(done & ~state.loop)


def _next_clips(
    cm: CrowdModel,
    config: StepConfig,
    state: CrowdState,
    alive: Array,
    wp: Array,
    synthesized: Bool[Array, " N"],
) -> tuple[dict[str, Array], Array]:
    """The next clip of each agent past the middle of its cycle without one (at most
    ``refresh`` a step, kriged within ``krige_budget``): the slot's new control, mix and
    duration and ``has_next``; and how many choices wait a step."""
    n = state.num_agents
    last = float(cm.frames - 1)
    need = alive & ~state.has_next & (state.tau >= last / 2)
    idx = first_true(need, min(config.refresh or n // 32 + 64, n), n)
    safe = jnp.where(idx < n, idx, 0)
    origin = jnp.stack(
        [state.origin_x[safe], state.origin_z[safe], state.origin_heading[safe]], axis=1
    )
    budget = config.krige_budget or sum(config.capacities) // 32 + 64
    if config.avoid:  # the next cycle follows the simulated velocity, not the waypoint
        aim = aim_point(
            state.x[safe],
            state.z[safe],
            state.vx[safe],
            state.vz[safe],
            state.heading[safe],
            1.5 * cm.cycle_seconds,
        )
        pace = jnp.sqrt(state.vx[safe] ** 2 + state.vz[safe] ** 2)
    else:
        aim, pace = state.waypoints[safe, wp[safe]], state.speed[safe]
    c, a, dur, done = next_clips_lod(
        cm,
        origin,
        state.control[safe, state.current[safe]],
        aim,
        pace,
        state.height[safe],
        config.min_reliability,
        synthesized[safe] & (idx < n),
        budget,
    )
    idx = jnp.where(done, idx, n)  # choices beyond the kriging budget wait a step
    slot = 1 - state.current[safe]
    chosen = {
        "control": state.control.at[idx, slot].set(c, mode="drop"),
        "mix": state.mix.at[idx, slot].set(a, mode="drop"),
        "duration": state.duration.at[idx, slot].set(dur, mode="drop"),
        "has_next": state.has_next.at[idx].set(True, mode="drop"),
    }
    deferred = jnp.sum(need, dtype=jnp.int32) - jnp.sum(idx < n, dtype=jnp.int32)
    return chosen, deferred


def schedule(
    cm: CrowdModel,
    config: StepConfig,
    state: CrowdState,
    synthesized: Bool[Array, " N"],
    world: World | None = None,
) -> tuple[CrowdState, Array]:
    """Waypoints, next-clip choice at mid-cycle (bounded per step) and clip hand-over.

    In a ``world`` with a layout a waypoint is reached on entering its navigation target
    (field ≤ 0, see :mod:`jcrowd.pedestrians.scene`: the reach disc cut by walls, or the goal
    region, so a goal region works as an exit), never through a wall.

    Agents synthesized this step get a kriged next clip, the others the nearest captured cycle
    to the controls they aim at (:func:`jcrowd.crowd.clips.next_clips_lod`).
    """
    last = float(cm.frames - 1)
    wp, alive = _waypoints(config, state, world)
    chosen, deferred = _next_clips(cm, config, state, alive, wp, synthesized)
    wrap = state.tau >= last
    take = wrap & chosen["has_next"]
    # Only what scheduling changes; every other field (the slot's, the dynamics') passes through.
    changed: dict[str, Any] = {
        **chosen,
        "tau": jnp.where(wrap, state.tau - last, state.tau),
        "current": jnp.where(take, 1 - state.current, state.current),
        "has_next": chosen["has_next"] & ~take,
        "origin_x": jnp.where(wrap, state.x, state.origin_x),
        "origin_z": jnp.where(wrap, state.z, state.origin_z),
        "origin_heading": jnp.where(wrap, state.heading, state.origin_heading),
        "far_valid": state.far_valid & ~take,
        "alive": alive,
        "waypoint": wp,
    }
    return replace(state, **changed), deferred
