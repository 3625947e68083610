"""The pedestrian models' parameters, one traced pytree (:class:`AvoidanceParams`).

The collision-free speed model's (:mod:`jcrowd.pedestrians.avoidance`, Tordeux, Chraibi &
Seyfried 2016, Eqs. 2 and 4, with our smooth ``V``, anisotropy, wall slide and standing rule)
and the reaction time and anticipation model's (:mod:`jcrowd.pedestrians.reaction`). The
defaults of ``a``, ``D``, ``a_w``, ``D_w``, ``t_a``, ``a_a``, ``D_a`` and ``τ`` are JuPedSim
1.4's; ``T``, ``n``, ``λ``, ``m``, ``c``, ``v_go``, ``τ_p`` and the heading's
(:mod:`jcrowd.pedestrians.heading`) are ours, validated in ``bench/pedestrians.py``
(docs/validation.md). Every field is an array, so a changed value
(a calibration, a gradient step) never recompiles.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = ["AvoidanceParams"]


class AvoidanceParams(eqx.Module):
    """The avoidance models' parameters (traced: changing them never recompiles).

    Attributes:
        strength: ``a`` of the neighbour repulsion (dimensionless).
        range: ``D`` of the neighbour repulsion (m).
        wall_strength: ``a_w`` of the wall repulsion.
        wall_range: ``D_w`` of the wall repulsion (m).
        time_gap: ``T`` (s).
        sharpness: ``n`` of the smooth ``V`` (module docstring).
        anisotropy: ``λ``, the weight of a neighbour straight behind in Eq. (4).
        wall_slide: ``m`` (m), how far from contact the desire starts sliding along a wall.
        anticipation_time: ``t_a`` (s), how far ahead neighbours' paths are predicted.
        anticipation_strength, anticipation_range: ``a_a``, ``D_a`` (m) of the sideways step.
        reaction_time: ``τ`` (s) over which the anticipating direction follows.
        plain_reaction_time: the same for the plain model, given the last velocities (the
            fifth change, :mod:`jcrowd.pedestrians.reaction`).
        keep_right: ``b`` (m), the bias to step right of someone met head-on.
        side_width: ``w`` (m).
        back_share: the share of the speed left walking straight back from the heading (1:
            the heading does not change the speed; :mod:`jcrowd.pedestrians.heading`).
        walk_speed: ``v_walk`` (m/s), from which the heading follows the velocity alone.
        heading_time: ``τ_h`` (s) over which the heading relaxes.
        turn_rate: ``ω`` (rad/s), the fastest the heading turns.
        stand_turn_share: the share of ``ω`` a standing body turns at.
        stand_drive: ``c``, the net drive ``‖E‖`` of Eq. (4) below which a standing person
            slows in proportion (:mod:`jcrowd.pedestrians.avoidance`; a free walker's is 1);
            0 (the default) turns the rule off.
        go_speed: ``v_go`` (m/s), the last speed at which that slowing is gone.
    """

    strength: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=8.0)
    range: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.1)
    wall_strength: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=5.0)
    wall_range: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.02)
    time_gap: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.6)
    sharpness: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=4.0)
    anticipation_time: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1.0)
    anticipation_strength: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=8.0)
    anticipation_range: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.1)
    reaction_time: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.3)
    keep_right: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.1)
    side_width: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.1)
    wall_slide: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.1)
    anisotropy: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.3)
    plain_reaction_time: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.1)
    back_share: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1.0)
    walk_speed: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.5)
    heading_time: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.1)
    turn_rate: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=3.0)
    stand_turn_share: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.4)
    stand_drive: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)
    go_speed: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=2.0)
