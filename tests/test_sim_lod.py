"""Simulation level of detail (``[dynamics] far_every``: jcrowd.crowd.steering.due_rows and the
pedestrian step's ``due`` rows).

Oracles: a loop over rows for who is due; the full step (every agent every step) for the
velocities of the agents that are due — they see the same neighbours — and the previous
velocities for the others; the stepped crowd's own contract (no recompiles, discs kept apart).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.crowd.steering import due_rows
from jcrowd.errors import JcrowdError
from jcrowd.pedestrians import AvoidanceParams, Pedestrians, grid_spec, open_world, pedestrian_step
from jcrowd.scenario import parse_scenario


def _due_loop(near, tick, every):
    return [i for i in range(len(near)) if near[i] or (tick + i) % every == 0]


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(1, 60),
    every=st.integers(2, 6),
    tick=st.integers(0, 10_000),
    seed=st.integers(0, 1000),
)
def test_due_rows_equal_a_loop_and_cover_everyone_in_turn(n, every, tick, seed):
    """Property: the rows due are the near ones and every ``every``-th of the others (loop
    oracle), padded with N; over ``every`` consecutive ticks each row is due at least once."""
    rng = np.random.default_rng(seed)
    near = rng.random(n) < 0.2
    dt = jnp.float32(1 / 30)
    size = int(near.sum()) + -(-n // every)
    seen = np.zeros(n, bool)
    for k in range(every):
        clock = jnp.full(n, (tick + k) / 30, jnp.float32)
        got = np.asarray(due_rows(jnp.asarray(near), clock, dt, every, size))
        want = _due_loop(near, tick + k, every)
        assert [int(i) for i in got if i < n] == want
        assert (got[len(want) :] == n).all()
        seen[want] = True
    assert seen.all()


def _crowd(n=120, seed=0):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-6, 6, (n, 2)).astype(np.float32)
    goal = rng.uniform(-6, 6, (n, 2)).astype(np.float32)
    alive = rng.random(n) > 0.1
    speed = rng.uniform(1.0, 1.4, n).astype(np.float32)
    prev = rng.normal(0, 1, (n, 2)).astype(np.float32)
    grid = grid_spec((-8.0, -8.0), (8.0, 8.0), 1.6, max_density=4.0)
    args = tuple(
        jnp.asarray(a)
        for a in (pos[:, 0], pos[:, 1], goal[:, 0], goal[:, 1], speed, np.full(n, 0.2, np.float32))
    )
    return grid, args, jnp.asarray(alive), (jnp.asarray(prev[:, 0]), jnp.asarray(prev[:, 1]))


def _velocities(grid, x, z, tx, tz, speed, radius, alive, previous, due=None):
    """The pedestrian step's velocities ``(vx, vz)`` of agents walking straight at ``(tx, tz)``
    in an open world, relaxing from ``previous`` (the plain model)."""
    peds = Pedestrians(
        jnp.stack([x, z], axis=1),
        jnp.zeros(x.shape[0], jnp.int32),
        speed,
        radius,
        alive,
        velocity=jnp.stack(previous, axis=1),
        goal=jnp.stack([tx, tz], axis=1),
        anticipate=False,
    )
    _, info = pedestrian_step(AvoidanceParams(), open_world(grid), peds, 1 / 30, due=due)
    return info.velocity[:, 0], info.velocity[:, 1]


def test_due_agents_move_as_with_everyone_due_and_the_others_keep_their_velocity():
    """Oracle: the step with every agent due, from the same previous velocities (the plain
    model relaxes from them over its reaction time). Tolerance 1e-6 m/s: the same sums on a subset
    (the kernel's order of summation is per agent, unchanged)."""
    grid, args, alive, prev = _crowd()
    n = args[0].shape[0]
    full = jax.jit(lambda *a: _velocities(grid, *a))
    want_x, want_z = full(*args, alive, prev)
    due = jnp.asarray(np.r_[np.arange(3, n, 4), [n] * 5], jnp.int32)
    part = jax.jit(lambda *a: _velocities(grid, *a[:8], due=a[8]))
    got_x, got_z = part(*args, alive, prev, due)
    is_due = np.zeros(n, bool)
    is_due[3::4] = True
    live = np.asarray(alive)
    for got, want, before in ((got_x, want_x, prev[0]), (got_z, want_z, prev[1])):
        got, want, before = np.asarray(got), np.asarray(want), np.asarray(before)
        np.testing.assert_allclose(got[is_due], want[is_due], atol=1e-6)
        np.testing.assert_array_equal(got[~is_due & live], before[~is_due & live])
        assert (got[~live] == 0).all()
    kept = ~is_due & live  # premise: for them the full step would have changed the velocity
    assert np.abs(np.asarray(want_x)[kept] - np.asarray(prev[0])[kept]).max() > 0.1


def test_everyone_due_equals_no_selection():
    """Transformation: a selection holding every row (in order) is the plain step, bit for bit."""
    grid, args, alive, prev = _crowd(seed=1)
    n = args[0].shape[0]
    a = _velocities(grid, *args, alive, prev)
    b = _velocities(grid, *args, alive, prev, due=jnp.arange(n, dtype=jnp.int32))
    for u, v in zip(a, b, strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


PLAZA = """
seed = 2
duration = 4.0
fps = 30
[ground]
center = [0, 0]
size = [40, 40]
[camera]
eye = [0, 2, -21]
target = [0, 0, 0]
[[groups]]
name = "east"
count = 60
spawn = {{ shape = "rect", center = [-8, 0], size = [6, 10] }}
goal = {{ shape = "rect", center = [18, 0], size = [3, 30] }}
[[groups]]
name = "west"
count = 60
spawn = {{ shape = "rect", center = [8, 0], size = [6, 10] }}
goal = {{ shape = "rect", center = [-18, 0], size = [3, 30] }}
[dynamics]
avoid = true
far_every = {every}
"""


@pytest.mark.slow
def test_far_agents_in_turn_keep_apart_without_recompiling():
    """The crossing plaza with far agents every 4 steps: no recompiles after the first step,
    and nobody closer than 0.9 × the two radii (the safety bar of issue 18)."""
    from helpers import step_model

    from jcrowd.crowd import prepare

    sim, state = prepare(parse_scenario(PLAZA.format(every=4), "plaza.toml"), step_model())
    assert sim.config.far_every == 4
    fn = sim.compiled()
    view, dt = sim.view_at(0.0), sim.dt_array
    closest = np.inf
    for _ in range(90):
        state, _ = fn(state, view, dt)
        x, z, alive = (np.asarray(a) for a in (state.x, state.z, state.alive))
        p = np.stack([x, z], 1)[alive]
        d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(len(p)) * 1e9
        closest = min(closest, d.min())
    assert fn._cache_size() == 1
    assert closest >= 0.9 * 0.4, closest


@pytest.mark.parametrize("value", ['"social-force"', '"CSM"', "1"])
def test_an_unknown_dynamics_model_is_an_error_naming_the_key(value):
    text = PLAZA.replace("far_every = {every}", f"model = {value}").format()
    with pytest.raises(
        JcrowdError, match=r"dynamics.model: expected 'collision-free-speed' or 'anticipation'"
    ):
        parse_scenario(text, "plaza.toml")


def test_the_dynamics_model_reaches_the_step():
    """``model`` picks the step's avoidance: the plain model by default, anticipation on
    request (the setting the compiled step reads)."""
    from jcrowd import load_default_model
    from jcrowd.crowd import prepare

    model = load_default_model()
    for line, want in (("", False), ('model = "anticipation"', True)):
        text = PLAZA.replace("far_every = {every}", line).format()
        sim, _ = prepare(parse_scenario(text, "plaza.toml"), model)
        assert sim.config.anticipate is want


@pytest.mark.parametrize("value", ["0", "9", "true", "1.5"])
def test_far_every_errors_name_the_key(value):
    text = PLAZA.replace("far_every = {every}", f"far_every = {value}").format()
    with pytest.raises(JcrowdError, match=r"dynamics.far_every: expected an integer in \[1, 8\]"):
        parse_scenario(text, "plaza.toml")


def test_a_spawn_region_too_small_to_spread_agents_names_the_group():
    """With avoidance on, 500 agents of radius 0.2 m in 12 m × 10 m (the plaza's corner walkers
    before they got room: 4.2 per m², where random placement two radii apart fails) are refused
    with the key path and the room they need; the same with avoidance off is accepted."""
    text = PLAZA.format(every=1).replace(
        'count = 60\nspawn = { shape = "rect", center = [-8, 0], size = [6, 10] }',
        'count = 500\nspawn = { shape = "rect", center = [-8, 0], size = [12, 10] }',
    )
    assert "count = 500" in text
    with pytest.raises(JcrowdError, match=r"groups\[0\]\.spawn: expected room for 500 agents two"):
        parse_scenario(text, "plaza.toml")
    with pytest.raises(JcrowdError, match=r"≥ 188 m² free, ≤ 2.65 per m²\), found 120 m² free"):
        parse_scenario(text, "plaza.toml")
    parse_scenario(text.replace("avoid = true", "avoid = false"), "plaza.toml")
