"""The crowd step with the dynamics on (``[dynamics] avoid = true``, jcrowd.crowd.steering).

Oracles: closed forms for the heading and aim rules; for the stepped crowd, the step's own
contract checked from outside — the root moves by the reported velocity times dt, nobody comes
closer than the discs allow (the same scene without avoidance does overlap). The split over two
devices is compared with one device in tests/test_split_devices.py (this module's ``COUNTERFLOW``
with ``PILLAR``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import step_model

from jcrowd.crowd import aim_point, prepare
from jcrowd.scenario import parse_scenario

COUNTERFLOW = """
seed = 3
duration = 8.0
fps = 30
[ground]
center = [0, 0]
size = [30, 40]
[camera]
eye = [16, 9, -2]
target = [0, 0, 0]
[[groups]]
name = "north"
count = 16
speed = [1.2, 1.4]
spawn = {{ shape = "rect", center = [0, -5], size = [5, 4] }}
goal = {{ shape = "rect", center = [0, 17], size = [8, 3] }}
[[groups]]
name = "south"
count = 16
speed = [1.2, 1.4]
spawn = {{ shape = "rect", center = [0, 5], size = [5, 4] }}
goal = {{ shape = "rect", center = [0, -17], size = [8, 3] }}
[dynamics]
avoid = {avoid}
model = "{model}"
"""


def test_aim_point_extrapolates_the_velocity():
    got = aim_point(
        jnp.asarray([1.0, 1.0]),
        jnp.asarray([2.0, 2.0]),
        jnp.asarray([0.5, 0.0]),
        jnp.asarray([1.0, 0.0]),
        jnp.asarray([0.0, np.pi / 2]),
        2.0,
    )
    # Moving: position + 2 s of velocity; standing still: 0.1 m ahead along the heading (+x).
    np.testing.assert_allclose(np.asarray(got), [[2.0, 4.0], [1.1, 2.0]], atol=1e-6)


def _run(avoid: bool, steps: int = 150, model: str = "collision-free-speed"):
    text = COUNTERFLOW.format(avoid="true" if avoid else "false", model=model)
    sim, state = prepare(parse_scenario(text, "t.toml"), step_model())
    fn = sim.compiled(donate=False)
    closest, follow = np.inf, 0.0
    for i in range(steps):
        new, frame = fn(state, sim.view_at(i * sim.dt), sim.dt)
        alive = np.asarray(state.alive) & np.asarray(new.alive)
        x0, z0 = np.asarray(state.x)[alive], np.asarray(state.z)[alive]
        x1, z1 = np.asarray(new.x)[alive], np.asarray(new.z)[alive]
        vx, vz = np.asarray(new.vx)[alive], np.asarray(new.vz)[alive]
        follow = max(follow, float(np.abs(x1 - x0 - vx * sim.dt).max()))
        follow = max(follow, float(np.abs(z1 - z0 - vz * sim.dt).max()))
        d = np.hypot(x1[:, None] - x1[None], z1[:, None] - z1[None]) + 9 * np.eye(len(x1))
        closest = min(closest, float(d.min()))
        state = new
    return closest, follow, int(frame.crowding), fn


@pytest.mark.parametrize("model", ["collision-free-speed", "anticipation"])
def test_avoiding_agents_keep_apart_and_the_root_follows_the_simulation(model):
    closest, follow, crowding, fn = _run(True, model=model)
    assert closest >= 0.9 * 0.4, closest  # two 0.2 m discs, as the dynamics bench's bar
    assert follow < 1e-5  # root += v·dt exactly (float32 of positions ~10 m)
    assert crowding == 0
    assert fn._cache_size() == 1  # compiled once over 150 steps


def test_without_avoidance_the_same_crowd_overlaps():
    """The premise of the test above: head-on groups do collide when nobody avoids."""
    closest, _, _, _ = _run(False)
    assert closest < 0.2


PILLAR = """
[[obstacles]]
shape = "circle"
center = [0.5, 0]
radius = 1.2
"""

PATH_SCENE = """
seed = 1
duration = 2.0
fps = 30
[ground]
center = [0, 0]
size = [40, 40]
[camera]
eye = [16, 9, -2]
target = [0, 0, 0]
[[groups]]
name = "walkers"
count = 6
speed = [1.3, 1.3]
spawn = {{ shape = "rect", center = [-10, 0], size = [2, 2] }}
path = {{ waypoints = [[0, 0], [0, 10]], loop = false }}
[dynamics]
avoid = {avoid}
"""


@pytest.mark.parametrize("avoid", [True, False])
def test_a_crowded_waypoint_counts_as_passed_only_past_it_and_within_pass_reach(avoid):
    """schedule.PASS_REACH: with avoidance, an agent beyond the reach disc but past the
    waypoint along the next leg (here: north of (0, 0), the next waypoint (0, 10)) and within
    PASS_REACH reaches moves on; one as far but short of it (south), or beyond PASS_REACH
    reaches, does not; without avoidance only the reach disc counts. The oracle: the rule's
    geometry written out by hand for six placed agents."""
    from jcrowd.crowd.schedule import PASS_REACH, schedule

    text = PATH_SCENE.format(avoid="true" if avoid else "false")
    sim, state = prepare(parse_scenario(text, "t.toml"), step_model())
    reach = sim.config.reach
    inside, between, beyond = 0.5 * reach, 0.5 * (1 + PASS_REACH) * reach, 1.2 * PASS_REACH * reach
    # (x, z) of each agent around the waypoint (0, 0); the next leg runs north (+z).
    spots = [(0, inside), (0, between), (0, -between), (0, beyond), (between, 0.1), (0, -inside)]
    want = [True, avoid, False, False, avoid, True]
    state = _placed(state, spots)
    new, _ = schedule(sim.crowd, sim.config, state, jnp.ones(6, bool), sim.world)
    assert sim.world is None  # no obstacles: the reach rule, not a navigation target
    np.testing.assert_array_equal(np.asarray(new.waypoint) == 1, want)


def _placed(state, spots):
    from dataclasses import replace

    x = jnp.asarray([s[0] for s in spots], jnp.float32)
    z = jnp.asarray([s[1] for s in spots], jnp.float32)
    # The scenario jitters each agent's waypoints; the test places them exactly.
    waypoints = jnp.broadcast_to(jnp.asarray([[0.0, 0.0], [0.0, 10.0]]), state.waypoints.shape)
    return replace(state, x=x, z=z, waypoints=waypoints)


def test_agents_are_numbered_in_grid_cell_order_within_each_group():
    """With the dynamics on, prepare renumbers each group's agents in the neighbour grid's cell
    order (locality of the step's reads); the crowd itself is the same. Oracle: the unsorted
    spawn and the cells computed here by a loop. Catches a permutation applied to some columns
    and not others (positions would no longer match their waypoints or speeds), groups mixed,
    or no sorting at all (spawn order is random in space)."""
    from jcrowd.scenario import spawn

    scenario = parse_scenario(COUNTERFLOW.format(avoid="true", model="collision-free-speed"), "c")
    sim, state = prepare(scenario, step_model())
    raw, got = spawn(scenario), sim.spawn
    grid = sim.config.grid
    assert grid is not None

    # Same agents: each spawned row (position, speed, height, goal) appears once in the result.
    def rows(sp):
        return sorted(
            zip(
                map(tuple, np.round(sp.position, 6)),
                np.round(sp.speed, 6),
                np.round(sp.height, 6),
                map(tuple, np.round(sp.waypoints.reshape(len(sp.speed), -1), 6)),
                sp.group,
                strict=True,
            )
        )

    assert rows(raw) == rows(got)
    np.testing.assert_array_equal(got.group, raw.group)  # groups keep their runs of ids
    for g in np.unique(got.group):
        cells = []
        for x, z in got.position[got.group == g]:
            ix = min(max(int((x - grid.origin[0]) // grid.cell), 0), grid.shape[0] - 1)
            iz = min(max(int((z - grid.origin[1]) // grid.cell), 0), grid.shape[1] - 1)
            cells.append(ix * grid.shape[1] + iz)
        assert cells == sorted(cells)
    np.testing.assert_allclose(np.asarray(state.x), got.position[:, 0], atol=1e-6)
    assert not np.array_equal(raw.position, got.position)  # premise: spawn order was not sorted
