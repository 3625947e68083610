"""Ground geometry: :class:`Region` (rect, circle, polygon) and the polygon operations under it.

A point is ``[x, z]`` in metres (the ground is the x–z plane, y up). Polygons are simple (no
crossing or touching edges) with positive area; either orientation is accepted. They are sampled
through an ear-clipping triangulation, each triangle chosen with probability proportional to its
area, so samples are uniform over the polygon.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from jaxtyping import Bool, Float

from jcrowd.scenario.check import Problem, real, reals, require
from jcrowd.scenario.check import points as point_list

__all__ = [
    "MIN_POLYGON_AREA_M2",
    "Region",
    "polygon_area",
    "polygon_contains",
    "polygon_problem",
    "sample_triangles",
    "triangulate",
]

MIN_POLYGON_AREA_M2 = 1e-6
"""Polygons of this area or less are degenerate (collinear points)."""


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def polygon_area(points: Float[np.ndarray, "P 2"]) -> float:
    """Signed area (shoelace, m²); positive when the points turn from +x towards +z."""
    nxt = np.roll(points, -1, axis=0)
    return 0.5 * float(np.sum(_cross(points, nxt)))


def _crossing_edges(points: np.ndarray) -> tuple[int, int] | None:
    """First pair of edges that cross or touch (edge k joins points[k] and points[k+1])."""
    n = len(points)
    a, b = points, np.roll(points, -1, axis=0)
    # Two edges that meet at their shared vertex must not fold back over each other.
    fold = (_cross(b - a, np.roll(b - a, -1, axis=0)) == 0) & (
        np.sum((a - b) * (np.roll(b, -1, axis=0) - b), axis=1) > 0
    )
    if fold.any():
        k = int(np.argmax(fold))
        return k, (k + 1) % n
    A, B, C, D = a[:, None], b[:, None], a[None], b[None]
    d1, d2 = _cross(D - C, A - C), _cross(D - C, B - C)
    d3, d4 = _cross(B - A, C - A), _cross(B - A, D - A)

    def on(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        return np.all((np.minimum(p, q) <= r) & (r <= np.maximum(p, q)), axis=-1)

    hit = ((d1 * d2 < 0) & (d3 * d4 < 0)) | (
        ((d1 == 0) & on(C, D, A))
        | ((d2 == 0) & on(C, D, B))
        | ((d3 == 0) & on(A, B, C))
        | ((d4 == 0) & on(A, B, D))
    )
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    hit &= (j > i + 1) & ~((i == 0) & (j == n - 1))
    if not hit.any():
        return None
    first = np.argwhere(hit)[0]
    return int(first[0]), int(first[1])


def polygon_problem(points: Float[np.ndarray, "P 2"]) -> str | None:
    """Why ``points`` is not a simple polygon of positive area ("expected …, found …"), or None."""
    n = len(points)
    if n < 3:
        return f"expected at least 3 points [x, z], found {n}"
    same = np.all(points == np.roll(points, -1, axis=0), axis=1)
    if same[-1]:
        return (
            "expected distinct points, found the last point repeating points[0] "
            "(a polygon closes by itself)"
        )
    if same.any():
        k = int(np.argmax(same))
        return f"expected distinct consecutive points, found points[{k + 1}] repeating points[{k}]"
    centred = points - points.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False)
    if spread[1] <= 1e-12 * spread[0]:
        return "expected points spanning an area, found them all on one line (collinear)"
    crossing = _crossing_edges(points)
    if crossing is not None:
        i, j = crossing
        return (
            f"expected a simple polygon, found edges {i} and {j} crossing or touching "
            f"(edge k joins points[k] and points[k+1])"
        )
    area = abs(polygon_area(points))
    if area <= MIN_POLYGON_AREA_M2:
        return f"expected a polygon of area > {MIN_POLYGON_AREA_M2:g} m², found {area:.3g} m²"
    return None


def _in_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Points ``p`` inside or on the positively oriented triangle ``abc``."""
    return (_cross(b - a, p - a) >= 0) & (_cross(c - b, p - b) >= 0) & (_cross(a - c, p - c) >= 0)


def triangulate(points: Float[np.ndarray, "P 2"]) -> Float[np.ndarray, "T 3 2"]:
    """Ear-clipping triangulation of a simple polygon (positively oriented triangles).

    A vertex where the boundary runs straight on is dropped without a triangle, so T ≤ P − 2.
    """
    pts = np.asarray(points, np.float64)
    if polygon_area(pts) < 0:
        pts = pts[::-1]
    idx = list(range(len(pts)))
    triangles = []
    while len(idx) > 3:
        ring = pts[idx]
        prev, nxt = np.roll(ring, 1, axis=0), np.roll(ring, -1, axis=0)
        turn = _cross(ring - prev, nxt - ring)
        m, ear = len(idx), -1
        for k in range(m):
            if turn[k] == 0:
                ear = k
                break
            others = np.delete(ring, [(k - 1) % m, k, (k + 1) % m], axis=0)
            if turn[k] > 0 and not _in_triangle(others, prev[k], ring[k], nxt[k]).any():
                ear = k
                break
        if ear < 0:  # only round-off can leave a simple polygon without an ear
            ear = int(np.argmax(turn))
        if turn[ear] != 0:
            triangles.append(np.stack([prev[ear], ring[ear], nxt[ear]]))
        del idx[ear]
    triangles.append(pts[idx])
    return np.stack(triangles)


