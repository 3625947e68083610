"""The pedestrian step (jcrowd.pedestrians.step): safety on a bottleneck run, exits, passing,
overflow, walls from geometry, and transformations (jit == eager)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely
from on_devices import run_on_devices

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians import (
    AvoidanceParams,
    Pedestrians,
    build_world,
    pedestrian_step,
    wall_segments,
)


def _bottleneck(width: float):
    room = shapely.box(0.0, 0.0, 6.0, 6.0)
    corridor = shapely.box(3.0 - width / 2, 6.0 - 1e-9, 3.0 + width / 2, 9.0)
    return shapely.union(room, corridor), shapely.box(3.0 - width / 2, 8.5, 3.0 + width / 2, 9.0)


def _peds(pos, speed=1.34, anticipate=False):
    n = len(pos)
    return Pedestrians(
        jnp.asarray(pos, jnp.float32),
        jnp.zeros(n, jnp.int32),
        jnp.full(n, speed, jnp.float32),
        jnp.full(n, 0.2, jnp.float32),
        jnp.ones(n, bool),
        jnp.zeros((n, 2), jnp.float32) if anticipate else None,
    )


def _grid_positions(n, lo, hi, spacing, seed=0):
    xs = np.arange(lo[0], hi[0], spacing)
    zs = np.arange(lo[1], hi[1], spacing)
    pts = np.stack(np.meshgrid(xs, zs), -1).reshape(-1, 2)
    rng = np.random.default_rng(seed)
    return pts[rng.choice(len(pts), n, replace=False)] + rng.uniform(-0.05, 0.05, (n, 2))


@pytest.mark.parametrize("anticipate", [False, True], ids=["plain", "anticipating"])
def test_a_bottleneck_empties_safely(anticipate):
    """40 agents leave a 6 m room through a 1 m corridor: all leave, no NaN, nobody inside a
    wall, no two closer than 0.9 of their summed radii (the model is collision-free)."""
    area, exit_ = _bottleneck(1.0)
    world = build_world(area, [exit_])
    peds = _peds(_grid_positions(40, (0.5, 0.5), (5.5, 5.0), 0.6), anticipate=anticipate)
    step = jax.jit(pedestrian_step)
    params = AvoidanceParams()
    inside = shapely.buffer(area, 0.01)
    worst = np.inf
    for _ in range(1500):
        peds, info = step(params, world, peds, 1 / 30)
        alive = np.asarray(peds.alive)
        pos = np.asarray(peds.position)[alive]
        assert np.isfinite(pos).all() and int(info.overflow) == 0
        if len(pos) > 1:
            d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + 9 * np.eye(len(pos))
            worst = min(worst, d.min() / 0.4)
        assert shapely.contains_xy(inside, pos[:, 0], pos[:, 1]).all()
        if not alive.any():
            break
    assert not np.asarray(peds.alive).any()  # everyone reached the exit within 50 s
    assert worst >= 0.9, worst


def test_two_agents_walking_at_each_other_pass():
    """Head-on in an open area, 0.1 m off axis: they sidestep and both arrive."""
    area = shapely.box(0.0, -5.0, 20.0, 5.0)
    world = build_world(
        area, [shapely.box(19.0, -5.0, 20.0, 5.0), shapely.box(0.0, -5.0, 1.0, 5.0)]
    )
    base = _peds(np.array([[2.0, 0.05], [18.0, -0.05]]))
    peds = Pedestrians(
        base.position, jnp.array([0, 1], jnp.int32), base.speed, base.radius, base.alive
    )
    step = jax.jit(pedestrian_step)
    closest = np.inf
    for _ in range(600):
        peds, _ = step(AvoidanceParams(), world, peds, 1 / 30)
        p = np.asarray(peds.position)
        if np.asarray(peds.alive).all():
            closest = min(closest, float(np.linalg.norm(p[0] - p[1])))
    assert not np.asarray(peds.alive).any()
    assert 0.36 <= closest < 1.0  # they came close (so they met) but did not overlap


def test_exit_removes_agents_inside_their_target():
    area, exit_ = _bottleneck(1.2)
    world = build_world(area, [exit_])
    peds = _peds(np.array([[3.0, 8.6], [3.0, 2.0]]))
    peds, info = pedestrian_step(AvoidanceParams(), world, peds, 1 / 30)
    np.testing.assert_array_equal(np.asarray(info.arrived), [True, False])
    np.testing.assert_array_equal(np.asarray(peds.alive), [False, True])


def test_overflow_is_counted():
    area, exit_ = _bottleneck(1.2)
    world = build_world(area, [exit_], grid_cell=2.0, max_density=0.5)  # 4 slots per cell
    peds = _peds(_grid_positions(12, (0.5, 0.5), (2.0, 2.0), 0.45))  # 16 places in one cell
    _, info = pedestrian_step(AvoidanceParams(), world, peds, 1 / 30)
    assert int(info.overflow) > 0


def test_jit_equals_eager():
    area, exit_ = _bottleneck(1.2)
    world = build_world(area, [exit_])
    peds = _peds(_grid_positions(25, (0.5, 0.5), (5.5, 5.5), 0.7))
    a, ia = pedestrian_step(AvoidanceParams(), world, peds, 1 / 30)
    b, ib = jax.jit(pedestrian_step)(AvoidanceParams(), world, peds, 1 / 30)
    np.testing.assert_allclose(np.asarray(a.position), np.asarray(b.position), atol=1e-6)
    np.testing.assert_allclose(np.asarray(ia.velocity), np.asarray(ib.velocity), atol=1e-5)


def test_walls_are_the_walkable_boundary_and_bad_worlds_are_errors():
    area = shapely.box(0, 0, 4, 4).difference(shapely.box(1, 1, 2, 2))
    segs = wall_segments(area)
    assert segs.shape == (8, 2, 2)  # four outer edges, four around the hole
    lines = shapely.unary_union(shapely.linestrings(segs))
    assert lines.equals(shapely.unary_union([area.exterior, *area.interiors]))
    with pytest.raises(JcrowdError, match=r"target 1: .*covers no walkable cell"):
        build_world(area, [shapely.box(3, 3, 4, 4), shapely.box(1.2, 1.2, 1.8, 1.8)])
    with pytest.raises(JcrowdError, match="expected a walkable area"):
        build_world(shapely.Polygon(), [shapely.box(0, 0, 1, 1)])


SPLIT_SCRIPT = """
import json
import numpy as np, jax, jax.numpy as jnp, shapely
from jcrowd.pedestrians import AvoidanceParams, Pedestrians, build_world, split_pedestrian_step
room = shapely.box(0.0, 0.0, 6.0, 6.0)
area = shapely.union(room, shapely.box(2.5, 6.0 - 1e-9, 3.5, 9.0))
world = build_world(area, [shapely.box(2.5, 8.5, 3.5, 9.0)])
xs = np.arange(0.5, 5.5, 0.6)
pts = np.stack(np.meshgrid(xs, np.arange(0.5, 5.0, 0.6)), -1).reshape(-1, 2)[:40]
n = len(pts)
peds = Pedestrians(jnp.asarray(pts, jnp.float32), jnp.zeros(n, jnp.int32),
                   jnp.full(n, 1.34, jnp.float32), jnp.full(n, 0.2, jnp.float32),
                   jnp.ones(n, bool), VELOCITY)
