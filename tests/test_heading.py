"""The body heading of the pedestrian step (jcrowd.pedestrians.heading).

Oracles: a scalar loop of the turn rule written with ``math`` (not the vectorized code), the
heading share's closed form at the three bearings, and the direction to a goal or down a
distance field measured by finite differences of the field (not its gradient code).
Properties: the turn never exceeds ``ω Δt``; a lower ``back_share`` never speeds anyone up.
Transformations: jit == eager; the split step is compared in tests/test_split_devices.py
(its anticipating case carries a heading).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians import AvoidanceParams, Pedestrians, build_world, pedestrian_step
from jcrowd.pedestrians.heading import body_speed, facing, turn_heading
from jcrowd.pedestrians.navigation import field_values
from jcrowd.pedestrians.neighbours import grid_spec
from jcrowd.pedestrians.world import open_world


def _turn_loop(params: AvoidanceParams, heading, velocity, desired, dt):
    """The turn rule one agent at a time in plain floats."""
    walk, tau, rate = float(params.walk_speed), float(params.heading_time), float(params.turn_rate)
    stand = float(params.stand_turn_share)
    out = []
    for h, (vx, vz), (dx, dz) in zip(heading, velocity, desired, strict=True):
        speed = math.hypot(vx, vz)
        s = min(max(speed / walk, 0.0), 1.0)
        w = s * s * (3 - 2 * s) if speed > 1e-6 else 0.0
        ux, uz = (vx / speed, vz / speed) if speed > 1e-6 else (0.0, 0.0)
        tx, tz = w * ux + (1 - w) * dx, w * uz + (1 - w) * dz
        if math.hypot(tx, tz) <= 1e-6:
            out.append(h)
            continue
        diff = math.atan2(tx, tz) - h
        diff = (diff + math.pi) % (2 * math.pi) - math.pi
        turn = diff * min(1.0, dt / tau)
        limit = rate * (stand + (1 - stand) * w) * dt
        out.append(h + max(-limit, min(limit, turn)))
    return np.array(out)


def test_turn_equals_a_scalar_loop():
    rng = np.random.default_rng(3)
    n = 64
    heading = rng.uniform(-4, 4, n).astype(np.float32)
    velocity = (rng.normal(size=(n, 2)) * rng.uniform(0, 1.5, (n, 1))).astype(np.float32)
    velocity[:5] = 0.0  # standing: the desired direction alone
    ang = rng.uniform(-np.pi, np.pi, n)
    desired = np.stack([np.sin(ang), np.cos(ang)], 1).astype(np.float32)
    desired[:2] = 0.0  # standing with nowhere to go: the heading stays
    params, dt = AvoidanceParams(), 1 / 30
    got = turn_heading(
        params, jnp.asarray(heading), jnp.asarray(velocity), jnp.asarray(desired), dt
    )
    want = _turn_loop(params, heading, velocity, desired, dt)
    np.testing.assert_allclose(np.asarray(got), want, atol=2e-5)
    assert np.asarray(got)[0] == heading[0] and np.asarray(got)[1] == heading[1]


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-10, 10),
    st.floats(-3, 3),
    st.floats(-3, 3),
    st.floats(-np.pi, np.pi),
    st.floats(1e-3, 0.5),
)
def test_the_turn_is_bounded_by_the_rate(heading, vx, vz, goal, dt):
    params = AvoidanceParams()
    desired = jnp.asarray([[math.sin(goal), math.cos(goal)]], jnp.float32)
    new = turn_heading(
        params,
        jnp.asarray([heading], jnp.float32),
        jnp.asarray([[vx, vz]], jnp.float32),
        desired,
        dt,
    )
    assert (
        abs(float(new[0]) - np.float32(heading)) <= float(params.turn_rate) * dt * (1 + 1e-5) + 1e-5
    )


def test_the_heading_share_at_three_bearings():
    """``b + (1 − b)((1 + cos φ)/2)²``: 1 ahead, (1 + 3b)/4 to the side, b straight back."""
    params = AvoidanceParams(back_share=0.25)
    face = facing(jnp.zeros(3))  # facing +z
    ex, ez = jnp.asarray([0.0, 1.0, 0.0]), jnp.asarray([1.0, 0.0, -1.0])
    got = body_speed(params, ex, ez, jnp.full(3, 1.2), face)
    np.testing.assert_allclose(np.asarray(got), [1.2, 1.2 * 0.4375, 1.2 * 0.25], rtol=1e-6)
    unchanged = body_speed(AvoidanceParams(), ex, ez, jnp.full(3, 1.2), face)
    np.testing.assert_array_equal(np.asarray(unchanged), np.full(3, 1.2, np.float32))


def _room():
    area = shapely.box(0.0, 0.0, 8.0, 8.0)
    return build_world(area, [shapely.box(7.0, 7.0, 8.0, 8.0)])


def test_a_standing_agent_turns_to_face_down_its_field():
    """Nobody walks (free speed 0): each body turns, at most ω Δt a step, until it faces the
    field's steepest descent (finite differences of the field)."""
    world = _room()
    pos = np.array([[1.0, 1.0], [2.0, 5.0], [6.0, 2.5]], np.float32)
    n = len(pos)
    peds = Pedestrians(
        jnp.asarray(pos),
        jnp.zeros(n, jnp.int32),
        jnp.zeros(n, jnp.float32),
        jnp.full(n, 0.2, jnp.float32),
        jnp.ones(n, bool),
        jnp.zeros((n, 2), jnp.float32),
        False,
        heading=jnp.asarray([math.pi, -2.0, 2.5], jnp.float32),
    )
    params, dt = AvoidanceParams(), 1 / 30
    step = jax.jit(pedestrian_step)
    before = np.asarray(peds.heading)
    for _ in range(200):  # a standing body turns at 0.4 of 3 rad/s
        peds, info = step(params, world, peds, dt)
        after = np.asarray(peds.heading)
        turned = np.abs(np.remainder(after - before + np.pi, 2 * np.pi) - np.pi)
        assert (turned <= float(params.turn_rate) * dt + 1e-5).all()
        before = after
        assert np.abs(np.asarray(info.velocity)).max() == 0.0
    np.testing.assert_array_equal(np.asarray(peds.position), pos)  # nobody moved
    eps = 0.05
    x, z = jnp.asarray(pos[:, 0]), jnp.asarray(pos[:, 1])
    t = jnp.zeros(n, jnp.int32)
    gx = field_values(world.nav, t, x + eps, z) - field_values(world.nav, t, x - eps, z)
    gz = field_values(world.nav, t, x, z + eps) - field_values(world.nav, t, x, z - eps)
    down = np.arctan2(-np.asarray(gx), -np.asarray(gz))
    off = np.degrees(
        np.abs(np.remainder(np.asarray(peds.heading) - down + np.pi, 2 * np.pi) - np.pi)
    )
    assert (off < 3.0).all(), off


