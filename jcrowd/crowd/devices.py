"""The crowd split over devices: one block of agents per device (DESIGN §5).

:func:`shard_state` places a state's agent axis over every device of every process, agents
interleaved (:func:`agent_order`); :func:`split_step` runs the step on each block with
:func:`per_device_config`'s share of every budget; :func:`in_agent_order` reads a per-agent
array back in agent order. One device: everything is unchanged.
"""

from __future__ import annotations

import functools
from dataclasses import replace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jcrowd.crowd.clips import CrowdModel
from jcrowd.crowd.lod import CameraView
from jcrowd.crowd.pool import Pool
from jcrowd.crowd.state import CrowdState, Frame, StepConfig
from jcrowd.crowd.stepping import step
from jcrowd.errors import ScenarioError
from jcrowd.pedestrians.world import World

__all__ = [
    "agent_mesh",
    "agent_order",
    "check_divisible",
    "in_agent_order",
    "on_all_devices",
    "per_device_config",
    "shard_state",
    "split_step",
]


def on_all_devices(tree: Any) -> Any:
    """``tree`` replicated on every device of a one-process multi-device run (unchanged on one
    device, and with several processes, where JAX places the replicated inputs itself).

    The split step takes the camera and ``dt`` replicated; arrays left on one device are copied
    to the others by JAX's slow argument path at every call, a fixed cost per step that weighs
    most in small crowds. Placing them once removes it.
    """
    if len(jax.devices()) == 1 or jax.process_count() > 1:
        return tree
    from jax.sharding import NamedSharding
    from jax.sharding import PartitionSpec as P

    return jax.device_put(tree, NamedSharding(agent_mesh(), P()))


def agent_mesh() -> Any:
    """The one-axis mesh ``agents`` over every device of every process (``jax.devices()``
    order): the state's agent axis is split over it (:func:`shard_state`) and the step runs one
    block per device on it."""
    from jax.sharding import Mesh

    return Mesh(np.array(jax.devices()), ("agents",))


@functools.cache
def agent_order(agents: int, devices: int) -> np.ndarray:
    """The agent at each position of a state split over ``devices`` (:func:`shard_state`):
    device ``k``'s block holds agents ``k, k + K, k + 2K, …``.

    Interleaved rather than contiguous because the LOD budget is per device
    (:func:`per_device_config`) and scenarios spawn group by group: with contiguous blocks a
    group near the camera would sit in one device's block and overflow its share of the near
    levels while the other device's share went unused.
    """
    check_divisible(agents, devices)
    per = agents // devices
    order = (np.arange(per)[None, :] * devices + np.arange(devices)[:, None]).reshape(-1)
    order.flags.writeable = False  # cached: built once per (agents, devices), not per read-back
    return order


def in_agent_order(x: Any, state: CrowdState) -> np.ndarray:
    """A host copy of a per-agent array of ``state`` (or of a frame stepped from it: ``level``,
    ``dots``), agent axis first, put in agent order."""
    host = np.asarray(x)
    if state.interleave == 1:
        return host
    out = np.empty_like(host)
    out[agent_order(host.shape[0], state.interleave)] = host
    return out


def check_divisible(agents: int, devices: int) -> None:
    """The agent axis splits into equal blocks, one per device."""
    if agents % devices:
        raise ScenarioError(
            f"sharding: expected an agent count divisible by the {devices} devices, found {agents}"
        )


