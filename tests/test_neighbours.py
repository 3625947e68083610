"""The neighbour grid (jcrowd.pedestrians.neighbours) against a brute-force all-pairs oracle."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians import candidates, cell_list, grid_spec
from jcrowd.pedestrians.neighbours import exclusive_prefix_sum


def _crowd(n: int, seed: int, lo=(-5.0, -3.0), hi=(5.0, 3.0), dead=0.2):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(lo, hi, size=(n, 2)).astype(np.float32)
    alive = rng.random(n) >= dead
    return pos, alive


def _brute_cells(spec, pos, alive):
    """Per cell, the alive agent ids in it, in id order (a plain loop over agents)."""
    cells: dict[int, list[int]] = {}
    for i, (x, z) in enumerate(pos):
        if not alive[i]:
            continue
        ix = min(max(int(np.floor((x - spec.origin[0]) / spec.cell)), 0), spec.shape[0] - 1)
        iz = min(max(int(np.floor((z - spec.origin[1]) / spec.cell)), 0), spec.shape[1] - 1)
        cells.setdefault(ix * spec.shape[1] + iz, []).append(i)
    return cells


@pytest.mark.parametrize(("n", "cell", "seed"), [(200, 1.0, 0), (400, 0.7, 1), (60, 2.5, 2)])
def test_cells_and_overflow_equal_a_loop_over_agents(n, cell, seed):
    """Each cell stores its first ``capacity`` alive agents in id order; the rest are counted."""
    pos, alive = _crowd(n, seed)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), cell, max_density=1.0, headroom=1.0)
    cl = cell_list(spec, jnp.asarray(pos), jnp.asarray(alive))
    order, start, place = np.asarray(cl.order), np.asarray(cl.start), np.asarray(cl.place)
    brute = _brute_cells(spec, pos, alive)
    overflow, stored = 0, 0
    for c in range(spec.num_cells):
        want = brute.get(c, [])
        kept = want[: spec.capacity]
        overflow += len(want) - len(kept)
        assert list(order[start[c] : start[c + 1]]) == kept, c
        assert all(place[i] == start[c] + r for r, i in enumerate(kept)), c
        assert all(place[i] == n for i in want[spec.capacity :]), c
        stored += len(kept)
    assert start[-1] == stored and (order[stored:] == n).all()
    assert (place[~alive] == n).all()
    assert int(cl.overflow) == overflow
    assert overflow > 0  # premise: capacities chosen so some cells overflow


def test_candidates_hold_every_neighbour_within_a_cell_size():
    """Without overflow, every alive pair closer than the cell size meets in the candidates,
    and no candidate is dead, the agent itself or outside the 3 × 3 cells (all-pairs oracle)."""
    n = 300
    pos, alive = _crowd(n, 3)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), 1.2)
    cl = cell_list(spec, jnp.asarray(pos), jnp.asarray(alive))
    assert int(cl.overflow) == 0
    cand = np.asarray(candidates(spec, cl, jnp.asarray(pos)))
    d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    near = (d < spec.cell) & alive[:, None] & alive[None] & ~np.eye(n, dtype=bool)
    for i in range(n):
        got = set(cand[i][cand[i] < n].tolist())
        assert len(got) == np.sum(cand[i] < n)  # no duplicates
        want = set(np.nonzero(near[i])[0].tolist())
        assert want <= got, (i, want - got)
        assert i not in got and all(alive[j] for j in got)
        # Candidates lie in the 3 × 3 block: within two cell diagonals (clamping aside).
        assert all(d[i, j] < 2 * np.sqrt(2) * spec.cell for j in got)
    assert near.sum() > 500  # premise: plenty of close pairs


def test_outside_agents_are_clamped_into_border_cells():
    pos = np.array([[-50.0, 0.0], [-4.9, 0.1], [50.0, 50.0], [4.9, 2.9]], np.float32)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), 1.0)
    cl = cell_list(spec, jnp.asarray(pos), jnp.ones(4, bool))
    cell = np.asarray(cl.cell)
    assert cell[0] == cell[1] and cell[2] == cell[3] == spec.num_cells - 1
    cand = np.asarray(candidates(spec, cl, jnp.asarray(pos)))
    assert 1 in cand[0] and 3 in cand[2]


@settings(max_examples=25, deadline=None)
@given(
    n=st.integers(0, 80),
    cell=st.floats(0.3, 4.0),
    seed=st.integers(0, 10_000),
)
def test_every_alive_agent_is_stored_or_counted(n, cell, seed):
    """Property: stored + overflow = alive, and an agent is stored at most once."""
    pos, alive = _crowd(n, seed, dead=0.3)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), cell, max_density=2.0, headroom=1.0)
    # Compiled (one program per example; op by op each example's new shapes compile every op).
    cl = jax.jit(cell_list, static_argnums=0)(spec, jnp.asarray(pos), jnp.asarray(alive))
    stored = np.asarray(cl.order)
    stored = stored[stored < n]
    assert len(set(stored.tolist())) == len(stored)
    assert len(stored) + int(cl.overflow) == int(alive.sum())
    place = np.asarray(cl.place)
    assert (np.asarray(cl.order)[place[place < n]] == np.nonzero(place < n)[0]).all()


def test_jit_equals_eager():
    pos, alive = _crowd(150, 5)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), 1.0)

    def both(p, a):
        cl = cell_list(spec, p, a)
        return cl.order, cl.start, cl.place, cl.overflow, candidates(spec, cl, p)

    eager = both(jnp.asarray(pos), jnp.asarray(alive))
    jitted = jax.jit(both)(jnp.asarray(pos), jnp.asarray(alive))
    for a, b in zip(eager, jitted, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_grid_spec_errors_and_capacity():
    spec = grid_spec((0.0, 0.0), (10.0, 4.0), 2.0)
    assert spec.shape == (5, 2) and spec.capacity == 48  # 8 /m² × 4 m² × 1.5
    with pytest.raises(JcrowdError, match="positive cell size"):
        grid_spec((0.0, 0.0), (1.0, 1.0), 0.0)
    with pytest.raises(JcrowdError, match="hi > lo"):
        grid_spec((0.0, 0.0), (0.0, 1.0), 1.0)


@pytest.mark.parametrize(("n", "k"), [(60, 8), (300, 24), (300, 200)])
def test_compact_candidates_are_the_3x3_cells_in_order(n, k):
    """Oracle: a loop over the 3 × 3 cells (column ix − 1, ix, ix + 1; within a column z
    increasing; within a cell ids increasing, from the brute-force cell lists): the first k
    of that list, the agent itself then blanked, are the compacted ids, and its length less
    the agent itself is the count."""
    from jcrowd.pedestrians import compact_candidates

    pos, alive = _crowd(n, 4)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), 1.0)
    cl = cell_list(spec, jnp.asarray(pos), jnp.asarray(alive))
    brute = _brute_cells(spec, pos, alive)
    got, count = compact_candidates(spec, cl, jnp.asarray(pos), k)
    got, count = np.asarray(got), np.asarray(count)
    nx, nz = spec.shape
    for i in range(n):
        ix = min(max(int(np.floor((pos[i, 0] + 5.0) / spec.cell)), 0), nx - 1)
        iz = min(max(int(np.floor((pos[i, 1] + 3.0) / spec.cell)), 0), nz - 1)
        block = [
            j
            for jx in (ix - 1, ix, ix + 1)
            for jz in (iz - 1, iz, iz + 1)
            if 0 <= jx < nx and 0 <= jz < nz
            for j in brute.get(jx * nz + jz, [])
        ]
        assert count[i] == len([j for j in block if j != i]), i
        assert [int(j) for j in got[i] if j < n] == [j for j in block[:k] if j != i], i
    assert (count > k).any() or k == 200  # premise: some agents have more than k
    assert count.max() <= k or k < 200


def test_compact_candidates_for_a_block_use_its_rows():
    from jcrowd.pedestrians import compact_candidates

    pos, alive = _crowd(120, 6)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), 1.0)
    cl = cell_list(spec, jnp.asarray(pos), jnp.asarray(alive))
    whole, whole_n = compact_candidates(spec, cl, jnp.asarray(pos), 40)
    ids = jnp.arange(1, 120, 2, dtype=jnp.int32)
    part, part_n = compact_candidates(spec, cl, jnp.asarray(pos)[ids], 40, ids)
    np.testing.assert_array_equal(np.asarray(part), np.asarray(whole)[1::2])
    np.testing.assert_array_equal(np.asarray(part_n), np.asarray(whole_n)[1::2])


def test_an_empty_crowd_and_a_lone_agent():
    """Edge cases of the rounds and the bucket: no agents at all (every cell empty, nothing
    counted) and one agent (stored first, no candidates)."""
    spec = grid_spec((0.0, 0.0), (10.0, 10.0), 1.6)
    empty = cell_list(spec, jnp.zeros((0, 2)), jnp.zeros(0, bool))
    assert empty.order.shape == (0,) and int(empty.overflow) == 0
    assert (np.asarray(empty.start) == 0).all()
    one = cell_list(spec, jnp.ones((1, 2)), jnp.ones(1, bool))
    assert int(one.place[0]) == 0 and int(one.order[0]) == 0 and int(one.start[-1]) == 1
    cand = np.asarray(candidates(spec, one, jnp.ones((1, 2))))
    assert (cand == 1).all()


def _prefix_loop(x):
    """The running sum with a leading 0, one entry after the other (a plain Python loop)."""
    out, total = [0], 0
    for v in x:
        total += int(v)
        out.append(total)
    return np.asarray(out, np.int64)


@pytest.mark.parametrize("c", [0, 1, 15, 16, 17, 255, 256, 257, 4099])
def test_exclusive_prefix_sum_equals_a_loop(c):
    """Sizes around the block (16) and its square cover the padding and the recursion; exact
    (integers), so no tolerance. Catches an off-by-one block offset or a lost tail."""
    x = np.random.default_rng(c).integers(0, 40, c).astype(np.int32)
    got = np.asarray(exclusive_prefix_sum(jnp.asarray(x)))
    np.testing.assert_array_equal(got, _prefix_loop(x))


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(0, 1000), max_size=600))
def test_exclusive_prefix_sum_properties(values):
    """Starts at 0, ends at the total, and each step adds that entry (differences give x back)."""
    x = jnp.asarray(np.asarray(values, np.int32))
    s = np.asarray(exclusive_prefix_sum(x))
    assert s.shape == (len(values) + 1,) and s[0] == 0 and s[-1] == sum(values)
    np.testing.assert_array_equal(np.diff(s), np.asarray(values, np.int64))


def test_exclusive_prefix_sum_jit_equals_eager_and_counts_come_from_ranks():
    """jit == eager; and in a cell list the starts' differences are each cell's stored count,
    counted here from the agents' cells (the step reads the counts off the rounds' marks)."""
    x = jnp.asarray(np.random.default_rng(3).integers(0, 9, 1000).astype(np.int32))
    np.testing.assert_array_equal(
        np.asarray(jax.jit(exclusive_prefix_sum)(x)), np.asarray(exclusive_prefix_sum(x))
    )
    pos, alive = _crowd(300, 7)
    spec = grid_spec((-5.0, -3.0), (5.0, 3.0), 0.8, max_density=1.5, headroom=1.0)
    cl = cell_list(spec, jnp.asarray(pos), jnp.asarray(alive))
    stored = np.asarray(cl.place) < 300
    want = np.bincount(np.asarray(cl.cell)[stored], minlength=spec.num_cells)
    np.testing.assert_array_equal(np.diff(np.asarray(cl.start)), want)
    assert int(cl.overflow) > 0  # some cells full: their count stops at the capacity
