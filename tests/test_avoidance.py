"""The collision-free speed model (jcrowd.pedestrians.avoidance) against a NumPy transcription.

The oracle below is the model's four equations (Tordeux, Chraibi & Seyfried 2016, Eqs. 1–4;
walls and, with last velocities, the standing rule as the module docstring reads them) written
as plain float64 loops over every other agent and every wall, without the candidate lists,
padding or masks of the JAX version.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jcrowd.pedestrians import (
    AvoidanceParams,
    Motion,
    avoid,
    avoid_one,
    candidates,
    cell_list,
    grid_spec,
)

A, D, AW, DW, T = 8.0, 0.1, 5.0, 0.02, 0.6
SHARP, LAMBDA, SLIDE = 4.0, 0.3, 0.1  # V's sharpness n, the anisotropy λ, the slide reach m
DRIVE, GO = 0.7, 2.0  # c and v_go of the standing rule (with a last velocity)
STANDING = AvoidanceParams(stand_drive=DRIVE, go_speed=GO)  # the rule on (off by default)


def _oracle(pos, desired, speed, radius, walls):
    """Velocities and spacings of every agent, Eqs. (1)–(4), float64 loops."""
    n = len(pos)
    vel, gaps = np.zeros((n, 2)), np.full(n, np.inf)
    for i in range(n):
        e = _desire_and_bodies(i, desired, pos, radius, walls)
        vel[i], gaps[i] = _walls_then_speed(i, e, pos, speed, radius, walls)
    return vel, gaps


def _desire_and_bodies(i, desired, pos, radius, walls):
    """Eq. (4) before the walls: agent ``i``'s slid desire plus every other body's push."""
    e0 = _slid(i, desired[i], pos, radius, walls)
    e = e0.copy()
    for j in range(len(pos)):
        if j != i:
            e += _body_push(i, j, pos, radius, e0)
    return e


def _slid(i, desired, pos, radius, walls):
    """Agent ``i``'s desire with the into-wall part taken by the wall it presses into most:
    each wall's push-in ``reach · min(0, e^0·n)``, ``reach`` 1 at contact falling to 0 at
    ``SLIDE`` beyond it; the most negative one is taken off along its ``n``."""
    e0 = np.array(desired, np.float64)
    worst, normal = 0.0, np.zeros(2)
    for a, b in walls:
        t = np.clip(np.dot(pos[i] - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        d = pos[i] - (a + t * (b - a))
        s = np.hypot(*d)
        reach = min(1.0, max(0.0, (radius[i] + SLIDE - s) / SLIDE))
        push_in = reach * min(0.0, np.dot(e0, d / s))
        if push_in < worst:
            worst, normal = push_in, d / s
    e0 = e0 - worst * normal
    return e0 / np.hypot(*e0)


def _body_push(i, j, pos, radius, e0):
    """Eq. (4)'s repulsion of agent ``i`` by agent ``j``: ``a e^{(ℓ_ij − s_ij)/D}`` along
    ``x_i − x_j``, weighted ``λ + (1 − λ)(1 + cos φ)/2`` by the angle ``φ`` between ``e0`` and
    the direction to ``j``."""
    d = pos[i] - pos[j]
    s = np.hypot(*d)
    cos = np.dot(-d / s, e0)
    weight = LAMBDA + (1 - LAMBDA) * (1 + cos) / 2
    return weight * A * np.exp((radius[i] + radius[j] - s) / D) * d / s


def _speed(v0, gap):
    """V(s − ℓ): ``v0 x (1 + x^n)^{−1/n}``, ``x = gap/(v0 T)``; 0 without room."""
    if gap <= 0:
        return 0.0
    x = gap / (v0 * T)
    return v0 * x / (1 + x**SHARP) ** (1 / SHARP) if np.isfinite(x) else v0


def _wall_push(i, pos, radius, walls):
    """Eq. (4)'s walls: each repels ``i`` by ``a_w e^{(r_i − d)/D_w}`` along its normal."""
    push = np.zeros(2)
    for a, b in walls:
        t = np.clip(np.dot(pos[i] - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        d = pos[i] - (a + t * (b - a))
        s = np.hypot(*d)
        push += AW * np.exp((radius[i] - s) / DW) * d / s
    return push


def _walls_then_speed(i, e, pos, speed, radius, walls, own=None, drive_sum=None):
    """Agent ``i``'s direction ``e`` plus the walls' repulsion, normalised (Eq. 4's end), then
    its spacing and speed along it (Eqs. 2–3): ``(velocity, spacing)``. Given its last velocity
    ``own``, the speed is times ``min(1, ‖E‖/c + ‖own‖/v_go)``, ``E`` the unnormalised sum
    (``drive_sum`` plus the walls; by default ``e``'s)."""
    walls_push = _wall_push(i, pos, radius, walls)
    e = np.array(e, np.float64) + walls_push
    raw = e if drive_sum is None else np.asarray(drive_sum) + walls_push
    v, gap = _speed_along(i, e / np.hypot(*e), pos, speed, radius, walls)
    if own is None:
        return v, gap
    return v * min(1.0, np.hypot(*raw) / DRIVE + np.hypot(*own) / GO), gap


def _speed_along(i, e, pos, speed, radius, walls):
    """Agent ``i``'s spacing ahead along unit ``e`` and its speed there (Eqs. 2–3):
    ``(velocity, spacing)``."""
    gap = np.inf
    for j in range(len(pos)):
        if j == i:
            continue
        u = pos[j] - pos[i]
        size = radius[i] + radius[j]
        if np.dot(u, e) >= 0 and abs(u[0] * e[1] - u[1] * e[0]) <= size:
            gap = min(gap, np.hypot(*u) - size)
    for a, b in walls:  # a wall ahead: a neighbour of size 0 at its closest point
        t = np.clip(np.dot(pos[i] - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        u = a + t * (b - a) - pos[i]
        if np.dot(u, e) >= 0 and abs(u[0] * e[1] - u[1] * e[0]) <= radius[i]:
            gap = min(gap, np.hypot(*u) - radius[i])
    return _speed(speed[i], gap) * e, gap


def _scene(n, seed, spread=3.0):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-spread, spread, (n, 2))
    # Keep agents apart by at least their sizes (the model's admissible states).
    for _ in range(200):
        d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(n) * 9
        i, j = np.unravel_index(np.argmin(d), d.shape)
        if d[i, j] > 0.45:
            break
        pos[j] = rng.uniform(-spread, spread, 2)
    angle = rng.uniform(-np.pi, np.pi, n)
    desired = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    speed = rng.uniform(0.8, 1.6, n)
    radius = rng.uniform(0.17, 0.22, n)
    walls = np.array([[[-4.0, -3.5], [4.0, -3.5]], [[3.6, -4.0], [3.6, 4.0]]])
    return pos, desired, speed, radius, walls


def _run(pos, desired, speed, radius, walls, cell=2.0):
    """The JAX path as the step runs it: grid, candidates, every wall a candidate."""
    n = len(pos)
    f32 = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, walls)]
    spec = grid_spec((-6.0, -6.0), (6.0, 6.0), cell)
    cl = cell_list(spec, f32[0], jnp.ones(n, bool))
    cand = candidates(spec, cl, f32[0])
    wall_ids = jnp.broadcast_to(jnp.arange(len(walls), dtype=jnp.int32), (n, len(walls)))
    return avoid(AvoidanceParams(), *f32[:4], cand, f32[4], wall_ids)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_velocities_equal_the_equations(seed):
    """Random 12-agent scenes inside one 12 m grid cell block: every pair interacts."""
    pos, desired, speed, radius, walls = _scene(12, seed)
    want_v, want_gap = _oracle(pos, desired, speed, radius, walls)
    got_v, got_gap = _run(pos, desired, speed, radius, walls, cell=12.0)
    # float32 against float64: positions of a few metres, exponentials summed; 2e-5 m/s is
    # ~100 float32 ulps of a 1 m/s velocity.
    np.testing.assert_allclose(np.asarray(got_v), want_v, atol=2e-5)
    finite = np.isfinite(want_gap)
    np.testing.assert_array_equal(np.isfinite(np.asarray(got_gap)), finite)
    np.testing.assert_allclose(np.asarray(got_gap)[finite], want_gap[finite], atol=2e-5)
    assert finite.any() and (~finite).any()  # premise: some have someone ahead, some not


def test_a_dense_scene_through_the_grid_equals_all_pairs_beyond_the_cutoff():
    """60 agents in 6 × 6 m with 2 m cells: neighbours farther than a cell are dropped by the
    grid but repel by less than a·exp(−(2 − 0.44)/0.1) ≈ 1e-6, below the tolerance."""
    pos, desired, speed, radius, walls = _scene(60, 7)
    want_v, _ = _oracle(pos, desired, speed, radius, walls)
    got_v, _ = _run(pos, desired, speed, radius, walls, cell=2.0)
    np.testing.assert_allclose(np.asarray(got_v), want_v, atol=5e-5)


def test_closed_forms():
    """Alone: walks at its free speed; behind someone at gap g: ``V(g) = v0 x (1 + x⁴)^{−¼}``,
    ``x = g/(v0 T)`` (the repulsion a·e^{−g/D} only shortens the +z direction), worked by hand:
    g = 0.5 m → x = 0.6410, V = 0.8014 m/s; g = 2 m → x = 2.564, V = 1.2926 m/s. Touching
    (g = 0): R = a = 8 outweighs the desire, the direction flips and, nobody being behind, it
    backs off at its free speed."""
    walls = np.zeros((0, 2, 2))
    for gap, want in ((None, 1.3), (0.5, 0.8014), (2.0, 1.2926), (0.0, -1.3)):
        pos = [[0.0, 0.0]] if gap is None else [[0.0, 0.0], [0.0, 0.4 + gap]]
        n = len(pos)
        v, _ = _run(
            np.array(pos), np.tile([0.0, 1.0], (n, 1)), np.full(n, 1.3), np.full(n, 0.2), walls
        )
        # 1e-4: the hand-worked values are rounded to 4 decimals.
        np.testing.assert_allclose(np.asarray(v)[0], [0.0, want], atol=1e-4)


def _standing(pos, params=None, own=None):
    """Velocities of people at ``pos``, all wanting +z at 1.3 m/s (r = 0.2 m), by the plain
    model with its reaction time at Δt = τ_p (so the velocity is the model's own, not
    relaxed), every other one a candidate, no walls; last velocities ``own`` (default 0:
    standing)."""
    n = len(pos)
    cand = jnp.asarray([[j for j in range(n) if j != i] for i in range(n)], jnp.int32)
    last = jnp.zeros((n, 2), jnp.float32) if own is None else jnp.asarray(own, jnp.float32)
    v, _ = avoid(
        STANDING if params is None else params,
        jnp.asarray(pos, jnp.float32),
        jnp.tile(jnp.asarray([0.0, 1.0], jnp.float32), (n, 1)),
        jnp.full(n, 1.3, jnp.float32),
        jnp.full(n, 0.2, jnp.float32),
        cand,
        jnp.zeros((0, 2, 2), jnp.float32),
        jnp.zeros((n, 0), jnp.int32),
        motion=Motion(last, None, jnp.float32(TAU_PLAIN)),
    )
    return np.asarray(v)


def test_a_person_behind_another_stands_where_desire_and_repulsion_cancel():
    """The standing rule on two people in a line, the back one standing: its net drive is
    ``E = 1 − a e^{−g/D}`` (a neighbour straight ahead weighs 1), its speed ``V(g) min(1,
    |E|/c)`` forward, or ``v0 min(1, |E|/c)`` backing off with nobody behind. By hand:
    g = 0.25 m → R = 0.6567, E = 0.3433, V = 0.4156, v = 0.2038 m/s; g = 0.18 m → R = 1.3224,
    E = −0.3224, v = −0.5987 m/s; at g* = D ln a = 0.20794 m it stands. Without the rule
    (``stand_drive`` 0, the default) it walks at the full V(0.25) = 0.4156 m/s."""
    for gap, want in ((0.25, 0.2038), (0.18, -0.5987), (0.1 * np.log(8.0), 0.0)):
        v = _standing([[0.0, 0.0], [0.0, 0.4 + gap]])
        np.testing.assert_allclose(v[0], [0.0, want], atol=2e-4)
    v = _standing([[0.0, 0.0], [0.0, 0.65]], AvoidanceParams())
    np.testing.assert_allclose(v[0], [0.0, 0.4156], atol=2e-4)


def test_a_walking_person_follows_as_the_paper_says():
    """The rule's share ``min(1, ‖E‖/c + ‖v'‖/v_go)``: walking at v_go = 2 m/s the share is 1,
    and the person 0.25 m behind another walks at the paper's V(0.25) = 0.4156 m/s (standing,
    0.2038: the test above)."""
    v = _standing([[0.0, 0.0], [0.0, 0.65]], own=[[0.0, 2.0], [0.0, 0.0]])
    np.testing.assert_allclose(v[0], [0.0, 0.4156], atol=2e-4)


def test_the_middle_of_three_stands_where_front_and_back_balance():
    """Three standing in a line: the middle one is pushed back by the front one (weight 1) and
    forward by the back one (weight λ = 0.3), ``E = 1 − R(g_f) + λ R(g_b)``. With g_b = 0.1 m,
    ``R(g_b) = 8/e = 2.9430``, the balance is at ``R(g_f) = 1.8829``, g_f = 0.14466 m: it
    stands (|v| below 1 mm/s). 2 cm farther forward, ``E = 1 − 8e^{−1.6466} + 0.8829 =
    0.3412`` and it walks at ``V(0.16466) · 0.3412/0.7``."""
    for gf, want in ((0.14466, 0.0), (0.16466, 0.3412 / 0.7)):
        v = _standing([[0.0, -0.5], [0.0, 0.0], [0.0, 0.4 + gf]])
        x = gf / (1.3 * 0.6)
        free = 1.3 * x / (1 + x**4) ** 0.25
        np.testing.assert_allclose(v[1], [0.0, want * free], atol=1e-3)


def test_a_queue_settles_instead_of_stepping_forward_and_back():
    """A person 0.5 m behind a standing one, stepped at 30 Hz by the plain model with its
    reaction time as the crowd steps it: the gap closes to the balance g* = D ln a and stays
    (within 2 mm over the last 2 s, overshooting by under 1 cm on the way). With the paper's
    normalised Eq. (4) (``stand_drive`` 0, the default) the same person steps forward and back
    around g* for as long as it runs."""

    def gaps(params):
        pos = jnp.asarray([[0.0, 0.0], [0.0, 0.9]], jnp.float32)
        desired = jnp.asarray([[0.0, 1.0], [0.0, 1.0]], jnp.float32)
        speed = jnp.asarray([1.3, 0.0], jnp.float32)  # the front one stands
        radius = jnp.full(2, 0.2, jnp.float32)
        cand = jnp.asarray([[1], [0]], jnp.int32)
        walls, wall_ids = jnp.zeros((0, 2, 2)), jnp.zeros((2, 0), jnp.int32)
        v = jnp.zeros((2, 2), jnp.float32)
        out = []
        for _ in range(180):
            motion = Motion(v, None, jnp.float32(1 / 30))
            v, _ = avoid(params, pos, desired, speed, radius, cand, walls, wall_ids, motion=motion)
            pos = pos + v / 30.0
            out.append(float(pos[1, 1] - pos[0, 1]) - 0.4)
        return np.array(out)

    g_star = 0.1 * np.log(8.0)
    calm = gaps(STANDING)
    assert np.all(np.abs(calm[-60:] - g_star) < 2e-3)
    assert calm.min() > g_star - 0.01
    restless = gaps(AvoidanceParams())
    assert np.ptp(restless[-60:]) > 0.01


def test_a_wall_turns_an_agent_walking_into_it():
    """Facing a wall at 1 cm beyond its radius, the repulsion a_w·e^{−0.5} ≈ 3 beats the desire."""
    v, _ = _run(
        np.array([[0.0, 0.0]]),
        np.array([[0.0, 1.0]]),
        np.array([1.0]),
        np.array([0.2]),
        np.array([[[-1.0, 0.21], [1.0, 0.21]]]),
    )
    assert float(np.asarray(v)[0, 1]) < 0.0


def test_batched_equals_one_by_one_and_jit_equals_eager():
    pos, desired, speed, radius, walls = _scene(10, 11)
    args = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, walls)]
    n = len(pos)
    cand = jnp.asarray([[j for j in range(n) if j != i] for i in range(n)], jnp.int32)
    wall_ids = jnp.zeros((n, 2), jnp.int32).at[:, 1].set(1)
    p = AvoidanceParams()
    batched = avoid(p, *args[:4], cand, args[4], wall_ids)
    jitted = jax.jit(avoid)(p, *args[:4], cand, args[4], wall_ids)
    for i in range(n):
        one = avoid_one(
            p,
            args[0][i],
            args[1][i],
            args[2][i],
            args[3][i],
            args[0][cand[i]],
            args[3][cand[i]],
            jnp.ones(n - 1, bool),
            args[4],
            jnp.ones(2, bool),
        )
        np.testing.assert_allclose(np.asarray(batched[0][i]), np.asarray(one[0]), atol=1e-6)
    np.testing.assert_allclose(np.asarray(jitted[0]), np.asarray(batched[0]), atol=1e-6)


