"""Differentiable rollouts (jcrowd.rollouts.rollout): gradients against central differences for
every parameter kind, checkpointed against plain, jit against eager and against a loop of the
step, the surrogates' properties, the door helper, and bad input.

The scene: a 4 m × 4 m room with a 1 m door into a corridor; four agents stand before the
door at the start and six more leave a source at the back of the room, two per second. In 3 s
(90 steps) the first ones are through the door and the exit line 0.6 m into the corridor, the
last still in the room, and nobody has reached the target at the corridor's end (8.5 m), so no
agent leaves the scene (an arrival is a switch that central differences could straddle). The
flow stays below the door's capacity: with eight agents pressing into this door the pathwise
derivative grew about 2× every 5 steps and central differences no longer converged as h
shrank (jcrowd.rollouts.rollout, "Limits").

Compiling the gradient of 90 steps of the pedestrian step takes about a minute on a 2-core
CPU, so the gradient tests share one compiled function and are marked slow.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians import AvoidanceParams, Pedestrians, build_world, pedestrian_step
from jcrowd.rollouts.doors import door_walls, every_wall, find_door
from jcrowd.rollouts.rollout import (
    RolloutParams,
    RolloutSetup,
    Trajectory,
    initial_params,
    mean_travel_time,
    rollout,
    soft_exit_count,
)

STEPS = 90
DT = 1.0 / 30.0
LINE = ((0.0, 4.6), (0.0, 1.0))  # a point of the exit line and its normal, out of the room
RATE = 2.0
# The fields of AvoidanceParams the plain model with a reaction time reads (the others are the
# anticipation model's: their gradients are exactly 0 here).
PLAIN_FIELDS = (
    "strength",
    "range",
    "wall_strength",
    "wall_range",
    "time_gap",
    "sharpness",
    "wall_slide",
    "anisotropy",
    "plain_reaction_time",
)


@functools.cache
def _world() -> tuple[Any, Any]:
    """The room, its door and the start (host arrays, float32 as built)."""
    room = shapely.box(0.0, 0.0, 4.0, 4.0)
    corridor = shapely.box(1.5, 4.0 - 1e-9, 2.5, 9.0)
    world = build_world(shapely.union(room, corridor), [shapely.box(1.5, 8.5, 2.5, 9.0)])
    door = find_door(
        np.asarray(world.walls), [(1.5, 4.0), (1.5, 9.0)], [(2.5, 4.0), (2.5, 9.0)], tol=1e-4
    )
    rng = np.random.default_rng(3)
    front = [(2.0, 3.3), (1.3, 2.8), (2.7, 2.6), (2.0, 2.2)]
    back = [(x, z) for z in (1.3, 0.6) for x in (1.2, 2.0, 2.8)]
    start = np.asarray(front + back) + rng.uniform(-0.05, 0.05, (len(front) + len(back), 2))
    # Those before the door left the source long before the start; the others leave it in order.
    rank = np.concatenate([np.full(len(front), -30.0), np.arange(len(back), dtype=float)])
    return world, (door, start, rank)


def _setup(
    dtype: Any = jnp.float64, *, anticipate: bool = False, checkpoint: bool = True, **kw: Any
) -> RolloutSetup:
    world, (door, start, rank) = _world()
    n = len(start)
    peds = Pedestrians(
        jnp.asarray(start, dtype),
        jnp.zeros(n, jnp.int32),
        jnp.full(n, 1.34, dtype),
        jnp.full(n, 0.2, dtype),
        jnp.ones(n, bool),
        jnp.zeros((n, 2), dtype),
        anticipate,
    )
    return RolloutSetup(
        world,
        peds,
        jnp.asarray(rank, dtype),
        steps=kw.pop("steps", STEPS),
        dt=DT,
        doors=(door,),
        checkpoint=checkpoint,
        **kw,
    )


def _params(setup: RolloutSetup, dtype: Any = jnp.float64) -> RolloutParams:
    p = initial_params(setup, AvoidanceParams(), rate=RATE)
    return jax.tree.map(lambda a: a.astype(dtype), p)


def _loss(params: RolloutParams, setup: RolloutSetup) -> jax.Array:
    """Both surrogates and a generic linear read-out of where everyone is at the end (so every
    agent's path counts, not only those near the exit line)."""
    traj = rollout(params, setup)
    weights = jnp.asarray(
        np.random.default_rng(0).standard_normal(traj.position.shape[1:]), traj.position.dtype
    )
    return (
        soft_exit_count(traj, *LINE)
        + mean_travel_time(traj, *LINE)
        + 0.1 * jnp.mean(traj.position[-1] * weights)
    )


_value_and_grad = jax.jit(jax.value_and_grad(_loss))
_rollout = jax.jit(rollout)


@pytest.fixture
def x64() -> Iterator[None]:
    """float64 for this test only (central differences need it); the setting is restored."""
    with jax.enable_x64(True):
        yield


def _central(
    params: RolloutParams, setup: RolloutSetup, where: Any, direction: Any, h: float
) -> float:
    """``(L(θ + h d) − L(θ − h d)) / 2h`` for the leaf (or leaves) ``where`` picks."""

    def moved(sign: float) -> RolloutParams:
        return eqx.tree_at(
            where, params, jax.tree.map(lambda a, d: a + sign * h * d, where(params), direction)
        )

    plus, _ = _value_and_grad(moved(1.0), setup)
    minus, _ = _value_and_grad(moved(-1.0), setup)
    return float(plus - minus) / (2 * h)


def _directional(grad: RolloutParams, where: Any, direction: Any) -> float:
    parts = jax.tree.map(lambda g, d: jnp.sum(g * d), where(grad), direction)
    return float(sum(jax.tree.leaves(parts)))


def _check(analytic: float, numeric: float, what: str) -> None:
    # The bound: relative error ≤ 1e-2. Central differences at h = 1e-6 (relative) in
    # float64 carry truncation ~h² and rounding ~1e-16/h ≈ 1e-10, far below it; what could
    # exceed it is a step straddling a switch of the hard structure (module docstring of
    # jcrowd.rollouts.rollout), which these fixed directions do not.
    assert abs(numeric) > 1e-6, f"{what}: the central difference is {numeric}, nothing to check"
    assert abs(analytic - numeric) <= 1e-2 * abs(numeric), (what, analytic, numeric)


# ------------------------------------------------------------------------- gradients


def _check_avoidance_fields(params, setup, grad, names) -> None:
    """Each named avoidance parameter's gradient against central differences (step 1e-6·|value|)."""
    for name in names:
        value = float(getattr(params.avoidance, name))
        num = _central(
            params,
            setup,
            lambda p, name=name: getattr(p.avoidance, name),
            jnp.ones((), jnp.float64),
            1e-6 * abs(value),
        )
        _check(float(getattr(grad.avoidance, name)), num, name)


@pytest.mark.slow
def test_gradient_matches_central_differences_for_avoidance_params(x64: None) -> None:
    setup = _setup()
    params = _params(setup)
    _, grad = _value_and_grad(params, setup)
    _check_avoidance_fields(params, setup, grad, PLAIN_FIELDS)
    for name in ("anticipation_time", "anticipation_strength", "reaction_time", "keep_right"):
        assert float(getattr(grad.avoidance, name)) == 0.0, name  # not read by the plain model


@pytest.mark.slow
def test_gradient_matches_central_differences_for_desired_speeds(x64: None) -> None:
    setup = _setup()
    params = _params(setup)
    _, grad = _value_and_grad(params, setup)
    d = jnp.asarray(np.random.default_rng(1).standard_normal(params.speed.shape))
    num = _central(params, setup, lambda p: p.speed, d, 1e-6)
    _check(_directional(grad, lambda p: p.speed, d), num, "speed")
    # One agent of the source alone: its speed only matters once it has left.
    one = jnp.zeros_like(params.speed).at[6].set(1.0)
    num = _central(params, setup, lambda p: p.speed, one, 1e-6)
    _check(float(grad.speed[6]), num, "speed[6]")


@pytest.mark.slow
def test_gradient_matches_central_differences_for_walls(x64: None) -> None:
    """A random move of every vertex, each moving the ends of all segments that meet there
    (the rings stay closed). Moving one segment's end alone splits a corner into two, and
    where an agent slides along the corner its two walls press alike (the slide picks one):
    central differences then average two one-sided slopes (measured: 10 % off)."""
    setup = _setup()
    params = _params(setup)
    _, grad = _value_and_grad(params, setup)
    ends = np.asarray(params.walls).reshape(-1, 2)
    _, vertex = np.unique(ends.round(6), axis=0, return_inverse=True)
    moves = np.random.default_rng(2).standard_normal((vertex.max() + 1, 2))
    d = jnp.asarray(moves[vertex.ravel()].reshape(params.walls.shape))
    num = _central(params, setup, lambda p: p.walls, d, 1e-6)
    _check(_directional(grad, lambda p: p.walls, d), num, "walls")


@pytest.mark.slow
def test_gradient_matches_central_differences_for_door_width(x64: None) -> None:
    setup = _setup()
    params = _params(setup)
    _, grad = _value_and_grad(params, setup)
    num = _central(params, setup, lambda p: p.door_width, jnp.ones(1), 1e-6)
    _check(float(grad.door_width[0]), num, "door width")


@pytest.mark.slow
def test_gradient_matches_central_differences_for_source_rate(x64: None) -> None:
    setup = _setup()
    params = _params(setup)
    _, grad = _value_and_grad(params, setup)
    num = _central(params, setup, lambda p: p.rate, jnp.ones(()), 1e-6 * RATE)
    _check(float(grad.rate), num, "rate")


@pytest.mark.slow
def test_gradient_is_not_silently_zero(x64: None) -> None:
    """Every parameter kind moves the loss: a gradient cut somewhere (a stop_gradient, an
    integer cast, a parameter the rollout forgot to read) fails here."""
    setup = _setup()
    _, grad = _value_and_grad(_params(setup), setup)
    kinds = {
        "avoidance": jnp.stack([getattr(grad.avoidance, f) for f in PLAIN_FIELDS]),
        "speed": grad.speed,
        "walls": grad.walls,
        "door_width": grad.door_width,
        "rate": grad.rate,
    }
    for name, g in kinds.items():
        assert np.isfinite(np.asarray(g)).all(), name
        # Each is at least 1e-3 on this scene (measured: 1e-2 … 1e0); 1e-4 leaves margin.
        assert float(jnp.max(jnp.abs(g))) > 1e-4, name
    # Every agent has walked by the end, those of the source too: each speed counts.
    assert np.all(np.abs(np.asarray(grad.speed)) > 0)


@pytest.mark.slow
def test_checkpointed_gradient_equals_plain_gradient(x64: None) -> None:
    """Blocks under jax.checkpoint (9 blocks of 10 steps here) recompute the same values: the
    gradients agree to rounding (float64; the recomputation may fuse differently)."""
    setup = _setup()
    params = _params(setup)
    v1, g1 = _value_and_grad(params, setup)
    v2, g2 = _value_and_grad(params, _setup(checkpoint=False))
    np.testing.assert_allclose(float(v1), float(v2), rtol=1e-12)
    for a, b in zip(jax.tree.leaves(g1), jax.tree.leaves(g2), strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_anticipation_model_gradient_matches_central_differences(x64: None) -> None:
    """The anticipation model's own parameters (and the rate, through agents stepping in
    among standing ones) on the same scene."""
    setup = _setup(anticipate=True)
    params = _params(setup)
    _, grad = _value_and_grad(params, setup)
    _check_avoidance_fields(
        params,
        setup,
        grad,
        ("anticipation_strength", "anticipation_range", "reaction_time", "strength"),
    )
    num = _central(params, setup, lambda p: p.rate, jnp.ones(()), 1e-6 * RATE)
    _check(float(grad.rate), num, "rate")


# ------------------------------------------------------------------------- transformations


def _float32_setup() -> RolloutSetup:
    """The scene in float32, 90 steps in blocks of 8: the last block is padded with six
    steps that change nothing."""
    return _setup(jnp.float32, block=8)


@pytest.mark.slow
def test_rollout_jit_equals_eager_equals_a_loop_of_the_step() -> None:
    """The loop is the oracle: pedestrian_step with each agent's speed times its soft entry
    weight, step after step."""
    setup = _float32_setup()
    params = _params(setup, jnp.float32)
    jitted = _rollout(params, setup)
    eager = rollout(params, setup)
    step = jax.jit(pedestrian_step)
    peds, weights = setup.peds, np.asarray(jitted.entered)
    assert weights.shape == (STEPS + 1, 10) and np.all(weights[:, :4] > 0.99)
    loop = [peds.position]
    for k in range(STEPS):
        walking = eqx.tree_at(lambda p: p.speed, peds, params.speed * weights[k])
        peds, _ = step(params.avoidance, setup.world, walking, DT)
        loop.append(peds.position)
    # Separately compiled programs may fuse (and round) differently; float32 over 90 steps.
    np.testing.assert_allclose(np.asarray(eager.position), np.asarray(jitted.position), atol=1e-5)
    np.testing.assert_allclose(np.asarray(jitted.position), np.stack(loop), atol=1e-5)
    assert int(jitted.overflow) == 0 and np.asarray(jitted.alive).all()


@pytest.mark.slow
def test_surrogates_are_bounded_and_the_count_grows_with_time() -> None:
    """0 ≤ C(T) ≤ N, C non-decreasing in T here (everyone walks out, nobody back),
    0 ≤ mean travel time ≤ T and non-decreasing in T (censored times only grow)."""
    setup = _float32_setup()
    traj = _rollout(_params(setup, jnp.float32), setup)
    n = traj.position.shape[1]
    times = np.arange(0, STEPS + 1, 10) * DT
    counts = np.array([float(soft_exit_count(traj, *LINE, time=t)) for t in times])
    travel = np.array([float(mean_travel_time(traj, *LINE, time=t)) for t in times])
    assert np.all((counts >= 0) & (counts <= n))
    assert np.all(np.diff(counts) >= -1e-4)  # float32 sums
    assert counts[-1] > 2.0  # a few through: the count is doing something
    assert np.all((travel >= 0) & (travel <= times + 1e-6))
    assert np.all(np.diff(travel) >= 0)


# ------------------------------------------------------------------------- doors and errors


def test_door_width_moves_both_sides_symmetrically() -> None:
    world, (door, _, _) = _world()
    walls = world.walls
    wider = np.asarray(door_walls(walls, (door,), jnp.asarray([1.6], walls.dtype)))
    before = np.asarray(walls)
    (ls, le), (rs, re) = door.left[0], door.right[0]
    np.testing.assert_allclose(wider[rs, re] - wider[ls, le], [1.6, 0.0], atol=1e-6)
    np.testing.assert_allclose(wider[rs, re] + wider[ls, le], before[rs, re] + before[ls, le])
    moved = {p for p in door.left + door.right}
    for s in range(len(before)):
        for e in (0, 1):
            if (s, e) not in moved:
                np.testing.assert_array_equal(wider[s, e], before[s, e])
    # The rings stay closed: each segment still ends where the next begins.
    ends = {tuple(np.round(x, 6)) for x in wider.reshape(-1, 2)}
    assert len(ends) == len({tuple(np.round(x, 6)) for x in before.reshape(-1, 2)})


def test_every_wall_makes_each_wall_a_candidate_everywhere() -> None:
    world, _ = _world()
    every = every_wall(world)
    s = world.walls.shape[0]
    assert every.cell_walls.shape == (world.cell_walls.shape[0], s)
    assert np.all(np.asarray(every.cell_walls) == np.arange(s))


def test_bad_input_is_an_error() -> None:
    world, _ = _world()
    walls = np.asarray(world.walls)
    with pytest.raises(JcrowdError, match="wall vertex"):
        find_door(walls, [(1.0, 4.0)], [(2.5, 4.0)])
    with pytest.raises(JcrowdError, match="at least one left"):
        find_door(walls, [], [(2.5, 4.0)])
    setup = _setup(jnp.float32)
    with pytest.raises(JcrowdError, match="steps ≥ 1"):
        _setup(jnp.float32, steps=0)
    with pytest.raises(JcrowdError, match="entry_rank"):
        RolloutSetup(setup.world, setup.peds, jnp.zeros(3), steps=5)
    params = _params(setup, jnp.float32)
    with pytest.raises(JcrowdError, match=r"params\.speed"):
        rollout(eqx.tree_at(lambda p: p.speed, params, params.speed[:3]), setup)
    with pytest.raises(JcrowdError, match=r"params\.door_width"):
        rollout(eqx.tree_at(lambda p: p.door_width, params, jnp.zeros(2)), setup)
    n = setup.peds.position.shape[0]
    short = Trajectory(
        jnp.zeros((3, n, 2)), jnp.ones((3, n), bool), jnp.ones((3, n)), jnp.int32(0), DT
    )
    with pytest.raises(JcrowdError, match="time in"):
        soft_exit_count(short, *LINE, time=1.0)
    with pytest.raises(JcrowdError, match="time in"):
        mean_travel_time(short, *LINE, time=-0.5)
