"""A layout in the animated crowd step (jcrowd.pedestrians.scene): navigation fields and walls.

Oracles: shapely geometry (is an agent inside a wall, does the straight line cross it), the
field ids enumerated by hand, and the behaviour a wall with a door must cause — everyone
reaches the far side through the door and nobody is ever inside the wall.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely

from jcrowd import load_default_model
from jcrowd.crowd import prepare
from jcrowd.errors import ScenarioError
from jcrowd.pedestrians.navigation import field_values
from jcrowd.pedestrians.scene import build_scene, scene_bytes
from jcrowd.scenario import free_space, parse_scenario, spawn

BASE = """
seed = 5
duration = 30.0
fps = 10
[ground]
center = [0, 0]
size = [20, 12]
[camera]
eye = [0, 14, -12]
target = [0, 0, 0]
[dynamics]
avoid = {avoid}
"""

# A wall across the ground at x = 0 with a 1.2 m door at z in [3.4, 4.6]: the straight line
# from the spawn square to the goal runs through the wall, 4 m from the door.
DOOR = """
[[walls]]
points = [[0, -6], [0, 3.4]]
thickness = 0.3
[[walls]]
points = [[0, 4.6], [0, 6]]
thickness = 0.3
"""

CROSSING = """
[[groups]]
name = "crossers"
count = 12
speed = [1.2, 1.4]
spawn = { shape = "rect", center = [-6, 0], size = [3, 3] }
goal = { shape = "rect", center = [7, 0], size = [2, 3] }
"""


def _scenario(text: str):
    return parse_scenario(text, "t.toml")


def test_a_layout_needs_the_dynamics():
    with pytest.raises(ScenarioError, match=r"t.toml: dynamics.avoid: expected true in a scen"):
        _scenario(BASE.format(avoid="false") + DOOR + CROSSING)


def test_field_ids_follow_groups_and_waypoints():
    """One field per group goal and per path waypoint, in group order; agents' rows padded with
    their last waypoint's field, as the spawn pads the waypoints."""
    text = (
        BASE.format(avoid="true")
        + DOOR
        + CROSSING
        + """
[[groups]]
name = "walkers"
count = 3
spawn = { shape = "rect", center = [-6, -4], size = [2, 2] }
path = { waypoints = [[-3, 4], [5, 4], [7, -4]] }
"""
    )
    s = _scenario(text)
    sp = spawn(s)
    sim, _ = prepare(s, load_default_model())
    scene, ids = build_scene(s, sp, sim.config.grid, sim.config.reach)
    want = np.array([[0, 0, 0]] * 12 + [[1, 2, 3]] * 3)
    np.testing.assert_array_equal(ids, want)
    assert scene.nav.fields.shape[0] == 4
    assert scene_bytes(s) == scene.nav.fields.nbytes  # the memory the docs state
    # Each path waypoint lies in its own target (field ≤ 0 there), the others' are farther.
    nav = scene.nav
    for k, w in enumerate([[-3, 4], [5, 4], [7, -4]]):
        vals = [
            float(field_values(nav, np.array([j]), np.array([w[0]]), np.array([w[1]]))[0])
            for j in (1, 2, 3)
        ]
        assert vals[k] <= 0.0 < min(v for j, v in enumerate(vals) if j != k), (k, vals)


def test_fields_too_large_are_refused_before_they_are_built(monkeypatch):
    import jcrowd.pedestrians.scene as scene_module

    monkeypatch.setattr(scene_module, "MAX_FIELD_BYTES", 1000)
    s = _scenario(BASE.format(avoid="true") + DOOR + CROSSING)
    with pytest.raises(ScenarioError, match=r"t.toml: obstacles/walls/walkable: expected nav"):
        prepare(s, load_default_model())


def test_a_target_does_not_reach_through_a_wall():
    """A waypoint 0.6 m in front of the wall: the far side within ``reach`` (2 m) is not in its
    target — its field there is the walk round through the door (> 4 m), not ≤ 0."""
    text = (
        BASE.format(avoid="true")
        + DOOR
        + """
[[groups]]
name = "g"
count = 2
spawn = { shape = "rect", center = [-6, 0], size = [2, 2] }
path = { waypoints = [[-0.6, 0]] }
"""
    )
    s = _scenario(text)
    sim, _ = prepare(s, load_default_model())
    nav = sim.world.nav
    near = float(field_values(nav, np.array([0]), np.array([-1.0]), np.array([0.0]))[0])
    far = float(field_values(nav, np.array([0]), np.array([0.8]), np.array([0.0]))[0])
    assert near <= 0.0
    # Round the wall: from (0.8, 0) up to the door (~4 m) and back down to the disc (~2 m).
    assert far > 4.0, far


