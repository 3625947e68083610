"""Level changes without popping (jcrowd.crowd.level_blend, issue 19).

Oracles: the blend's bookkeeping written out case by case; the eased points by a loop over the
agents of every level's slots; in the step, a run with the blend against the same run with it
switched off (the dynamics and phases are the same, only the drawn poses differ), judged by the
joints' second differences (a pop is a spike in them).
"""

from __future__ import annotations

from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jcrowd.crowd import stepping
from jcrowd.crowd.level_blend import (
    BLEND_SECONDS,
    BlendRows,
    blend_capacity,
    blend_levels,
    blend_plan,
    blend_weight,
)

W = BLEND_SECONDS


def _weight(left):
    """The old level's share written out: ``3u² − 2u³`` of ``u = left / W`` in [0, 1]."""
    u = np.clip(np.asarray(left, np.float64) / W, 0.0, 1.0)
    return 3 * u**2 - 2 * u**3


def _plan_oracle(shown, frm, left, level, alive, levels):
    """One agent: what blends this frame, and for how long more."""
    if not alive or level >= levels:
        return levels, 0.0
    if shown < levels and shown != level:  # changed this frame
        if frm < levels and left > 0 and frm == level:  # back to the level it blended from
            return shown, W - left
        return shown, W
    if frm < levels and frm != level and left > 0:
        return frm, left
    return levels, 0.0


def test_the_plan_starts_swaps_continues_and_ends_blends():
    levels = 4
    cases = [  # (shown, from, left, level, alive)
        (1, 4, 0.0, 2, True),  # a change: blend from 1
        (2, 4, 0.0, 2, True),  # no change, not blending
        (2, 1, 0.2, 2, True),  # blending on
        (2, 1, 0.2, 1, True),  # back to the level it blends from: swapped
        (2, 1, 0.2, 3, True),  # another change inside the window: from 2, afresh
        (4, 4, 0.0, 0, True),  # from a dot: nothing to blend from
        (1, 4, 0.0, 4, True),  # now a dot
        (1, 4, 0.0, 2, False),  # gone
        (2, 1, 0.0, 2, True),  # a blend that ran out
    ]
    cols = [np.array(c) for c in zip(*cases, strict=True)]
    got_from, got_left = blend_plan(
        jnp.asarray(cols[0], jnp.int32),
        jnp.asarray(cols[1], jnp.int32),
        jnp.asarray(cols[2], jnp.float32),
        jnp.asarray(cols[3], jnp.int32),
        jnp.asarray(cols[4]),
        levels,
    )
    want = [_plan_oracle(*c, levels) for c in cases]
    np.testing.assert_array_equal(np.asarray(got_from), [w[0] for w in want])
    np.testing.assert_allclose(np.asarray(got_left), [w[1] for w in want], atol=1e-7)


@pytest.mark.parametrize("seed", [0, 1])
def test_blended_points_equal_a_loop_over_the_slots(seed):
    """Random levels, slots and blends; decode returns a pose that encodes the agent and the
    level it was decoded at, so a wrong agent or level shows."""
    rng = np.random.default_rng(seed)
    n, levels, p = 300, 3, 5
    caps = (40, 80, 200)
    level = rng.integers(0, levels + 1, n)  # levels: not drawn
    slots, points = [], []
    for b, c in enumerate(caps):
        ids = np.flatnonzero(level == b)[:c]
        level[np.flatnonzero(level == b)[c:]] = levels  # beyond capacity: not drawn
        slots.append(np.concatenate([ids, np.full(c - len(ids), n)]).astype(np.int32))
        points.append(rng.normal(size=(c, p, 3)).astype(np.float32))
    source = np.where(rng.uniform(size=n) < 0.3, rng.integers(0, levels, n), levels)
    source = np.where((level < levels) & (source != level), source, levels).astype(np.int32)
    left = np.where(source < levels, rng.uniform(0.01, W, n), 0.0).astype(np.float32)

    def fake_pose(agent, a):
        return np.full((p, 3), agent + 1000.0 * (a + 1), np.float32)

    def decode(a, ids, used):
        del used
        return jnp.asarray(np.stack([fake_pose(int(i), a) for i in np.asarray(ids)]))

    got, unblended = blend_levels(
        [jnp.asarray(x) for x in points],
        [jnp.asarray(x) for x in slots],
        jnp.asarray(source),
        jnp.asarray(left),
        decode,
    )
    want = [x.copy() for x in points]
    for b in range(levels):
        for k, agent in enumerate(slots[b]):
            if agent < n and source[agent] < levels:
                w = _weight(left[agent])
                old = fake_pose(agent, source[agent])
                want[b][k] = w * old + (1 - w) * points[b][k]
    for b in range(levels):
        np.testing.assert_allclose(np.asarray(got[b]), want[b], rtol=1e-6, atol=1e-3)
    # Every source level's bucket holds its blending agents here (64 ≥ their number).
    assert int(unblended) == 0
    assert max(np.sum(source == a) for a in range(levels)) <= min(blend_capacity(c) for c in caps)


