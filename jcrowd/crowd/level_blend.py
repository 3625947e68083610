"""Level changes without popping: the drawn pose eases from the old level's to the new one's.

When an agent's level of detail changes its pose would jump in one frame: a joint the new level
freezes snaps to its frozen rotation, the core changes rank (issue 19). For
:data:`BLEND_SECONDS` after a change the step draws

    ``p = w·p_from + (1 − w)·p_level``,  ``w = left / BLEND_SECONDS``,

``p_from`` the agent decoded at the level it left (same phase, clips and root: only the level
differs), ``p_level`` at its level now, and ``left`` falling from ``BLEND_SECONDS`` to 0 by
``dt`` each step. At the change the drawn pose is the old level's exactly; each later frame
moves by ``Δw·(p_from − p_level)`` more than the agent's own motion, ``Δw = dt /
BLEND_SECONDS`` (a ramp: its largest step is the smallest any easing over the window can have;
a smoothstep's is 1.5× it). At 30 fps and 0.3 s that is a ninth of the level difference per
frame.

An agent changing level again inside the window starts a new blend from the level it leaves,
but one going *back* to the level it is blending from swaps the two and keeps the weight
(``left ← BLEND_SECONDS − left``), so a level flickering at a threshold stays continuous. The
old-level poses are decoded in a fixed-size bucket per level (:func:`blend_capacity`); agents
beyond it show their new level at once and are counted (``Frame.unblended``).

State per agent (:class:`~jcrowd.crowd.state.CrowdState`): ``shown`` (the level drawn in the
last frame, ``L`` none), ``blend_from`` (``L``: not blending) and ``blend_left`` (s): 12 bytes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

__all__ = ["BLEND_SECONDS", "blend_capacity", "blend_levels", "blend_plan"]

BLEND_SECONDS = 0.3
"""How long a level change eases in (s); the issue asks for 0.2–0.3 s."""


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


def blend_levels(
    points: Sequence[Float[Array, "C P 3"]],
    slots: Sequence[Int[Array, " C"]],
    source: Int[Array, " N"],
    left: Float[Array, " N"],
    decode: Callable[[int, Int[Array, " K"], Array], Float[Array, "K P 3"]],
) -> tuple[tuple[Float[Array, "C P 3"], ...], Int[Array, ""]]:
    """Each level's points with the blending agents' poses eased from their ``source`` level.

    ``slots``: each level's agent ids (``N`` pads them); ``decode(a, ids, used)`` returns
    agents ``ids`` (padded with ``N``; the first ``used`` are real) decoded at level ``a``.
    Blending agents are drawn, so they are looked for among the slots, not the whole crowd.
    Returns the points and how many blending agents did not fit their source level's bucket
    (:func:`blend_capacity`; they show their level at once).
    """
    n, levels = source.shape[0], len(points)
    sizes = [int(ids.shape[0]) for ids in slots]
    total = sum(sizes)
    # Per place in the levels' slots one after the other: its level and its slot there
    # (one past the end: the padding place).
    level_of = np.concatenate([np.full(c, b, np.int32) for b, c in enumerate(sizes)] + [[-1]])
    slot_of = np.concatenate([np.arange(c, dtype=np.int32) for c in sizes] + [[0]])
    ids_at = jnp.concatenate([*slots, jnp.full((1,), n, jnp.int32)])
    src = jnp.where(ids_at < n, source[jnp.minimum(ids_at, n - 1)], levels)
    out = list(points)
    unblended = jnp.zeros((), jnp.int32)
    for a in range(levels):
        mask = src == a
        size = blend_capacity(sizes[a])
        (place,) = jnp.nonzero(mask, size=size, fill_value=total)
        count = jnp.sum(mask, dtype=jnp.int32)
        unblended = unblended + jnp.maximum(count - size, 0)
        ids = ids_at[place]
        old = decode(a, ids, jnp.minimum(count, size))
        w = (left[jnp.minimum(ids, n - 1)] / BLEND_SECONDS)[:, None, None]
        lev, slot = jnp.asarray(level_of)[place], jnp.asarray(slot_of)[place]
        for b in range(levels):
            if b == a:
                continue
            at = jnp.where(lev == b, slot, sizes[b])
            now = out[b][jnp.minimum(at, sizes[b] - 1)]
            out[b] = out[b].at[at].set(now + w * (old - now), mode="drop")
    return tuple(out), unblended