@pytest.mark.slow
def test_agents_walk_through_the_door_and_never_into_the_wall():
    s = _scenario(BASE.format(avoid="true") + DOOR + CROSSING)
    space = free_space(s.ground, s.layout)
    # The premise: walking straight at the goal would cross the wall.
    straight = shapely.LineString([(-6, 0), (7, 0)])
    assert not space.covers(straight)
    sim, state = prepare(s, load_default_model())
    fn = sim.compiled(donate=False)
    r = s.dynamics.radius
    inside, closest, went_through = 0, np.inf, np.zeros(sim.num_agents, bool)
    for i in range(sim.steps):
        state, _ = fn(state, sim.view_at(i * sim.dt), sim.dt)
        alive = np.asarray(state.alive)
        x, z = np.asarray(state.x)[alive], np.asarray(state.z)[alive]
        # Inside a wall: the disc's centre deeper than 0.05 m into the wall (float32 and a
        # step's overshoot); the walls' repulsion keeps centres ~r off them.
        inside += int((~shapely.contains_xy(space.buffer(0.05), x, z)).sum())
        crossing = alive & (np.abs(np.asarray(state.x)) < 0.3)
        went_through |= crossing & (np.abs(np.asarray(state.z) - 4.0) < 0.6)
        if len(x) > 1:
            d = np.hypot(x[:, None] - x[None], z[:, None] - z[None]) + 9 * np.eye(len(x))
            closest = min(closest, float(d.min()))
    assert inside == 0
    assert not np.asarray(state.alive).any()  # everyone reached the goal and left
    assert went_through.all()  # each through the door
    assert closest >= 0.9 * 2 * r, closest
    assert fn._cache_size() == 1


def test_steering_with_a_scene_is_the_same_under_jit():
    """jit == eager for the dynamics stage with fields and walls (the stage the scene adds)."""
    from jcrowd.crowd.steering import walk

    s = _scenario(BASE.format(avoid="true") + DOOR + CROSSING)
    sim, state = prepare(s, load_default_model())
    near = jnp.ones(state.num_agents, bool)
    dt = jnp.float32(sim.dt)

    def run(state):
        return walk(sim.config, sim.world, state, near, dt)

    args = (state,)
    eager = run(*args)
    jitted = jax.jit(run)(*args)
    for e, j in zip(eager, jitted, strict=True):
        # Same float32 equations; compiled, XLA fuses them and uses its own exp. The direction
        # sums repulsions a·exp((ℓ − s)/D) that reach ~10 against a unit desire, and normalising
        # carries their few-ulp differences over: measured 6e-6 m/s, bound 2e-5 m/s.
        np.testing.assert_allclose(np.asarray(j), np.asarray(e), atol=2e-5)
    # And the desired direction is the field's: agents west of the wall head for the door
    # (north-east), not straight east at the goal.
    vz = np.asarray(eager[1])
    assert (vz > 0.1).mean() > 0.5, vz


@pytest.mark.slow
def test_the_entrance_example_passes_people_at_the_measured_rate():
    """examples/entrance.toml, the Wuppertal 2018 entrance (75 people, 0.5 m gap) in the
    animated crowd: flow through the gap within ±25 % of the measured 1.16 /s and first to last
    crossing within ±25 % of 64.5 s (the bars of bench/pedestrians.py for its standalone
    dynamics). Flow over the middle 80 % of crossings, as PedPy's notebook measures it; a
    crossing is the first step an agent is south of the gap (z < 0) or has left."""
    from pathlib import Path

    from jcrowd.scenario import load_scenario

    path = Path(__file__).parent.parent / "examples" / "entrance.toml"
    s = load_scenario(path)
    space = free_space(s.ground, s.layout)
    sim, state = prepare(s, load_default_model())
    fn = sim.compiled()
    n = sim.num_agents
    crossed = np.full(n, np.inf)
    inside = 0
    for i in range(sim.steps):
        state, _ = fn(state, sim.view_at(i * sim.dt), sim.dt)
        alive, x, z = (np.asarray(a) for a in (state.alive, state.x, state.z))
        t = (i + 1) * sim.dt
        crossed = np.where(np.isinf(crossed) & (~alive | (z < 0)), t, crossed)
        inside += int((~shapely.contains_xy(space.buffer(0.05), x[alive], z[alive])).sum())
        if not alive.any():
            break
    assert np.isfinite(crossed).all()  # everyone got through
    t = np.sort(crossed)
    lo, hi = int(0.1 * n), int(0.9 * n) - 1
    flow = (hi - lo) / (t[hi] - t[lo])
    total = t[-1] - t[0]
    assert abs(flow / 1.16 - 1) <= 0.25, flow
    assert abs(total / 64.5 - 1) <= 0.25, total
    assert inside == 0


def test_lod_plant_feet_reaches_the_step():
    """``[lod] plant_feet`` (default true) is the step's ``plant_feet``."""
    model = load_default_model()
    on, _ = prepare(_scenario(BASE.format(avoid="true") + CROSSING), model)
    off, _ = prepare(
        _scenario(BASE.format(avoid="true") + "[lod]\nplant_feet = false\n" + CROSSING), model
    )
    assert on.config.plant_feet and not off.config.plant_feet
