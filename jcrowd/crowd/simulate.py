"""A scenario and a motion model → a ready-to-step crowd (pure; files are read elsewhere).

:func:`prepare` turns a :class:`~jcrowd.scenario.schema.Scenario` into the three things the step
needs — the :class:`~jcrowd.crowd.clips.CrowdModel`, a static
:class:`~jcrowd.crowd.state.StepConfig` and the first :class:`~jcrowd.crowd.state.CrowdState`
— and :meth:`Simulation.view_at` gives the camera at a time. The step itself is compiled once per
:class:`Simulation` (:meth:`Simulation.compiled`).

LOD settings and the model's level count: a scenario lists distance thresholds independently
of the model it runs with. The first ``L − 1`` thresholds are used for an ``L``-level model;
if the scenario lists fewer, the missing ones continue every 20 m past the last. Capacities,
when given, must have one entry per model level (``lod.capacities``). With
``importance = "pixels"`` agents are ranked by projected height; levels still come from the
distance thresholds.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import jax
import jax.numpy as jnp
import numpy as np

from jcrowd.crowd.clips import CrowdModel, build_crowd_model
from jcrowd.crowd.devices import on_all_devices, split_step
from jcrowd.crowd.lod import CameraView
from jcrowd.crowd.pool import Pool, expected_stay, plan_pool
from jcrowd.crowd.state import CrowdState, Frame, StepConfig, init_state
from jcrowd.crowd.stepping import default_capacities, step
from jcrowd.errors import ScenarioError
from jcrowd.model.motion_model import MotionModel
from jcrowd.pedestrians.blocking import OneStepAtATime
from jcrowd.pedestrians.neighbours import GridSpec, grid_spec
from jcrowd.pedestrians.scene import build_scene, field_ids
from jcrowd.pedestrians.world import World
from jcrowd.scenario.camera import camera_at
from jcrowd.scenario.schema import Scenario
from jcrowd.scenario.spawning import Spawn, spawn, spawn_sources

__all__ = [
    "KSteps",
    "Record",
    "Simulation",
    "prepare",
    "record_shapes",
    "step_compiler_options",
    "thresholds_for",
]


@functools.cache
def step_compiler_options() -> dict[str, Any]:
    """XLA options the step is compiled with: on CPU, copy insertion with region analysis.

    Without it XLA:CPU copies every donated state buffer the step updates before writing it
    (10 fields, e.g. ``copy(%state_heading)`` in the compiled HLO), because the buffer has other
    readers it cannot order, so every step moves those fields through memory twice; with it
    those copies go and results are unchanged (the test suite runs with it). An XLA or a JAX
    without the option (``No such compile option``, or no ``compiler_options`` argument)
    compiles without it; found once per process by compiling a one-element function.
    """
    if jax.default_backend() != "cpu":
        return {}
    options: dict[str, Any] = {"xla_cpu_copy_insertion_use_region_analysis": True}
    try:
        jax.jit(lambda x: x + 1, compiler_options=options)(jnp.zeros(1, jnp.float32))
    except (TypeError, jax.errors.JaxRuntimeError):
        return {}
    return options


def thresholds_for(thresholds: tuple[float, ...], levels: int) -> tuple[float, ...]:
    """The first ``levels − 1`` thresholds, continued every 20 m if there are too few."""
    out = list(thresholds[: levels - 1])
    while len(out) < levels - 1:
        out.append((out[-1] if out else 10.0) + 20.0)
    return tuple(float(t) for t in out)


@dataclass(frozen=True)
class Simulation:
    """Everything fixed for a run: the prepared model, the step settings, the scenario."""

    crowd: CrowdModel
    config: StepConfig
    scenario: Scenario
    spawn: Spawn
    world: World | None = None
    pool: Pool | None = None

    @property
    def num_agents(self) -> int:
        return self.spawn.num_agents

    @property
    def dt(self) -> float:
        return 1.0 / self.scenario.fps

    @property
    def steps(self) -> int:
        return max(1, round(self.scenario.duration_s * self.scenario.fps))

    def view_at(self, t: float) -> CameraView:
        """The scenario camera at time ``t`` (s) as traced arrays, already on every device the
        step runs on (:func:`on_all_devices`); one shared object for a fixed camera."""
        if len(self.scenario.camera.keys) == 1:
            return self._fixed_view
        return self._view(t)

    @functools.cached_property
    def _fixed_view(self) -> CameraView:
        return self._view(0.0)

    @functools.cached_property
    def dt_array(self) -> jax.Array:
        """``dt`` as a float32 array on every device the step runs on: pass it to the compiled
        step (a Python float is converted and copied to each device at every call)."""
        return on_all_devices(jnp.asarray(self.dt, jnp.float32))

    def _view(self, t: float) -> CameraView:
        cam = self.scenario.camera
        eye, target = camera_at(cam, t)
        return on_all_devices(
            CameraView(
                eye=jnp.asarray(eye, jnp.float32),
                target=jnp.asarray(target, jnp.float32),
                fov_deg=jnp.asarray(cam.fov_deg, jnp.float32),
                aspect=jnp.asarray(cam.width / cam.height, jnp.float32),
                height_px=jnp.asarray(cam.height, jnp.float32),
            )
        )

    def views(self, first: int, steps: int) -> CameraView:
        """The scenario camera at frames ``first … first + steps − 1`` (times ``i · dt``),
        stacked on a leading axis of ``steps``, as :meth:`compiled_steps` takes them; on every
        device the step runs on."""
        cam = self.scenario.camera
        keys = [camera_at(cam, (first + i) * self.dt) for i in range(steps)]
        eyes, targets = [e for e, _ in keys], [t for _, t in keys]
        const = np.ones(steps, np.float32)
        return on_all_devices(
            CameraView(
                eye=jnp.asarray(np.stack(eyes), jnp.float32),
                target=jnp.asarray(np.stack(targets), jnp.float32),
                fov_deg=jnp.asarray(cam.fov_deg * const),
                aspect=jnp.asarray(cam.width / cam.height * const),
                height_px=jnp.asarray(cam.height * const),
            )
        )

    def _one_step(self) -> Callable[[CrowdState, CameraView, jax.Array], tuple[CrowdState, Frame]]:
        """The step with the model and settings closed over, split over the devices if there
        are several (:func:`~jcrowd.crowd.devices.split_step`)."""
        crowd, config, world, pool = self.crowd, self.config, self.world, self.pool
        devices = jax.devices()
        if len(devices) > 1:
            return cast(Any, split_step(crowd, config, devices, world, pool))

        def one(state: CrowdState, view: CameraView, dt: jax.Array) -> tuple[CrowdState, Frame]:
            return step(crowd, config, state, view, dt, world=world, pool=pool)

        return one

    def _kept(self, key: tuple[Any, ...], make: Callable[[], Any]) -> Any:
        """``make()`` once per ``key`` and device set, kept with the simulation (a jitted
        function keeps its traces and compilations: calling again reuses them)."""
        kept = self.__dict__.setdefault("_kept_fns", {})
        full = (*key, tuple(jax.devices()))
        if full not in kept:
            kept[full] = make()
        return kept[full]

    def _traced_step(
        self,
    ) -> Callable[[CrowdState, CameraView, jax.Array], tuple[CrowdState, Frame]]:
        """:meth:`_one_step` under one ``jit`` (:meth:`_kept`): inside the compiled loops and
        :func:`record_shapes` it is traced once per argument shapes, where tracing the plain
        function each time takes seconds."""
        return self._kept(("traced",), lambda: jax.jit(self._one_step()))

    def compiled(self, donate: bool = True) -> Any:
        """``jit(step)`` with the model and settings closed over: ``(state, view, dt) → …``.

        With ``donate`` the input state's buffers are given to the output (XLA updates the
        fields a step changes in place instead of copying the whole state, ~70 MB at 100k
        agents): the state passed in must not be used again; copy it first if it must
        (``jax.tree.map(jnp.copy, state)``).

        One jitted function per simulation, ``donate`` and device set: calling this again
        returns it, with what it compiled.
        """
        return self._kept(("compiled", donate), lambda: _jit(self._one_step(), donate))

    def compiled_steps(self, steps: int, record: Record, donate: bool = True) -> Any:
        """Up to ``steps`` frames in one compiled call: ``(state, views, dt, count) →
        (state, records)``.

        The call runs ``count`` single steps (an int32 array, at most ``steps``: a different
        count does not recompile) in one compiled loop, frame ``i`` with camera ``views[i]``
        (:meth:`views`), and returns the state after them and, in buffers with a leading axis
        of ``steps``, ``record(state, view, frame)`` of each frame: what the caller keeps of
        the state at the frame's start and of the frame the step returns (``record`` is
        traced: it selects and may reduce, it must not read back to the host). Rows past
        ``count`` hold what an earlier call wrote there (zeros at first). The states and
        records equal ``count`` calls of :meth:`compiled` (the same step, tested bit for bit,
        on one device and split over several).

        Why: each call of the compiled step is a Python-level dispatch of the whole state
        (about 130 arrays) plus, on several devices, a wait for the step to finish; the loop
        pays that once per ``steps`` frames. The buffers are ``steps`` times one frame's
        record (:func:`record_shapes`), so a caller recording large frames picks a smaller
        ``steps``; they are reused from call to call (:class:`KSteps`): a call's records are
        valid until the next call.
        """
        one = self._traced_step()

        def advance(s: CrowdState, view: CameraView, dt: jax.Array) -> tuple[CrowdState, Any]:
            new, frame = one(s, view, dt)
            return new, record(s, view, frame)

        def run(
            state: CrowdState, buffers: Any, views: CameraView, dt: jax.Array, count: jax.Array
        ) -> tuple[CrowdState, Any]:
            def body(i: jax.Array, carry: tuple[CrowdState, Any]) -> tuple[CrowdState, Any]:
                s, buf = carry
                new, out = advance(s, jax.tree.map(lambda v: v[i], views), dt)
                put = functools.partial(jax.lax.dynamic_update_index_in_dim, index=i, axis=0)
                return new, jax.tree.map(put, buf, out)

            return jax.lax.fori_loop(0, jnp.minimum(count, steps), body, (state, buffers))

        return KSteps(_jit(run, donate, (1,)), advance, steps)


class KSteps:
    """The compiled loop of :meth:`Simulation.compiled_steps`:
    ``(state, views, dt, count) → (state, records)``.

    The records' buffers are allocated by the first call, laid out over the devices as the
    compiled loop returns them, and handed back to the loop at the next call (donated), so a
    call neither allocates nor clears them: a call's records are valid until the next call
    (read them to the host first; arrays of an earlier call are deleted).
    """

    def __init__(self, jitted: Any, advance: Callable[..., Any], steps: int) -> None:
        self._jitted = jitted
        self._advance = advance
        self._steps = steps
        self._buffers: Any = None

    def _fresh(self, state: CrowdState, views: CameraView, dt: jax.Array, count: Any) -> Any:
        """Zeroed buffers laid out as the compiled loop returns its records (so the next
        call, which takes the records back, has the first call's signature: no second
        compilation). One device: left uncommitted, as the step's own outputs are from an
        uncommitted state."""
        first = jax.tree.map(lambda v: v[0], views)
        shapes = jax.eval_shape(self._advance, state, first, dt)[1]  # the step's trace reused
        spec = jax.tree.map(
            lambda a: jax.ShapeDtypeStruct((self._steps, *a.shape), a.dtype), shapes
        )

        def zeros() -> Any:
            return jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype), spec)

        if len(jax.devices()) == 1:
            return jax.jit(zeros)()
        compiled = self._jitted.lower(state, spec, views, dt, count).compile()
        return jax.jit(zeros, out_shardings=compiled.output_shardings[1])()

    def __call__(
        self, state: CrowdState, views: CameraView, dt: jax.Array, count: jax.Array
    ) -> tuple[CrowdState, Any]:
        buffers = self._buffers
        if buffers is None:
            buffers = self._fresh(state, views, dt, count)
        self._buffers = None
        state, records = self._jitted(state, buffers, views, dt, count)
        self._buffers = records
        return state, records

    def _cache_size(self) -> int:
        return int(self._jitted._cache_size())


Record = Callable[[CrowdState, CameraView, Frame], Any]
"""What :meth:`Simulation.compiled_steps` keeps of each frame: ``record(state at the frame's
start, camera, frame) → pytree of arrays``."""


def record_shapes(sim: Simulation, state: CrowdState, record: Record) -> Any:
    """The shapes and dtypes (``jax.ShapeDtypeStruct``) ``record`` returns for one frame of
    ``sim`` from ``state``; nothing runs."""
    one = sim._traced_step()

    def frame(s: CrowdState, view: CameraView, dt: jax.Array) -> Any:
        return record(s, view, one(s, view, dt)[1])

    return jax.eval_shape(frame, state, sim.view_at(0.0), sim.dt_array)


def _jit(run: Callable[..., Any], donate: bool, also: tuple[int, ...] = ()) -> Any:
    """``run`` compiled with the step's options (:func:`step_compiler_options`), donating its
    first argument if ``donate`` and the arguments ``also``; on several devices, returning only
    once every device is done (:class:`~jcrowd.pedestrians.blocking.OneStepAtATime`)."""
    options = step_compiler_options()
    donated = ((0,) if donate else ()) + also
    if options:
        jitted = jax.jit(run, donate_argnums=donated, compiler_options=options)
    else:
        jitted = jax.jit(run, donate_argnums=donated)
    return jitted if len(jax.devices()) == 1 else OneStepAtATime(jitted)


NEIGHBOUR_CELL_M = 1.6
"""Cell of the dynamics' neighbour grid: the 3 × 3 cells round an agent reach 1.6 m at least,
about where the collision-free speed model's speed stops depending on the gap ahead
(``ℓ + v0·T`` = 0.4 + 1.34 m with its defaults)."""

NEIGHBOUR_DENSITY = 4.0
"""Agents per m² a neighbour cell is sized for (× 1.5 headroom): beyond it the frame counts
``crowding``."""


def _neighbour_grid(scenario: Scenario) -> GridSpec:
    """The dynamics' neighbour grid over the ground, with a cell of margin."""
    lo, hi = scenario.ground.bounds()
    m = NEIGHBOUR_CELL_M
    return grid_spec(
        (lo[0] - m, lo[1] - m), (hi[0] + m, hi[1] + m), m, max_density=NEIGHBOUR_DENSITY
    )


