"""Navigation: a distance-to-target field per target, and the direction down its gradient.

Each target (a goal region, or a waypoint's neighbourhood) gets the shortest walking distance
from every cell of a regular grid, around obstacles: the solution of the eikonal equation
``|∇D| = 1`` with ``D = 0`` on the target, computed once when a scenario is prepared by fast
marching (Sethian 1996) with scikit-fmm (second-order stencil). Fast marching was chosen over an
iterative JAX eikonal solver because it visits each cell once (a Jacobi-style solver needs as
many sweeps as the grid is wide, thousands for a 1 km site at 0.25 m) and the fields are computed
once per scenario, on the host; the step only reads them.

Cells inside obstacles carry the distance continued into the obstacle (the nearest walkable
cell's value plus the step to it) for a band of a few cells, so that interpolating next to a wall
gives a gradient along the wall, not into it; deeper obstacle cells and walkable cells that cannot
reach the target hold :data:`UNREACHABLE`.

An agent's desired direction is ``−∇D / |∇D|`` at its position, ``∇D`` by central differences
of the bilinearly interpolated field (half a cell either side). The fields are one array
``(targets, nx, nz)`` of float32: ``targets × cells × 4`` bytes.

Conventions: ground points ``[x, z]`` in metres; cell ``(i, k)`` has its centre at
``origin + (i + ½, k + ½)·cell``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import shapely
import skfmm
from jaxtyping import Array, Bool, Float, Int

from jcrowd.errors import JcrowdError

__all__ = [
    "UNREACHABLE",
    "FieldGrid",
    "Navigation",
    "desired_directions",
    "distance_field",
    "field_grid",
    "field_values",
    "rasterize",
]

UNREACHABLE = 1e6
"""Field value (m) of cells that cannot reach the target, and deep inside obstacles."""

_BAND = 3  # obstacle cells next to walkable ones that get a continued distance


@dataclass(frozen=True)
class FieldGrid:
    """The static shape of the navigation grid: lower corner ``origin`` (m), ``cell`` (m),
    ``shape`` = cells along x and z."""

    origin: tuple[float, float]
    cell: float
    shape: tuple[int, int]

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates ``(x (nx, nz), z (nx, nz))``."""
        x = self.origin[0] + (np.arange(self.shape[0]) + 0.5) * self.cell
        z = self.origin[1] + (np.arange(self.shape[1]) + 0.5) * self.cell
        return np.meshgrid(x, z, indexing="ij")


def field_grid(lo: Sequence[float], hi: Sequence[float], cell: float = 0.25) -> FieldGrid:
    """A grid covering ``lo``–``hi`` (m) with one cell of margin on every side."""
    if not 0 < cell <= 0.25:
        raise JcrowdError(f"navigation: expected a cell size in (0, 0.25] m, found {cell}")
    nx = math.ceil((hi[0] - lo[0]) / cell) + 2
    nz = math.ceil((hi[1] - lo[1]) / cell) + 2
    return FieldGrid((float(lo[0]) - cell, float(lo[1]) - cell), float(cell), (nx, nz))


def rasterize(grid: FieldGrid, area: shapely.Geometry) -> Bool[np.ndarray, "nx nz"]:
    """Cells whose centre lies in ``area`` (boundary included)."""
    x, z = grid.centres()
    return np.asarray(shapely.intersects_xy(area, x, z))


def distance_field(
    grid: FieldGrid,
    walkable: Bool[np.ndarray, "nx nz"],
    target: Bool[np.ndarray, "nx nz"],
    *,
    clearance: float = 0.0,
) -> Float[np.ndarray, "nx nz"]:
    """Shortest walking distance (m) from every cell to the ``target`` cells, around obstacles.

    With ``clearance > 0`` (m) the field is the travel time at unit speed through a medium that
    slows towards walls, ``speed = 0.25 + 0.75·min(1, d_wall / clearance)`` (``d_wall``: the
    cell's distance to the nearest obstacle), so the paths it sends agents on keep off walls and
    corners (a shortest path touches every corner it turns around) yet still pass gaps narrower
    than ``2·clearance``; far from walls it equals the distance.

    Target cells hold 0 … −½ cell (the signed distance inside the target); see the module
    docstring for obstacle and unreachable cells.

    Raises:
        JcrowdError: no walkable target cell.
    """
    goal = target & walkable
    if not goal.any():
        raise JcrowdError("navigation: the target covers no walkable cell")
    phi = np.ma.MaskedArray(np.where(goal, -1.0, 1.0), mask=~walkable)
    if clearance > 0 and (~walkable).any():
        wall = np.asarray(skfmm.distance(np.where(walkable, 1.0, -1.0), dx=grid.cell))
        speed = 0.25 + 0.75 * np.clip(wall / clearance, 0.0, 1.0)
        d = skfmm.travel_time(phi, np.ma.MaskedArray(speed, mask=~walkable), dx=grid.cell)
        d = np.ma.where(goal, -np.ma.abs(d), d)  # travel times are unsigned; the target is ≤ 0
    else:
        d = skfmm.distance(phi, dx=grid.cell, order=2)
    reached = walkable & ~np.ma.getmaskarray(d)
    field = np.where(reached, np.ma.getdata(d), UNREACHABLE)
    return _continue_into_obstacles(field, reached, ~walkable, grid.cell).astype(np.float32)


