"""Level of detail: importance, distance levels with hysteresis, frustum culling and a budget.

Paper 000 §5.1 picks an agent's accuracy level from its distance to the camera (full detail
nearer than 30 m, then coarser with distance); paper 003 §3 drops joints the same way. On top
of that sits a *budget* like a game engine's animation budget allocator (DESIGN §5): every
level has a static capacity; agents are ranked by importance and level 0 is filled first, then
level 1, …, each agent at least as coarse as its distance allows. Overflow goes coarser and is
counted, never dropped. Shapes are static, so the step compiles once whatever the histogram.

Importance is either closeness (``-distance``) or the projected height in pixels of a
``height``-metre character; both rank agents in the same order for one camera except for the
pixel measure's use of depth along the view axis instead of Euclidean distance.

Conventions: positions are ``(x, y, z)`` metres, y up; the camera looks from ``eye`` to
``target`` with a vertical field of view ``fov_deg`` and aspect ``width / height``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jcrowd.indexing import first_true, first_true_per_class

__all__ = [
    "Buckets",
    "CameraView",
    "assign_buckets",
    "distance_levels",
    "in_frustum",
    "screen_height_px",
]


class CameraView(eqx.Module):
    """A pinhole camera as traced arrays (changing it never recompiles the step)."""

    eye: Float[Array, " 3"]
    target: Float[Array, " 3"]
    fov_deg: Float[Array, ""]
    aspect: Float[Array, ""]
    height_px: Float[Array, ""]

    def basis(self) -> tuple[Array, Array, Array]:
        """Unit forward, right and up vectors of the camera (right-handed, y up)."""
        fwd = self.target - self.eye
        fwd = fwd / jnp.linalg.norm(fwd)
        right = jnp.cross(fwd, jnp.array([0.0, 1.0, 0.0], fwd.dtype))
        right = right / jnp.maximum(jnp.linalg.norm(right), 1e-9)
        up = jnp.cross(right, fwd)
        return fwd, right, up


Points = Float[Array, "N 3"] | tuple[Array, Array, Array]
"""Points as ``(N, 3)`` rows or as three ``(N,)`` coordinate arrays (the crowd step's layout)."""


def _view_coords(view: CameraView, points: Points) -> tuple[Array, Array, Array]:
    """Depth, right and up coordinates of points in the camera frame.

    Written per coordinate (three multiply-adds), not as ``(N, 3) @ (3,)``: XLA:CPU runs the
    latter as a separate matrix product per axis, where multiply-adds fuse with their neighbours.
    """
    fwd, right, up = view.basis()
    cols = points if isinstance(points, tuple) else (points[:, 0], points[:, 1], points[:, 2])
    d = [c - view.eye[k] for k, c in enumerate(cols)]

    def along(axis: Array) -> Array:
        return d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]

    return along(fwd), along(right), along(up)


def in_frustum(
    view: CameraView, points: Points, radius: float = 1.0, far: float = 1e4
) -> Bool[Array, " N"]:
    """Whether a sphere of ``radius`` around each point touches the view frustum.

    Conservative: a sphere less than ``radius`` outside every plane (near through the eye, the
    four sides, ``far``) counts, so nothing visible is culled; one near a corner may pass.
    """
    depth, x, y = _view_coords(view, points)
    tan_v = jnp.tan(jnp.deg2rad(view.fov_deg) / 2)
    tan_h = tan_v * view.aspect
    # Distance of the centre outside each side plane, measured perpendicular to the plane.
    out_h = (jnp.abs(x) - depth * tan_h) / jnp.sqrt(1 + tan_h**2)
    out_v = (jnp.abs(y) - depth * tan_v) / jnp.sqrt(1 + tan_v**2)
    return (depth > -radius) & (depth < far + radius) & (out_h < radius) & (out_v < radius)


def screen_height_px(
    view: CameraView, points: Points, height: Float[Array, " N"]
) -> Float[Array, " N"]:
    """Projected height in pixels of a ``height``-metre character standing at each point."""
    depth, _, _ = _view_coords(view, points)
    tan_v = jnp.tan(jnp.deg2rad(view.fov_deg) / 2)
    return height / (2 * jnp.maximum(depth, 1e-3) * tan_v) * view.height_px


def distance_levels(
    distance: Float[Array, " N"],
    previous: Int[Array, " N"],
    thresholds: Float[Array, " L1"],
    hysteresis: float,
) -> Int[Array, " N"]:
    """The finest level each agent's distance allows, with hysteresis.

    Without hysteresis the level is the number of thresholds the distance exceeds. With it, an
    agent only goes coarser once past ``threshold + hysteresis`` and finer once nearer than
    ``threshold − hysteresis``: the new level is ``previous`` clipped to that band, so an agent
    held anywhere inside the band never changes level.
    """
    thresholds = jnp.asarray(thresholds, distance.dtype)
    # One compare per threshold over the agents (an (N, L − 1) matrix reduced along its short
    # axis is a strided loop on XLA:CPU).
    lo = jnp.zeros(distance.shape, jnp.int32)
    hi = jnp.zeros(distance.shape, jnp.int32)
    for k in range(thresholds.shape[0]):
        lo = lo + (distance > thresholds[k] + hysteresis).astype(jnp.int32)
        hi = hi + (distance > thresholds[k] - hysteresis).astype(jnp.int32)
    return jnp.clip(previous, lo, hi).astype(jnp.int32)