def test_a_walker_faces_where_it_walks_and_a_standing_one_its_goal():
    """In an open world: one agent walks to its goal (its heading ends along its velocity);
    one with free speed 0 stands and faces its goal, behind it at the start."""
    world = open_world(grid_spec((0.0, 0.0), (10.0, 10.0), 1.0))
    peds = Pedestrians(
        jnp.asarray([[2.0, 2.0], [5.0, 5.0]], jnp.float32),
        jnp.zeros(2, jnp.int32),
        jnp.asarray([1.2, 0.0], jnp.float32),
        jnp.full(2, 0.2, jnp.float32),
        jnp.ones(2, bool),
        jnp.zeros((2, 2), jnp.float32),
        False,
        goal=jnp.asarray([[8.0, 2.0], [5.0, 1.0]], jnp.float32),
        heading=jnp.asarray([0.0, 0.0], jnp.float32),  # both face +z
    )
    step = jax.jit(pedestrian_step)
    for _ in range(90):
        peds, info = step(AvoidanceParams(), world, peds, 1 / 30)
    h = np.asarray(peds.heading)
    v = np.asarray(info.velocity)
    np.testing.assert_allclose(
        np.remainder(h[0], 2 * np.pi), math.atan2(v[0, 0], v[0, 1]), atol=1e-3
    )
    for _ in range(120):  # standing, it turns at 0.4 of the rate: π takes over 2.6 s
        peds, info = step(AvoidanceParams(), world, peds, 1 / 30)
    h = np.asarray(peds.heading)
    assert abs(np.remainder(h[1], 2 * np.pi) - math.pi) < 1e-3  # goal at −z: θ = π