def test_gradients_are_finite_and_match_finite_differences():
    """The velocity is differentiable in the repulsion strength (a later issue calibrates it):
    central differences in float64 agree with jax.grad."""
    pos, desired, speed, radius, walls = _scene(8, 4, spread=1.5)
    n = len(pos)
    cand = jnp.asarray([[j for j in range(n) if j != i] for i in range(n)], jnp.int32)
    wall_ids = jnp.zeros((n, 2), jnp.int32).at[:, 1].set(1)
    weights = np.random.default_rng(0).standard_normal((n, 2))  # a generic linear read-out
    with jax.enable_x64(True):
        args = [jnp.asarray(x, jnp.float64) for x in (pos, desired, speed, radius, walls)]

        def total(a):
            p = AvoidanceParams(a, 0.1, 5.0, 0.02, 1.0)
            return jnp.sum(avoid(p, *args[:4], cand, args[4], wall_ids)[0] * weights)

        a0, h = jnp.float64(8.0), 1e-5
        fd = (total(a0 + h) - total(a0 - h)) / (2 * h)
        g = jax.grad(total)(a0)
        assert np.isfinite(float(g)) and abs(float(fd)) > 1e-6
        # Central differences at h = 1e-5 in float64: truncation ~h² and rounding ~1e-11.
        np.testing.assert_allclose(float(g), float(fd), rtol=1e-4)


