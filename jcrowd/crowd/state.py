"""The crowd's state, the step's settings and the frame a step returns.

:class:`CrowdState` holds every agent's state with the agent axis leading (so one
``PartitionSpec("agents")`` shards all of it); :class:`StepConfig` the static settings
:mod:`jcrowd.crowd.stepping` is compiled with; :class:`Frame` is what a renderer or a recorder
reads from one step; :func:`init_state` builds the first state from spawned agents.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from jcrowd.crowd.clips import CrowdModel, next_clips
from jcrowd.crowd.synthesis import clip_core
from jcrowd.errors import JcrowdError
from jcrowd.indexing import first_true
from jcrowd.pedestrians.neighbours import GridSpec
from jcrowd.pedestrians.params import AvoidanceParams

__all__ = ["DEFAULT_RADIUS", "CrowdState", "Frame", "StepConfig", "init_state", "refresh_far_cores"]

DEFAULT_RADIUS = 0.2
"""Body radius (m) of an agent for the crowd dynamics (JuPedSim's default)."""


@dataclass(frozen=True)
class StepConfig:
    """Static settings of the step (changing one compiles a new step).

    Attributes:
        capacities: agents per level (finest first); the last usually covers every agent.
        thresholds: distances (m) past which an agent is at least level i + 1.
        hysteresis: band (m) round each threshold inside which the level does not change.
        blend_max_level: levels ≤ this blend clips; coarser ones switch at the frame.
        refresh: clips chosen per step at most (0: ``N / 32 + 64``, above the rate at which
            1.1 s cycles end at 30 steps per second, N / 33; :func:`jcrowd.crowd.simulate.prepare`
            sets it from the frame rate and the model's shortest cycle).
        reach: a waypoint within this distance (m) counts as reached.
        importance: ``"distance"`` (nearer first) or ``"pixels"`` (taller on screen first).
        min_reliability: below this ρ the next clip is averaged with the nearest sample's clip.
        foot_lock: near levels (≤ ``blend_max_level``) keep the stance foot from sliding:
            without the dynamics by moving the root (the lowest foot joint stays put), with
            them by planting the feet (``plant_feet``).
        plant_feet: with the dynamics and ``foot_lock``, near agents' stance feet are planted
            and their legs bent to reach them (:mod:`jcrowd.motion.planting`).
        min_pixels: agents whose projected height is below this are not synthesized (root
            only, drawn as dots); 0 synthesizes every agent in the frustum.
        chunk: a level's bucket is decoded in chunks of at least this many slots (at most 8
            per level), only as many chunks as hold agents (a capacity is a maximum, not a
            cost; see :func:`decode_bucket`).
        krige_budget: next clips kriged per step at most, for agents being synthesized (0:
            ``Σ capacities / 32 + 64``; ``prepare`` sets it like ``refresh`` for the agents
            the capacities hold); the others play the nearest captured cycle
            (:func:`jcrowd.crowd.clips.next_clips_lod`).
        avoid: the crowd dynamics drive the roots (:mod:`jcrowd.crowd.steering`): agents
            avoid each other, the root is the simulated position and clips follow the
            velocity; ``foot_lock`` plants the feet instead of moving the root.
        grid: the dynamics' neighbour grid (required with ``avoid``).
        far_every: simulation level of detail: agents drawn coarser than ``blend_max_level``
            (or not drawn) compute their avoidance every ``far_every`` steps, in turn, and
            walk on at their last velocity in between (1: everyone every step).
        anticipate: with ``avoid``, agents anticipate each other's paths (the anticipation
            velocity model's reading in :mod:`jcrowd.pedestrians.avoidance`); off: the plain
            collision-free speed model.
        avoidance: ``(name, value)`` pairs set on
            :class:`~jcrowd.pedestrians.params.AvoidanceParams` (e.g. calibrated ones,
            ``[dynamics] params``); the others keep their defaults.
    """

    capacities: tuple[int, ...]
    thresholds: tuple[float, ...]
    hysteresis: float = 2.0
    blend_max_level: int = 1
    refresh: int = 0
    reach: float = 2.0
    importance: str = "distance"
    min_reliability: float = 0.5
    foot_lock: bool = True
    plant_feet: bool = True
    min_pixels: float = 3.0
    chunk: int = 64
    krige_budget: int = 0
    avoid: bool = False
    grid: GridSpec | None = None
    far_every: int = 1
    anticipate: bool = False
    avoidance: tuple[tuple[str, float], ...] = ()

    def avoidance_params(self) -> AvoidanceParams:
        """The avoidance model's parameters: the defaults with :attr:`avoidance` set."""
        values: dict[str, Any] = dict(self.avoidance)
        return AvoidanceParams(**values)

    def check(self, levels: int) -> None:
        """Raise :class:`JcrowdError` unless the settings fit a model with ``levels`` levels."""
        if len(self.capacities) != levels or any(c < 1 for c in self.capacities):
            raise JcrowdError(
                f"lod.capacities: expected {levels} positive integers (one per model level), "
                f"found {list(self.capacities)}"
            )
        if len(self.thresholds) != levels - 1:
            raise JcrowdError(
                f"lod.thresholds: expected {levels - 1} distances for a {levels}-level model, "
                f"found {list(self.thresholds)}"
            )
        if self.chunk < 1:
            raise JcrowdError(f"lod.chunk: expected a positive integer, found {self.chunk}")
        for name in ("refresh", "krige_budget"):
            if getattr(self, name) < 0:
                raise JcrowdError(
                    f"lod.{name}: expected a non-negative integer (0: default), "
                    f"found {getattr(self, name)}"
                )
        if self.far_every < 1:
            raise JcrowdError(
                f"dynamics.far_every: expected a positive integer, found {self.far_every}"
            )
        if self.avoid and self.grid is None:
            raise JcrowdError("dynamics: expected a neighbour grid with avoid on, found none")
        fields = AvoidanceParams.__dataclass_fields__
        for name, value in self.avoidance:
            if name not in fields or not 0 < value < float("inf"):
                raise JcrowdError(
                    f"dynamics.params: avoidance.{name}: expected a positive number named one of "
                    f"{', '.join(sorted(fields))}, found {name} = {value}"
                )
        if self.importance not in ("distance", "pixels"):
            raise JcrowdError(
                f"lod.importance: expected 'distance' or 'pixels', found {self.importance!r}"
            )


class CrowdState(eqx.Module):
    """Every agent's state; leading axis = agents (``N``), ``A`` = mixing-vector length."""

    # Per-agent scalars are kept as separate (N,) arrays, not (N, 2) or (N, 3) rows: XLA:CPU
    # vectorizes a loop over one contiguous axis, and a fusion writing an (N, 2) result
    # evaluates its whole expression once per column (dead reckoning would be computed twice).
    x: Float[Array, " N"]  # root position, m
    z: Float[Array, " N"]
    heading: Float[Array, " N"]  # rad; faces (sin, 0, cos)
    tau: Float[Array, " N"]  # phase in aligned frames, [0, T − 1)
    # Two clip slots per agent, ``current`` naming the playing one; the next clip is written into
    # the other, and the hand-over flips ``current`` (no copy of the mixing vectors).
    control: Float[Array, "N 2 d"]  # clips' controls
    mix: Float[Array, "N 2 A"]  # clips' mixing vectors [b(c); 1; ĉ]
    duration: Float[Array, "N 2"]  # clips' durations (model frames)
    current: Int[Array, " N"]  # 0 or 1
    has_next: Bool[Array, " N"]
    origin_x: Float[Array, " N"]  # root position and heading at the current cycle's start
    origin_z: Float[Array, " N"]
    origin_heading: Float[Array, " N"]
    level: Int[Array, " N"]  # last LOD level; L = culled
    # The current clip's core at the coarsest level, kept while the clip plays: recomputed
    # only when the clip changes (refresh_far_cores), not every step.
    far_core: Float[Array, "N RR"]
    far_valid: Bool[Array, " N"]
    alive: Bool[Array, " N"]
    height: Float[Array, " N"]  # skeleton scale (m): stature / CrowdModel.body_height
    speed: Float[Array, " N"]  # m/s (style)
    waypoints: Float[Array, "N K 2"]
    num_waypoints: Int[Array, " N"]
    loop: Bool[Array, " N"]
    waypoint: Int[Array, " N"]  # index of the waypoint being walked to
    # Navigation field per waypoint (jcrowd.pedestrians.scene); −1 without a layout (walk straight).
    field: Int[Array, "N K"]
    vx: Float[Array, " N"]  # simulated velocity (m/s) when the step avoids (else the spawn one)
    vz: Float[Array, " N"]
    radius: Float[Array, " N"]  # m, the body disc the crowd dynamics keeps apart
    # With the dynamics on: the agent stands, its phase waiting at a double-support phase
    # (jcrowd.crowd.following.follow_phase).
    stands: Bool[Array, " N"]
    # The stride warp of the planted feet (jcrowd.crowd.following.stride_warp: 1 walking, 0
    # standing or turning on the spot) and the heading the agent last stood still at.
    stride: Float[Array, " N"]
    stand_heading: Float[Array, " N"]
    # Level changes ease in (jcrowd.crowd.level_blend): the level drawn in the last frame and
    # the level being blended from (L: none), with the blend's seconds left.
    shown: Int[Array, " N"]
    blend_from: Int[Array, " N"]
    blend_left: Float[Array, " N"]
    # With the dynamics on, near agents' planted feet (jcrowd.motion.planting): per foot the pin
    # (x, z; the release offset while it swings), planted in the last frame, pinned by the toe.
    pin: Float[Array, "N 2 2"]
    planted: Bool[Array, "N 2"]
    pin_toe: Bool[Array, "N 2"]
    # The slot, not its agent (jcrowd.crowd.pool): time since the start (s, the same in every
    # slot), the source agents queued for it (reservoir rows, −1 padding; one −1 column
    # without sources), how many of them it has taken, and the agent it holds (−1: none yet).
    clock: Float[Array, " N"]
    queue: Int[Array, "N Q"]
    next_row: Int[Array, " N"]
    agent: Int[Array, " N"]
    # Devices whose blocks hold the agents interleaved (jcrowd.crowd.devices.shard_state): with K
    # > 1 position p of every array is agent agent_order(N, K)[p], not agent p.
    interleave: int = eqx.field(static=True, default=1)

    @property
    def num_agents(self) -> int:
        return int(self.x.shape[0])

    @property
    def position(self) -> Float[Array, "N 2"]:
        """Root positions ``(N, 2)`` as ``(x, z)`` rows (for recorders and tests)."""
        return jnp.stack([self.x, self.z], axis=1)

    @property
    def origin(self) -> Float[Array, "N 3"]:
        """``(x, z, heading)`` rows at each agent's current cycle start."""
        return jnp.stack([self.origin_x, self.origin_z, self.origin_heading], axis=1)

    def clip(self, which: str = "current") -> tuple[Array, Array, Array]:
        """``(control (N, d), mix (N, A), duration (N,))`` of the current or the next clip."""
        # A select, not a gather: XLA:CPU vectorizes the select, not the gather.
        first = (self.current == 0) if which == "current" else (self.current == 1)
        return (
            jnp.where(first[:, None], self.control[:, 0], self.control[:, 1]),
            jnp.where(first[:, None], self.mix[:, 0], self.mix[:, 1]),
            jnp.where(first, self.duration[:, 0], self.duration[:, 1]),
        )


class Frame(eqx.Module):
    """What a renderer (or a recorder) needs from one step, all with static shapes.

    ``slots[l]`` are agent ids (``N`` in unused slots), ``points[l]`` the world positions of
    every joint and End Site of those agents ``(C_l, J + E, 3)``. ``level`` is each agent's
    level (``L``: not synthesized); ``dots`` marks agents in view but not synthesized (below
    ``min_pixels`` or beyond the budget): a renderer draws them at their root. ``overflow``
    counts agents placed coarser than their distance allows (dots by budget included),
    ``deferred`` agents whose next-clip choice waits a step, ``crowding`` agents the
    dynamics' neighbour grid could not hold (0 when the step does not avoid), ``unblended``
    agents whose level change showed at once (:mod:`jcrowd.crowd.level_blend`).
    """

    slots: tuple[Int[Array, " C"], ...]
    valid: tuple[Bool[Array, " C"], ...]
    points: tuple[Float[Array, "C P 3"], ...]
    level: Int[Array, " N"]
    dots: Bool[Array, " N"]
    overflow: Int[Array, ""]
    deferred: Int[Array, ""]
    crowding: Int[Array, ""]
    unblended: Int[Array, ""]


def init_state(
    cm: CrowdModel,
    spawn: dict[str, Array],
    key: Array,
    min_reliability: float = 0.5,
    resting: bool = False,
) -> CrowdState:
    """The first state: every agent on its first clip at a random phase (``key``).

    Phases are uniform over the whole cycle, and agents already past its middle get their next
    clip here, as the step would have given it: the step then sees cycle ends at their steady
    rate from the first frame. (Phases drawn from the first half only would make every agent
    need a choice within the first half cycle — twice the steady rate — beyond the per-step
    ``refresh`` budget, and leave a backlog of deferred choices.)

    ``spawn`` holds ``position (N, 2)``, ``heading``, ``height`` (the skeleton's scale, not
    the stature: :func:`~jcrowd.crowd.simulate.prepare` divides by ``cm.body_height``), ``speed``
    ``(N,)``,
    ``waypoints (N, K, 2)``, ``num_waypoints (N,)``, ``loop (N,)``, and optionally ``radius``
    ``(N,)`` (default :data:`DEFAULT_RADIUS`), ``field`` ``(N, K)`` (each waypoint's
    navigation field, :func:`jcrowd.pedestrians.scene.build_scene`; default −1: none), and for a
    pool with sources (:mod:`jcrowd.crowd.pool`) ``queue`` ``(N, Q)``, ``agent`` and ``alive``
    ``(N,)`` (defaults: no queue, agent ``i`` in slot ``i``, everyone alive).

    ``resting``: the first velocity is 0, not the free speed along the heading. With the crowd
    dynamics on, an agent then waits for its first avoidance update: a far agent updating every
    ``far_every`` steps would otherwise walk its first steps blind, into its neighbours.
    """
    n = spawn["position"].shape[0]
    heading = jnp.asarray(spawn["heading"], jnp.float32)
    pos = jnp.asarray(spawn["position"], jnp.float32)
    waypoints = jnp.asarray(spawn["waypoints"], jnp.float32)
    height = jnp.asarray(spawn["height"], jnp.float32)
    speed = jnp.asarray(spawn["speed"], jnp.float32)
    clips = _initial_clips(cm, pos, heading, waypoints[:, 0], speed, height, key, min_reliability)
    return CrowdState(
        **clips,
        x=pos[:, 0],
        z=pos[:, 1],
        heading=heading,
        current=jnp.zeros(n, jnp.int32),
        # Copies: a donated state must not hold one buffer in two fields.
        origin_x=jnp.copy(pos[:, 0]),
        origin_z=jnp.copy(pos[:, 1]),
        origin_heading=jnp.copy(heading),
        level=jnp.zeros(n, jnp.int32),
        far_core=jnp.zeros((n, int(np.prod(cm.decoders.levels[-1].ranks))), jnp.float32),
        far_valid=jnp.zeros(n, bool),
        alive=jnp.asarray(spawn.get("alive", np.ones(n, bool)), bool),
        height=height,
        speed=speed,
        waypoints=waypoints,
        num_waypoints=jnp.asarray(spawn["num_waypoints"], jnp.int32),
        loop=jnp.asarray(spawn["loop"], bool),
        waypoint=jnp.zeros(n, jnp.int32),
        field=jnp.asarray(spawn.get("field", np.full(waypoints.shape[:2], -1)), jnp.int32),
        vx=0.0 * speed if resting else speed * jnp.sin(heading),
        vz=0.0 * speed if resting else speed * jnp.cos(heading),
        radius=jnp.asarray(spawn.get("radius", np.full(n, DEFAULT_RADIUS)), jnp.float32),
        stands=jnp.zeros(n, bool),
        stride=jnp.full(n, 0.0 if resting else 1.0, jnp.float32),
        stand_heading=jnp.copy(heading),
        shown=jnp.full(n, len(cm.decoders.levels), jnp.int32),
        blend_from=jnp.full(n, len(cm.decoders.levels), jnp.int32),
        blend_left=jnp.zeros(n, jnp.float32),
        pin=jnp.zeros((n, 2, 2), jnp.float32),
        planted=jnp.zeros((n, 2), bool),
        pin_toe=jnp.zeros((n, 2), bool),
        clock=jnp.zeros(n, jnp.float32),
        # One empty column without sources: a zero-width array split over devices comes back
        # from the compiled step with another sharding and would recompile it every call.
        queue=jnp.asarray(spawn.get("queue", np.full((n, 1), -1)), jnp.int32),
        next_row=jnp.zeros(n, jnp.int32),
        agent=jnp.asarray(spawn.get("agent", np.arange(n)), jnp.int32),
    )


def _initial_clips(
    cm: CrowdModel,
    pos: Array,
    heading: Array,
    target: Array,
    speed: Array,
    height: Array,
    key: Array,
    min_reliability: float,
) -> dict[str, Any]:
    """Each agent's first clip, its phase (uniform over the cycle, from ``key``) and, past the
    cycle's middle, its next clip: the clip-slot fields of :class:`CrowdState`."""
    n = pos.shape[0]
    # A zero-length "previous cycle" ending where the agent stands: next_clips then plans the
    # first cycle from the spawn pose.
    origin = jnp.concatenate([pos, heading[:, None]], axis=1)
    zero = jnp.zeros((n, cm.lo.shape[0]), jnp.float32)
    c, a, dur = _first_clips(cm, origin, zero, target, speed, height, min_reliability)
    last = float(cm.frames - 1)
    tau = jax.random.uniform(key, (n,), jnp.float32, 0.0, last)
    has_next = tau >= last / 2
    c2, a2, dur2 = _first_clips(cm, origin, c, target, speed, height, min_reliability)
    return {
        "tau": tau,
        "control": jnp.stack([c, jnp.where(has_next[:, None], c2, c)], axis=1),
        "mix": jnp.stack([a, jnp.where(has_next[:, None], a2, a)], axis=1),
        "duration": jnp.stack([dur, jnp.where(has_next, dur2, dur)], axis=1),
        "has_next": has_next,
    }


@eqx.filter_jit
def _first_clips(
    cm: CrowdModel,
    origin: Array,
    control: Array,
    target: Array,
    speed: Array,
    height: Array,
    min_reliability: float,
) -> tuple[Array, Array, Array]:
    return next_clips(cm, origin, control, target, speed, height, min_reliability)


def refresh_far_cores(
    cm: CrowdModel, state: CrowdState, safe: Int[Array, " C"], ok: Bool[Array, " C"]
) -> CrowdState:
    """Compute the coarsest-level core of each agent in the bucket whose cached one is stale.

    Stale: never computed, or the agent's clip changed since (the hand-over clears ``far_valid``).
    The issue's design — keep the clip, recompute its core only when the clip changes — for the
    level holding most synthesized agents (the coarsest; see
    :func:`jcrowd.crowd.stepping.default_capacities`), whose ``A × R_P R_T`` core product would
    otherwise run for each of them every step. Usually few are stale per step (an agent changes clip
    once per cycle), so at most an eighth of the bucket + 16 is compacted and computed; when more
    are (the first step, a camera cut) the whole bucket is — one branch runs, and either way every
    agent of the bucket leaves valid. The scatter into the ``(N, R)`` cache stays outside the branch
    so the cache is updated in place.
    """
    lv = cm.decoders.levels[-1]
    n, cap = state.num_agents, safe.shape[0]
    budget = min(cap, cap // 8 + 16)
    stale = ok & ~state.far_valid[safe]
    cores_of = jax.vmap(lambda i: clip_core(lv, state.mix[i, state.current[i]]).reshape(-1))

    def some() -> tuple[Array, Array]:
        k = first_true(stale, budget, cap)
        ids = jnp.where(k < cap, safe[jnp.minimum(k, cap - 1)], n)
        cores = cores_of(jnp.minimum(ids, n - 1))
        pad = cap - budget
        return jnp.pad(ids, (0, pad), constant_values=n), jnp.pad(cores, ((0, pad), (0, 0)))

    def every() -> tuple[Array, Array]:
        return jnp.where(ok, safe, n), cores_of(safe)

    ids, cores = jax.lax.cond(jnp.sum(stale) <= budget, some, every)
    far_core = state.far_core.at[ids].set(cores, mode="drop")
    far_valid = state.far_valid.at[jnp.where(ok, safe, n)].set(True, mode="drop")
    return eqx.tree_at(lambda s: (s.far_core, s.far_valid), state, (far_core, far_valid))
