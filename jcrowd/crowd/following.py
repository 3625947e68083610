"""Walkers following the simulated crowd: the gait phase advances with the distance
the root walks, and a slow agent stands at a double-support phase.

With the crowd dynamics on (:attr:`~jcrowd.crowd.state.StepConfig.avoid`) the simulation moves
the roots; the step (:mod:`jcrowd.crowd.stepping`) asks :func:`follow_phase` how far each
agent's phase goes in a step and :func:`stands_at` whether it stands.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array

from jcrowd.crowd.clips import CrowdModel

__all__ = [
    "FOLLOW_MAX_RATE",
    "SHUFFLE_BELOW",
    "SHUFFLE_CADENCE",
    "STAND_APPROACH",
    "STAND_BELOW",
    "STRIDE_EASE_S",
    "TURNING_DEG_S",
    "TURN_CADENCE",
    "TURN_STEP_DEG",
    "follow_phase",
    "stands_at",
    "stride_warp",
    "turns_on_the_spot",
]


FOLLOW_MAX_RATE = 2.0
"""With the dynamics on, the phase runs at most this many times its clip's own rate."""

STAND_BELOW = 0.1
"""With the dynamics on, an agent slower than this (m/s) stands: its phase goes on to the next
double-support phase and waits there (:func:`follow_phase`)."""

SHUFFLE_BELOW = 0.2
"""With the dynamics on, an agent slower than this (m/s) but not standing shuffles: its phase
runs at most :data:`SHUFFLE_CADENCE` times the model's mean cadence (nobody walks in place at
walking cadence below 0.2 m/s)."""

SHUFFLE_CADENCE = 0.4
"""The cap of a shuffling agent's cadence, as a fraction of the model's mean. Without it the
phase follows ``walked / stride`` frame by frame, and the time warp makes the clip's root
travel per aligned frame small in parts of the cycle, so a walker at 0.1–0.2 m/s stepped at
0.5–1.4 times the mean cadence for a frame or two (about 1 % of the slow agent-frames of
the entrance scenario, ``bench/follow.py``). Capped, the root walks a little ahead of the feet
there."""

STAND_APPROACH = 0.35
"""On its way to stand, the phase runs at this fraction of the model's mean cadence (a cycle per
:attr:`~jcrowd.crowd.clips.CrowdModel.cycle_seconds`): below half a walk's, so an agent about
to stand does not walk in place. Not a fraction of the clip's own rate at the
phase, ``dt·fps/ΔA``: the time warp makes that two or three times the mean in parts of the
cycle (measured on the entrance run: 0.4 of it put 4 % of the slow agent-frames above half
the mean cadence)."""


TURN_STEP_DEG = 30.0
"""A standing body whose heading has turned this far (degrees) from where it stood takes a step
on the spot (:func:`turns_on_the_spot`). Game rigs re-plant after 45° or so; ours is smaller
because a planted foot is moved, not turned, so its heel or toe swings round the pin with the
body until the step re-plants it."""

TURNING_DEG_S = 30.0
"""A slow agent between two double supports whose body turns faster than this (°/s) finishes
its step at :data:`TURN_CADENCE`, not at :data:`STAND_APPROACH` (a standing body turns at up
to 69°/s, :mod:`jcrowd.pedestrians.heading`; slower turns are a body settling)."""

TURN_CADENCE = 1.0
"""A step on the spot runs at this fraction of the model's mean cadence: half a cycle, one
foot lifted and set down under its hip at the body's new heading."""

STRIDE_EASE_S = 0.3
"""The stride warp (:func:`stride_warp`) changes by at most 1 over this many seconds, so a foot
in the air does not jump when an agent starts or stops."""


def turns_on_the_spot(
    stands: Array, slow: Array, heading: Array, stand_heading: Array, facing: Array, dt: Array
) -> Array:
    """Which slow agents step on the spot this step: one standing (phase at a double support)
    whose ``heading`` is more than :data:`TURN_STEP_DEG` from the ``stand_heading`` it stood at,
    or one between double supports whose body turns (``heading`` → ``facing``) faster than
    :data:`TURNING_DEG_S`."""

    def wrapped(a: Array) -> Array:
        return jnp.abs(jnp.remainder(a + jnp.pi, 2.0 * jnp.pi) - jnp.pi)

    twisted = wrapped(heading - stand_heading) > jnp.deg2rad(TURN_STEP_DEG)
    turning = wrapped(facing - heading) > jnp.deg2rad(TURNING_DEG_S) * dt
    return slow & jnp.where(stands, twisted, turning)