def test_gradients_through_the_standing_rule_match_finite_differences():
    """Three standing in a line (last velocities 0.1 m/s), the standing rule on: the middle
    one's share ``‖E‖/c + ‖v'‖/v_go`` is below 1 (premise), and the velocities' derivatives in
    ``c`` and in the repulsion strength agree with central differences in float64."""
    pos = np.array([[0.0, -0.5], [0.0, 0.0], [0.0, 0.4 + 0.16466]])
    n = len(pos)
    cand = jnp.asarray([[j for j in range(n) if j != i] for i in range(n)], jnp.int32)
    weights = np.random.default_rng(1).standard_normal((n, 2))
    with jax.enable_x64(True):
        own = jnp.tile(jnp.asarray([[0.0, 0.1]]), (n, 1))
        args = (
            jnp.asarray(pos),
            jnp.tile(jnp.asarray([[0.0, 1.0]]), (n, 1)),
            jnp.full(n, 1.3),
            jnp.full(n, 0.2),
            cand,
            jnp.zeros((0, 2, 2)),
            jnp.zeros((n, 0), jnp.int32),
        )

        def total(c, a):
            p = AvoidanceParams(strength=a, stand_drive=c, go_speed=GO)
            v, _ = avoid(p, *args, motion=Motion(own, None, jnp.float64(TAU_PLAIN)))
            return jnp.sum(v * weights)

        c0, a0, h = jnp.float64(DRIVE), jnp.float64(8.0), 1e-6
        gc, ga = jax.grad(total, argnums=(0, 1))(c0, a0)
        fd_c = (total(c0 + h, a0) - total(c0 - h, a0)) / (2 * h)
        fd_a = (total(c0, a0 + h) - total(c0, a0 - h)) / (2 * h)
        assert abs(float(fd_c)) > 1e-3  # premise: the rule acts on someone
        np.testing.assert_allclose([float(gc), float(ga)], [float(fd_c), float(fd_a)], rtol=1e-5)


