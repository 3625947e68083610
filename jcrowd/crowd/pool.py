"""Sources: agents that appear over time, in a pool of slots of fixed size (static shapes).

A scenario's ``[[sources]]`` add agents while it runs (:func:`jcrowd.scenario.spawn_sources`:
every such agent with its appearance time, drawn on the host). The compiled step cannot grow
the crowd, so the state has a fixed number of *slots*: the agents placed at t = 0 first, then as
many more as :func:`plan_pool` finds the scenario needs at once. A slot whose agent has left
(reached its goal or its open path's end) takes the next agent queued for it.

Planning (host, once, :func:`plan_pool`): agents are handed to slots in order of appearance;
each agent is expected to leave after :func:`expected_stay` (1.5 × its route at its own speed,
plus 5 s; a looping agent never leaves), and takes the slot expected to be free first, or a
new slot when none is. Each slot gets a queue of the agents it will hold, in order.

Stepping (:func:`spawn_due`, inside the compiled step): a slot whose agent is gone and whose
next queued agent's time has come takes that agent — every per-agent field copied from the
*reservoir*, a state built once for all source agents (so their first clips are chosen as for
the agents at t = 0). At most ``budget`` slots take an agent per step; when an agent stays
longer than expected, the one queued behind it waits until the slot is free, and an agent whose
disc would overlap someone already there (or appearing in the same step) waits a step and
tries again — late, never lost, never on top of anyone (``jcrowd run`` reports the agents
still waiting as ``spawn_late``). With the crowd split over devices the overlap test sees the
slot's own device's agents only. The state's
``agent`` says which agent each slot holds (ids: t = 0 agents ``0 … N0 − 1``, source agents
``N0 + row`` in order of appearance; ``−1`` before a slot's first agent).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import fields

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jcrowd.crowd.state import CrowdState
from jcrowd.indexing import first_true

__all__ = ["POOL_FIELDS", "Pool", "expected_stay", "plan_pool", "spawn_due"]

POOL_FIELDS = ("clock", "queue", "next_row", "agent")
"""CrowdState fields that belong to the slot, not to the agent in it (not copied at a spawn)."""


class Pool(eqx.Module):
    """What the step needs to spawn source agents: the ``reservoir`` state (one row per source
    agent, in order of appearance), their appearance ``times`` (s), the id of the first source
    agent (``N0``, the agents at t = 0 before it) and the most slots filled per step."""

    reservoir: CrowdState
    times: Float[Array, " R"]
    first_id: int = eqx.field(static=True)
    budget: int = eqx.field(static=True)


def expected_stay(
    position: Float[np.ndarray, "N 2"],
    waypoints: Float[np.ndarray, "N K 2"],
    num_waypoints: Int[np.ndarray, " N"],
    loop: np.ndarray,
    speed: Float[np.ndarray, " N"],
) -> Float[np.ndarray, " N"]:
    """Seconds each agent is expected to stay: 1.5 × the length of its route (start, then its
    waypoints) at its own speed, + 5 s; ``inf`` for looping agents."""
    pts = np.concatenate([position[:, None, :], waypoints], axis=1)
    legs = np.linalg.norm(np.diff(pts, axis=1), axis=2)  # (N, K)
    real = np.arange(waypoints.shape[1])[None, :] < num_waypoints[:, None]
    length = np.sum(np.where(real, legs, 0.0), axis=1)
    stay = 1.5 * length / np.maximum(speed, 1e-3) + 5.0
    return np.where(loop, np.inf, stay)


def plan_pool(
    initial_stay: Float[np.ndarray, " N0"],
    initial_group: Int[np.ndarray, " N0"],
    times: Float[np.ndarray, " R"],
    stay: Float[np.ndarray, " R"],
    group: Int[np.ndarray, " R"],
    multiple: int = 8,
) -> tuple[Int[np.ndarray, "P Q"], Int[np.ndarray, " P"]]:
    """Each slot's queue of source agents (rows of ``times``, ``−1`` padding) and its group,
    slots ``0 … N0 − 1`` holding the t = 0 agents first. A slot only ever holds agents of one
    group (its colour stays the group's). ``times`` must be sorted. The slot count is rounded
    up to a multiple of ``multiple`` (devices split it evenly); padding slots hold nobody."""
    free: dict[int, list[tuple[float, int]]] = {}
    for k, (s, g) in enumerate(zip(initial_stay, initial_group, strict=True)):
        free.setdefault(int(g), []).append((float(s), k))
    for heap in free.values():
        heapq.heapify(heap)
    queues: list[list[int]] = [[] for _ in range(len(initial_stay))]
    groups = [int(g) for g in initial_group]
    for row, (t, s, g) in enumerate(zip(times, stay, group, strict=True)):
        heap = free.setdefault(int(g), [])
        if heap and heap[0][0] <= t:
            _, slot = heapq.heappop(heap)
        else:
            slot = len(queues)
            queues.append([])
            groups.append(int(g))
        queues[slot].append(row)
        heapq.heappush(heap, (float(t + s), slot))
    p = max(1, math.ceil(len(queues) / multiple)) * multiple
    q = max((len(x) for x in queues), default=0)
    out = np.full((p, q), -1, np.int32)
    for slot, rows in enumerate(queues):
        out[slot, : len(rows)] = rows
    slot_group = np.zeros(p, np.int32)
    slot_group[: len(groups)] = groups
    return out, slot_group


def spawn_due(
    state: CrowdState,
    reservoir: CrowdState,
    times: Float[Array, " R"],
    first_id: int,
    budget: int,
) -> CrowdState:
    """Slots whose agent is gone take their next queued agent once its time has come (at most
    ``budget`` slots per call, and not while the agent's disc would overlap an alive agent's or
    that of an agent taken earlier in the call): every per-agent field from the reservoir's
    row, ``alive``, and the slot's ``agent`` = ``first_id + row``."""
    n, q = state.num_agents, state.queue.shape[1]
    at = jnp.minimum(state.next_row, q - 1)
    row = jnp.take_along_axis(state.queue, at[:, None], axis=1)[:, 0]
    queued = (state.next_row < q) & (row >= 0)
    due = ~state.alive & queued & (times[jnp.maximum(row, 0)] <= state.clock)
    idx = first_true(due, min(budget, n), n)
    rows = row[jnp.minimum(idx, n - 1)]
    # An agent whose disc would overlap someone's waits (its slot tries again next step): the
    # agents alive in this block, and the agents appearing before it in this call.
    safe_rows = jnp.maximum(rows, 0)
    rx, rz, rr = (getattr(reservoir, k)[safe_rows] for k in ("x", "z", "radius"))
    d2 = (rx[:, None] - state.x[None, :]) ** 2 + (rz[:, None] - state.z[None, :]) ** 2
    reach = rr[:, None] + state.radius[None, :]
    blocked = jnp.any(state.alive[None, :] & (d2 < reach * reach), axis=1)
    e2 = (rx[:, None] - rx[None, :]) ** 2 + (rz[:, None] - rz[None, :]) ** 2
    earlier = jnp.tril(jnp.ones((len(idx), len(idx)), bool), k=-1) & (idx < n)[None, :]
    blocked |= jnp.any(earlier & (e2 < (rr[:, None] + rr[None, :]) ** 2), axis=1)
    idx = jnp.where(blocked, n, idx)
    names = [f.name for f in fields(CrowdState) if f.name not in (*POOL_FIELDS, "interleave")]
    new = [
        getattr(state, k).at[idx].set(getattr(reservoir, k)[jnp.maximum(rows, 0)], mode="drop")
        for k in names
    ]
    state = eqx.tree_at(lambda s: [getattr(s, k) for k in names], state, new)
    agent = state.agent.at[idx].set(first_id + rows, mode="drop")
    next_row = state.next_row.at[idx].add(1, mode="drop")
    return eqx.tree_at(lambda s: (s.agent, s.next_row), state, (agent, next_row))
