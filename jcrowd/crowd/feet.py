"""Planted feet in the crowd step: whether a step plants, and the near agents' feet planted
from their pins (:mod:`jcrowd.motion.planting`), one agent or a bucket at a time.

The step (:mod:`jcrowd.crowd.stepping`) plants each near level's agents inside its chunked
decode (:func:`plant_agent`), the coarsest bucket after its blend (:func:`plant_bucket`), and an
agent leaving the near levels from the pose it blends from; each returns the new pins, planted
and toe flags that :class:`~jcrowd.crowd.state.CrowdState` carries to the next step.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array

from jcrowd.crowd.clips import CrowdModel
from jcrowd.crowd.state import CrowdState, StepConfig
from jcrowd.motion.planting import plant_feet

__all__ = ["no_pins", "plant_agent", "plant_bucket", "plants_feet"]


def plants_feet(cm: CrowdModel, config: StepConfig) -> bool:
    """Whether the step plants near agents' feet (:mod:`jcrowd.motion.planting`)."""
    return config.avoid and config.foot_lock and config.plant_feet and bool(cm.legs)


def no_pins(state: CrowdState) -> tuple[Array, Array, Array]:
    """Pins, planted and toe flags of nobody planted."""
    return (
        jnp.zeros_like(state.pin),
        jnp.zeros_like(state.planted),
        jnp.zeros_like(state.pin_toe),
    )


def plant_agent(
    cm: CrowdModel, state: CrowdState, i: Array, pts: Array
) -> tuple[Array, Array, Array, Array]:
    """Agent ``i``'s points with its stance feet planted (:mod:`jcrowd.motion.planting`), and
    its new pins, planted and toe flags."""
    return plant_feet(
        cm.legs,
        (float(cm.double_support[0]), float(cm.double_support[1])),
        float(cm.frames - 1),
        pts,
        state.tau[i],
        state.height[i],
        state.pin[i],
        state.planted[i],
        state.pin_toe[i],
        None,  # the decoded points are warped already (the step's _agent_level)
        state.stride[i],
    )


def plant_bucket(
    cm: CrowdModel, state: CrowdState, ids: Array, pts: Array
) -> tuple[Array, tuple[Array, Array, Array]]:
    """A bucket's points with their stance feet planted, and its agents' new pins."""
    out, pin, on, toe = jax.vmap(lambda i, p: plant_agent(cm, state, i, p))(ids, pts)
    return out, (pin, on, toe)
