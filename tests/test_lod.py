"""LOD: hysteresis, frustum, and the budgeted bucket assignment against a greedy loop."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jcrowd.crowd import (
    CameraView,
    assign_buckets,
    default_capacities,
    distance_levels,
    in_frustum,
    screen_height_px,
)

THR = jnp.asarray([30.0, 40.0, 50.0, 60.0, 80.0])


def _greedy(min_level, importance, eligible, caps):
    """Oracle: in order of importance, each agent takes the first level ≥ its minimum with room."""
    n, nl = len(min_level), len(caps)
    used = [0] * nl
    level = np.full(n, nl)
    for i in np.argsort(-importance, kind="stable"):
        if not eligible[i]:
            continue
        for lv in range(min_level[i], nl):
            if used[lv] < caps[lv]:
                used[lv] += 1
                level[i] = lv
                break
    return level


def test_distance_levels_without_hysteresis_counts_thresholds():
    d = jnp.asarray([0.0, 29.9, 30.1, 45.0, 79.0, 500.0])
    got = distance_levels(d, jnp.zeros(6, jnp.int32), THR, 0.0)
    np.testing.assert_array_equal(np.asarray(got), [0, 0, 1, 2, 4, 5])


def test_hysteresis_agent_held_at_threshold_changes_level_at_most_once():
    rng = np.random.default_rng(3)
    level = jnp.zeros(1, jnp.int32)
    changes = 0
    for d in 40.0 + rng.uniform(-1.9, 1.9, 200):  # jitter inside the ±2 m band round 40 m
        new = distance_levels(jnp.asarray([d]), level, THR, 2.0)
        changes += int(new[0] != level[0])
        level = new
    assert changes <= 1
    # Leaving the band does move it.
    far = distance_levels(jnp.asarray([42.5]), level, THR, 2.0)
    near = distance_levels(jnp.asarray([37.5]), far, THR, 2.0)
    assert int(far[0]) == 2 and int(near[0]) == 1


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_budget_equals_greedy_loop(seed):
    rng = np.random.default_rng(seed)
    n = 300
    min_level = rng.integers(0, 4, n)
    importance = rng.normal(size=n)
    eligible = rng.random(n) < 0.8
    caps = (20, 40, 60, n)
    b = assign_buckets(jnp.asarray(min_level), jnp.asarray(importance), jnp.asarray(eligible), caps)
    want = _greedy(min_level, importance, eligible, caps)
    np.testing.assert_array_equal(np.asarray(b.level), want)
    for lv, (slots, ok) in enumerate(zip(b.slots, b.valid, strict=True)):
        ids = np.asarray(slots)[np.asarray(ok)]
        assert sorted(ids.tolist()) == sorted(np.nonzero(want == lv)[0].tolist())
        # The valid slots lead (decode_bucket stops at the first invalid chunk).
        used = int(np.sum(ok))
        assert np.all(np.asarray(ok)[:used]) and not np.any(np.asarray(ok)[used:])
    assert int(b.unplaced) == 0
    assert int(b.overflow) == int(np.sum(eligible & (want > min_level)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_unconstrained_branch_equals_greedy_fill_when_everything_fits(seed):
    """The fast branch (no level overflows) gives the greedy fill's buckets slot for slot."""
    from jcrowd.crowd.lod import _greedy as greedy_fill
    from jcrowd.crowd.lod import _unconstrained

    rng = np.random.default_rng(seed)
    n = 400
    min_level = jnp.asarray(rng.integers(0, 4, n))
    eligible = jnp.asarray(rng.random(n) < 0.7)
    counts = np.bincount(np.asarray(min_level)[np.asarray(eligible)], minlength=4)
    caps = tuple(int(c) + int(rng.integers(0, 9)) for c in counts)  # every level fits
    slow = greedy_fill(min_level, jnp.asarray(rng.normal(size=n)), eligible, caps)
    fast = _unconstrained(jnp.where(eligible, min_level, 4), caps)
    for a, b in zip(jax.tree.leaves(slow), jax.tree.leaves(fast), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # The public entry takes the fast branch here and the greedy one once a level overflows.
    small = (int(counts[0]) - 3, *caps[1:])
    got = assign_buckets(min_level, jnp.asarray(rng.normal(size=n)), eligible, small)
    assert int(got.overflow) + int(got.unplaced) >= 3


@pytest.mark.parametrize(
    ("agents", "caps"),
    [
        (90, (90,) * 6),  # a small crowd fits every level whole
        (256, (256,) * 6),
        (1_000, (256, 256, 256, 256, 1_000 // 4 + 64, 1_000)),  # level 4's share passes 256
        (10_000, (256, 10_000 // 32 + 64, 10_000 // 16 + 64, 10_000 // 8 + 64, 2_564, 10_000)),
        (10**6, (256, 512, 1_024, 2_048, 4_096, 16_384)),  # the fixed budget
    ],
)
def test_default_budget_by_hand(agents, caps):
    """The default capacities worked out by hand: at least 256 per level (everyone in a small
    crowd, so a few dozen people near the camera are never pushed to level 1), a share of a
    medium crowd, the fixed budget of a large one."""
    assert default_capacities(agents, 6) == caps


@pytest.mark.parametrize("agents", [1, 7, 90, 300, 5_000, 70_000, 3 * 10**6])
@pytest.mark.parametrize("levels", [2, 4, 6])
def test_default_budget_properties(agents, levels):
    """Every level holds at most the crowd and at least a level before it, and a crowd that
    fits level 0 fits every level."""
    caps = default_capacities(agents, levels)
    assert len(caps) == levels
    assert all(0 < c <= agents for c in caps)
    assert list(caps) == sorted(caps)
    if caps[0] == agents:
        assert set(caps) == {agents}


def test_budget_small_capacity_most_important_get_level_zero_none_dropped():
    n = 50
    min_level = jnp.zeros(n, jnp.int32)  # everyone near
    importance = -jnp.arange(n, dtype=jnp.float32)  # agent 0 most important
    b = assign_buckets(min_level, importance, jnp.ones(n, bool), (5, 10, n))
    level = np.asarray(b.level)
    np.testing.assert_array_equal(level[:5], 0)
    np.testing.assert_array_equal(level[5:15], 1)
    np.testing.assert_array_equal(level[15:], 2)
    assert int(b.overflow) == 45 and int(b.unplaced) == 0


def test_budget_jit_compiles_once_for_any_histogram():
    caps = (4, 8, 64)
    f = jax.jit(assign_buckets, static_argnums=3)
    rng = np.random.default_rng(0)
    for _ in range(3):
        f(
            jnp.asarray(rng.integers(0, 3, 64)),
            jnp.asarray(rng.normal(size=64), jnp.float32),
            jnp.asarray(rng.random(64) < 0.5),
            caps,
        )
    assert f._cache_size() == 1


def _view():
    return CameraView(
        eye=jnp.asarray([0.0, 1.7, 0.0]),
        target=jnp.asarray([0.0, 1.7, 10.0]),
        fov_deg=jnp.asarray(60.0),
        aspect=jnp.asarray(16 / 9),
        height_px=jnp.asarray(720.0),
    )


def test_frustum_front_back_and_sides():
    pts = jnp.asarray(
        [
            [0.0, 1.0, 20.0],  # straight ahead
            [0.0, 1.0, -20.0],  # behind
            [200.0, 1.0, 20.0],  # far to the side
            [0.0, 1.0, -0.5],  # just behind the eye, within the radius
        ]
    )
    np.testing.assert_array_equal(np.asarray(in_frustum(_view(), pts)), [True, False, False, True])


def test_screen_height_closed_form():
    """A 1.8 m character 10 m ahead with a 60° vertical fov: 1.8 / (2·10·tan 30°) · 720 px."""
    px = screen_height_px(_view(), jnp.asarray([[0.0, 0.0, 10.0]]), jnp.asarray([1.8]))
    assert float(px[0]) == pytest.approx(1.8 / (2 * 10 * np.tan(np.pi / 6)) * 720, rel=1e-5)


def _frustum_planes(eye, target, fov_deg, aspect):
    """Outward unit normals of the left, right, bottom and top planes (all through the eye), in
    NumPy from the camera geometry: each normal is the cross product of the two corner rays on
    that side of the image, normalized, and turned away from the view direction."""
    eye, target = np.asarray(eye, np.float64), np.asarray(target, np.float64)
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    half_h = np.tan(np.deg2rad(fov_deg) / 2)  # image half-height at unit depth
    half_w = half_h * aspect
    corner = {
        (sx, sy): fwd + sx * half_w * right + sy * half_h * up for sx in (-1, 1) for sy in (-1, 1)
    }
    normals = []
    for c1, c2 in (
        ((-1, -1), (-1, 1)),  # left
        ((1, -1), (1, 1)),  # right
        ((-1, -1), (1, -1)),  # bottom
        ((-1, 1), (1, 1)),  # top
    ):
        nrm = np.cross(corner[c1], corner[c2])
        nrm /= np.linalg.norm(nrm)
        normals.append(nrm if nrm @ fwd < 0 else -nrm)  # outward: away from the view axis
    return eye, fwd, right, up, np.array(normals)


def test_frustum_sphere_test_against_plane_distances():
    """Spheres at ±(radius − ε) and ±(radius + ε) from each side plane, from the near plane
    (through the eye) and from the far plane, against perpendicular plane distances computed
    in NumPy from eye, target, fov and aspect. A wide fov makes the side planes' normals far
    from the camera's right/up axes, so a side-plane distance not divided by the normal's
    length (|x| − depth·tan instead of (|x| − depth·tan)/√(1 + tan²)) culls spheres that
    still touch the frustum."""
    eye, target, fov, aspect, radius, far = [1.0, 2.5, -3.0], [4.0, 1.0, 9.0], 100.0, 1.6, 1.5, 80.0
    view = CameraView(
        eye=jnp.asarray(eye, jnp.float32),
        target=jnp.asarray(target, jnp.float32),
        fov_deg=jnp.asarray(fov, jnp.float32),
        aspect=jnp.asarray(aspect, jnp.float32),
        height_px=jnp.asarray(720.0, jnp.float32),
    )
    e, fwd, right, up, normals = _frustum_planes(eye, target, fov, aspect)
    half_h = np.tan(np.deg2rad(fov) / 2)
    # ε = 0.1 m: far above float32 rounding of these coordinates (~1e-5 m), and small enough
    # that (radius − ε)·√(1 + tan²) > radius for every side plane here (tan ≥ 1.19), so the
    # un-normalized distance misclassifies the +(radius − ε) spheres.
    eps = 0.1
    offsets = np.array([-(radius + eps), -(radius - eps), radius - eps, radius + eps])
    points, expected = [], []
    for k, nrm in enumerate(normals):
        for depth in (4.0, 30.0):
            # The middle of that side of the image at this depth: on the plane, far from the
            # other three planes.
            across = right if k < 2 else up
            half = half_h * aspect if k < 2 else half_h
            on_plane = e + depth * fwd + (1 if k % 2 else -1) * depth * half * across
            assert abs((on_plane - e) @ nrm) < 1e-9  # it is on the plane
            for off in offsets:
                points.append(on_plane + off * nrm)
                expected.append(off < radius)
    axis = (-(radius + eps), -(radius - eps), radius - eps, far - eps, far + radius - eps)
    for d in axis:
        points.append(e + d * fwd)  # on the view axis: only the near/far planes matter
        expected.append(d > -radius)
    points.append(e + (far + radius + eps) * fwd)  # a sphere wholly beyond the far plane
    expected.append(False)
    pts = np.array(points)
    # The oracle: a sphere touches the frustum (conservative plane test) iff its centre is less
    # than radius outside every side plane, the near plane (through the eye) and the far plane.
    dist_sides = (pts - e) @ normals.T
    depth = (pts - e) @ fwd
    oracle = (dist_sides < radius).all(1) & (depth > -radius) & (depth < far + radius)
    np.testing.assert_array_equal(oracle, expected)  # the table is what it says
    got = in_frustum(view, jnp.asarray(pts, jnp.float32), radius=radius, far=far)
    np.testing.assert_array_equal(np.asarray(got), oracle)
