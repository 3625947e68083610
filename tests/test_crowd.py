"""The crowd step: buckets, jit, traces, clip hand-over continuity, paths, and two processes on
one mesh, with three of the shipped model's levels (conftest's ``step_model``). The step split
over devices in one process is compared with one device in tests/test_split_devices.py (this
module's ``SCENE``)."""

from __future__ import annotations

import json
from dataclasses import replace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from on_devices import finish, start_python

from jcrowd.crowd import decode_coeffs, level_points, pose_from_coeffs, prepare, step
from jcrowd.io import save_motion_model
from jcrowd.scenario import parse_scenario

SCENE = """
model = "default"
seed = 3
duration = 10.0
fps = 30
[ground]
center = [0, 0]
size = [200, 200]
[camera]
eye = [0, 1.7, -20]
target = [0, 1.0, 0]
fov = 60
[[groups]]
name = "walkers"
count = {count}
speed = [1.1, 1.4]
spawn = {{ shape = "rect", center = [0, 20], size = [40, 40] }}
path = {{ waypoints = [[0, 60], [60, 60]], loop = false }}
"""


@pytest.fixture(scope="module")
def model(step_model):
    return step_model


@pytest.fixture(scope="module")
def prepared(model):
    """``prepare`` of ``SCENE`` with ``count`` agents, once per count for the module (a prepare
    builds the crowd model from the motion model: seconds); each call returns the simulation
    and a copy of the first state, which a compiled step may donate."""
    done = {}

    def get(count):
        if count not in done:
            done[count] = prepare(parse_scenario(SCENE.format(count=count), "test.toml"), model)
        sim, state = done[count]
        return sim, jax.tree.map(jnp.copy, state)

    return get


def _sim(prepared, count=24, **lod):
    sim, state = prepared(count)
    if lod:
        sim = replace(sim, config=replace(sim.config, **lod))
    return sim, state


def _run(sim, state, steps, fn=None):
    fn = fn or sim.compiled(donate=False)
    frames = []
    for i in range(steps):
        state, frame = fn(state, sim.view_at(i * sim.dt), sim.dt)
        frames.append(frame)
    return state, frames


def test_state_is_under_one_kilobyte_per_agent(prepared):
    """The state's arrays (every leaf's bytes, 10 agents) stay within 1 KiB per agent."""
    _, state = _sim(prepared, count=10)
    nbytes = sum(x.nbytes for x in jax.tree.leaves(state))
    assert nbytes / 10 <= 1024


@pytest.mark.slow
def test_padded_buckets_equal_unpadded(prepared):
    """Capacities with room to spare (padding slots) give the same crowd as tight ones."""
    sim, state = _sim(prepared)
    tight_state, tight = _run(sim, state, 8)
    nlev = len(sim.config.capacities)
    hist = np.bincount(np.asarray(tight[0].level), minlength=nlev + 1)
    roomy = tuple(int(c) + 5 for c in hist[:nlev])  # ≥ each level's count: no overflow either way
    sim2 = replace(sim, config=replace(sim.config, capacities=roomy))
    roomy_state, roomy_frames = _run(sim2, state, 8)
    for a, b in zip(jax.tree.leaves(tight_state), jax.tree.leaves(roomy_state), strict=True):
        # Same per-agent arithmetic in a differently sized vmap: XLA may vectorise the tails
        # differently, a few float32 ulps of values up to ~60 m (ulp 3.8–7.6 µm): 3e-5.
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=3e-5)
    for lv in range(nlev):
        f1, f2 = tight[-1], roomy_frames[-1]
        ids1 = np.asarray(f1.slots[lv])[np.asarray(f1.valid[lv])]
        ids2 = np.asarray(f2.slots[lv])[np.asarray(f2.valid[lv])]
        assert sorted(ids1) == sorted(ids2)
        p1 = dict(zip(ids1, np.asarray(f1.points[lv])[np.asarray(f1.valid[lv])], strict=True))
        p2 = dict(zip(ids2, np.asarray(f2.points[lv])[np.asarray(f2.valid[lv])], strict=True))
        for i in ids1:
            np.testing.assert_allclose(p1[i], p2[i], atol=1e-5)