def prepare(scenario: Scenario, model: MotionModel) -> tuple[Simulation, CrowdState]:
    """Build the simulation and its first state (deterministic from ``scenario.seed``).

    A layout (obstacles, walls, walkable area) becomes the step's
    :class:`~jcrowd.pedestrians.world.World`: navigation fields per waypoint and the walls
    (:func:`~jcrowd.pedestrians.scene.build_scene`).

    Raises:
        ScenarioError: settings that do not fit the model, or a layout whose navigation fields
            are too large or cannot reach a target.
    """
    crowd = build_crowd_model(model)
    levels = len(model.levels)
    lod = scenario.lod
    sp = spawn(scenario)
    if scenario.dynamics.avoid:
        sp = _in_grid_order(sp, _neighbour_grid(scenario))
    sources, times = spawn_sources(scenario)
    queue = None
    if len(times):
        stay = [
            expected_stay(s.position, s.waypoints, s.num_waypoints, s.loop, s.speed)
            for s in (sp, sources)
        ]
        queue, slot_group = plan_pool(stay[0], sp.group, times, stay[1], sources.group)
        sp = _slots(sp, sources, queue, slot_group)
    agents = sp.num_agents
    if lod.capacities is not None and len(lod.capacities) != levels:
        raise ScenarioError(
            f"{scenario.source}: lod.capacities: expected {levels} integers (one per level of "
            f"the model), found {list(lod.capacities)}"
        )
    caps = lod.capacities if lod.capacities is not None else default_capacities(agents, levels)
    caps = tuple(min(int(c), agents) for c in caps)
    # Clip choices per step: every agent ends at most one cycle per shortest cycle, so
    # N / (fps · shortest cycle) choices per step keep up with any mix of clips (+64 slack);
    # the kriged ones are bounded by the agents that can be synthesized at once.
    steps_per_cycle = scenario.fps * crowd.shortest_cycle_seconds
    config = StepConfig(
        capacities=caps,
        refresh=min(agents, math.ceil(agents / steps_per_cycle) + 64),
        krige_budget=math.ceil(sum(caps) / steps_per_cycle) + 64,
        thresholds=thresholds_for(lod.thresholds_m, levels),
        hysteresis=lod.hysteresis_m,
        blend_max_level=lod.blend_max_level,
        importance=lod.screen,
        min_pixels=lod.min_pixels,
        plant_feet=lod.plant_feet,
        avoid=scenario.dynamics.avoid,
        grid=_neighbour_grid(scenario) if scenario.dynamics.avoid else None,
        far_every=scenario.dynamics.far_every,
        anticipate=scenario.dynamics.model == "anticipation",
        avoidance=scenario.dynamics.avoidance,
    )
    config.check(levels)
    world = None
    if not scenario.layout.empty:
        world, _ = build_scene(scenario, sp, cast(GridSpec, config.grid), config.reach)
    key_slots, key_sources = jax.random.split(jax.random.key(scenario.seed))
    arrays = _state_arrays(scenario, sp, world is not None, model.body_height)
    pool = None
    if queue is not None:
        n0 = scenario.num_agents
        arrays["queue"] = queue
        arrays["alive"] = np.arange(agents) < n0
        arrays["agent"] = np.where(np.arange(agents) < n0, np.arange(agents), -1)
        reservoir = init_state(
            crowd,
            _state_arrays(scenario, sources, world is not None, model.body_height),
            key_sources,
            resting=config.avoid,
        )
        per_step = np.bincount(np.floor(times * scenario.fps).astype(np.int64)).max()
        pool = Pool(reservoir, jnp.asarray(times, jnp.float32), n0, int(2 * per_step + 8))
    key = key_slots if pool is not None else jax.random.key(scenario.seed)
    state = init_state(crowd, arrays, key, resting=config.avoid)
    return Simulation(crowd, config, scenario, sp, world, pool), state