def test_a_block_of_the_crowd_against_the_whole_equals_the_whole():
    """One device's interleaved block (agents k, k + 2, …), its candidates looked up by id in
    the whole crowd's grid and its neighbours read from the whole crowd (``others``), gets the
    rows the whole crowd's step gives those agents — the split step's contract."""
    pos, desired, speed, radius, walls = _scene(40, 9, spread=4.0)
    f32 = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, walls)]
    n = len(pos)
    spec = grid_spec((-6.0, -6.0), (6.0, 6.0), 2.0)
    cl = cell_list(spec, f32[0], jnp.ones(n, bool))
    wall_ids = jnp.broadcast_to(jnp.arange(2, dtype=jnp.int32), (n, 2))
    whole, _ = avoid(AvoidanceParams(), *f32[:4], candidates(spec, cl, f32[0]), f32[4], wall_ids)
    for k in range(2):
        ids = jnp.arange(k, n, 2, dtype=jnp.int32)
        block, _ = avoid(
            AvoidanceParams(),
            f32[0][ids],
            f32[1][ids],
            f32[2][ids],
            f32[3][ids],
            candidates(spec, cl, f32[0][ids], ids),
            f32[4],
            wall_ids[ids],
            others=(f32[0], f32[3]),
        )
        np.testing.assert_allclose(np.asarray(block), np.asarray(whole)[k::2], atol=1e-6)


