"""The animated crowd step: one compiled function advancing every agent (DESIGN §5, 000 §4–5).

``step(cm, config, state, view, dt) -> (state, frame)`` runs named stages, top to bottom:

1. **Level of detail** (:mod:`jcrowd.crowd.lod`): agents outside the view frustum are culled,
   and so are those shorter on screen than ``min_pixels`` (a ``dot`` for the renderer); the
   others get the finest level their camera distance allows (with hysteresis) and fill the
   levels' static capacities by importance; the excess becomes dots (``overflow``).
2. **Dynamics** (with ``[dynamics] avoid``; :func:`jcrowd.crowd.steering.walk`): the
   pedestrian step of :mod:`jcrowd.pedestrians` gives each agent its velocity. It runs before
   the synthesis, so the phase follows the velocity the root walks in the same step.
3. **Level blending** (:mod:`jcrowd.crowd.level_blend`): an agent whose level changed eases
   from the old level's pose to the new one's over 0.45 s, continuous in value and velocity;
   the old level is decoded here.
4. **Synthesis** per level (:mod:`jcrowd.crowd.synthesis`), ``vmap`` over the level's bucket,
   run only on the chunks of slots that hold agents (:func:`decode_bucket`): the pose at phase
   τ, blended with the next clip for levels ≤ ``blend_max_level``, FK on the level's
   skeleton, τ advancing by ``dt · fps / ΔA(τ)`` (the inverse time-warp, 001 §3.5) — or, with
   the dynamics, with the distance walked (:func:`~jcrowd.crowd.following.follow_phase`).
   Culled agents advance their root only, by dead reckoning along their clip's arc (000 §4.3).
5. **Root motion**: by ``v·dt`` with the dynamics (the body facing the dynamics' heading;
   below 0.1 m/s the agent stands at a double-support phase, and steps on the spot when its
   body has turned, :func:`~jcrowd.crowd.following.turns_on_the_spot`), else by
   the decoded motion, with the stance foot locked near the camera.
6. **Clips** (:mod:`jcrowd.crowd.schedule`): waypoints, the next cycle chosen at mid-cycle
   (bounded per step, kriged for synthesized agents), the hand-over at the cycle's end.
7. **Frame**: the levels' slots and points, dots and the step's counters.

Blending reading (000 §5, "blending the second half of the synthesized motion with the first
half of the following motion"): the paper's clips are two strides, ours one gait cycle, so
over the old cycle's second half the pose eases (smoothstep) from the old clip to the new clip
*at the same phase*, and at the cycle end the new clip continues from phase 0. Far levels
switch at the cycle end without blending. Everything has a static shape; no host round trip
inside a step.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Int

from jcrowd.crowd.clips import CrowdModel, local_to_world
from jcrowd.crowd.feet import no_pins, plant_agent, plant_bucket, plants_feet
from jcrowd.crowd.following import (
    STAND_BELOW,
    follow_phase,
    stands_at,
    stride_warp,
    turns_on_the_spot,
)
from jcrowd.crowd.level_blend import BlendRows, blend_plan, blend_sources
from jcrowd.crowd.lod import (
    Buckets,
    CameraView,
    assign_buckets,
    distance_levels,
    in_frustum,
    screen_height_px,
)
from jcrowd.crowd.pool import Pool, spawn_due
from jcrowd.crowd.schedule import schedule
from jcrowd.crowd.state import CrowdState, Frame, StepConfig, refresh_far_cores
from jcrowd.crowd.steering import walk
from jcrowd.crowd.synthesis import clip_core, coeffs_at, level_points, pose_from_coeffs, root_rates
from jcrowd.motion.fastmath import sincos
from jcrowd.motion.planting import warp_stride
from jcrowd.pedestrians.heading import smoothstep
from jcrowd.pedestrians.world import World

__all__ = [
    "bucket_chunk",
    "decode_bucket",
    "default_capacities",
    "step",
]


BUDGET_FINEST = 256
"""Default capacity of level 0; level l holds twice level l − 1's."""
BUDGET_LAST = 16_384
"""Default capacity of the coarsest level."""


