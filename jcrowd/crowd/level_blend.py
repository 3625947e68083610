"""Level changes without popping: the drawn pose eases from the old level's to the new one's.

When an agent's level of detail changes its pose would jump in one frame: a joint the new level
freezes snaps to its frozen rotation, the core changes rank. For
:data:`BLEND_SECONDS` after a change the step draws

    ``p = w·p_from + (1 − w)·p_level``,  ``w = S(left / BLEND_SECONDS)``,  ``S(u) = 3u² − 2u³``,

``p_from`` the agent decoded at the level it left (same phase, clips and root: only the level
differs), ``p_level`` at its level now, and ``left`` falling from ``BLEND_SECONDS`` to 0 by
``dt`` each step. At the change the drawn pose is the old level's, and as ``S′`` is 0 at both
ends the drawn joints keep the old level's velocity there and take the new level's at the end:
the change is continuous in value and in velocity (what an inertialized transition gives,
Bollo, GDC 2018), where a linear ramp would add ``(p_from − p_level) / BLEND_SECONDS`` to the
velocity at once. Each later frame moves by at most ``1.5·Δu·|p_from − p_level|`` more than
the agent's own motion (``S′ ≤ 1.5``, ``Δu = dt / BLEND_SECONDS``): over 0.45 s at 30 fps a
ninth of the level difference per frame, the largest step a linear ramp over 0.3 s makes.

Why not an inertialized offset (the pose offset carried from the switch and decaying with a
half-life of ~0.1 s): an offset frozen at the switch would leave the old level's error in place
while the pose moves on, and a 0.1 s half-life moves a sixth to a fifth of the offset in one
frame at 30 fps (critically damped or plain exponential). Both poses are decoded at the same
phase here anyway, so the old level's pose itself is faded out: the inertialized transition's
continuity with a smaller largest step.

An agent changing level again inside the window starts a new blend from the level it leaves,
but one going *back* to the level it is blending from swaps the two and keeps the weight
(``left ← BLEND_SECONDS − left``: ``S(1 − u) = 1 − S(u)``), so a level flickering at a
threshold stays continuous. The old-level poses are decoded in a fixed-size bucket per level
(:func:`blend_capacity`); agents beyond it show their new level at once and are counted
(``Frame.unblended``).

State per agent (:class:`~jcrowd.crowd.state.CrowdState`): ``shown`` (the level drawn in the
last frame, ``L`` none), ``blend_from`` (``L``: not blending) and ``blend_left`` (s): 12 bytes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.indexing import first_true, first_true_per_class
from jcrowd.pedestrians.heading import smoothstep

__all__ = [
    "BLEND_SECONDS",
    "BlendRows",
    "blend_capacity",
    "blend_levels",
    "blend_plan",
    "blend_sources",
    "blend_weight",
]

BLEND_SECONDS = 0.45
"""How long a level change eases in (s): 1.5 × 0.3 s, so the smoothstep's largest step per
frame is a linear 0.3 s ramp's."""


def blend_weight(left: Float[Array, "*n"]) -> Float[Array, "*n"]:
    """``w = S(left / BLEND_SECONDS)``: the old level's share with ``left`` seconds of the
    blend to go (1 at the change, 0 at the end, zero slope at both)."""
    return smoothstep(left / BLEND_SECONDS)