def per_device_config(config: StepConfig, devices: int) -> StepConfig:
    """One device's share of the step's budgets: each capacity, ``refresh`` and
    ``krige_budget`` divided by the device count, rounded up (capacities to at least one
    chunk)."""
    if devices == 1:
        return config

    def share(v: int, floor: int = 1) -> int:
        return max(-(-v // devices), floor) if v > 0 else v

    return replace(
        config,
        capacities=tuple(share(c, min(c, config.chunk)) for c in config.capacities),
        refresh=share(config.refresh),
        krige_budget=share(config.krige_budget),
    )


def _with_crowd_counters(frame: Frame, gathered: list[jax.Array]) -> Frame:
    """One device's frame with the crowd's counters: overflow, deferred clips and unblended
    changes summed over the devices, the crowding (every device fills the same grid) the
    largest. The four cross in one collective, ordered after the positions' gather."""
    counters = jnp.stack([frame.overflow, frame.deferred, frame.crowding, frame.unblended]).astype(
        jnp.int32
    )
    if gathered:
        counters, _ = jax.lax.optimization_barrier((counters, gathered))
    every = jax.lax.all_gather(counters, "agents")  # (K, 4)
    return replace(
        frame,
        overflow=every[:, 0].sum().astype(frame.overflow.dtype),
        deferred=every[:, 1].sum().astype(frame.deferred.dtype),
        crowding=every[:, 2].max().astype(frame.crowding.dtype),
        unblended=every[:, 3].sum().astype(frame.unblended.dtype),
    )


def split_step(
    crowd: CrowdModel,
    config: StepConfig,
    devices: list[Any],
    world: World | None = None,
    pool: Pool | None = None,
) -> Any:
    """The step over several devices: each runs it on its own block of agents.

    ``shard_map`` over a one-axis mesh ``agents`` (the mesh :func:`shard_state` places the state
    on): device ``k`` steps its block — agents ``k, k + K, …`` (:func:`agent_order`) — with
    :func:`per_device_config`'s share of every budget, so no data moves between devices inside
    a step except the two counters (summed). The LOD budget is therefore per device: a device
    whose block holds more near agents than its share of a level's capacity places the excess
    coarser even if another device has room (interleaved blocks sample the whole crowd, so
    this rarely binds). A frame's level-``l`` bucket is the devices' buckets one after the
    other (agent ids; each block's valid slots lead within it).

    Why not one global program partitioned by XLA: the step's compactions (``nonzero``,
    ``top_k``, scatters over the agent axis) then need the whole axis on every device, so
    every compaction moves the axis between devices and the partitioned step is slower than
    the same step on one device; split like this, each device compacts only its own block
    (``bench/step.py --cpu-devices K`` times the split step).
    """
    from jax import shard_map
    from jax.sharding import PartitionSpec as P

    k = len(devices)
    mesh = agent_mesh()
    local_config = per_device_config(config, k)

    def local(state: CrowdState, view: CameraView, dt: jax.Array) -> tuple[CrowdState, Frame]:
        gathered: list[jax.Array] = []

        def gather(block: jax.Array) -> jax.Array:
            gathered.append(jax.lax.all_gather(block, "agents", tiled=True))
            return gathered[-1]

        n_local = state.num_agents
        device = jax.lax.axis_index("agents")
        # The block's rows in the gathered crowd: device k's block follows devices 0 … k − 1.
        rows = device * n_local + jnp.arange(n_local, dtype=jnp.int32)
        new, frame = step(crowd, local_config, state, view, dt, gather, rows, world, pool)
        slots = tuple(  # local slot s holds agent s·K + k (agent_order)
            jnp.where(ok, s * k + device, n_local * k).astype(s.dtype)
            for s, ok in zip(frame.slots, frame.valid, strict=True)
        )
        return new, _with_crowd_counters(replace(frame, slots=slots), gathered)

    agents, same = P("agents"), P()
    nlev = len(config.capacities)
    per_level = (agents,) * nlev
    frame_spec = Frame(per_level, per_level, per_level, agents, agents, same, same, same, same)  # type: ignore[arg-type]
    mapped = shard_map(
        local,
        mesh=mesh,
        in_specs=(agents, same, same),
        out_specs=(agents, frame_spec),
        check_vma=False,
    )

    def run(state: CrowdState, view: CameraView, dt: jax.Array) -> tuple[CrowdState, Frame]:
        check_divisible(state.num_agents, k)
        if state.interleave != k:
            raise ScenarioError(
                f"sharding: expected a state placed on the {k} devices by "
                f"jcrowd.crowd.devices.shard_state (agents interleaved over them), found one laid "
                f"out for {state.interleave} device(s)"
            )
        return mapped(state, view, dt)

    return run


def shard_state(state: CrowdState) -> CrowdState:
    """Place the state with its agent axis split over every device of every process.

    One device: unchanged. Several (``XLA_FLAGS=--xla_force_host_platform_device_count=K`` on
    CPU, several GPUs, or several processes after ``jax.distributed.initialize``): a one-axis
    mesh ``agents`` over ``jax.devices()``, device ``k`` holding agents ``k, k + K, …``
    (:func:`agent_order`; the state's ``interleave`` records ``K``, and per-agent arrays read
    back from it or from its frames go through :func:`in_agent_order`; frames' slot ids are
    agent ids). Each process feeds its own devices' blocks
    (``jax.make_array_from_process_local_data``). Every process builds the same initial state
    (spawning is deterministic from the seed), so no data is sent at start.
    """
    from jax.sharding import NamedSharding, PartitionSpec

    devices = jax.devices()
    if len(devices) == 1:
        return state
    n = state.num_agents
    order = agent_order(n, len(devices))
    sharding = NamedSharding(agent_mesh(), PartitionSpec("agents"))
    procs, me = jax.process_count(), jax.process_index()
    per = n // procs

    def place(x: jax.Array) -> jax.Array:
        host = np.asarray(x)[order]
        if procs == 1:
            return jax.device_put(host, sharding)
        return jax.make_array_from_process_local_data(
            sharding, host[me * per : (me + 1) * per], host.shape
        )

    return replace(jax.tree.map(place, state), interleave=len(devices))