@pytest.mark.parametrize(("cap", "used", "chunk"), [(10, 7, 3), (12, 12, 4), (9, 0, 4), (5, 5, 8)])
def test_decode_bucket_runs_only_the_chunks_that_hold_agents(cap, used, chunk):
    """Oracle: the whole bucket through ``fn``; chunks past ``used`` are zero, the rest equal."""
    from jcrowd.crowd import decode_bucket

    slots = jnp.arange(cap, dtype=jnp.int32) * 3 + 1
    fn = jax.vmap(lambda i: (jnp.sin(i.astype(jnp.float32)), jnp.stack([i, -i])))
    got = jax.jit(decode_bucket, static_argnums=(0, 3))(fn, slots, jnp.int32(used), chunk)
    want = fn(slots)
    run = cap if cap <= chunk else min(cap, -(-used // chunk) * chunk)
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape
        np.testing.assert_array_equal(np.asarray(g)[:run], np.asarray(w)[:run])
        assert not np.any(np.asarray(g)[run:])


@pytest.mark.slow
def test_chunked_step_equals_one_chunk(prepared):
    """Decoding buckets in chunks of 2 slots gives the crowd of one chunk per level."""
    sim, state = _sim(prepared)
    whole_state, whole = _run(replace(sim, config=replace(sim.config, chunk=4096)), state, 6)
    part_state, part = _run(replace(sim, config=replace(sim.config, chunk=2)), state, 6)
    for a, b in zip(jax.tree.leaves(whole_state), jax.tree.leaves(part_state), strict=True):
        # Same arithmetic in differently sized vmaps (a few float32 ulps, as above).
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=3e-5)
    for lv in range(len(sim.config.capacities)):
        ok = np.asarray(whole[-1].valid[lv])
        np.testing.assert_array_equal(ok, np.asarray(part[-1].valid[lv]))
        np.testing.assert_allclose(
            np.asarray(whole[-1].points[lv])[ok], np.asarray(part[-1].points[lv])[ok], atol=1e-5
        )


@pytest.mark.slow
def test_jit_equals_eager(prepared):
    """Two steps of the compiled step equal the step run op by op (``disable_jit``): every
    state leaf to rtol 1e-5, atol 2e-5."""
    sim, state = _sim(prepared, count=6)
    eager = lambda s, v, dt: step(sim.crowd, sim.config, s, v, dt)  # noqa: E731
    with jax.disable_jit():
        s_eager, _ = _run(sim, state, 2, eager)
    s_jit, _ = _run(sim, state, 2)
    for a, b in zip(jax.tree.leaves(s_eager), jax.tree.leaves(s_jit), strict=True):
        # Eager runs op by op in float32; jit fuses (FMA, reassociation): ~1e-6 of 1–20 m.
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=2e-5)


@pytest.mark.slow
def test_frame_points_equal_direct_decode(prepared):
    """A level-0 agent's drawn points are the synthesis of its (clip, phase) before the step."""
    sim, state = _sim(prepared, count=8)
    _, frames = _run(sim, state, 1)
    frame = frames[0]
    slots, ok = np.asarray(frame.slots[0]), np.asarray(frame.valid[0])
    plain = ok & ~np.asarray(state.has_next)[np.minimum(slots, state.num_agents - 1)]
    assert plain.any()  # an agent not blending yet: its pose is its current clip's alone
    i = int(slots[plain][0])
    lv = sim.crowd.decoders.levels[0]
    g = decode_coeffs(lv, state.clip()[1][i], state.tau[i])
    y = pose_from_coeffs(lv, g)
    want = level_points(lv, y, state.position[i], state.heading[i], state.height[i])
    got = np.asarray(frame.points[0])[np.nonzero(slots == i)[0][0]]
    np.testing.assert_allclose(got, np.asarray(want), atol=1e-5)


def test_traced_once_with_changing_level_histogram(prepared):
    """200 steps with the camera pulling away: the histogram changes, the step compiles once."""
    sim, state = _sim(prepared, count=40)
    fn = sim.compiled()
    hists = set()
    for i in range(200):
        eye = jnp.asarray([0.0, 1.7, -20.0 - 0.5 * i])
        view = eqx.tree_at(lambda v: v.eye, sim.view_at(0.0), eye)
        state, frame = fn(state, view, sim.dt)
        hists.add(tuple(np.bincount(np.asarray(frame.level), minlength=7)))
    assert len(hists) > 3
    assert fn._cache_size() == 1