def _in_grid_order(sp: Spawn, grid: GridSpec) -> Spawn:
    """The spawned agents renumbered within each group in the neighbour grid's cell order
    (stable; groups keep their order and their agents stay one run of ids).

    With the dynamics on, the step reads the crowd in cell order every step (the grid's
    counting sort, the candidates' rows) and writes per-cell tables: with ids in spawn order
    those reads jump over the whole crowd, with ids in cell order they run nearly in sequence.
    The order holds at the start and loosens as people walk (nothing re-sorts the crowd later).
    """
    ix = np.clip(np.floor((sp.position[:, 0] - grid.origin[0]) / grid.cell), 0, grid.shape[0] - 1)
    iz = np.clip(np.floor((sp.position[:, 1] - grid.origin[1]) / grid.cell), 0, grid.shape[1] - 1)
    cell = ix.astype(np.int64) * grid.shape[1] + iz.astype(np.int64)
    order = np.lexsort((cell, sp.group))  # by group, then cell; ties keep spawn order
    return Spawn(**{f.name: getattr(sp, f.name)[order] for f in dataclasses.fields(Spawn)})


def _state_arrays(
    scenario: Scenario, sp: Spawn, fields: bool, body_height: float
) -> dict[str, Any]:
    """The spawn's columns as :func:`init_state` takes them (device arrays): the statures
    become skeleton scales (``height / body_height``)."""
    arrays: dict[str, Any] = {
        "position": sp.position,
        "heading": sp.heading,
        "height": sp.height / body_height,
        "speed": sp.speed,
        "waypoints": sp.waypoints,
        "num_waypoints": sp.num_waypoints,
        "loop": sp.loop,
        "radius": np.full(sp.num_agents, scenario.dynamics.radius, np.float32),
    }
    if fields:
        arrays["field"] = field_ids(scenario, sp)
    return {k: jnp.asarray(np.asarray(v)) for k, v in arrays.items()}


def _slots(sp: Spawn, sources: Spawn, queue: np.ndarray, slot_group: np.ndarray) -> Spawn:
    """The pool's slots at t = 0: the agents placed then, and each further slot filled with its
    first queued source agent (not alive until it appears; padding slots with the first source
    agent, never alive)."""
    extra = queue[sp.num_agents :, 0]
    rows = np.where(extra >= 0, extra, 0)
    cols = {
        f.name: np.concatenate([getattr(sp, f.name), getattr(sources, f.name)[rows]])
        for f in dataclasses.fields(Spawn)
    }
    cols["group"] = np.concatenate([sp.group, slot_group[sp.num_agents :]]).astype(np.int32)
    return Spawn(**cols)