@pytest.mark.parametrize(
    ("clump", "spread"),
    [(0, 200), (14, 186), (40, 160), (200, 0)],
    ids=["all-sparse", "middle-tier", "some-dense", "all-dense"],
)
def test_grid_kernel_equals_avoid_with_every_slot(clump, spread):
    """avoid_in_grid reads each agent's first 8 candidates, then 32 for agents with 8 or more,
    then nine full cells for those with 32 or more (in a bucket, or everyone when the largest
    bucket is too small): the same velocities as avoid over every candidate of the 3 × 3
    cells, in every branch. Tolerance 2e-6 m/s: the same float32 terms summed in another
    order. A clump of ``clump`` agents in 2 × 2 m gives them ``clump − 1`` or more candidates
    (14: the middle tier only; 40: both tiers), ``spread`` agents over 60 × 60 m have few;
    with 200 in the clump more move on than the largest bucket, max(64, N/8), holds."""
    from jcrowd.pedestrians import CANDIDATE_TIERS, avoid_in_grid, compact_candidates

    rng = np.random.default_rng(clump + spread)
    pos = np.concatenate(
        [rng.uniform(-1, 1, (clump, 2)), rng.uniform(-30, 30, (spread, 2))]
    ).astype(np.float32)
    n = len(pos)
    ang = rng.uniform(0, 2 * np.pi, n)
    desired = np.stack([np.cos(ang), np.sin(ang)], 1).astype(np.float32)
    speed, radius = np.full(n, 1.3, np.float32), np.full(n, 0.2, np.float32)
    alive = np.ones(n, bool)
    alive[::17] = False  # the dead get 0 and are nobody's neighbour
    spec = grid_spec((-32.0, -32.0), (32.0, 32.0), 2.0, max_density=40.0)
    p, rows = jnp.asarray(pos), jnp.arange(n, dtype=jnp.int32)
    cl = cell_list(spec, p, jnp.asarray(alive))
    walls, wall_ids = jnp.zeros((0, 2, 2)), jnp.zeros((n, 1), jnp.int32)
    args = (jnp.asarray(desired), jnp.asarray(speed), jnp.asarray(radius))
    # Compiled (one shape for all three cases): op by op, the branches cost ~10 s per case.
    want, _ = jax.jit(avoid)(AvoidanceParams(), p, *args, candidates(spec, cl, p), walls, wall_ids)
    want = np.where(alive[:, None], np.asarray(want), 0.0)
    got = jax.jit(avoid_in_grid, static_argnums=1)(
        AvoidanceParams(),
        spec,
        cl,
        p,
        *args,
        jnp.asarray(alive),
        (p, args[2]),
        rows,
        walls,
        wall_ids,
    )
    np.testing.assert_allclose(np.asarray(got), want, atol=2e-6)
    # The premises: which tiers each case reaches.
    assert CANDIDATE_TIERS == (8, 32)
    _, count = compact_candidates(spec, cl, p, 8)
    count = np.where(alive, np.asarray(count), 0)
    reach = (int(np.sum(count >= 8)), int(np.sum(count >= 32)))
    want_reach = {0: (0, 0), 14: (">0", 0), 40: (">0", ">0"), 200: (">64", ">64")}[clump]
    for got_n, rule in zip(reach, want_reach, strict=True):
        assert got_n == 0 if rule == 0 else got_n > int(rule[1:]), (reach, want_reach)


# --------------------------------------------------------------------------- anticipation

TA, AA, DA, TAU, KEEP, WIDTH, WALKING = 1.0, 8.0, 0.1, 0.3, 0.1, 0.1, 0.3


def _oracle_anticipating(pos, desired, speed, radius, walls, vel, dt):
    """The anticipating velocities as jcrowd.pedestrians.reaction's docstring reads Xu, Chraibi &
    Seyfried (2021), float64 loops: the closest approach found by sampling the horizon finely
    (not the closed form), the side and weights written out per pair, then the reaction time,
    the walls and the speed of Eqs. (2)–(3)."""
    n = len(pos)
    vel_out, gaps = np.zeros((n, 2)), np.full(n, np.inf)
    times = np.linspace(0.0, TA, 200001)
    for i in range(n):
        e0 = _slid(i, desired[i], pos, radius, walls)
        e = e0.copy()
        right = np.array([-e0[1], e0[0]])
        for j in range(n):
            if j == i:
                continue
            e += _body_push(i, j, pos, radius, e0)
            d = pos[i] - pos[j]
            s = np.hypot(*d)
            # Prediction: x_i − x_j over the horizon at constant velocities.
            sep = d[None] + (vel[i] - vel[j])[None] * times[:, None]
            k = np.argmin(np.hypot(sep[:, 0], sep[:, 1]))
            p = sep[k]
            ahead = max(0.0, np.dot(-d / s, e0))
            vj = np.hypot(*vel[j])
            against = (1.0 - np.dot(vel[j] / vj, e0)) / 2 if vj > 0 else 0.0
            weight = ahead * against * min(1.0, vj / WALKING)
            strength = AA * np.exp((radius[i] + radius[j] - np.hypot(*p)) / DA)
            e += weight * strength * np.tanh((np.dot(p, right) + KEEP) / WIDTH) * right
        raw = e.copy()
        e /= np.hypot(*e)
        sp = np.hypot(*vel[i])
        prev = vel[i] / sp if sp > 0.05 else e
        e = prev + (e - prev) * min(1.0, dt / TAU)
        e /= np.hypot(*e)
        vel_out[i], gaps[i] = _walls_then_speed(i, e, pos, speed, radius, walls, vel[i], raw)
    return vel_out, gaps


def _velocities(n, seed):
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-np.pi, np.pi, n)
    v = rng.uniform(0.0, 1.5, n)[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    v[::5] *= 0.02  # some nearly standing (below 5 cm/s: no direction to relax from)
    return v


def _every_pair(pos, desired, speed, radius, walls, vel):
    """float32 inputs of :func:`avoid` where every agent is every other's candidate and every
    wall each agent's: ``([pos, desired, speed, radius, walls, vel], candidates, wall ids)``."""
    n = len(pos)
    f32 = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, walls, vel)]
    cand = jnp.asarray([[j for j in range(n) if j != i] for i in range(n)], jnp.int32)
    wall_ids = jnp.broadcast_to(jnp.arange(len(walls), dtype=jnp.int32), (n, len(walls)))
    return f32, cand, wall_ids


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_anticipating_velocities_equal_the_reading(seed):
    """Random 12-agent scenes with random last velocities, every pair interacting. Tolerance
    1e-4 m/s: float32 against float64, and the oracle's closest approach sampled every 5 µs
    of the horizon (a position error below 1e-5 m, through exp(·/0.1) below 1e-4 relative)."""
    pos, desired, speed, radius, walls = _scene(12, seed, spread=2.0)
    vel = _velocities(12, seed)
    dt = 1 / 30
    want_v, _ = _oracle_anticipating(pos, desired, speed, radius, walls, vel, dt)
    f32, cand, wall_ids = _every_pair(pos, desired, speed, radius, walls, vel)
    motion = Motion(f32[5], f32[5], dt)
    got_v, _ = avoid(STANDING, *f32[:4], cand, f32[4], wall_ids, motion=motion)
    np.testing.assert_allclose(np.asarray(got_v), want_v, atol=1e-4)
    plain, _ = avoid(AvoidanceParams(), *f32[:4], cand, f32[4], wall_ids)
    # Premise: anticipation changes these scenes (by more than the tolerance, many times over).
    assert np.abs(np.asarray(plain) - want_v).max() > 1e-2