step = split_pedestrian_step()
left = []
for _ in range(200):
    peds, info = step(AvoidanceParams(), world, peds, jnp.float32(1 / 30))
    left.append(int(np.sum(np.asarray(info.arrived))))
print(json.dumps({"pos": np.asarray(peds.position).tolist(),
                  "alive": np.asarray(peds.alive).tolist(), "left": left,
                  "devices": jax.device_count()}))
"""


@pytest.mark.slow
@pytest.mark.parametrize(
    "velocity", ["None", "jnp.zeros((n, 2), jnp.float32)"], ids=["plain", "anticipating"]
)
def test_split_over_two_devices_equals_one_device(velocity):
    """split_pedestrian_step on 2 devices (blocks of 20, neighbours — and, anticipating, their
    velocities — through the all-gather) equals it on 1 device: same agents out at the same
    steps, positions to 1e-4 m after 200 steps of a jammed bottleneck (float32 sums in another
    order, grown over the steps)."""
    script = SPLIT_SCRIPT.replace("VELOCITY", velocity)
    out = {k: run_on_devices(script, k) for k in (1, 2)}
    assert out[1]["devices"] == 1 and out[2]["devices"] == 2
    assert out[2]["left"] == out[1]["left"] and sum(out[1]["left"]) > 0
    assert out[2]["alive"] == out[1]["alive"]
    np.testing.assert_allclose(out[2]["pos"], out[1]["pos"], atol=1e-4)