def test_blending_agents_beyond_the_bucket_are_counted_and_shown_at_their_level():
    n, p = 200, 2
    slots = [jnp.arange(100, dtype=jnp.int32), jnp.arange(100, 200, dtype=jnp.int32)]
    points = [jnp.zeros((100, p, 3)), jnp.ones((100, p, 3))]
    source = jnp.concatenate([jnp.full(100, 2), jnp.zeros(100)]).astype(jnp.int32)  # 100 from 0
    left = jnp.full(n, W, jnp.float32)

    def decode(a, ids, used):
        return jnp.zeros((ids.shape[0], p, 3))

    got, unblended = blend_levels(points, slots, source, left, decode)
    size = blend_capacity(100)
    assert int(unblended) == 100 - size
    eased = np.asarray(got[1])[:, 0, 0]
    assert np.sum(eased == 0.0) == size and np.sum(eased == 1.0) == 100 - size
    jitted, _ = jax.jit(lambda pts, s, l: blend_levels(pts, slots, s, l, decode))(
        points, source, left
    )
    np.testing.assert_array_equal(np.asarray(jitted[1]), np.asarray(got[1]))


STEP_SCENE = """
seed = 3
duration = 4.0
fps = 30
[ground]
center = [0, 5]
size = [30, 30]
[[camera.keys]]
time = 0.0
eye = [0, 1.7, -2]
target = [0, 1.0, 5]
[[camera.keys]]
time = 2.5
eye = [0, 1.7, -2]
target = [0, 1.0, 5]
[[camera.keys]]
time = 2.52
eye = [0, 1.7, -8]
target = [0, 1.0, 5]
[lod]
thresholds = [3, 4.5, 6, 7.5, 9]
hysteresis = 0.3
[[groups]]
name = "waiting"
count = 6
spawn = { shape = "rect", center = [0, 2], size = [4, 3] }
goal = { shape = "rect", center = [0, 18], size = [8, 1] }
[dynamics]
avoid = true
"""


def _drawn_run(model, steps):
    """Every agent's drawn points per frame (NaN where not drawn), levels and standing."""
    from jcrowd.crowd import prepare
    from jcrowd.scenario import parse_scenario

    sim, state = prepare(parse_scenario(STEP_SCENE, "t.toml"), model)
    state = replace(state, speed=jnp.full_like(state.speed, 0.0015))  # below any scenario's
    fn = sim.compiled(donate=False)
    n = state.num_agents
    out, levels, stands = [], [], []
    for i in range(steps):
        stands.append(np.asarray(state.stands))
        state, frame = fn(state, sim.view_at(i * sim.dt), sim.dt)
        pts = None
        for lv in range(len(frame.points)):
            ok = np.asarray(frame.valid[lv])
            p = np.asarray(frame.points[lv])
            if pts is None:
                pts = np.full((n, *p.shape[1:]), np.nan, np.float32)
            pts[np.asarray(frame.slots[lv])[ok]] = p[ok]
        out.append(pts)
        levels.append(np.asarray(frame.level))
        assert int(frame.unblended) == 0
    return np.stack(out), np.stack(levels), np.stack(stands), sim.dt


def _no_blend(slots, source, left, decode):
    """The step's blend switched off: nobody has a pose to blend from."""
    n = source.shape[0]
    rows = BlendRows(jnp.zeros((1, 1, 3)), jnp.zeros(1), jnp.zeros(n, jnp.int32), jnp.full(1, -1))
    return rows, jnp.int32(0)