def _continue_into_obstacles(
    field: np.ndarray, known: np.ndarray, obstacle: np.ndarray, cell: float
) -> np.ndarray:
    """Give ``_BAND`` obstacle cells beyond the known ones their best neighbour's value plus the
    step to it (walkable cells that cannot reach the target stay unreachable)."""
    field, known = field.copy(), known.copy()
    steps = [(di, dk, cell * math.hypot(di, dk)) for di in (-1, 0, 1) for dk in (-1, 0, 1)]
    for _ in range(_BAND):
        padded = np.pad(np.where(known, field, np.inf), 1, constant_values=np.inf)
        best = np.full(field.shape, np.inf)
        for di, dk, step in steps:
            if di == dk == 0:
                continue
            shifted = padded[1 + di : 1 + di + field.shape[0], 1 + dk : 1 + dk + field.shape[1]]
            best = np.minimum(best, shifted + step)
        new = ~known & obstacle & np.isfinite(best)
        field[new] = best[new]
        known |= new
    return field


class Navigation(eqx.Module):
    """Distance fields on one grid: ``fields`` ``(targets, nx, nz)`` float32 (m)."""

    fields: Float[Array, "T nx nz"]
    grid: FieldGrid = eqx.field(static=True)


def field_values(nav: Navigation, target: Int[Array, " N"], x: Array, z: Array) -> Array:
    """Bilinear interpolation of each agent's target field at ``(x, z)`` (clamped to the grid)."""
    g = nav.grid
    i0, fu = _corner(g.origin[0], g.cell, g.shape[0], x)
    k0, fv = _corner(g.origin[1], g.cell, g.shape[1], z)
    nz = g.shape[1]
    # One flat index per corner: XLA:CPU gathers from a 1-D table several times faster than
    # with a (target, i, k) index triple.
    c00 = (target * g.shape[0] + i0) * nz + k0
    f = nav.fields.reshape(-1)
    return (
        f[c00] * (1 - fu) * (1 - fv)
        + f[c00 + nz] * fu * (1 - fv)
        + f[c00 + 1] * (1 - fu) * fv
        + f[c00 + nz + 1] * fu * fv
    )


def desired_directions(
    nav: Navigation, target: Int[Array, " N"], position: Float[Array, "N 2"]
) -> Float[Array, "N 2"]:
    """Unit ``−∇D`` of each agent's target field at its position (0 where the field is flat):
    the central difference ``D(x + h) − D(x − h)`` of the bilinear field along each axis,
    ``h`` half a cell.

    The four bilinear lookups read nodes of one 3 × 3 block of the grid, so the block is read
    once (9 reads, not 16) and each lookup picks its corners from it.
    """
    g = nav.grid
    h = 0.5 * g.cell
    x, z = position[:, 0], position[:, 1]
    ix = [_corner(g.origin[0], g.cell, g.shape[0], x + d) for d in (-h, 0.0, h)]
    kz = [_corner(g.origin[1], g.cell, g.shape[1], z + d) for d in (-h, 0.0, h)]
    # Every lookup's lower corner is the block's first node or the next (floors of points
    # half a cell apart differ by at most one).
    a = jnp.minimum(ix[0][0], g.shape[0] - 3)
    b = jnp.minimum(kz[0][0], g.shape[1] - 3)
    nz = g.shape[1]
    flat = nav.fields.reshape(-1)
    base = (target * g.shape[0] + a) * nz + b
    block = [[flat[base + i * nz + k] for k in range(3)] for i in range(3)]

    def lookup(i: tuple[Array, Array], k: tuple[Array, Array]) -> Array:
        (i0, fu), (k0, fv) = i, k
        # Rounding can floor x + h two nodes past the block's first when it lands on a node
        # (under jit, (x + h − origin)/cell came out 335.0 where x − h gave 333.99997): that
        # is the block's last node, weight fu + 1 = 1 from the node before it.
        fu = jnp.where(i0 == a + 2, fu + 1.0, fu)
        fv = jnp.where(k0 == b + 2, fv + 1.0, fv)
        di, dk = i0 == a, k0 == b  # lower corner at the block's first row / column

        def node(r: int, c: int) -> Array:
            row = [jnp.where(di, block[r][q], block[r + 1][q]) for q in (c, c + 1)]
            return jnp.where(dk, row[0], row[1])

        return (
            node(0, 0) * (1 - fu) * (1 - fv)
            + node(1, 0) * fu * (1 - fv)
            + node(0, 1) * (1 - fu) * fv
            + node(1, 1) * fu * fv
        )

    gx = lookup(ix[2], kz[1]) - lookup(ix[0], kz[1])
    gz = lookup(ix[1], kz[2]) - lookup(ix[1], kz[0])
    sq = gx * gx + gz * gz
    # 0 where the field is flat, with a gradient of 0 there (sqrt's is infinite: NaN).
    norm = jnp.where(sq > 0.0, jnp.sqrt(jnp.where(sq > 0.0, sq, 1.0)), 0.0)
    safe = jnp.maximum(norm, 1e-9)
    return jnp.where(norm[:, None] > 1e-9, -jnp.stack([gx, gz], axis=1) / safe[:, None], 0.0)


def _corner(origin: float, cell: float, n: int, x: Array) -> tuple[Array, Array]:
    """The lower interpolation node along one axis (int32) and the weight of the upper one, as
    :func:`field_values` clamps them."""
    u = jnp.clip((x - origin) / cell - 0.5, 0.0, n - 1.0)
    i0 = jnp.minimum(jnp.floor(u), n - 2.0)
    return i0.astype(jnp.int32), u - i0