def test_clip_handover_is_continuous(prepared):
    """Per-frame joint displacement of blended (level-0) agents at clip hand-overs stays within
    the 99th percentile of their within-clip displacements."""
    sim, state = _sim(prepared, count=6, capacities=(6,) * 3, thresholds=(1e3,) * 2)
    fn = sim.compiled()
    prev_pts, prev_tau = None, None
    inside, boundary = [], []
    for i in range(120):
        tau = np.asarray(state.tau)  # read before the step takes the state's buffers
        new, frame = fn(state, sim.view_at(i * sim.dt), sim.dt)
        ok = np.asarray(frame.valid[0])
        ids = np.asarray(frame.slots[0])[ok]
        pts = np.full((6, np.asarray(frame.points[0]).shape[1], 3), np.nan)
        pts[ids] = np.asarray(frame.points[0])[ok]
        if prev_pts is not None:
            move = np.linalg.norm(pts - prev_pts, axis=2).max(axis=1)  # (agents,)
            wrapped = tau < prev_tau
            boundary += move[wrapped].tolist()
            inside += move[~wrapped].tolist()
        prev_pts, prev_tau, state = pts, tau, new
    assert len(boundary) >= 4
    assert max(boundary) <= np.percentile(inside, 99)


def test_path_with_corner_is_walked_and_open_path_ends(model):
    """Agents reach both waypoints of an L-shaped path (a 90° corner) and then leave."""
    text = SCENE.format(count=3).replace("duration = 10.0", "duration = 90.0")
    sim, state = prepare(parse_scenario(text, "t.toml"), model)
    fn = sim.compiled()
    best = np.full((3, 2), np.inf)
    heading_steps = []
    for _ in range(90 * 30):
        before = np.asarray(state.heading)
        state, _ = fn(state, sim.view_at(0.0), sim.dt)
        heading_steps.append(np.abs(np.asarray(state.heading) - before))
        pos = np.asarray(state.position)
        for k in range(2):
            d = np.linalg.norm(pos - np.asarray(state.waypoints)[:, k], axis=1)
            best[:, k] = np.minimum(best[:, k], d)
        if not np.asarray(state.alive).any():
            break
    assert np.all(best < sim.config.reach + 0.5)
    assert not np.asarray(state.alive).any()
    # The root turns through the motion, a few degrees per step, never snapped.
    assert np.max(heading_steps) < np.deg2rad(10)


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.slow
def test_two_processes_on_loopback_equal_one_process(model, tmp_path):
    """`jcrowd run` as two processes (2 CPU devices each, one 4-device mesh over gloo) records
    the same crowd as one process on one device (the oracle: positions and headings to 1e-5);
    each prints exactly one JSON object, and the one-process run compiles its step once. The
    one-device side stays a process of its own: the command is the thing compared."""
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.format(count=32))
    save_motion_model(tmp_path / "m.jcm", model)
    base = ["-m", "jcrowd.cli", "run", str(scene), "--model", str(tmp_path / "m.jcm")]
    base += ["--steps", "5", "--json"]
    single = finish(start_python([*base, "--out", str(tmp_path / "one.npz")], 1))
    assert json.loads(single)["recompiles"] == 0
    port = _free_port()
    multi = ["--coordinator", f"127.0.0.1:{port}", "--num-processes", "2", "--process-id"]
    procs = [
        start_python([*base, "--out", str(tmp_path / "two.npz"), *multi, str(i)], 2)
        for i in range(2)
    ]
    try:
        outs = [finish(p, what=f"process {i} of 2") for i, p in enumerate(procs)]
    finally:
        for p in procs:  # the other one, if one failed: it would wait for its peer
            if p.poll() is None:
                p.kill()
    for out in outs:
        assert json.loads(out)["agents"] == 32  # stdout holds exactly one JSON object
    one, two = np.load(tmp_path / "one.npz"), np.load(tmp_path / "two.npz")
    # Same float32 program over 4 devices in 2 processes: collectives may reorder sums, 1e-5.
    np.testing.assert_allclose(two["position"], one["position"], atol=1e-5)
    np.testing.assert_allclose(two["heading"], one["heading"], atol=1e-5)