TAU_PLAIN = 0.1  # s: the plain model's reaction time


def _oracle_reacting(pos, desired, speed, radius, walls, vel, dt):
    """The plain model with a reaction time, float64 loops: the paper's velocity (Eqs. 1–4,
    walls and the standing rule included) relaxed from the last one by ``min(1, dt/τ_p)`` with
    ``τ_p = 0.1`` s, and no faster than Eqs. (2)–(3) allow along the relaxed direction."""
    n = len(pos)
    vel_out, gaps = np.zeros((n, 2)), np.full(n, np.inf)
    for i in range(n):
        e = _desire_and_bodies(i, desired, pos, radius, walls)
        paper, _ = _walls_then_speed(i, e, pos, speed, radius, walls, vel[i])
        relaxed = vel[i] + (paper - vel[i]) * min(1.0, dt / TAU_PLAIN)
        d = relaxed / np.hypot(*relaxed)
        allowed, gaps[i] = _speed_along(i, d, pos, speed, radius, walls)
        vel_out[i] = min(np.hypot(*relaxed), np.hypot(*allowed)) * d
    return vel_out, gaps


@pytest.mark.parametrize("seed", [0, 1])
def test_plain_model_with_a_reaction_time_equals_the_loops(seed):
    """``Motion`` without the crowd's velocities: the plain model whose velocity relaxes (the
    crowd step's, against the step-to-step swing of a dense queue). Same scenes and 1e-4 m/s
    tolerance as the anticipating reading (float32 against float64). Catches the relaxation
    applied before the walls, from the wrong velocity, without the cap along the relaxed
    direction, or not at all (premise below)."""
    pos, desired, speed, radius, walls = _scene(12, seed, spread=2.0)
    vel = _velocities(12, seed)
    dt = 1 / 30
    want_v, _ = _oracle_reacting(pos, desired, speed, radius, walls, vel, dt)
    f32, cand, wall_ids = _every_pair(pos, desired, speed, radius, walls, vel)
    motion = Motion(f32[5], None, dt)
    got_v, _ = avoid(STANDING, *f32[:4], cand, f32[4], wall_ids, motion=motion)
    np.testing.assert_allclose(np.asarray(got_v), want_v, atol=1e-4)
    jitted = jax.jit(lambda *a: avoid(STANDING, *a, motion=Motion(f32[5], None, jnp.float32(dt))))(
        *f32[:4], cand, f32[4], wall_ids
    )[0]
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(got_v), atol=1e-6)
    plain, _ = avoid(AvoidanceParams(), *f32[:4], cand, f32[4], wall_ids)
    assert np.abs(np.asarray(plain) - want_v).max() > 1e-2  # premise: the relaxation acts


def test_a_relaxed_velocity_towards_a_neighbour_is_capped_along_its_own_direction():
    """Agent 0 walked at 1.3 m/s straight at agent 1, now 5 cm beyond contact, and wants to go
    sideways: the paper's velocity turns away at once, the relaxed one still points mostly at
    agent 1 and must slow to what Eqs. (2)–(3) allow along it (the collision-free bound).
    Same oracle and tolerance as above; the premise: without the cap it would walk on at
    more than five times that."""
    pos = np.array([[0.0, 0.0], [0.0, 0.45]])
    desired = np.array([[1.0, 0.0], [0.0, 1.0]])
    speed, radius = np.array([1.3, 1.3]), np.array([0.2, 0.2])
    vel, walls = np.array([[0.0, 1.3], [0.0, 0.0]]), np.zeros((0, 2, 2))
    want_v, want_gap = _oracle_reacting(pos, desired, speed, radius, walls, vel, 1 / 30)
    f32 = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, vel)]
    got, gap = avoid(
        STANDING,
        *f32[:4],
        jnp.asarray([[1], [0]], jnp.int32),
        jnp.zeros((0, 2, 2)),
        jnp.zeros((2, 1), jnp.int32),
        motion=Motion(f32[4], None, 1 / 30),
    )
    np.testing.assert_allclose(np.asarray(got), want_v, atol=1e-4)
    np.testing.assert_allclose(float(gap[0]), want_gap[0], atol=1e-5)
    e = _desire_and_bodies(0, desired, pos, radius, walls)
    paper, _ = _walls_then_speed(0, e / np.hypot(*e), pos, speed, radius, walls)
    relaxed = vel[0] + (paper - vel[0]) / 3
    assert paper[1] < 0 < relaxed[1]  # premise: the relaxed velocity still points at agent 1
    assert np.hypot(*relaxed) > 5 * np.hypot(*np.asarray(got)[0])  # premise: the cap binds


