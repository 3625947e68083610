"""Geometry a rollout's parameters move: door openings and walls beyond the host's cell lists.

Part of the differentiable rollouts (:mod:`jcrowd.rollouts.rollout`, "Door widths" and
"Geometry"): a :class:`Door` names the wall vertices on either side of an opening (found on
the host by :func:`find_door`), :func:`door_walls` opens it to a traced width, and
:func:`every_wall` makes every wall a candidate of every neighbour cell, for walls moved
farther than ``WALL_REACH_M`` from where the host listed them. Positions ``[x, z]`` in metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jcrowd.errors import JcrowdError
from jcrowd.pedestrians.world import World

__all__ = ["Door", "door_walls", "every_wall", "find_door"]


@dataclass(frozen=True)
class Door:
    """An opening between two groups of wall vertices (static topology).

    Attributes:
        left, right: ``(segment, end)`` pairs, ``end`` 0 or 1, of the vertices on either side
            of the opening; each side moves as one. The first pair of each side spans the
            opening.
        axis: unit vector from the left side to the right, across the opening.
    """

    left: tuple[tuple[int, int], ...]
    right: tuple[tuple[int, int], ...]
    axis: tuple[float, float]


def find_door(
    walls: Float[np.ndarray, "S 2 2"],
    left: Sequence[Sequence[float]],
    right: Sequence[Sequence[float]],
    tol: float = 1e-6,
) -> Door:
    """The :class:`Door` whose sides are the wall vertices at the points ``left`` and ``right``
    (m; every endpoint within ``tol`` of one of them). The first point of each side spans the
    opening; name more (a corridor's far corners) to move whole side walls with it.

    Raises:
        JcrowdError: a side without points, a point that is no wall vertex, or sides that
            coincide.
    """
    ends = np.asarray(walls, np.float64)
    sides = []
    for name, points in (("left", left), ("right", right)):
        if len(points) == 0:
            raise JcrowdError(f"door: expected at least one {name} point, found none")
        pairs = []
        for pt in points:
            near = np.linalg.norm(ends - np.asarray(pt, np.float64), axis=-1) <= tol
            if not near.any():
                raise JcrowdError(f"door: expected a wall vertex at {name} point {tuple(pt)}")
            pairs += [(int(s), int(e)) for s, e in zip(*np.nonzero(near), strict=True)]
        sides.append(tuple(pairs))
    span = np.asarray(right[0], np.float64) - np.asarray(left[0], np.float64)
    width = float(np.linalg.norm(span))
    if not width > tol:
        raise JcrowdError(f"door: expected the two sides apart, found {width} m between them")
    return Door(sides[0], sides[1], (float(span[0] / width), float(span[1] / width)))


def door_walls(
    walls: Float[Array, "S 2 2"], doors: Sequence[Door], widths: Float[Array, " D"]
) -> Float[Array, "S 2 2"]:
    """``walls`` with door ``d`` opened to ``widths[d]`` (m) about its current centre: its left
    side moves by ``−½(w − w_0) u`` and its right by ``+½(w − w_0) u``, ``u`` its axis and
    ``w_0 = (b − a)·u`` the width between the first vertices ``a``, ``b`` of its sides."""
    for d, door in enumerate(doors):
        u = jnp.asarray(door.axis, walls.dtype)
        (ls, le), (rs, re) = door.left[0], door.right[0]
        shift = 0.5 * (widths[d] - (walls[rs, re] - walls[ls, le]) @ u)
        for pairs, sign in ((door.left, -1.0), (door.right, 1.0)):
            seg, end = (np.asarray(c, np.int32) for c in zip(*pairs, strict=True))
            walls = walls.at[seg, end].add(sign * shift * u)
    return walls


def every_wall(world: World) -> World:
    """``world`` with every wall a candidate of every cell (``(cells, S)`` ids): for walls
    moved beyond the host's per-cell lists (``WALL_REACH_M``); costs ``S`` walls per agent."""
    s, cells = world.walls.shape[0], world.grid.num_cells
    ids = jnp.broadcast_to(jnp.arange(s, dtype=jnp.int32), (cells, max(s, 1)))
    return eqx.tree_at(lambda w: w.cell_walls, world, ids if s else jnp.zeros_like(ids))