@pytest.mark.slow
def test_detail_culling_turns_tiny_agents_into_walking_dots(prepared):
    """Agents shorter on screen than ``min_pixels`` are dots: not synthesized, still walking,
    counted; with ``min_pixels = 0`` the same agents are synthesized."""
    # A 1.7 m agent 20–60 m from the camera is ~18–53 px tall at 720p with a 60° fov: a
    # 100 px threshold makes every agent in view a dot, 0 none.
    sim, state = _sim(prepared, count=12, min_pixels=100.0)
    fn = sim.compiled(donate=False)
    view = sim.view_at(0.0)
    new, frame = fn(state, view, sim.dt)
    nlev = len(sim.config.capacities)
    dots = np.asarray(frame.dots)
    assert dots.sum() >= 6 and (np.asarray(frame.level) == nlev).all()  # some are out of view
    assert not any(np.asarray(v).any() for v in frame.valid)
    moved = np.linalg.norm(np.asarray(new.position) - np.asarray(state.position), axis=1)
    assert (moved > 0.01).all()  # ~1.3 m/s × 1/30 s ≈ 4 cm by dead reckoning
    sim0 = replace(sim, config=replace(sim.config, min_pixels=0.0))
    _, frame0 = sim0.compiled(donate=False)(state, view, sim.dt)
    assert not np.asarray(frame0.dots).any()
    synthesized = np.zeros(12, bool)
    for slots, ok in zip(frame0.slots, frame0.valid, strict=True):
        synthesized[np.asarray(slots)[np.asarray(ok)]] = True
    np.testing.assert_array_equal(synthesized, dots)  # exactly the agents in view


@pytest.mark.slow
def test_agents_beyond_the_budget_become_dots_and_count_as_overflow(prepared):
    """One slot per level: three agents are placed, the others in view (counted with room for
    all 24, the oracle) are dots, and the overflow counts at least them."""
    sim, state = _sim(prepared, count=24, capacities=(1,) * 3, min_pixels=0.0)
    view = sim.view_at(0.0)
    _, frame = sim.compiled(donate=False)(state, view, sim.dt)
    placed = sum(int(np.asarray(v).sum()) for v in frame.valid)
    dots = int(np.asarray(frame.dots).sum())
    roomy = replace(sim, config=replace(sim.config, capacities=(24,) * 3))
    _, all_in = roomy.compiled(donate=False)(state, view, sim.dt)
    visible = sum(int(np.asarray(v).sum()) for v in all_in.valid)
    assert placed == 3 and visible > 3  # one per level; the rest of those in view are dots
    assert dots == visible - placed and int(frame.overflow) >= dots


def _one_hot_rows(mix, samples):
    b = mix[:, :samples]
    return np.isclose(b.max(axis=1), 1.0, atol=1e-6) & np.all(
        np.isclose(np.sort(b, axis=1)[:, :-1], 0.0, atol=1e-6), axis=1
    )


@pytest.mark.slow
def test_next_clip_is_kriged_for_synthesized_agents_and_captured_for_the_rest(prepared):
    """Agents not synthesized choose the nearest captured cycle (one-hot weights); agents
    synthesized get the kriged clip (dense weights)."""
    for min_pixels, want_one_hot in ((1e9, True), (3.0, False)):
        sim, state = _sim(prepared, min_pixels=min_pixels)
        s = sim.crowd.decoders.kriging.num_samples
        state, frames = _run(sim, state, 40)
        synthesized = np.asarray(frames[-1].level) < len(sim.config.capacities)
        assert synthesized.any() != want_one_hot  # the near scene: all 24 in view and tall
        chosen = np.asarray(state.has_next)
        assert chosen.sum() >= 3
        nxt = np.asarray(state.clip("next")[1])[chosen]
        assert np.all(_one_hot_rows(nxt, s) == want_one_hot)


def test_kriging_budget_defers_choices_and_counts_them(prepared):
    """A kriging budget of 1: at most one new kriged choice per step (``has_next`` read before
    and after each step), and the choices left for later are counted (``deferred`` > 0)."""
    sim, state = _sim(prepared, krige_budget=1)
    fn = sim.compiled(donate=False)
    before = np.asarray(state.has_next)
    deferred = 0
    for i in range(40):
        state, frame = fn(state, sim.view_at(i * sim.dt), sim.dt)
        after = np.asarray(state.has_next)
        assert int(np.sum(after & ~before)) <= 1  # at most one kriged choice per step
        before = after
        deferred += int(frame.deferred)
    assert deferred > 0