def blend_capacity(capacity: int) -> int:
    """Old-level poses decoded per step for agents that left a level of ``capacity`` slots:
    an eighth of it, at least 64 (never more than the level holds)."""
    return min(capacity, max(64, capacity // 8))


def blend_plan(
    shown: Int[Array, " N"],
    blend_from: Int[Array, " N"],
    blend_left: Float[Array, " N"],
    level: Int[Array, " N"],
    alive: Bool[Array, " N"],
    levels: int,
) -> tuple[Int[Array, " N"], Float[Array, " N"]]:
    """This frame's ``(blend_from, blend_left)`` from the last frame's and the level each agent
    is drawn at now (``levels``: not drawn). ``blend_from == levels`` where nothing blends."""
    drawn = alive & (level < levels)
    changed = drawn & (shown < levels) & (shown != level)
    blending = (blend_from < levels) & (blend_left > 0.0)
    back = changed & blending & (blend_from == level)
    fresh = jnp.where(back, BLEND_SECONDS - blend_left, BLEND_SECONDS)
    left = jnp.where(changed, fresh, blend_left)
    source = jnp.where(changed, shown, blend_from)
    active = drawn & (source < levels) & (source != level) & (left > 0.0)
    return jnp.where(active, source, levels), jnp.where(active, left, 0.0)


class BlendRows(eqx.Module):
    """The poses agents blend from this frame: ``old (K + 1, P, 3)`` decoded at the level each
    left, ``weight (K + 1,)`` its ``w``, and ``row (N,)`` each agent's row (``K``, a zero row
    with weight 0, for agents not blending); ``place`` each row's place in the levels' slots
    one after the other (their total: none)."""

    old: Float[Array, "K1 P 3"]
    weight: Float[Array, " K1"]
    row: Int[Array, " N"]
    place: Int[Array, " K1"]

    def ease(self, agent: Int[Array, ""], points: Float[Array, "P 3"]) -> Float[Array, "P 3"]:
        """One agent's drawn points: ``w·p_from + (1 − w)·points`` (``points`` when it does
        not blend)."""
        k = self.row[agent]
        return points + self.weight[k] * (self.old[k] - points)

    def ease_bucket(self, points: Float[Array, "C P 3"], start: int) -> Float[Array, "C P 3"]:
        """A whole level's points, whose slots start at place ``start``: only the blending
        rows are read and written (for a large bucket, where easing every slot in its decode
        would cost more than the few that blend)."""
        size = points.shape[0]
        inside = (self.place >= start) & (self.place < start + size)
        at = jnp.where(inside, self.place - start, size)
        now = points[jnp.minimum(at, size - 1)]
        eased = now + self.weight[:, None, None] * (self.old - now)
        return points.at[at].set(eased, mode="drop")


def blend_sources(
    slots: Sequence[Int[Array, " C"]],
    source: Int[Array, " N"],
    left: Float[Array, " N"],
    decode: Callable[[int, Int[Array, " K"], Array], Float[Array, "K P 3"]],
) -> tuple[BlendRows, Int[Array, ""]]:
    """The old-level poses of the agents blending this frame, decoded once per source level.

    ``slots``: each level's agent ids this frame (``N`` pads them); blending agents are
    drawn, so they are looked for among the slots, not the whole crowd. ``decode(a, ids,
    used)`` returns agents ``ids`` (padded with ``N``; the first ``used`` are real) decoded at
    level ``a``. Returns the rows and how many blending agents did not fit their source
    level's bucket (:func:`blend_capacity`; they show their level at once). The step eases
    each agent in its own level's decode (:meth:`BlendRows.ease`), so no level's points are
    copied for the few that blend.
    """
    n, levels = source.shape[0], len(slots)
    sizes = [int(ids.shape[0]) for ids in slots]
    total = sum(sizes)
    ids_at = jnp.concatenate([*slots, jnp.full((1,), n, jnp.int32)])
    src = jnp.where(ids_at < n, source[jnp.minimum(ids_at, n - 1)], levels)
    # The blending places first (one compaction of the slots), then each source level's.
    budget = [blend_capacity(c) for c in sizes]
    any_src = src < levels
    blending = first_true(any_src, min(total, sum(budget)), total)
    unblended = jnp.maximum(jnp.sum(any_src, dtype=jnp.int32) - blending.shape[0], 0)
    src_b = jnp.concatenate([src, jnp.full((1,), levels, src.dtype)])[blending]
    padded = jnp.concatenate([blending, jnp.full((1,), total, blending.dtype)])
    olds, ids_all, places = [], [], []
    per_level = first_true_per_class(src_b, tuple(budget), blending.shape[0])
    for a, k in enumerate(per_level):
        count = jnp.sum(src_b == a, dtype=jnp.int32)
        unblended = unblended + jnp.maximum(count - budget[a], 0)
        ids = ids_at[padded[k]]
        olds.append(decode(a, ids, jnp.minimum(count, budget[a])))
        ids_all.append(ids)
        places.append(padded[k])
    ids = jnp.concatenate(ids_all)
    rows = ids.shape[0]
    old = jnp.concatenate([*olds, jnp.zeros((1, *olds[0].shape[1:]), olds[0].dtype)])
    weight = jnp.concatenate([blend_weight(left[jnp.minimum(ids, n - 1)]), jnp.zeros(1)])
    weight = jnp.where(jnp.concatenate([ids < n, jnp.zeros(1, bool)]), weight, 0.0)
    row = jnp.full(n, rows, jnp.int32).at[ids].set(jnp.arange(rows, dtype=jnp.int32), mode="drop")
    place = jnp.concatenate([*places, jnp.full((1,), total, blending.dtype)])
    return BlendRows(old, weight.astype(old.dtype), row, place.astype(jnp.int32)), unblended


def blend_levels(
    points: Sequence[Float[Array, "C P 3"]],
    slots: Sequence[Int[Array, " C"]],
    source: Int[Array, " N"],
    left: Float[Array, " N"],
    decode: Callable[[int, Int[Array, " K"], Array], Float[Array, "K P 3"]],
) -> tuple[tuple[Float[Array, "C P 3"], ...], Int[Array, ""]]:
    """Each level's points with the blending agents' poses eased from their ``source`` level,
    as the step does it for points decoded without the blend (:func:`blend_sources`, then
    :meth:`BlendRows.ease` on every slot of every level but the last, whose blending rows
    :meth:`BlendRows.ease_bucket` eases)."""
    rows, unblended = blend_sources(slots, source, left, decode)
    n = source.shape[0]
    eased, start = [], 0
    for b, (ids, pts) in enumerate(zip(slots, points, strict=True)):
        if b < len(slots) - 1:
            safe = jnp.where(ids < n, ids, 0)
            out = jax.vmap(rows.ease)(safe, pts)
            eased.append(jnp.where((ids < n)[:, None, None], out, pts))
        else:
            eased.append(rows.ease_bucket(pts, start))
        start += ids.shape[0]
    return tuple(eased), unblended
