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
    "follow_phase",
    "stands_at",
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


def follow_phase(
    cm: CrowdModel, tau: Array, natural: Array, walked: Array, stride: Array, dt: Array
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
    the walk resumes from it.
    """
    rate = jnp.clip(walked / jnp.maximum(stride, 1e-4), 0.0, FOLLOW_MAX_RATE * natural)
    ahead = jnp.full_like(tau, 2.0 * (cm.frames - 1))
    for p in _stand_phases(cm):
        ahead = jnp.where((p - tau >= -1e-3) & (p - tau < ahead), jnp.maximum(p - tau, 0.0), ahead)
    towards = jnp.minimum(STAND_APPROACH * (cm.frames - 1) * dt / cm.cycle_seconds, ahead)
    shuffle = SHUFFLE_CADENCE * (cm.frames - 1) * dt / cm.cycle_seconds
    rate = jnp.where(walked < SHUFFLE_BELOW * dt, jnp.minimum(rate, shuffle), rate)
    slow = walked < STAND_BELOW * dt
    return jnp.where(slow, jnp.where(ahead <= 1e-3, 0.0, towards), rate)


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
