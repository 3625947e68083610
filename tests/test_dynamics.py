"""The pedestrian step (jcrowd.pedestrians.step): safety on a bottleneck run, exits, passing,
overflow, walls from geometry, and transformations (jit == eager). The step split over two
devices is compared with one device in tests/test_split_devices.py."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely

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
