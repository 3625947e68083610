"""Differentiable rollouts of the pedestrian model and smooth surrogates of what they yield.

:func:`rollout` maps the model's continuous parameters — the avoidance model's
(:class:`~jcrowd.pedestrians.params.AvoidanceParams`), every agent's desired speed, the wall
and obstacle segments, door widths and a source's rate (:class:`RolloutParams`) — to a
trajectory that ``jax.grad`` differentiates. It steps
:func:`~jcrowd.pedestrians.step.pedestrian_step` itself, so the rollout is the simulator's
dynamics, not a copy of them; levels of detail and clips are not in it.

Readings taken:

- **Hard structure is fixed by the forward pass.** The neighbour grid, which neighbour or wall
  is nearest ahead (Eq. 3), the wall the desire slides along and the removal of arrived agents
  carry no gradient: ``jax.grad`` is the derivative of the smooth piece the forward run lies on,
  the true derivative almost everywhere. A soft "alive" weight would change the model itself.
  Put the surrogates' exit lines upstream of the targets so removal never reaches them.
- **Geometry.** Gradients reach walls and obstacles through the wall terms of Eqs. (3)–(4); the
  navigation fields are built on the host and do not move with them (:func:`every_wall` makes
  every wall a candidate of every cell for geometry moved far from the built one).
- **Doors and sources.** :func:`~jcrowd.rollouts.doors.door_walls` opens a :class:`Door` to a
  width about its centre. A source's agent of rank ``q_i`` leaves its start at ``t_i = q_i /
  rate``, its desired speed weighted by ``e_i(t) = σ((t − t_i)/τ_e)``, ``τ_e`` = 0.15 s (a
  0.6 s rise, about a social-force model's relaxation time).
- **Limits.** Where people press into each other (a jam before a door) the pathwise derivative
  grows about ×1.4 per step; below capacity it grows about linearly and equals central
  differences (``tests/test_grad_dynamics.py``). For a jam, differentiate short horizons.
- **Memory.** Blocks of ``⌈√steps⌉`` steps under ``jax.checkpoint``, each step inside too: the
  backward pass keeps ``steps/block + block`` states of about 30 B per agent, for two extra
  forward passes (``bench/grad_memory.py``).

Surrogates (temperatures are arguments): :func:`soft_exit_count`, agents past an exit line by
time ``T``, ``Σ_i σ(((x_i(T) − p)·n)/τ_c)`` with ``τ_c`` = 0.1 m; :func:`mean_travel_time`,
``(1/N) Σ_i Σ_{k<K} Δt e_i(t_k) (1 − σ(((x_i(t_k) − p)·n)/τ_c))``, each agent's time from
entering to passing the line censored at ``T``. docs/design/rollouts.md has the measurements
behind these readings. Positions ``[x, z]`` in metres, time in seconds; every floating array
is computed at the precision of ``params.speed``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.pedestrians.step import Pedestrians, pedestrian_step
from jcrowd.pedestrians.world import World
from jcrowd.rollouts.doors import Door, door_walls

__all__ = [
    "COUNT_TEMPERATURE",
    "ENTRY_TEMPERATURE",
    "RolloutParams",
    "RolloutSetup",
    "Trajectory",
    "entry_weights",
    "initial_params",
    "mean_travel_time",
    "rollout",
    "soft_exit_count",
]

ENTRY_TEMPERATURE = 0.15
"""``τ_e`` (s) of the soft entry ``σ((t − t_i)/τ_e)`` (module docstring)."""

COUNT_TEMPERATURE = 0.1
"""``τ_c`` (m) of the soft exit indicator ``σ(((x − p)·n)/τ_c)`` (module docstring)."""


class RolloutParams(eqx.Module):
    """The continuous parameters a rollout is differentiated in.

    Attributes:
        avoidance: the avoidance model's parameters.
        speed: ``(N,)`` each agent's desired (free) speed ``v0`` (m/s).
        walls: ``(S, 2, 2)`` wall and obstacle segments ``[[x, z], [x, z]]`` (m). A vertex
            where two segments meet is two entries here: move both, as :func:`door_walls`
            does (at a corner the two walls press alike and the slide picks one; moving one
            end alone splits the corner, and the derivative there is one-sided).
        door_width: ``(D,)`` the width (m) of each of the setup's doors.
        rate: the source's rate (agents/s).
    """

    avoidance: AvoidanceParams
    speed: Float[Array, " N"]
    walls: Float[Array, "S 2 2"]
    door_width: Float[Array, " D"]
    rate: Float[Array, ""] = eqx.field(converter=jnp.asarray)


class RolloutSetup(eqx.Module):
    """What a rollout holds fixed: the scene, the start, the source's order and the time grid.

    Attributes:
        world: the scene (:func:`~jcrowd.pedestrians.world.build_world`); its walls are replaced
            by ``params.walls``.
        peds: the agents at ``t = 0``; their ``speed`` is replaced by ``params.speed``. With
            ``velocity`` the step relaxes over the reaction time (and anticipates with
            ``anticipate``), as in the simulator.
        entry_rank: ``(N,)`` agent ``i`` leaves the source at ``rank_i / rate`` seconds
            (module docstring); ``None``: everyone walks from the start.
        steps: steps of ``dt`` seconds.
        doors: the openings whose widths ``params.door_width`` sets.
        entry_temperature: ``τ_e`` (s) of the soft entry.
        checkpoint: blocks of steps under ``jax.checkpoint`` (else every step's residuals are
            kept for the backward pass).
        block: steps per checkpointed block; 0: ``⌈√steps⌉``.
        adjoint_decay: ``γ`` in ``(0, 1]``: the backward pass multiplies the cotangent of the
            positions and velocities by ``γ`` at every step, so a parameter's effect through
            ``k`` steps of the dynamics counts ``γ^k`` (truncated backpropagation through
            time; the forward pass is unchanged). 1: the exact gradient. Below 1 for jams,
            where the exact one grows about ×1.4 per step ("Limits"): a biased, bounded
            gradient (:mod:`jcrowd.rollouts.layout_opt` measures what it is worth).
    """

    world: World
    peds: Pedestrians
    entry_rank: Float[Array, " N"] | None = None
    steps: int = eqx.field(static=True, default=100)
    dt: float = eqx.field(static=True, default=1.0 / 30.0)
    doors: tuple[Door, ...] = eqx.field(static=True, default=())
    entry_temperature: float = eqx.field(static=True, default=ENTRY_TEMPERATURE)
    checkpoint: bool = eqx.field(static=True, default=True)
    block: int = eqx.field(static=True, default=0)
    adjoint_decay: float = eqx.field(static=True, default=1.0)

    def __check_init__(self) -> None:
        if not 0.0 < self.adjoint_decay <= 1.0:
            raise JcrowdError(
                f"rollout: expected adjoint_decay in (0, 1], found {self.adjoint_decay}"
            )
        n, s = self.peds.position.shape[0], self.world.walls.shape[0]
        if self.steps < 1 or not self.dt > 0 or not self.entry_temperature > 0:
            raise JcrowdError(
                f"rollout: expected steps ≥ 1, dt > 0 and entry_temperature > 0, found "
                f"{self.steps}, {self.dt}, {self.entry_temperature}"
            )
        if self.block < 0:
            raise JcrowdError(f"rollout: expected block ≥ 0 steps, found {self.block}")
        if self.entry_rank is not None and self.entry_rank.shape != (n,):
            raise JcrowdError(
                f"rollout: expected entry_rank of shape ({n},), found {self.entry_rank.shape}"
            )
        for door in self.doors:
            if any(not 0 <= seg < s or end not in (0, 1) for seg, end in door.left + door.right):
                raise JcrowdError(f"rollout: door {door} names a vertex outside the {s} walls")


class Trajectory(eqx.Module):
    """A rollout's samples at ``t_k = k·dt``, ``k = 0 … steps`` (leading axis).

    Attributes:
        position: ``(K + 1, N, 2)`` m; an agent that left stays where it arrived.
        alive: ``(K + 1, N)`` in the scene (not yet at its target).
        entered: ``(K + 1, N)`` the soft entry ``e_i(t_k)`` (1 without a source).
        overflow: the most agents the neighbour grid could not store at any step (0: none;
            otherwise the run is not the model's — size the grid larger).
        dt: the step (s).
    """

    position: Float[Array, "K1 N 2"]
    alive: Bool[Array, "K1 N"]
    entered: Float[Array, "K1 N"]
    overflow: Int[Array, ""]
    dt: float = eqx.field(static=True)


def initial_params(
    setup: RolloutSetup, avoidance: AvoidanceParams | None = None, rate: float = 1.0
) -> RolloutParams:
    """The parameters the setup was built with: its speeds and walls, its doors' widths as
    built, ``avoidance`` (default: the model's defaults) and ``rate`` (agents/s)."""
    walls = setup.world.walls
    widths = [
        (walls[d.right[0]] - walls[d.left[0]]) @ jnp.asarray(d.axis, walls.dtype)
        for d in setup.doors
    ]
    return RolloutParams(
        AvoidanceParams() if avoidance is None else avoidance,
        setup.peds.speed,
        walls,
        jnp.stack(widths) if widths else jnp.zeros((0,), walls.dtype),
        jnp.asarray(rate, walls.dtype),
    )


def entry_weights(
    setup: RolloutSetup, rate: Float[Array, ""], times: Float[Array, " K"]
) -> Float[Array, "K N"]:
    """The soft entry ``e_i(t) = σ((t − rank_i/rate)/τ_e)`` at each time (1 without a
    source)."""
    n = setup.peds.position.shape[0]
    if setup.entry_rank is None:
        return jnp.ones((times.shape[0], n), times.dtype)
    t_in = setup.entry_rank.astype(times.dtype) / rate
    return jax.nn.sigmoid((times[:, None] - t_in[None, :]) / setup.entry_temperature)


def _cast(tree: Any, dtype: Any) -> Any:
    """``tree`` with its floating arrays cast to ``dtype``."""

    def one(x: Any) -> Any:
        if eqx.is_array(x) and jnp.issubdtype(x.dtype, jnp.floating):
            return x.astype(dtype)
        return x

    return jax.tree.map(one, tree)


def _scan(step: Callable, carry: Any, xs: Array, setup: RolloutSetup) -> tuple[Any, Any]:
    """``lax.scan(step, carry, xs)``, under two levels of ``jax.checkpoint`` when the setup
    asks: blocks of ``block`` steps, and each step inside a block. The last block is padded
    with steps that leave the carry as it is, so one block is compiled."""
    if not setup.checkpoint:
        return jax.lax.scan(step, carry, xs)
    block = min(setup.block or math.ceil(math.sqrt(setup.steps)), setup.steps)
    blocks = -(-setup.steps // block)
    pad = blocks * block - setup.steps
    weights = jnp.concatenate([xs, jnp.zeros((pad, *xs.shape[1:]), xs.dtype)])
    valid = jnp.arange(blocks * block) < setup.steps

    @partial(jax.checkpoint, prevent_cse=False)
    def each(carry: Any, x: tuple[Array, Array]) -> tuple[Any, Any]:
        weight, ok = x
        new, out = step(carry, weight)
        return jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, carry), out

    @jax.checkpoint
    def run_block(carry: Any, xb: tuple[Array, Array]) -> tuple[Any, Any]:
        return jax.lax.scan(each, carry, xb)

    shape = (blocks, block)
    carry, ys = jax.lax.scan(
        run_block, carry, (weights.reshape(*shape, *xs.shape[1:]), valid.reshape(shape))
    )
    return carry, jax.tree.map(lambda a: a.reshape(-1, *a.shape[2:])[: setup.steps], ys)


@partial(jax.custom_vjp, nondiff_argnums=(1,))
def _fade(x: Any, decay: float) -> Any:
    """``x`` forward; its cotangent times ``decay`` backward (``RolloutSetup.adjoint_decay``)."""
    return x


def _fade_fwd(x: Any, decay: float) -> tuple[Any, None]:
    return x, None


def _fade_bwd(decay: float, _: None, g: Any) -> tuple[Any]:
    return (jax.tree.map(lambda a: a * decay, g),)


_fade.defvjp(_fade_fwd, _fade_bwd)


def rollout(params: RolloutParams, setup: RolloutSetup) -> Trajectory:
    """Step the setup's agents ``setup.steps`` times with the dynamics of
    :func:`~jcrowd.pedestrians.step.pedestrian_step` under ``params``; differentiable in
    ``params`` (module docstring: what carries no gradient, what the memory is).

    Not compiled here: ``jax.jit`` (or ``eqx.filter_jit``) the loss around it.

    Raises:
        JcrowdError: parameters whose shapes do not fit the setup (agents, walls, doors).
    """
    n, s = setup.peds.position.shape[0], setup.world.walls.shape[0]
    want = {"speed": (n,), "walls": (s, 2, 2), "door_width": (len(setup.doors),), "rate": ()}
    for name, shape in want.items():
        found = getattr(params, name).shape
        if found != shape:
            raise JcrowdError(f"rollout: expected params.{name} of shape {shape}, found {found}")
    dtype = params.speed.dtype
    params, setup = _cast((params, setup), dtype)
    rate = eqx.error_if(params.rate, params.rate <= 0, "rollout: expected a positive rate")
    world = eqx.tree_at(
        lambda w: w.walls, setup.world, door_walls(params.walls, setup.doors, params.door_width)
    )
    times = jnp.arange(setup.steps + 1, dtype=dtype) * setup.dt
    entered = entry_weights(setup, rate, times)
    peds = setup.peds

    def step(
        carry: tuple[Pedestrians, Array], weight: Array
    ) -> tuple[tuple[Pedestrians, Array], tuple[Array, Array]]:
        peds, overflow = carry
        if setup.adjoint_decay != 1.0:
            decay = setup.adjoint_decay
            peds = eqx.tree_at(lambda p: p.position, peds, _fade(peds.position, decay))
            if peds.velocity is not None:
                peds = eqx.tree_at(lambda p: p.velocity, peds, _fade(peds.velocity, decay))
        walking = eqx.tree_at(lambda p: p.speed, peds, params.speed * weight)
        moved, info = pedestrian_step(params.avoidance, world, walking, setup.dt)
        moved = eqx.tree_at(lambda p: p.speed, moved, peds.speed)
        return (moved, jnp.maximum(overflow, info.overflow)), (moved.position, moved.alive)

    (_, overflow), (position, alive) = _scan(
        step, (peds, jnp.zeros((), jnp.int32)), entered[:-1], setup
    )
    return Trajectory(
        jnp.concatenate([peds.position[None], position]),
        jnp.concatenate([peds.alive[None], alive]),
        entered,
        overflow,
        setup.dt,
    )


def _past_line(
    position: Float[Array, "*k N 2"],
    point: Sequence[float] | Array,
    normal: Sequence[float] | Array,
    temperature: float,
) -> Float[Array, "*k N"]:
    """The soft indicator ``σ(((x − p)·n)/τ_c)`` of being past the line (``n`` normalised)."""
    p = jnp.asarray(point, position.dtype)
    n = jnp.asarray(normal, position.dtype)
    n = n / jnp.sqrt(jnp.sum(n * n))
    return jax.nn.sigmoid(((position - p) @ n) / temperature)


def _index(traj: Trajectory, time: float | None) -> int:
    last = traj.position.shape[0] - 1
    if time is None:
        return last
    k = round(time / traj.dt)
    if not 0 <= k <= last:
        raise JcrowdError(f"surrogate: expected a time in [0, {last * traj.dt:g}] s, found {time}")
    return k


def soft_exit_count(
    traj: Trajectory,
    point: Sequence[float] | Array,
    normal: Sequence[float] | Array,
    time: float | None = None,
    temperature: float = COUNT_TEMPERATURE,
) -> Float[Array, ""]:
    """Agents through the exit line by ``time`` (s, rounded to a step; default the last):
    ``Σ_i σ(((x_i(T) − p)·n)/τ_c)``, ``p`` a point of the line, ``n`` its normal pointing out
    (any length), ``τ_c`` the ``temperature`` (m). In ``[0, N]``.

    Raises:
        JcrowdError: a time outside the trajectory.
    """
    k = _index(traj, time)
    return jnp.sum(_past_line(traj.position[k], point, normal, temperature))


def mean_travel_time(
    traj: Trajectory,
    point: Sequence[float] | Array,
    normal: Sequence[float] | Array,
    time: float | None = None,
    temperature: float = COUNT_TEMPERATURE,
) -> Float[Array, ""]:
    """Mean time (s) from entering to passing the exit line, censored at ``time`` (default
    the trajectory's end): ``(1/N) Σ_i Σ_{k<K} Δt e_i(t_k) (1 − σ(((x_i(t_k) − p)·n)/τ_c))``
    (module docstring).

    Raises:
        JcrowdError: a time outside the trajectory.
    """
    k = _index(traj, time)
    inside = 1.0 - _past_line(traj.position[:k], point, normal, temperature)
    n = traj.position.shape[1]
    return traj.dt * jnp.sum(traj.entered[:k] * inside) / n