def test_anticipating_overlapping_bodies_equal_the_reading():
    """Eight agents dropped at random in 1.2 m × 1.2 m (bodies overlap, repulsions far above
    the desire): same oracle and tolerance."""
    rng = np.random.default_rng(3)
    pos = rng.uniform(-0.6, 0.6, (8, 2))
    ang = rng.uniform(-np.pi, np.pi, 8)
    desired = np.stack([np.cos(ang), np.sin(ang)], 1)
    speed, radius = np.full(8, 1.3), np.full(8, 0.2)
    d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + 9 * np.eye(8)
    assert d.min() < 0.4  # premise: some bodies overlap
    vel, walls = _velocities(8, 3), np.zeros((0, 2, 2))
    want_v, _ = _oracle_anticipating(pos, desired, speed, radius, walls, vel, 1 / 30)
    f32 = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, vel)]
    cand = jnp.asarray([[j for j in range(8) if j != i] for i in range(8)], jnp.int32)
    got, _ = avoid(
        STANDING,
        *f32[:4],
        cand,
        jnp.zeros((0, 2, 2)),
        jnp.zeros((8, 1), jnp.int32),
        motion=Motion(f32[4], f32[4], 1 / 30),
    )
    np.testing.assert_allclose(np.asarray(got), want_v, atol=1e-4)


def test_two_people_meeting_head_on_both_keep_right():
    """Exactly head-on, 3 m apart at 1.3 m/s each: the plain model's push is along the line
    and neither turns; anticipating, each steps to its own right (the keep-right tie-break),
    so they turn to opposite sides in the world. Symmetric: mirror-image velocities."""
    pos = np.array([[0.0, 0.0], [0.0, 3.0]])
    desired = np.array([[0.0, 1.0], [0.0, -1.0]])
    vel = desired * 1.3
    args = [jnp.asarray(x, jnp.float32) for x in (pos, desired, [1.3, 1.3], [0.2, 0.2])]
    cand = jnp.asarray([[1], [0]], jnp.int32)
    walls, wall_ids = jnp.zeros((0, 2, 2)), jnp.zeros((2, 1), jnp.int32)
    plain, _ = avoid(AvoidanceParams(), *args, cand, walls, wall_ids)
    np.testing.assert_allclose(np.asarray(plain)[:, 0], 0.0, atol=1e-7)
    v = jnp.asarray(vel, jnp.float32)
    got, _ = avoid(AvoidanceParams(), *args, cand, walls, wall_ids, motion=Motion(v, v, 1 / 30))
    got = np.asarray(got)
    # Walking +z with y up, the right is −x; walking −z it is +x.
    assert got[0, 0] < -0.01 and got[1, 0] > 0.01
    np.testing.assert_allclose(got[0], -got[1], atol=1e-6)


def test_a_neighbour_walking_the_same_way_is_followed_not_stepped_around():
    """Following: someone 0.6 m ahead walking the same way (or standing) adds no sideways
    step; the same person walking towards me does."""
    pos = np.array([[0.0, 0.0], [0.05, 0.6]])
    desired = np.array([[0.0, 1.0], [0.0, 1.0]])
    args = [jnp.asarray(x, jnp.float32) for x in (pos, desired, [1.3, 1.3], [0.2, 0.2])]
    cand = jnp.asarray([[1], [0]], jnp.int32)
    walls, wall_ids = jnp.zeros((0, 2, 2)), jnp.zeros((2, 1), jnp.int32)
    params = AvoidanceParams()  # the standing rule, which reads the velocity too, off
    plain, _ = avoid(params, *args, cand, walls, wall_ids)
    mine = jnp.asarray([[0.0, 1.3]], jnp.float32)
    for other, same in (([0.0, 1.3], True), ([0.0, 0.0], True), ([0.0, -1.3], False)):
        v = jnp.concatenate([mine, jnp.asarray([other], jnp.float32)])
        # dt = τ: no relaxation from the last direction, so only the sideways term differs.
        got, _ = avoid(params, *args, cand, walls, wall_ids, motion=Motion(v, v, 0.3))
        close = np.allclose(np.asarray(got)[0], np.asarray(plain)[0], atol=1e-6)
        assert close == same, (other, np.asarray(got)[0], np.asarray(plain)[0])


def test_anticipating_grid_kernel_and_block_equal_avoid():
    """avoid_in_grid with motion (velocities read in cell order) equals avoid with motion over
    every candidate; one interleaved block against the whole crowd equals the whole's rows.
    Tolerance 2e-6 m/s: the same float32 terms summed in another order."""
    from jcrowd.pedestrians import avoid_in_grid

    rng = np.random.default_rng(5)
    pos = np.concatenate([rng.uniform(-1, 1, (40, 2)), rng.uniform(-20, 20, (120, 2))])
    n = len(pos)
    ang = rng.uniform(0, 2 * np.pi, n)
    desired = np.stack([np.cos(ang), np.sin(ang)], 1)
    f32 = [
        jnp.asarray(x, jnp.float32)
        for x in (pos, desired, np.full(n, 1.3), np.full(n, 0.2), _velocities(n, 5))
    ]
    p, vel = f32[0], f32[4]
    spec = grid_spec((-22.0, -22.0), (22.0, 22.0), 2.0, max_density=40.0)
    cl = cell_list(spec, p, jnp.ones(n, bool))
    walls, wall_ids = jnp.zeros((0, 2, 2)), jnp.zeros((n, 1), jnp.int32)
    motion = Motion(vel, vel, 1 / 30)
    want, _ = jax.jit(avoid)(
        AvoidanceParams(), *f32[:4], candidates(spec, cl, p), walls, wall_ids, motion=motion
    )
    got = jax.jit(avoid_in_grid, static_argnums=1)(
        AvoidanceParams(),
        spec,
        cl,
        *f32[:4],
        jnp.ones(n, bool),
        (p, f32[3]),
        jnp.arange(n, dtype=jnp.int32),
        walls,
        wall_ids,
        motion,
    )
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), atol=2e-6)
    ids = jnp.arange(1, n, 2, dtype=jnp.int32)
    block, _ = avoid(
        AvoidanceParams(),
        *(a[ids] for a in f32[:4]),
        candidates(spec, cl, p[ids], ids),
        walls,
        wall_ids[ids],
        others=(p, f32[3]),
        motion=Motion(vel[ids], vel, 1 / 30),
    )
    np.testing.assert_allclose(np.asarray(block), np.asarray(want)[1::2], atol=1e-6)