def test_a_level_change_in_the_step_eases_from_the_old_pose_to_the_new(monkeypatch):
    """Six people stand still (free speed 1.5 mm/s: their phases wait at a double-support
    phase, so each level's pose is fixed) while the camera jumps back 6 m in one frame and
    every one of them changes level. The same run with the blend switched off is the oracle:
    its pose before the change is the old level's and after it the new level's, so the blended
    run must show ``w·before + (1 − w)·after`` with ``w = S(1 − k·dt / BLEND_SECONDS)`` the
    ``k``-th frame after the change — no jump at the change, the same path to the new pose."""
    from jcrowd import load_default_model

    model = load_default_model()
    steps = 100
    blended, levels, stands, dt = _drawn_run(model, steps)
    monkeypatch.setattr(stepping, "blend_sources", _no_blend)
    raw, raw_levels, _, _ = _drawn_run(model, steps)
    np.testing.assert_array_equal(levels, raw_levels)  # the blend moves nobody
    change = np.flatnonzero(np.any(levels[1:] != levels[:-1], axis=1)) + 1
    assert len(change) == 1, change  # premise: one frame, the camera's jump
    f = int(change[0])
    assert stands[f - 5 :].all()  # premise: everyone stands from before the jump on
    before, after = raw[f - 1], raw[f:]
    jump = np.linalg.norm(after[0] - before, axis=-1).max(axis=-1)
    assert (jump > 0.01).all(), jump  # premise: unblended, every pose jumps over 1 cm
    w = _weight(W - np.arange(len(after)) * float(dt))[:, None, None, None]
    want = w * before + (1 - w) * after
    # float32 poses of a few metres; the standing roots creep 1.5 mm/s (0.05 mm a frame), and
    # the old pose carries the creep since the change with its weight (up to ~0.3 mm).
    np.testing.assert_allclose(blended[f:], want, atol=4e-4)
    np.testing.assert_allclose(blended[:f], raw[:f], atol=1e-6)
    steps_after = np.linalg.norm(np.diff(blended[f - 1 :], axis=0), axis=-1).max(axis=-1)
    assert steps_after.max() <= 1.5 * jump.max() * float(dt) / W + 4e-4  # S′ ≤ 1.5


@pytest.mark.parametrize("dt", [1e-2, 1e-3])
def test_a_level_change_is_continuous_in_value_and_velocity(dt):
    """Closed form: two levels whose poses move linearly, ``p_from(t) = a + b·t`` and ``p(t) =
    c + d·t``, the change at ``t = 0``. The drawn pose before it is ``p_from``; after it the
    blend plan and weight are run frame by frame as the step does. At the change the drawn
    pose is ``a`` and its velocity ``b`` (the old level's), at the blend's end ``d``: a
    one-sided difference of step ``dt`` is within ``O(dt)`` of those, where a linear ramp
    would be off by ``(a − c) / BLEND_SECONDS`` (here over 2 m/s)."""
    a, b = np.array([1.0, 2.0, -1.0]), np.array([0.5, 0.0, 1.0])
    c, d = np.array([2.0, 1.0, -1.5]), np.array([-0.5, 0.3, 1.0])
    levels = 3
    plan = jax.jit(blend_plan, static_argnums=5)
    weight = jax.jit(lambda f, x: jnp.where(f < levels, blend_weight(x), 0.0))
    shown, frm, left = jnp.array([0]), jnp.array([levels]), jnp.zeros(1)
    times = np.arange(-3, round(W / dt) + 4) * dt
    drawn = []
    for t in times:
        level = jnp.array([0 if t < 0 else 1])
        frm, left = plan(shown, frm, left, level, jnp.array([True]), levels)
        w = float(weight(frm, left)[0])
        now = (a + b * t) if t < 0 else (c + d * t)
        drawn.append(w * (a + b * t) + (1 - w) * now)
        shown, left = level, jnp.maximum(left - dt, 0.0)
    drawn = np.array(drawn)
    at = int(np.flatnonzero(times >= 0)[0])
    np.testing.assert_allclose(drawn[at], a, atol=1e-6)  # value: the old level's at the change
    scale = np.abs(a - c).max() / W**2  # the size of the blend's second derivative
    v_before = (drawn[at] - drawn[at - 1]) / dt
    v_after = (drawn[at + 1] - drawn[at]) / dt
    np.testing.assert_allclose(v_before, b, atol=1e-4)
    np.testing.assert_allclose(v_after, b, atol=6 * scale * dt + 1e-3)
    end = at + round(W / dt)
    v_end = (drawn[end + 2] - drawn[end + 1]) / dt
    np.testing.assert_allclose(v_end, d, atol=1e-3)
    v_last = (drawn[end] - drawn[end - 1]) / dt
    np.testing.assert_allclose(v_last, d, atol=6 * scale * dt + 1e-3)