class Buckets(eqx.Module):
    """Per-level slots of a budgeted assignment.

    Attributes:
        slots: one ``(C_l,)`` int32 array per level: agent ids, ``N`` in unused slots.
        valid: one ``(C_l,)`` bool array per level; the valid slots are always the leading ones
            (every branch fills a level from the front), so a consumer may stop at the first
            invalid slot.
        level: ``(N,)`` int32 final level; ``L`` (one past the last) for agents not placed.
        overflow: agents placed coarser than their distance allowed, because of capacity.
        unplaced: eligible agents that fit in no level (0 when the last capacity covers all).
    """

    slots: tuple[Int[Array, " C"], ...]
    valid: tuple[Bool[Array, " C"], ...]
    level: Int[Array, " N"]
    overflow: Int[Array, ""]
    unplaced: Int[Array, ""]


def assign_buckets(
    min_level: Int[Array, " N"],
    importance: Float[Array, " N"],
    eligible: Bool[Array, " N"],
    capacities: tuple[int, ...],
) -> Buckets:
    """Fill level 0 with the most important eligible agents, then level 1, … (static shapes).

    Level ``l`` takes the ``C_l`` most important agents not yet placed whose ``min_level`` is
    at most ``l``. That equals the greedy rule "in order of importance, each agent takes the
    first level at least as coarse as it may be that still has room". When every level's
    candidates fit (the usual frame) the result is simply each agent at its ``min_level``, in
    agent order, and a cheaper branch computes it (:func:`_unconstrained`); otherwise the greedy
    fill ranks by importance (:func:`_greedy`). One branch runs (a scalar predicate).
    """
    nlev = len(capacities)
    want = jnp.where(eligible, min_level, nlev)
    # One reduction per level: a single (N, L) comparison would be materialized as a matrix.
    fits = jnp.all(jnp.stack([jnp.sum(want == lv) <= cap for lv, cap in enumerate(capacities)]))
    return jax.lax.cond(
        fits,
        lambda: _unconstrained(want, capacities),
        lambda: _greedy(min_level, importance, eligible, capacities),
    )


def _unconstrained(want: Int[Array, " N"], capacities: tuple[int, ...]) -> Buckets:
    """Every eligible agent at its ``want`` level (``L``: none), when no level overflows.

    Then at most ``Σ C_l`` agents are eligible: one pass over all agents compacts them, and the
    levels are split from that short list (a pass over N per level would cost L times more).
    """
    n, nlev = want.shape[0], len(capacities)
    short = min(n, sum(capacities))
    placed = first_true(want < nlev, short, n)
    placed_level = jnp.where(placed < n, want[jnp.minimum(placed, n - 1)], nlev)
    slots, valid = [], []
    per_level = first_true_per_class(placed_level, tuple(min(c, short) for c in capacities), short)
    for k, cap in zip(per_level, capacities, strict=True):
        idx = jnp.where(k < short, placed[jnp.minimum(k, short - 1)], n).astype(jnp.int32)
        idx = jnp.pad(idx, (0, cap - idx.shape[0]), constant_values=n)
        slots.append(idx)
        valid.append(idx < n)
    zero = jnp.zeros((), jnp.int32)
    return Buckets(tuple(slots), tuple(valid), want.astype(jnp.int32), zero, zero)


def _greedy(
    min_level: Int[Array, " N"],
    importance: Float[Array, " N"],
    eligible: Bool[Array, " N"],
    capacities: tuple[int, ...],
) -> Buckets:
    """The greedy fill of :func:`assign_buckets`, ranking a level only when it overflows."""
    n = min_level.shape[0]
    placed = ~eligible
    level = jnp.full((n,), len(capacities), jnp.int32)
    slots, valid = [], []
    neg = jnp.asarray(-jnp.inf, importance.dtype)
    for lv, cap in enumerate(capacities):
        cand = (~placed) & (min_level <= lv)
        if cap >= n:
            idx = first_true(cand, cap, n)
            ok = idx < n
        else:
            # Rank only when the candidates overflow the level (one branch runs: the predicate
            # is a scalar outside any vmap); otherwise every candidate fits, in agent order.
            def ranked(cand: Array, cap: int = cap) -> tuple[Array, Array]:
                top, idx = jax.lax.top_k(jnp.where(cand, importance, neg), cap)
                ok = top > neg
                return jnp.where(ok, idx, n).astype(jnp.int32), ok

            def compact(cand: Array, cap: int = cap) -> tuple[Array, Array]:
                idx = first_true(cand, cap, n)
                return idx.astype(jnp.int32), idx < n

            idx, ok = jax.lax.cond(jnp.sum(cand) > cap, ranked, compact, cand)
        idx = idx.astype(jnp.int32)
        placed = placed.at[idx].set(True, mode="drop")
        level = level.at[idx].set(lv, mode="drop")
        slots.append(idx)
        valid.append(ok)
    overflow = jnp.sum(eligible & (level < len(capacities)) & (level > min_level))
    unplaced = jnp.sum(eligible & (level == len(capacities)))
    return Buckets(
        tuple(slots), tuple(valid), level, overflow.astype(jnp.int32), unplaced.astype(jnp.int32)
    )