def sample_triangles(
    triangles: Float[np.ndarray, "T 3 2"], rng: np.random.Generator, n: int
) -> Float[np.ndarray, "n 2"]:
    """``n`` points uniform over the union of ``triangles`` (which must not overlap)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    area = 0.5 * np.abs(_cross(b - a, c - a))
    tri = rng.choice(len(triangles), size=n, p=area / area.sum())
    u = rng.random((n, 2))
    flip = u.sum(axis=1) > 1.0  # reflect the far half of the unit square onto the triangle
    u[flip] = 1.0 - u[flip]
    return a[tri] + u[:, :1] * (b[tri] - a[tri]) + u[:, 1:] * (c[tri] - a[tri])


def polygon_contains(
    polygon: Float[np.ndarray, "P 2"], points: Float[np.ndarray, "M 2"]
) -> Bool[np.ndarray, " M"]:
    """Even–odd rule: inside when a ray towards +x crosses the boundary an odd number of times."""
    x, z = points[:, 0], points[:, 1]
    inside = np.zeros(len(points), bool)
    n = len(polygon)
    for i in range(n):
        (xi, zi), (xj, zj) = polygon[i], polygon[(i + 1) % n]
        if zi == zj:  # a horizontal edge is never crossed by a horizontal ray
            continue
        straddles = (zi > z) != (zj > z)
        inside ^= straddles & (x < xi + (z - zi) * (xj - xi) / (zj - zi))
    return inside


@dataclass(frozen=True, eq=False)
class Region:
    """An area of the ground: a rectangle, a circle or a simple polygon (x–z, metres).

    ``kind`` is ``"rect"`` (axis-aligned: ``center`` and ``size = [width along x, depth along
    z]``), ``"circle"`` (``center``, ``radius``) or ``"polygon"`` (``points``: ≥ 3, no crossing
    or touching edges, positive area, either orientation, not closed by repeating the first
    point). Fields a kind does not use keep their defaults. ``sample`` is uniform over the area.
    """

    kind: str
    center: Float[np.ndarray, " 2"] = field(default_factory=lambda: np.zeros(2))
    size: Float[np.ndarray, " 2"] = field(default_factory=lambda: np.zeros(2))
    radius: float = 0.0
    points: Float[np.ndarray, "P 2"] = field(default_factory=lambda: np.zeros((0, 2)))
    _triangles: np.ndarray = field(init=False, repr=False, default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        put = object.__setattr__
        kinds = '"rect", "circle" or "polygon"'
        require(self.kind in ("rect", "circle", "polygon"), "shape", kinds, self.kind)
        if self.kind == "polygon":
            points = point_list(self.points, "points")
            problem = polygon_problem(points)
            if problem is not None:
                raise Problem("points", problem)
            put(self, "points", points)
            put(self, "_triangles", triangulate(points))
            return
        put(self, "center", reals(self.center, "center", "[x, z] (m)", 2))
        if self.kind == "rect":
            size = reals(self.size, "size", "[width, depth] (m)", 2)
            require(np.all(size > 0), "size", "[width, depth] both > 0 (m)", self.size)
            put(self, "size", size)
        else:
            require(
                real(self.radius) and self.radius > 0,
                "radius",
                "a radius > 0 (m)",
                self.radius,
            )
            put(self, "radius", float(self.radius))

    @classmethod
    def rect(cls, center: Sequence[float], size: Sequence[float]) -> Region:
        return cls("rect", center=np.asarray(center, np.float64), size=np.asarray(size, np.float64))

    @classmethod
    def circle(cls, center: Sequence[float], radius: float) -> Region:
        return cls("circle", center=np.asarray(center, np.float64), radius=radius)

    @classmethod
    def polygon(cls, points: Sequence[Sequence[float]]) -> Region:
        return cls("polygon", points=np.asarray(points, np.float64))

    @property
    def area(self) -> float:
        """Area in m²."""
        if self.kind == "rect":
            return float(self.size[0] * self.size[1])
        if self.kind == "circle":
            return math.pi * self.radius**2
        return abs(polygon_area(self.points))

    def bounds(self) -> tuple[Float[np.ndarray, " 2"], Float[np.ndarray, " 2"]]:
        """Axis-aligned bounding box ``(lo, hi)``, each ``[x, z]``."""
        if self.kind == "rect":
            return self.center - self.size / 2, self.center + self.size / 2
        if self.kind == "circle":
            return self.center - self.radius, self.center + self.radius
        return self.points.min(axis=0), self.points.max(axis=0)

    def sample(self, rng: np.random.Generator, n: int) -> Float[np.ndarray, "n 2"]:
        """``n`` points uniform over the region, ``(n, 2)`` float64."""
        if self.kind == "rect":
            return self.center + (rng.random((n, 2)) - 0.5) * self.size
        if self.kind == "circle":
            r = self.radius * np.sqrt(rng.random(n))  # √u: uniform per unit area, not per radius
            angle = rng.uniform(0.0, 2.0 * math.pi, n)
            return self.center + r[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        return sample_triangles(self._triangles, rng, n)

    def contains(self, points: Float[np.ndarray, "M 2"]) -> Bool[np.ndarray, " M"]:
        """Which of ``points`` lie in the region (boundary included for rects and circles)."""
        p = np.asarray(points, np.float64).reshape(-1, 2)
        if self.kind == "rect":
            return np.all(np.abs(p - self.center) <= self.size / 2, axis=1)
        if self.kind == "circle":
            return np.sum((p - self.center) ** 2, axis=1) <= self.radius**2
        return polygon_contains(self.points, p)
