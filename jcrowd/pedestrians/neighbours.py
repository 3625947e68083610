"""Who is near whom: a uniform cell grid with a static capacity per cell and a counted overflow.

The pattern of JAX MD's cell lists (``jax_md/partition.py``): the host sizes the grid once
(:func:`grid_spec`: origin, cell size, cells, agents per cell, with headroom), and the compiled
step fills it with fixed shapes (:func:`cell_list`), reporting how many agents found their cell
full instead of dropping them silently. An agent's candidates are the agents stored in the
3 × 3 cells around its own (:func:`candidates`); with cells at least as large as the
interaction range, every agent within that range of it is among them unless its cell
overflowed.

Layout: the stored agents in *cell order* (cell by cell, ids increasing within a cell) and each
cell's first place in that order — a counting sort. Cells are numbered ``ix·nz + iz``, so the
three cells ``(ix + d, iz − 1 … iz + 1)`` of one column of an agent's 3 × 3 block are one
contiguous run of the order: an agent's candidates are three runs, found with six reads of the
cells' starts, and reading them costs what they hold, not the cells' capacity. Memory: 4 B per
cell and a few per agent (a 1 km² ground in 1.6 m cells: 1.6 MB), where a table of slots per
cell would take ``capacity`` times more and be mostly empty where people walk apart. (JAX MD
sorts the particles by cell; here each agent's rank in its cell comes from rounds of
scatter-min — round ``r`` places the lowest unplaced id of every cell — which on XLA:CPU is
several times faster than sorting the crowd; docs/design/pedestrians.md.)

Conventions: ground positions are ``[x, z]`` in metres (the crowd step's layout); agent ids run
``0 … N − 1`` and ``N`` marks no agent. Positions outside the grid are clamped into its
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
from jcrowd.indexing import first_true

__all__ = [
    "CellList",
    "GridSpec",
    "candidates",
    "cell_index",
    "cell_list",
    "compact_candidates",
    "exclusive_prefix_sum",
    "grid_spec",
    "near_places",
]


@dataclass(frozen=True)
class GridSpec:
    """The static shape of a cell grid (host side; part of the compiled step's static config).

    Attributes:
        origin: ``(x, z)`` of the grid's lower corner (m).
        cell: cell edge (m), at least the interaction range.
        shape: cells along x and along z.
        capacity: the most agents a cell stores (more are counted as overflow).
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
    over a cell) times ``headroom``, and at least 4 agents.

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
    """Agents sorted into cells (a counting sort; see the module docstring).

    Attributes:
        order: ``(N,)`` the stored agents' ids, cell after cell (ids increasing within a cell),
            then ``N`` for the places left over.
        start: ``(cells + 1,)`` each cell's first place in ``order``; cell ``c`` holds
            ``order[start[c]:start[c + 1]]`` and ``start[cells]`` is the number stored.
        place: ``(N,)`` each agent's place in ``order`` (``N``: not alive or not stored).
        cell: ``(N,)`` each agent's cell (``cells`` for agents that are not alive).
        overflow: agents alive but not stored because their cell was full.
    """

    order: Int[Array, " N"]
    start: Int[Array, " C1"]
    place: Int[Array, " N"]
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

    Ranks are claimed in rounds: in round ``r`` every cell gives rank ``r`` to the lowest id
    among its agents not yet ranked (a scatter-max of round-stamped marks over the agents),
    until every agent is ranked or ``capacity`` rounds have run (the rounds stop at the fullest
    cell's count, a handful where people walk apart; after round 0 they run on a bucket of the
    agents still unranked when an eighth of the crowd holds them); the agents left over are
    counted in ``overflow``. Then
    each cell's count, their running sum (the starts) and every agent's place
    ``start[cell] + rank``.
    """
    n, ncell = position.shape[0], spec.num_cells
    if (spec.capacity + 1) * (n + 1) >= 2**31:
        raise JcrowdError(
            f"cell_list: expected (capacity + 1)·(agents + 1) < 2³¹ (int32 round marks), found "
            f"capacity {spec.capacity} and {n} agents"
        )
    ix, iz = _cell_coords(spec, position)
    cell = jnp.where(alive, ix * spec.shape[1] + iz, ncell).astype(jnp.int32)
    ids = jnp.arange(n, dtype=jnp.int32)
    if n == 0:  # nobody: every cell empty
        none = jnp.zeros((0,), jnp.int32)
        return CellList(none, jnp.zeros((ncell + 1,), jnp.int32), none, none, jnp.int32(0))

    # One table for all rounds: round r writes (r + 1)·(N + 1) − id, and a scatter-max keeps
    # this round's lowest id over the marks of earlier rounds (no table reset per round).
    stamp = n + 1

    def rounds(r0: Array, cell_k: Array, ids_k: Array, rank_k: Array, table: Array) -> tuple:
        """Rounds from ``r0`` for the agents ``ids_k`` (in increasing order; ``cell_k`` their
        cells, ``ncell`` for none), until all are ranked or ``capacity`` rounds have run."""

        def more(carry: tuple[Array, Array, Array, Array]) -> Array:
            r, placed, _, _ = carry
            return (r < spec.capacity) & ~jnp.all(placed)

        def round_(carry: tuple[Array, Array, Array, Array]) -> tuple[Array, Array, Array, Array]:
            r, placed, rank, table = carry
            key = jnp.where(placed, ncell, cell_k)
            mark = (r + 1) * stamp - ids_k
            table = table.at[key].max(mark, mode="drop")
            won = ~placed & (table[jnp.minimum(key, ncell - 1)] == mark)
            return r + 1, placed | won, jnp.where(won, r, rank), table

        start = (r0, (cell_k >= ncell) | (rank_k >= 0), rank_k, table)
        _, _, rank_k, table = jax.lax.while_loop(more, round_, start)
        return rank_k, table

    # Round 0 for everyone; where people walk apart it ranks nearly all of them, and the later
    # rounds run on a bucket of the agents left (an eighth of the crowd) when they fit in it.
    no_rank = jnp.full((n,), -1, jnp.int32)
    rank, table = _first_round(cell, ids, ncell, stamp, no_rank)
    left = (cell < ncell) & (rank < 0)
    bucket = max(1, n // 8)

    def in_bucket() -> tuple[Array, Array]:
        idx = first_true(left, bucket, n)
        cell_b = jnp.where(idx < n, cell[jnp.minimum(idx, n - 1)], ncell)
        rank_b, last = rounds(jnp.ones((), jnp.int32), cell_b, idx, no_rank[:bucket], table)
        return rank.at[idx].set(rank_b, mode="drop"), last

    def everyone() -> tuple[Array, Array]:
        return rounds(jnp.ones((), jnp.int32), cell, ids, rank, table)

    rank, table = jax.lax.cond(jnp.sum(left) <= bucket, in_bucket, everyone)
    stored = rank >= 0
    # A cell's last mark is round r's, (r + 1)·stamp − id with 0 ≤ id < N: the cell ranked
    # r + 1 agents (0 … r, one per round), and ⌈mark / stamp⌉ = r + 1; unmarked cells hold 0.
    counts = (table + (stamp - 1)) // stamp
    start = exclusive_prefix_sum(counts)
    place = jnp.where(stored, start[jnp.minimum(cell, ncell - 1)] + rank, n)
    order = jnp.full((n,), n, jnp.int32).at[place].set(ids, mode="drop")
    overflow = jnp.sum(alive & ~stored, dtype=jnp.int32)
    return CellList(order, start, place, cell, overflow)


PREFIX_BLOCK = 16
"""Entries summed one after the other per block by :func:`exclusive_prefix_sum`."""


def exclusive_prefix_sum(x: Int[Array, " C"]) -> Int[Array, " C1"]:
    """``[0, x₀, x₀ + x₁, …, Σx]``: the running sum of ``x`` with a leading 0 (``C + 1``
    entries), exact for integers.

    Blocked: the running sums within blocks of :data:`PREFIX_BLOCK` entries are
    :data:`PREFIX_BLOCK` − 1 elementwise adds over the blocks (one fused loop), and the blocks'
    offsets the same sum over the block totals, recursively. ``jnp.cumsum`` over the grid's
    cells (400k at 100k agents on the plaza) was the largest single cost of the neighbour grid
    on two CPU devices: its log-depth scan is about 40 passes over the array (1.5 ms alone,
    3.5 ms of the two-device step; this: 1.2 ms alone).
    """
    c, b = x.shape[0], PREFIX_BLOCK
    zero = jnp.zeros((1,), x.dtype)
    if c <= b:
        sums = [zero[0]]
        for j in range(c):
            sums.append(sums[-1] + x[j])
        return jnp.stack(sums)
    blocks = jnp.pad(x, (0, -c % b)).reshape(-1, b)
    within = [blocks[:, 0]]
    for j in range(1, b):
        within.append(within[-1] + blocks[:, j])
    inclusive = jnp.stack(within, axis=1)
    offset = exclusive_prefix_sum(inclusive[:, -1])[:-1]
    return jnp.concatenate([zero, (inclusive + offset[:, None]).reshape(-1)[:c]])


def _first_round(
    cell: Array, ids: Array, ncell: int, stamp: int, rank: Array
) -> tuple[Array, Array]:
    """Round 0 of :func:`cell_list`: each cell ranks its lowest id 0."""
    mark = stamp - ids
    table = jnp.zeros((ncell,), jnp.int32).at[cell].max(mark, mode="drop")
    won = (cell < ncell) & (table[jnp.minimum(cell, ncell - 1)] == mark)
    return jnp.where(won, 0, rank), table


def _runs(
    spec: GridSpec, cells: CellList, position: Float[Array, "n 2"]
) -> tuple[list[Array], list[Array]]:
    """The three runs of ``cells.order`` holding each agent's 3 × 3 cells: ``(lo, hi)`` places
    per column ``ix − 1, ix, ix + 1`` (empty beyond the grid's edges)."""
    nx, nz = spec.shape
    ix, iz = _cell_coords(spec, position)
    z0, z1 = jnp.maximum(iz - 1, 0), jnp.minimum(iz + 1, nz - 1) + 1
    lo, hi = [], []
    for dx in (-1, 0, 1):
        jx = ix + dx
        inside = (jx >= 0) & (jx < nx)
        base = jnp.clip(jx, 0, nx - 1) * nz
        lo.append(jnp.where(inside, cells.start[base + z0], 0))
        hi.append(jnp.where(inside, cells.start[base + z1], 0))
    return lo, hi


def near_places(
    spec: GridSpec,
    cells: CellList,
    position: Float[Array, "n 2"],
    k: int,
    own: Int[Array, " n"],
) -> tuple[Int[Array, "n k"], Int[Array, " n"]]:
    """The first ``k`` places of each agent's three runs (its 3 × 3 cells, column after
    column), ``N`` past their end and at the agent's own place ``own``; and how many
    candidates it has, itself excluded. An agent with fewer than ``k`` candidates has them all.
    """
    n = cells.order.shape[0]
    lo, hi = _runs(spec, cells, position)
    e0 = hi[0] - lo[0]
    e1 = e0 + hi[1] - lo[1]
    total = e1 + hi[2] - lo[2]
    t = jnp.arange(k, dtype=jnp.int32)[None, :]
    second = jnp.where(
        t < e1[:, None], lo[1][:, None] + t - e0[:, None], lo[2][:, None] + t - e1[:, None]
    )
    p = jnp.where(t < e0[:, None], lo[0][:, None] + t, second)
    p = jnp.where((t < total[:, None]) & (p != own[:, None]), p, n)
    return p, total - (own < n).astype(jnp.int32)


def _own_places(cells: CellList, ids: Array | None) -> Array:
    return cells.place if ids is None else cells.place[ids]


def compact_candidates(
    spec: GridSpec,
    cells: CellList,
    position: Float[Array, "n 2"],
    k: int,
    ids: Array | None = None,
) -> tuple[Int[Array, "n k"], Int[Array, " n"]]:
    """Each agent's first ``k`` candidates (ids, in :func:`candidates`' order, ``N`` past the
    last and for the agent itself) and how many it has (itself excluded).

    ``position`` is the agents asked about: all the agents ``cells`` holds (``N``, the
    default), or some of them whose ids are ``ids``. An agent whose count is below ``k`` has
    all its candidates in the ``k`` columns; with more it has the first ones in cell order, not
    the nearest: the caller treats ``count ≥ k`` as needing a longer list.
    """
    n = cells.order.shape[0]
    places, count = near_places(spec, cells, position, k, _own_places(cells, ids))
    order = jnp.concatenate([cells.order, jnp.full((1,), n, jnp.int32)])
    return order[places], count


def candidates(
    spec: GridSpec, cells: CellList, position: Float[Array, "n 2"], ids: Array | None = None
) -> Int[Array, "n M"]:
    """Each agent's candidate neighbours: the ids stored in the 3 × 3 cells around it, column
    of cells after column, ``N`` past the last and for the agent itself; ``9·capacity``
    columns, room for nine full cells. ``position`` and ``ids`` as in
    :func:`compact_candidates`. Every agent within ``spec.cell`` of an agent (and stored) is
    among its candidates.
    """
    return compact_candidates(spec, cells, position, 9 * spec.capacity, ids)[0]
