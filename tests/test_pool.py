"""Sources and the pool of slots (jcrowd.crowd.pool, [[sources]] in scenarios).

Oracles: closed forms for a source's appearance times; interval partitioning for the slot plan
(for one group the greedy plan needs exactly as many slots as windows overlap at the busiest
instant, counted by a sweep); a per-slot Python loop for ``spawn_due``; and the end-to-end
contract checked from outside the step — every source agent appears once, not before its time,
where its source is, and the step compiles once. The split over two devices is compared with one
device in tests/test_split_devices.py (this module's ``SCENE``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import step_model
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.crowd import prepare
from jcrowd.crowd.pool import plan_pool, spawn_due
from jcrowd.errors import ScenarioError
from jcrowd.scenario import Source, parse_scenario

SCENE = """
seed = 2
duration = {duration}
fps = 10
[ground]
center = [0, 0]
size = [40, 20]
[camera]
eye = [0, 14, -22]
target = [0, 0, 0]
[dynamics]
avoid = {avoid}
[[groups]]
name = "crossers"
count = {count}
speed = [1.3, 1.5]
spawn = {{ shape = "rect", center = [-15, 0], size = [2, 6] }}
goal = {{ shape = "rect", center = [15, 0], size = [2, 6] }}
[[sources]]
group = "crossers"
rate = 4.0
start = 1.0
count = 20
region = {{ shape = "rect", center = [-17, 0], size = [2, 8] }}
"""


def test_source_times_are_start_plus_k_over_rate():
    assert np.allclose(Source("g", 2.0, 1.0, stop=3.0).times(10.0), [1.0, 1.5, 2.0, 2.5])
    assert np.allclose(Source("g", 2.0, 1.0, count=3).times(10.0), [1.0, 1.5, 2.0])
    assert np.allclose(Source("g", 1.0, 7.5).times(10.0), [7.5, 8.5, 9.5])  # to the end
    assert len(Source("g", 1.0, 0.0, stop=2.0, count=9).times(10.0)) == 2  # the earlier limit


def _max_overlap(starts, ends):
    events = sorted([(s, 1) for s in starts] + [(e, -1) for e in ends])  # ends sort first
    best = cur = 0
    for _, d in events:
        cur += d
        best = max(best, cur)
    return best


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(0, 50), min_size=0, max_size=8),
    st.lists(st.tuples(st.floats(0, 100), st.floats(0.5, 30)), min_size=1, max_size=60),
)
def test_one_group_plan_uses_as_many_slots_as_windows_overlap(initial, arrivals):
    arrivals = sorted(arrivals)
    times = np.array([t for t, _ in arrivals])
    stay = np.array([s for _, s in arrivals])
    queue, group = plan_pool(
        np.array(initial), np.zeros(len(initial), int), times, stay, np.zeros(len(times), int), 1
    )
    # Every source agent is queued exactly once, in order of appearance within its slot.
    rows = queue[queue >= 0]
    assert sorted(rows.tolist()) == list(range(len(times)))
    for q in queue:
        r = q[q >= 0]
        assert np.all(np.diff(r) > 0)
    # No slot holds two agents whose expected stays overlap.
    for k, q in enumerate(queue):
        r = q[q >= 0]
        free = initial[k] if k < len(initial) else -np.inf
        for row in r:
            assert times[row] >= free - 1e-9
            free = times[row] + stay[row]
    # As few slots as the busiest instant needs (t = 0 agents hold their slot from 0).
    starts = [0.0] * len(initial) + times.tolist()
    ends = list(initial) + (times + stay).tolist()
    assert len(queue) == max(len(initial), _max_overlap(starts, ends))
    assert np.all(group == 0)


def test_slots_are_never_shared_between_groups():
    times = np.arange(10.0)
    queue, group = plan_pool(
        np.zeros(0), np.zeros(0, int), times, np.full(10, 0.5), np.arange(10) % 2, 8
    )
    assert len(queue) == 8  # two slots used, rounded up to 8
    for q, g in zip(queue, group, strict=True):
        r = q[q >= 0]
        assert np.all(r % 2 == g)


def _spawn_loop(state, reservoir, times, first_id, budget):
    """Slot by slot, in index order: the oracle of spawn_due. The first ``budget`` due slots
    are considered; one whose agent's disc overlaps an agent alive before the call, or an
    earlier considered one, waits."""
    g = {
        k: np.asarray(getattr(state, k)).copy()
        for k in ("alive", "next_row", "agent", "x", "z", "radius", "queue", "clock")
    }
    res = {k: np.asarray(getattr(reservoir, k)) for k in ("x", "z", "radius")}
    alive0 = g["alive"].copy()
    considered = []
    for s in range(len(alive0)):
        if alive0[s] or g["next_row"][s] >= g["queue"].shape[1]:
            continue
        row = g["queue"][s, g["next_row"][s]]
        if row < 0 or times[row] > g["clock"][s] or len(considered) == budget:
            continue
        p, r = np.array([res["x"][row], res["z"][row]]), res["radius"][row]
        hit = any(
            alive0[o] and np.hypot(p[0] - g["x"][o], p[1] - g["z"][o]) < r + g["radius"][o]
            for o in range(len(alive0))
        ) or any(np.hypot(*(p - q)) < r + rq for q, rq in considered)
        considered.append((p, r))
        if hit:
            continue
        g["alive"][s], g["agent"][s], g["x"][s] = True, first_id + row, res["x"][row]
        g["next_row"][s] += 1
    return g["alive"], g["next_row"], g["agent"], g["x"]


@pytest.mark.parametrize("budget", [2, 50])
def test_spawn_due_equals_a_slot_by_slot_loop(budget):
    """With the budget binding (2) and not (50)."""
    sim, state = prepare(
        parse_scenario(SCENE.format(duration=8, avoid="false", count=4), "t"), step_model()
    )
    pool = sim.pool
    rng = np.random.default_rng(0)
    n, q = state.queue.shape
    alive = rng.random(n) < 0.4
    clock = np.full(n, 2.6, np.float32)
    next_row = rng.integers(0, q + 1, n).astype(np.int32)
    import equinox as eqx

    state = eqx.tree_at(
        lambda s: (s.alive, s.clock, s.next_row),
        state,
        (jnp.asarray(alive), jnp.asarray(clock), jnp.asarray(next_row)),
    )
    got = spawn_due(state, pool.reservoir, pool.times, pool.first_id, budget)
    want = _spawn_loop(state, pool.reservoir, np.asarray(pool.times), pool.first_id, budget)
    for g, w in zip((got.alive, got.next_row, got.agent, got.x), want, strict=True):
        np.testing.assert_array_equal(np.asarray(g), w)
    jitted = jax.jit(spawn_due, static_argnums=(3, 4))(
        state, pool.reservoir, pool.times, pool.first_id, budget
    )
    np.testing.assert_array_equal(np.asarray(jitted.agent), np.asarray(got.agent))


def test_every_source_agent_appears_once_on_time_where_its_source_is():
    avoid = "true"  # (without avoidance the pool is the same; spawn_due's test covers it)
    sim, state = prepare(
        parse_scenario(SCENE.format(duration=12, avoid=avoid, count=4), "t"), step_model()
    )
    fn = sim.compiled(donate=False)
    n0, times = 4, np.asarray(sim.pool.times)
    first_seen = {}
    closest_at_appearance = np.inf
    for i in range(sim.steps):
        state, _ = fn(state, sim.view_at(i * sim.dt), sim.dt)
        agent, alive = np.asarray(state.agent), np.asarray(state.alive)
        x, z = np.asarray(state.x), np.asarray(state.z)
        held = agent[alive]
        assert len(set(held.tolist())) == len(held)  # nobody in two slots
        for s in np.nonzero(alive & (agent >= n0))[0]:
            a = int(agent[s])
            if a not in first_seen:
                first_seen[a] = ((i + 1) * sim.dt, x[s], z[s])
                others = alive & (np.arange(len(alive)) != s)
                d = np.hypot(x[others] - x[s], z[others] - z[s])
                closest_at_appearance = min(closest_at_appearance, d.min(initial=np.inf))
    assert sorted(first_seen) == list(range(n0, n0 + 20))  # all 20, once each
    for a, (t_seen, x, z) in first_seen.items():
        due = times[a - n0]
        assert t_seen >= due - 1e-6  # never early
        # Within the source region (2 × 8 m round (−17, 0)), moved by at most one step's walk.
        assert abs(x + 17) <= 1 + 0.2 and abs(z) <= 4 + 0.2
    # 20 agents at 4 /s and a pool sized for them: none waits for a slot, but one whose place
    # is taken waits until the agent there has walked off (≤ 1 s at 1.3 m/s, measured 0.75 s).
    late = max(t - times[a - n0] for a, (t, _, _) in first_seen.items())
    assert late <= 1.0
    if avoid == "true":  # nobody appears on top of anyone (0.9: the discs, as the bench's bar)
        assert closest_at_appearance >= 0.9 * 2 * 0.2, closest_at_appearance
    assert fn._cache_size() == 1


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ('group = "crossers"\nrate', r"t: sources\[0\]\.group: expected the name of a group"),
        ("rate = 4.0", r"t: sources\[0\]\.rate: expected agents per second > 0, found -1"),
        ("start = 1.0", r"t: sources\[0\]\.start: expected a time before the scenario ends"),
    ],
)
def test_bad_sources_name_the_key(edit, message):
    text = SCENE.format(duration=8, avoid="false", count=4)
    bad = {
        'group = "crossers"\nrate': 'group = "nobody"\nrate',
        "rate = 4.0": "rate = -1",
        "start = 1.0": "start = 9.0",
    }[edit]
    with pytest.raises(ScenarioError, match=message):
        parse_scenario(text.replace(edit, bad), "t")


def test_a_group_of_zero_needs_a_source():
    text = SCENE.format(duration=8, avoid="false", count=0)
    parse_scenario(text, "t")  # fed by the source: fine
    alone = text[: text.index("[[sources]]")]
    with pytest.raises(ScenarioError, match=r"t: groups\[0\]\.count: expected a positive integ"):
        parse_scenario(alone, "t")