def stride_warp(stride: Array, slow: Array, dt: Array) -> Array:
    """The stride warp after a step: towards 0 for an agent slower than :data:`STAND_BELOW`
    (its feet step under its hips: standing, or turning on the spot), else towards 1 (the
    decoded stride, which the phase follows), by at most ``dt / STRIDE_EASE_S``."""
    target = jnp.where(slow, 0.0, 1.0)
    most = dt / STRIDE_EASE_S
    return stride + jnp.clip(target - stride, -most, most)


def follow_phase(
    cm: CrowdModel,
    tau: Array,
    natural: Array,
    walked: Array,
    stride: Array,
    dt: Array,
    turning: Array | None = None,
) -> Array:
    """The phase step of an agent whose root the simulation moves.

    Walking: the aligned frames that carry the clip's root as far as the agent walked this step,
    ``walked / stride`` with ``stride`` the clip's root travel per aligned frame at the phase
    (m) — the stance foot then stays where it was planted on a straight walk whatever the
    simulated speed; between 0 and :data:`FOLLOW_MAX_RATE` times ``natural``, the clip's own
    step ``dt·fps/ΔA``. Below the slowest captured cycle the stride stays that cycle's and the
    cadence drops with the speed; below :data:`SHUFFLE_BELOW` it is capped at
    :data:`SHUFFLE_CADENCE` times the model's mean.

    Standing (slower than :data:`STAND_BELOW`): the phase goes on, at :data:`STAND_APPROACH`
    times the model's mean rate, to the clip's next double-support phase
    (:attr:`~jcrowd.crowd.clips.CrowdModel.double_support`, both heels down) and waits there
    until the agent walks again: the standing pose is the clip's own double-support frame, and
    the walk resumes from it. A slow agent ``turning`` on the spot (:func:`turns_on_the_spot`)
    steps instead: its phase runs at :data:`TURN_CADENCE` times the mean to the next double
    support, past the one it stands at.
    """
    rate = jnp.clip(walked / jnp.maximum(stride, 1e-4), 0.0, FOLLOW_MAX_RATE * natural)
    ahead = jnp.full_like(tau, 2.0 * (cm.frames - 1))
    for p in _stand_phases(cm):
        ahead = jnp.where((p - tau >= -1e-3) & (p - tau < ahead), jnp.maximum(p - tau, 0.0), ahead)
    towards = jnp.minimum(STAND_APPROACH * (cm.frames - 1) * dt / cm.cycle_seconds, ahead)
    shuffle = SHUFFLE_CADENCE * (cm.frames - 1) * dt / cm.cycle_seconds
    rate = jnp.where(walked < SHUFFLE_BELOW * dt, jnp.minimum(rate, shuffle), rate)
    slow = walked < STAND_BELOW * dt
    still = jnp.where(ahead <= 1e-3, 0.0, towards)
    if turning is not None:
        beyond = jnp.full_like(tau, 2.0 * (cm.frames - 1))
        for p in _stand_phases(cm):
            beyond = jnp.where((p - tau > 1e-3) & (p - tau < beyond), p - tau, beyond)
        step = TURN_CADENCE * (cm.frames - 1) * dt / cm.cycle_seconds
        still = jnp.where(turning, jnp.minimum(step, beyond), still)
    return jnp.where(slow, still, rate)


def stands_at(cm: CrowdModel, tau: Array) -> Array:
    """Whether phase ``tau`` is at one of the clip's double-support phases (within 1e-3)."""
    near = jnp.zeros(tau.shape, bool)
    for p in _stand_phases(cm):
        near = near | (jnp.abs(tau - p) <= 1e-3)
    return near


def _stand_phases(cm: CrowdModel) -> tuple[float, ...]:
    """The double-support phases in increasing order, and the first again one cycle on (a
    phase about to wrap waits at the cycle's end, which is the next cycle's start)."""
    return (*cm.double_support, cm.double_support[0] + float(cm.frames - 1))