def test_a_time_per_agent_equals_each_agents_own_step():
    """Far agents that update every k steps relax their direction by the k steps since their
    last update: ``Motion.dt`` per agent gives each row what a scalar ``dt`` of that agent's
    value gives (the relaxation's rate min(1, Δt/τ) reaches 1 at Δt = τ, so 0.1 s and 0.4 s
    differ)."""
    pos, desired, speed, radius, walls = _scene(10, 6, spread=2.0)
    vel = _velocities(10, 6)
    f32, cand, wall_ids = _every_pair(pos, desired, speed, radius, walls, vel)
    times = jnp.where(jnp.arange(len(pos)) % 2 == 0, 0.1, 0.4).astype(jnp.float32)

    def run(dt):
        v, _ = avoid(
            AvoidanceParams(), *f32[:4], cand, f32[4], wall_ids, motion=Motion(f32[5], f32[5], dt)
        )
        return np.asarray(v)

    got, short, long_ = run(times), run(0.1), run(0.4)
    # A few float32 ulps of a ~1 m/s velocity: a vector of times and a broadcast scalar are fused
    # into different XLA loops, which may round differently.
    np.testing.assert_allclose(got[0::2], short[0::2], atol=1e-6)
    np.testing.assert_allclose(got[1::2], long_[1::2], atol=1e-6)
    assert np.abs(short - long_).max() > 1e-3  # premise: the time matters


def _cap_oracle(pos, vel, radius, walls, horizon):
    """Each velocity with its speed capped to close at most half the free gap to any other
    agent (the whole gap to a wall) in ``horizon`` s: float64 loops over every agent and
    wall, with the closest point and the approach written out as vectors."""
    out = vel.copy()
    for i in range(len(pos)):
        speed = np.hypot(*vel[i])
        if speed == 0.0:
            continue
        e, limit = vel[i] / speed, np.inf
        for j in range(len(pos)):
            to_j = pos[j] - pos[i]
            d = np.hypot(*to_j)
            if j != i and e @ to_j > 0.0:
                free = max(0.0, d - radius[i] - radius[j])
                limit = min(limit, free / 2 / (horizon[i] * (e @ to_j) / d))
        for a, b in walls:
            q = a + np.clip(np.dot(pos[i] - a, b - a) / np.dot(b - a, b - a), 0, 1) * (b - a)
            to_q = q - pos[i]
            d = np.hypot(*to_q)
            if e @ to_q > 0.0:
                limit = min(limit, max(0.0, d - radius[i]) / (horizon[i] * (e @ to_q) / d))
        out[i] = e * min(speed, limit)
    return out


def _all_candidates(n, n_walls):
    cand = jnp.asarray([[j for j in range(n) if j != i] for i in range(n)], jnp.int32)
    return cand, jnp.broadcast_to(jnp.arange(n_walls, dtype=jnp.int32), (n, n_walls))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_horizon_caps_the_speed_as_the_loop_oracle_says(seed):
    """Agents updated only every few steps (simulation LOD) walk at most as fast as closes
    half their gap to anyone they walk towards within the horizon; the oracle caps the plain
    model's float64 velocities (``_oracle``) in a loop."""
    pos, desired, speed, radius, walls = _scene(12, seed, spread=2.0)
    horizon = np.random.default_rng(seed).choice([0.1, 0.4], len(pos))  # one per agent
    plain, _ = _oracle(pos, desired, speed, radius, walls)
    want = _cap_oracle(pos, plain, radius, walls, horizon)
    cand, wall_ids = _all_candidates(len(pos), len(walls))
    f32 = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, walls, horizon)]
    p = AvoidanceParams()
    got, _ = avoid(p, *f32[:4], cand, f32[4], wall_ids, horizon=f32[5])
    jitted, _ = jax.jit(avoid)(p, *f32[:4], cand, f32[4], wall_ids, horizon=f32[5])
    # float32 against float64, as in test_velocities_equal_the_equations.
    np.testing.assert_allclose(np.asarray(got), want, atol=2e-5)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(got), atol=1e-6)
    capped = np.hypot(*want.T) < np.hypot(*plain.T) - 1e-3
    assert capped.any() and (~capped).any()  # premise: the cap binds for some, not all


@pytest.mark.parametrize(("seed", "horizon"), [(7, 0.27), (9, 0.27), (6, 0.5)])
def test_agents_walking_a_capped_velocity_for_the_horizon_never_touch(seed, horizon):
    """The cap's promise, checked on positions: every agent walks its velocity for the whole
    horizon at once (as a far agent does between updates: 0.27 s is 8 steps at 30 fps) and
    no two bodies, nor a body and a wall, overlap afterwards — where without the cap some do
    (scenes picked so that they do)."""
    pos, desired, speed, radius, walls = _scene(40, seed, spread=3.0)
    cand, wall_ids = _all_candidates(len(pos), len(walls))
    f32 = [jnp.asarray(x, jnp.float32) for x in (pos, desired, speed, radius, walls)]
    p = AvoidanceParams()

    def closest(v):
        after = pos + np.asarray(v, np.float64) * horizon
        d = np.linalg.norm(after[:, None] - after[None], axis=-1) + np.eye(len(pos)) * 9
        bodies = np.min(d / (radius[:, None] + radius[None]))
        wall = min(after[:, 1].min() + 3.5, 3.6 - after[:, 0].max()) - radius.max()
        return bodies, wall

    capped, _ = avoid(p, *f32[:4], cand, f32[4], wall_ids, horizon=jnp.float32(horizon))
    bodies, wall = closest(capped)
    assert bodies >= 1.0 - 1e-5 and wall >= -1e-5  # float32 positions of a few metres
    plain, _ = avoid(p, *f32[:4], cand, f32[4], wall_ids)
    assert closest(plain)[0] < 1.0  # premise: uncapped, someone walks into someone