def test_first_state_spreads_phases_and_no_choice_waits(prepared):
    """Phases cover the whole cycle, agents past its middle start with their next clip, and
    the step's default choice budget keeps up: no choice is deferred."""
    sim, state = _sim(prepared, count=400)
    last = sim.crowd.frames - 1
    tau = np.asarray(state.tau)
    assert tau.min() < 0.1 * last and tau.max() > 0.9 * last
    np.testing.assert_array_equal(np.asarray(state.has_next), tau >= last / 2)
    _, frames = _run(sim, state, 45)
    assert sum(int(f.deferred) for f in frames) == 0


@pytest.mark.slow
def test_step_compiles_without_state_copies_and_same_results(prepared):
    """With copy insertion's region analysis (CPU), the compiled step copies no donated state
    buffer, and the crowd is bit-for-bit the one compiled without the option."""
    from jcrowd.crowd import step_compiler_options

    if not step_compiler_options():
        pytest.skip("this XLA has no xla_cpu_copy_insertion_use_region_analysis option")
    sim, state = _sim(prepared)

    def run(state, view, dt):  # the argument name fixes the HLO parameter names
        return step(sim.crowd, sim.config, state, view, dt)

    fn = sim.compiled()
    plain = jax.jit(run, donate_argnums=(0,))
    view, dt = sim.view_at(0.0), sim.dt
    assert "copy(%state_" not in fn.lower(state, view, dt).compile().as_text()
    assert "copy(%state_" in plain.lower(state, view, dt).compile().as_text()  # can fail
    a, b = jax.tree.map(jnp.copy, state), jax.tree.map(jnp.copy, state)
    for i in range(5):
        a, _ = fn(a, sim.view_at(i * sim.dt), dt)
        b, _ = plain(b, sim.view_at(i * sim.dt), dt)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.slow
def test_coarsest_level_cached_cores_match_direct_decode_across_clip_changes(prepared):
    """Every agent at the coarsest level for 50 steps (past its clip hand-over): each frame's
    points equal the decode of the agent's current clip computed from scratch."""
    sim, state = _sim(prepared, thresholds=(0.1, 0.2), refresh=24)
    lv = sim.crowd.decoders.levels[-1]
    fn = sim.compiled(donate=False)

    # One agent's points from scratch, compiled once (op by op it is ~1,000 dispatches a call).
    @eqx.filter_jit
    def direct(clip, tau, position, heading, height):
        y = pose_from_coeffs(lv, decode_coeffs(lv, clip, tau))
        return level_points(lv, y, position, heading, height)

    checked, handed_over = 0, 0
    for i in range(50):
        new, frame = fn(state, sim.view_at(i * sim.dt), sim.dt)
        slots, ok = np.asarray(frame.slots[-1]), np.asarray(frame.valid[-1])
        clips = state.clip()[1]
        for s in np.nonzero(ok)[0]:
            j = int(slots[s])
            want = direct(
                clips[j], state.tau[j], state.position[j], state.heading[j], state.height[j]
            )
            # The same float32 products in another order: ulps of points ~20–60 m out.
            np.testing.assert_allclose(np.asarray(frame.points[-1][s]), want, atol=3e-5)
            checked += 1
        handed_over += int(np.sum(np.asarray(new.current) != np.asarray(state.current)))
        state = new
    assert checked > 500 and handed_over > 5


@pytest.mark.parametrize("k", [1, 3, 12])
def test_waypoint_pick_by_selects_or_gather_equals_indexing(prepared, k, monkeypatch):
    """Both ways of reading each agent's current waypoint (selects up to SELECT_WAYPOINTS,
    a gather beyond) equal NumPy fancy indexing, exactly (no arithmetic)."""
    import jcrowd.crowd.steering as steering

    _, state = _sim(prepared, count=10)
    rng = np.random.default_rng(k)
    wps = jnp.asarray(rng.uniform(-50, 50, (10, k, 2)), jnp.float32)
    wp = jnp.asarray(rng.integers(0, k, 10), jnp.int32)
    state = eqx.tree_at(lambda s: s.waypoints, state, wps)
    want = np.asarray(wps)[np.arange(10), np.asarray(wp)]
    for limit in (0, 100):  # 0: always gather; 100: always selects
        monkeypatch.setattr(steering, "SELECT_WAYPOINTS", limit)
        tx, tz = jax.jit(steering.waypoint_xz)(state.waypoints, wp)
        np.testing.assert_array_equal(np.stack([tx, tz], axis=1), want)