def test_back_share_never_speeds_anyone_up():
    """A jammed bottleneck with headings facing every way: with ``back_share`` < 1 no agent's
    speed exceeds the same step's without (the collision-free bound is kept)."""
    rng = np.random.default_rng(0)
    world = _room()
    pos = rng.uniform(0.5, 7.5, (60, 2)).astype(np.float32)
    n = len(pos)
    peds = Pedestrians(
        jnp.asarray(pos),
        jnp.zeros(n, jnp.int32),
        jnp.full(n, 1.34, jnp.float32),
        jnp.full(n, 0.2, jnp.float32),
        jnp.ones(n, bool),
        jnp.asarray(rng.normal(size=(n, 2)) * 0.5, jnp.float32),
        True,
        heading=jnp.asarray(rng.uniform(-np.pi, np.pi, n), jnp.float32),
    )
    stepped = jax.jit(pedestrian_step)  # one program for both (op by op, every op compiles)
    _, free = stepped(AvoidanceParams(), world, peds, 1 / 30)
    _, bound = stepped(AvoidanceParams(back_share=0.25), world, peds, 1 / 30)
    s_free = np.linalg.norm(np.asarray(free.velocity), axis=1)
    s_bound = np.linalg.norm(np.asarray(bound.velocity), axis=1)
    assert (s_bound <= s_free + 1e-6).all()
    assert (s_bound < s_free - 1e-3).sum() > n // 4  # and it does slow many down


def test_jit_equals_eager_with_a_heading():
    world = _room()
    rng = np.random.default_rng(1)
    n = 20
    peds = Pedestrians(
        jnp.asarray(rng.uniform(0.5, 7.5, (n, 2)), jnp.float32),
        jnp.zeros(n, jnp.int32),
        jnp.full(n, 1.34, jnp.float32),
        jnp.full(n, 0.2, jnp.float32),
        jnp.ones(n, bool),
        jnp.zeros((n, 2), jnp.float32),
        True,
        heading=jnp.asarray(rng.uniform(-np.pi, np.pi, n), jnp.float32),
    )
    params = AvoidanceParams(back_share=0.5)
    eager, jitted = peds, peds
    step = jax.jit(pedestrian_step)
    for _ in range(5):
        eager, _ = pedestrian_step(params, world, eager, 1 / 30)
        jitted, _ = step(params, world, jitted, 1 / 30)
    np.testing.assert_allclose(np.asarray(eager.heading), np.asarray(jitted.heading), atol=1e-5)
    np.testing.assert_allclose(np.asarray(eager.position), np.asarray(jitted.position), atol=1e-5)


def test_a_heading_without_velocities_is_refused():
    world = _room()
    peds = Pedestrians(
        jnp.ones((1, 2), jnp.float32),
        jnp.zeros(1, jnp.int32),
        jnp.ones(1, jnp.float32),
        jnp.full(1, 0.2, jnp.float32),
        jnp.ones(1, bool),
        heading=jnp.zeros(1, jnp.float32),
    )
    with pytest.raises(JcrowdError, match="expected the last velocities"):
        pedestrian_step(AvoidanceParams(), world, peds, 1 / 30)