def default_capacities(agents: int, levels: int) -> tuple[int, ...]:
    """The default budget: level l < L − 1 holds ``min(max(N / 2^(L − l) + 64, 256),
    256 · 2^l)`` agents, the last 16,384; none holds more than the crowd's ``N``.

    A fixed budget for a large crowd, everyone for a small one: the screen holds only so many
    agents tall enough to show detail, so level 0's 256 slots are never full on
    ``bench/step.py``'s plaza (1280×720, 1 agent per 10 m², 3-pixel detail culling: its level
    histogram holds about a hundred agents at each of the levels 0–4 and most synthesized ones
    at level 5, at 100k and at 1M agents alike). A crowd of up to 256 agents fits every level
    whole, so no agent of it is drawn coarser than its distance asks: a scene with a few dozen
    people close to the camera shows them all at full detail, where a share of the crowd would
    move some to level 1 a few metres from the camera (a visible pose change, and a level-1
    pose's own error at that distance is a few pixels per frame). Denser scenes overflow
    coarser (counted), never vanish.
    """
    caps = [
        min(max(agents // 2 ** (levels - lv) + 64, BUDGET_FINEST), BUDGET_FINEST * 2**lv)
        for lv in range(levels - 1)
    ]
    return tuple(min(agents, c) for c in (*caps, BUDGET_LAST))


def _agent_level(
    cm: CrowdModel,
    level: int,
    near: bool,
    lock: bool,
    state: CrowdState,
    i: Array,
    dt: Array,
    cached: bool = False,
    follow: bool = False,
    turning: Array | None = None,
    warp: bool = False,
):
    """Pose and root motion of agent ``i`` at ``level`` (one agent; batched by ``vmap``).

    ``near``: blend into the next clip over the cycle's second half. ``lock``: move the root so
    that the stance foot stays put (see :func:`step`). ``cached``: the core is the agent's
    ``far_core`` (the coarsest level, kept current by
    :func:`jcrowd.crowd.state.refresh_far_cores`). ``follow``: the phase advances with the
    distance the agent walks (:func:`~jcrowd.crowd.following.follow_phase`); ``turning``: the
    agents stepping on the spot (:func:`~jcrowd.crowd.following.turns_on_the_spot`); ``warp``:
    the feet take the agent's stride warp (:func:`~jcrowd.motion.planting.warp_stride`; the
    the planted levels only: the coarser levels hold most agents, small on screen, and a warp
    per agent there costs more of the step than it shows).
    """
    lv = cm.decoders.levels[level]
    last = float(cm.frames - 1)
    k = state.current[i]

    # The clips' cores are computed once and evaluated at both phases the foot lock needs.
    core = state.far_core[i].reshape(lv.ranks) if cached else clip_core(lv, state.mix[i, k])
    core_next = clip_core(lv, state.mix[i, 1 - k]) if near else core

    def pose(tau: Array) -> Array:
        g = coeffs_at(lv, core, tau)
        if near:
            s = jnp.where(state.has_next[i], smoothstep((tau - last / 2) / (last / 2)), 0.0)
            g = g + s * (coeffs_at(lv, core_next, tau) - g)
        return pose_from_coeffs(lv, g)

    tau, h, heading = state.tau[i], state.height[i], state.heading[i]
    xz = jnp.stack([state.x[i], state.z[i]])
    y = pose(tau)
    pts = level_points(lv, y, xz, heading, h)
    if warp:
        pts = warp_stride(cm.legs, pts, heading, state.stride[i])
    rates = root_rates(y)
    dtau = dt * cm.decoders.fps / rates.delta_a
    if follow:
        walked = jnp.hypot(state.vx[i], state.vz[i]) * dt
        turns = None if turning is None else turning[i]
        dtau = follow_phase(cm, tau, dtau, walked, jnp.linalg.norm(rates.velocity) * h, dt, turns)
    dyaw = rates.yaw_rate * dtau
    dpos = local_to_world(rates.velocity * h * dtau, heading)
    if lock:
        # Root from the stance foot: the lowest foot joint now is where the foot is planted;
        # place the root so that, after the step's pose and turn, that joint has not moved.
        feet = jnp.asarray(cm.feet)
        j = feet[jnp.argmin(pts[feet, 1])]
        after = level_points(lv, pose(tau + dtau), xz, heading + dyaw, h)
        dpos = pts[j, jnp.array([0, 2])] - after[j, jnp.array([0, 2])]
    return pts, dtau, dyaw, dpos


CHUNK_CORE_FLOATS = 5 << 19
"""A chunk's cores (one per slot) stay under this many floats (10 MB) unless that would make
chunks smaller than ``StepConfig.chunk``."""


def bucket_chunk(capacity: int, chunk: int, core_floats: int = 0) -> int:
    """Chunk size for a bucket of ``capacity`` slots: at least ``chunk``, at most 8 chunks (every
    chunk pays each of its ops' dispatch once on XLA:CPU, so a big level takes bigger chunks),
    but no chunk whose ``core_floats``-float cores pass :data:`CHUNK_CORE_FLOATS`. That caps
    level 0 (1,200-float cores) at 2,184 slots: larger level-0 chunks decode fewer agent-frames
    per second, not more (``bench/step.py``'s full-detail rate decodes in these chunks).
    """
    size = max(chunk, -(-capacity // 8))
    if core_floats > 0:
        size = min(size, max(chunk, CHUNK_CORE_FLOATS // core_floats))
    return size


def decode_bucket(
    fn: Callable[[Array], Any], slots: Int[Array, " C"], used: Array, chunk: int
) -> Any:
    """``fn(slots)`` evaluated only on the chunks of ``chunk`` slots that hold agents.

    ``fn`` maps ``(k,)`` agent ids to a pytree of ``(k, ...)`` arrays (a ``vmap``-ed one-agent
    function); ``used`` is how many leading slots hold agents (buckets are filled from the
    front, :class:`jcrowd.crowd.lod.Buckets`). The first ``ceil(used / chunk)`` chunks run in a loop
    with a traced trip count — the shapes stay static, so a changing level histogram compiles
    nothing — and the rows of chunks not run are zero (their slots are not valid). A capacity
    is a bound, not the usual load: on ``bench/step.py``'s plaza levels 1–4 fill a small part of
    their 512–4,096 slots (its level histogram), so decoding every slot would mostly decode
    padding.
    """
    cap = slots.shape[0]
    if cap <= chunk:
        return fn(slots)
    pad = -cap % chunk
    ids = jnp.pad(slots, (0, pad))
    fn = jax.jit(fn)  # traced once: for the shapes here, the trace reused in the loop below
    shapes = jax.eval_shape(fn, ids[:chunk])
    init = jax.tree.map(lambda s: jnp.zeros((cap + pad, *s.shape[1:]), s.dtype), shapes)

    def body(k: Array, out: Any) -> Any:
        start = k * chunk
        res = fn(jax.lax.dynamic_slice_in_dim(ids, start, chunk))
        return jax.tree.map(
            lambda o, r: jax.lax.dynamic_update_slice_in_dim(o, r, start, 0), out, res
        )

    out = jax.lax.fori_loop(0, (used + chunk - 1) // chunk, body, init)
    return jax.tree.map(lambda o: o[:cap], out)


def _dead_reckoning(
    cm: CrowdModel, state: CrowdState, dt: Array, follow: bool = False, turning: Array | None = None
) -> tuple[Array, Array, Array, Array]:
    """Root-only advance ``(dτ, dyaw, dx, dz)`` along the clip's arc at its mean rate (with
    ``follow``, the phase at the clip's mean stride per aligned frame,
    :func:`~jcrowd.crowd.following.follow_phase`)."""
    ix, iz, iyaw = cm.index[:3]
    last = float(cm.frames - 1)
    control, _, duration = state.clip()
    dtau = dt * cm.decoders.fps * last / jnp.maximum(duration, 1.0)
    if follow:
        walked = jnp.hypot(state.vx, state.vz) * dt
        stride = jnp.hypot(control[:, ix], control[:, iz]) / last
        dtau = follow_phase(cm, state.tau, dtau, walked, stride, dt, turning)
    frac = dtau / last
    turn = control[:, iyaw]
    half = turn / 2
    # Constant speed and turn rate over the cycle end at (dx, dz) with heading + turn when the
    # local velocity is the chord rotated back by half the turn, lengthened by θ/2 / sin(θ/2).
    gain = jnp.where(jnp.abs(half) > 1e-4, half / sincos(jnp.where(half == 0, 1.0, half))[0], 1.0)
    x, z = control[:, ix] * gain * frac, control[:, iz] * gain * frac
    # Rotating by −half into the heading frame and then into the world is one rotation by
    # heading − half (three transcendentals per agent instead of five).
    ang = state.heading - half
    s, c = sincos(ang)
    return dtau, turn * frac, x * c + z * s, -x * s + z * c


class _Lod(eqx.Module):
    """The level-of-detail stage's result: who is in view, and the levels' buckets."""

    visible: Array
    buckets: Buckets


def _level_of_detail(
    cm: CrowdModel, config: StepConfig, state: CrowdState, view: CameraView
) -> _Lod:
    """Stage 1: frustum and detail culling, each agent's level by distance (with hysteresis),
    and the buckets of the levels' static capacities filled by importance."""
    nlev = len(cm.decoders.levels)
    stature = state.height * cm.body_height  # the drawn body's height (m)
    centre = (state.x, 0.55 * stature, state.z)
    visible = state.alive & in_frustum(view, centre, radius=0.6 * 1.9)
    dist = jnp.sqrt(sum((c - view.eye[k]) ** 2 for k, c in enumerate(centre)))
    previous = jnp.minimum(state.level, nlev - 1)
    thresholds = jnp.asarray(config.thresholds, jnp.float32)
    min_level = distance_levels(dist, previous, thresholds, config.hysteresis)
    pixels = screen_height_px(view, centre, stature)
    importance = -dist if config.importance == "distance" else pixels
    detailed = visible & (pixels >= config.min_pixels)
    return _Lod(visible, assign_buckets(min_level, importance, detailed, config.capacities))


class _Blending(eqx.Module):
    """The level-blending stage's result (:mod:`jcrowd.crowd.level_blend`)."""

    rows: BlendRows
    source: Array
    left: Array
    unblended: Array
    feet: tuple[Array, Array, Array]  # the pins of agents blending from a near level (planting)


def _blending(
    cm: CrowdModel, config: StepConfig, state: CrowdState, buckets: Buckets, dt: Array
) -> _Blending:
    """Stage 3: the agents whose level changed lately, decoded at the level they come from."""
    nlev = len(cm.decoders.levels)
    source, left = blend_plan(
        state.shown, state.blend_from, state.blend_left, buckets.level, state.alive, nlev
    )

    feet = no_pins(state)

    def old_pose(a: int, ids: Array, used: Array) -> Array:
        nonlocal feet
        near = a <= config.blend_max_level
        safe = jnp.where(ids < state.num_agents, ids, 0)

        def one(i: Array) -> Array:
            warp = near and plants_feet(cm, config)
            return _agent_level(cm, a, near, False, state, i, dt, follow=config.avoid, warp=warp)[0]

        chunk = bucket_chunk(ids.shape[0], config.chunk, cm.decoders.levels[a].cores.shape[1])
        pts = decode_bucket(jax.vmap(one), safe, used, chunk)
        if near and plants_feet(cm, config):
            # An agent leaving the near levels eases from its planted feet, not from where they
            # slid to: its old pose is planted as it was drawn, its pins carried on. (One going
            # to another near level is planted after the easing, with the same pins.)
            leaving = buckets.level[safe] > config.blend_max_level
            planted, new = plant_bucket(cm, state, safe, pts)
            pts = jnp.where(leaving[:, None, None], planted, pts)
            to = jnp.where(leaving, ids, state.num_agents)
            pin, on, toe = (o.at[to].set(v, mode="drop") for o, v in zip(feet, new, strict=True))
            feet = (pin, on, toe)
        return pts

    rows, unblended = blend_sources(buckets.slots, source, left, old_pose)
    return _Blending(rows, source, left, unblended, feet)


def _synthesis(
    cm: CrowdModel,
    config: StepConfig,
    state: CrowdState,
    buckets: Buckets,
    blend: BlendRows,
    feet: tuple[Array, Array, Array],
    dt: Array,
    turning: Array | None = None,
) -> tuple[CrowdState, list[Array], tuple[Array, Array, Array, Array]]:
    """Stage 4: per level, decode + forward kinematics of its bucket (eased from the old level
    where one is blending); every agent's root motion ``(dτ, dyaw, dx, dz)``, by dead
    reckoning for those not synthesized. Returns the state (far cores refreshed), each
    level's points and the root motion."""
    nlev = len(cm.decoders.levels)
    dtau, dyaw, dx, dz = _dead_reckoning(cm, state, dt, config.avoid, turning)
    points = []
    # Planted feet (with the dynamics): every agent's pins are rebuilt from the blend rows and
    # the near buckets; an agent in neither has none.
    plant = plants_feet(cm, config)
    feet_out = list(feet)
    for lv, (slots, ok) in enumerate(zip(buckets.slots, buckets.valid, strict=True)):
        safe = jnp.where(ok, slots, 0)
        near = lv <= config.blend_max_level
        lock = near and config.foot_lock and not config.avoid
        cached = lv == nlev - 1 and not near
        if cached:
            state = refresh_far_cores(cm, state, safe, ok)

        # Small buckets ease each agent in its decode; the large last one only its blending
        # rows afterwards (level_blend.BlendRows).
        in_decode = lv < nlev - 1

        # Near agents are planted in their decode too (in the chunks that run), but for the
        # last bucket, eased after its decode.
        planted = near and plant and in_decode

        def one(
            i, lv=lv, near=near, lock=lock, cached=cached, state=state, ease=in_decode, pl=planted
        ):
            pts, *motion = _agent_level(
                cm, lv, near, lock, state, i, dt, cached, config.avoid, turning, near and plant
            )
            pts = blend.ease(i, pts) if ease else pts
            if pl:
                pts, *feet = plant_agent(cm, state, i, pts)
                return (pts, *motion, *feet)
            return (pts, *motion)

        used = jnp.sum(ok, dtype=jnp.int32)
        chunk = bucket_chunk(len(slots), config.chunk, cm.decoders.levels[lv].cores.shape[1])
        pts, t_l, yaw_l, pos_l, *feet = decode_bucket(jax.vmap(one), safe, used, chunk)
        if not in_decode:
            pts = blend.ease_bucket(pts, sum(len(s) for s in buckets.slots[:lv]))
            if near and plant:
                pts, feet = plant_bucket(cm, state, safe, pts)
        if near and plant:
            feet_out = [
                o.at[slots].set(v, mode="drop") for o, v in zip(feet_out, feet, strict=True)
            ]
        points.append(pts)
        dtau = dtau.at[slots].set(t_l, mode="drop")
        dyaw = dyaw.at[slots].set(yaw_l, mode="drop")
        dx = dx.at[slots].set(pos_l[:, 0], mode="drop")
        dz = dz.at[slots].set(pos_l[:, 1], mode="drop")
    if plant:
        state = eqx.tree_at(lambda s: (s.pin, s.planted, s.pin_toe), state, tuple(feet_out))
    return state, points, (dtau, dyaw, dx, dz)


def _move_roots(
    cm: CrowdModel,
    config: StepConfig,
    state: CrowdState,
    alive: Array,
    motion: tuple[Array, Array, Array, Array],
    dt: Array,
    facing: Array | None,
) -> CrowdState:
    """Stage 5: the roots of the agents alive at the step's start move — by ``v·dt`` with the
    dynamics, the body taking their heading (``facing``) unless it stands in double support,
    else by the decoded or dead-reckoned motion — and the phase advances."""
    dtau, dyaw, dx, dz = motion
    vx, vz = state.vx, state.vz  # the dynamics' output; without them it stays as it was
    if config.avoid and facing is not None:
        dx, dz = vx * dt, vz * dt
        # A standing body turns too: its feet stay planted until it has turned far enough to
        # step on the spot (jcrowd.crowd.following.turns_on_the_spot).
        heading = facing
    else:
        heading = state.heading + dyaw
    moved = (
        jnp.where(alive, state.x + dx, state.x),
        jnp.where(alive, state.z + dz, state.z),
        jnp.where(alive, heading, state.heading),
        jnp.where(alive, state.tau + dtau, state.tau),
    )
    state = eqx.tree_at(lambda s: (s.x, s.z, s.heading, s.tau), state, moved)
    if config.avoid:  # (without the dynamics nobody stands: ``stands`` stays False)
        slow = jnp.hypot(vx, vz) < STAND_BELOW  # the speed the phase followed
        stands = alive & slow & stands_at(cm, state.tau)
        # The heading it stood still at: kept while it stands, followed otherwise.
        still = jnp.where(stands & state.stands, state.stand_heading, state.heading)
        # The stride warp the next frame is drawn with (this one's is the state's).
        stride = stride_warp(state.stride, slow, dt)
        state = eqx.tree_at(
            lambda s: (s.stands, s.stand_heading, s.stride), state, (stands, still, stride)
        )
    return state


def step(
    cm: CrowdModel,
    config: StepConfig,
    state: CrowdState,
    view: CameraView,
    dt: Array,
    gather: Callable[[Array], Array] | None = None,
    ids: Array | None = None,
    world: World | None = None,
    pool: Pool | None = None,
) -> tuple[CrowdState, Frame]:
    """Advance the crowd by ``dt`` seconds and return the frame at the step's start.

    The stages, in order: sources (``pool``: agents waiting for slots, those due appear),
    level of detail, dynamics (with ``config.avoid``), level blending, synthesis, root motion,
    clip scheduling, and the frame.

    ``gather`` and ``ids``: on one device of several, how the dynamics see the whole crowd
    (:func:`~jcrowd.pedestrians.step.pedestrian_step`); unused without ``config.avoid``.
    ``world``: the layout's navigation fields and walls (:mod:`jcrowd.pedestrians.scene`;
    ``None``: no layout).
    """
    nlev = len(cm.decoders.levels)
    dt = jnp.asarray(dt, jnp.float32)
    if pool is not None:
        state = spawn_due(state, pool.reservoir, pool.times, pool.first_id, pool.budget)
    lod = _level_of_detail(cm, config, state, view)
    buckets = lod.buckets
    alive = state.alive
    crowding, facing, turning = jnp.zeros((), jnp.int32), None, None
    if config.avoid:  # first: the phase follows this step's walk (the root moves by v·dt)
        near = buckets.level <= config.blend_max_level
        vx, vz, facing, crowding = walk(config, world, state, near, dt, gather, ids)
        slow = jnp.hypot(vx, vz) < STAND_BELOW
        h, stood = state.heading, state.stand_heading
        turning = turns_on_the_spot(state.stands, slow, h, stood, facing, dt)
        state = eqx.tree_at(lambda s: (s.vx, s.vz), state, (vx, vz))
    blending = _blending(cm, config, state, buckets, dt)
    state, points, motion = _synthesis(
        cm, config, state, buckets, blending.rows, blending.feet, dt, turning
    )
    state = _move_roots(cm, config, state, alive, motion, dt, facing)
    state, deferred = schedule(cm, config, state, buckets.level < nlev, world)
    shown = jnp.where(alive, buckets.level, nlev)
    left = jnp.maximum(blending.left - dt, 0.0)
    state = eqx.tree_at(
        lambda s: (s.shown, s.blend_from, s.blend_left, s.level),
        state,
        (shown, blending.source, left, buckets.level),
    )
    if pool is not None or config.far_every > 1:
        state = eqx.tree_at(lambda s: s.clock, state, state.clock + dt)
    frame = Frame(
        buckets.slots,
        buckets.valid,
        tuple(points),
        buckets.level,
        lod.visible & (buckets.level == nlev),
        buckets.overflow + buckets.unplaced,
        deferred,
        crowding,
        blending.unblended,
    )
    return state, frame
