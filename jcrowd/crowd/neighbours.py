"""Who is near whom: a uniform cell grid with a static capacity per cell and a counted overflow.

The pattern of JAX MD's cell lists (``jax_md/partition.py``): the host sizes the grid once
(:func:`grid_spec`: origin, cell size, cells, slots per cell, with headroom), and the compiled
step fills it with fixed shapes (:func:`cell_list`), reporting how many agents found their cell
full instead of dropping them silently. (JAX MD sorts the particles by cell; here slots are
claimed in rounds of scatters, which on XLA:CPU is several times faster than sorting the
crowd.) An agent's candidates are the agents stored in the 3 × 3
cells around its own (:func:`candidates`); with cells at least as large as the interaction
range, every agent within that range of it is among them unless its cell overflowed.

Conventions: ground positions are ``[x, z]`` in metres (the crowd step's layout); agent ids run
``0 … N − 1`` and ``N`` marks an empty slot. Positions outside the grid are clamped into its
border cells, so nobody is lost; the grid should still cover the walkable area, or the border
cells fill up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.errors import JcrowdError

__all__ = [
    "CellList",
    "GridSpec",
    "candidates",
    "cell_index",
    "cell_list",
    "compact_candidates",
    "grid_spec",
]


@dataclass(frozen=True)
class GridSpec:
    """The static shape of a cell grid (host side; part of the compiled step's static config).

    Attributes:
        origin: ``(x, z)`` of the grid's lower corner (m).
        cell: cell edge (m), at least the interaction range.
        shape: cells along x and along z.
        capacity: agent slots per cell.
    """

    origin: tuple[float, float]
    cell: float
    shape: tuple[int, int]
    capacity: int

    @property
    def num_cells(self) -> int:
        return self.shape[0] * self.shape[1]


def grid_spec(
    lo: tuple[float, float],
    hi: tuple[float, float],
    cell: float,
    *,
    max_density: float = 8.0,
    headroom: float = 1.5,
) -> GridSpec:
    """A grid covering the rectangle ``lo``–``hi`` (m) with cells of ``cell`` metres.

    The capacity holds ``max_density`` agents per m² (8 /m² is beyond the densest crowds
    measured in the shared experiments, 9.3 /m² at its peak in front of a bottleneck, averaged
    over a cell) times ``headroom``, and at least 4 slots.

    Raises:
        JcrowdError: a cell that is not positive or a rectangle without area.
    """
    if not cell > 0:
        raise JcrowdError(f"grid: expected a positive cell size, found {cell}")
    if not (hi[0] > lo[0] and hi[1] > lo[1]):
        raise JcrowdError(f"grid: expected hi > lo on both axes, found lo={lo}, hi={hi}")
    nx = max(1, math.ceil((hi[0] - lo[0]) / cell))
    nz = max(1, math.ceil((hi[1] - lo[1]) / cell))
    capacity = max(4, math.ceil(max_density * cell * cell * headroom))
    return GridSpec((float(lo[0]), float(lo[1])), float(cell), (nx, nz), capacity)


class CellList(eqx.Module):
    """Agents sorted into cells.

    Attributes:
        slots: ``(cells, capacity)`` agent ids per cell, ``N`` where empty; cell ``ix·nz + iz``.
        cell: ``(N,)`` each agent's cell (``cells`` for agents that are not alive).
        overflow: agents alive but not stored because their cell was full.
    """

    slots: Int[Array, "C K"]
    cell: Int[Array, " N"]
    overflow: Int[Array, ""]


def _cell_coords(spec: GridSpec, position: Float[Array, "N 2"]) -> tuple[Array, Array]:
    """Integer cell coordinates ``(ix, iz)``, clamped into the grid."""
    ix = jnp.floor((position[:, 0] - spec.origin[0]) / spec.cell).astype(jnp.int32)
    iz = jnp.floor((position[:, 1] - spec.origin[1]) / spec.cell).astype(jnp.int32)
    return jnp.clip(ix, 0, spec.shape[0] - 1), jnp.clip(iz, 0, spec.shape[1] - 1)


def cell_index(spec: GridSpec, position: Float[Array, "N 2"]) -> Int[Array, " N"]:
    """Each position's cell ``ix·nz + iz`` (clamped into the grid)."""
    ix, iz = _cell_coords(spec, position)
    return ix * spec.shape[1] + iz


def cell_list(spec: GridSpec, position: Float[Array, "N 2"], alive: Bool[Array, " N"]) -> CellList:
    """Sort the alive agents into the grid's cells, ``capacity`` per cell, in agent order.

    Slots are claimed in rounds: in round ``r`` every cell takes the lowest id among its
    agents not yet placed into its slot ``r`` (a scatter-min over the agents), until every
    agent is placed or the slots run out; the agents left over are counted in ``overflow``.
    Within a cell ids are thus increasing — the order a stable sort by cell gives — at a few
    scatters per occupied slot instead of a sort of the whole crowd (the rounds stop at the
    fullest cell's count, a handful where people walk apart).
    """
    n, ncell = position.shape[0], spec.num_cells
    ix, iz = _cell_coords(spec, position)
    cell = jnp.where(alive, ix * spec.shape[1] + iz, ncell).astype(jnp.int32)
    ids = jnp.arange(n, dtype=jnp.int32)

    def more(carry: tuple[Array, Array, Array]) -> Array:
        r, placed, _ = carry
        return (r < spec.capacity) & ~jnp.all(placed)

    def round_(carry: tuple[Array, Array, Array]) -> tuple[Array, Array, Array]:
        r, placed, slots = carry
        key = jnp.where(placed, ncell, cell)
        lowest = jnp.full((ncell,), n, jnp.int32).at[key].min(ids, mode="drop")
        won = ~placed & (lowest[jnp.minimum(key, ncell - 1)] == ids)
        slots = slots.at[jnp.where(won, cell, ncell), r].set(ids, mode="drop")
        return r + 1, placed | won, slots

    start = (
        jnp.zeros((), jnp.int32),
        cell >= ncell,
        jnp.full((ncell, spec.capacity), n, jnp.int32),
    )
    _, placed, slots = jax.lax.while_loop(more, round_, start)
    overflow = jnp.sum(~placed, dtype=jnp.int32)
    return CellList(slots, cell, overflow)


def candidates(
    spec: GridSpec, cells: CellList, position: Float[Array, "n 2"], ids: Array | None = None
) -> Int[Array, "n M"]:
    """Each agent's candidate neighbours: the ids stored in the 3 × 3 cells around it.

    ``position`` is the agents asked about: all the agents ``cells`` holds (``N``, the
    default), or some of them whose ids in ``cells`` are ``ids`` (one device's block of a crowd
    split over several). Returns ``(n, 9·capacity)`` ids, ``N`` where a slot is empty, a cell
    lies outside the grid or the id is the agent itself. Every agent within ``spec.cell`` of an
    agent (and stored) is among its candidates.
    """
    n = cells.cell.shape[0]
    own = jnp.arange(n, dtype=jnp.int32) if ids is None else ids.astype(jnp.int32)
    ix, iz = _cell_coords(spec, position)
    out = []
    for dx in (-1, 0, 1):
        for dz in (-1, 0, 1):
            jx, jz = ix + dx, iz + dz
            inside = (jx >= 0) & (jx < spec.shape[0]) & (jz >= 0) & (jz < spec.shape[1])
            c = jnp.where(inside, jx * spec.shape[1] + jz, 0)
            out.append(jnp.where(inside[:, None], cells.slots[c], n))  # (n, capacity) each
    found = jnp.concatenate(out, axis=1)
    return jnp.where(found == own[:, None], n, found)


def compact_candidates(
    spec: GridSpec,
    cells: CellList,
    position: Float[Array, "n 2"],
    k: int,
    ids: Array | None = None,
) -> tuple[Int[Array, "n k"], Int[Array, " n"]]:
    """The first ``k`` occupied slots of each agent's 3 × 3 cells, in :func:`candidates`' order
    (the agent's own slot blanked to ``N``), and how many candidates it has (itself excluded).

    Where the crowd is sparse most of the ``9·capacity`` slots :func:`candidates` returns are
    empty; this reads the cells' occupancy (a running sum over the 3 × 3 cells) and gathers only
    occupied slots. An agent whose count is below ``k`` has all its candidates in the ``k``
    columns (one may be its own, blanked); with more it has the first ones in cell order, not
    the nearest: the caller treats ``count ≥ k`` as needing the full list.
    """
    n = cells.cell.shape[0]
    own = jnp.arange(n, dtype=jnp.int32) if ids is None else ids.astype(jnp.int32)
    occupied = jnp.sum(cells.slots < n, axis=1, dtype=jnp.int32)  # (C,)
    ix, iz = _cell_coords(spec, position)
    block, count = [], []
    for dx in (-1, 0, 1):
        for dz in (-1, 0, 1):
            jx, jz = ix + dx, iz + dz
            inside = (jx >= 0) & (jx < spec.shape[0]) & (jz >= 0) & (jz < spec.shape[1])
            c = jnp.where(inside, jx * spec.shape[1] + jz, 0)
            block.append(c)
            count.append(jnp.where(inside, occupied[c], 0))
    cell9 = jnp.stack(block, axis=1)  # (n, 9)
    count9 = jnp.stack(count, axis=1)
    end = jnp.cumsum(count9, axis=1)  # inclusive
    start = end - count9
    total = end[:, -1]
    t = jnp.arange(k, dtype=jnp.int32)
    # Column t reads cell j(t) = the number of cells whose run ends at or before t.
    j = jnp.sum(end[:, None, :] <= t[None, :, None], axis=2)  # (n, k), 9 where t ≥ total
    j_safe = jnp.minimum(j, 8)
    cell = jnp.take_along_axis(cell9, j_safe, axis=1)
    slot = t[None, :] - jnp.take_along_axis(start, j_safe, axis=1)
    found = cells.slots[cell, jnp.clip(slot, 0, spec.capacity - 1)]
    found = jnp.where(t[None, :] < total[:, None], found, n)
    home = cells.slots[ix * spec.shape[1] + iz]  # the agent's own cell: it is there if stored
    stored = jnp.any(home == own[:, None], axis=1)
    return jnp.where(found == own[:, None], n, found), total - stored.astype(jnp.int32)
