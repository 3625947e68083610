"""What a crowd frame is drawn from: the capsule and ground meshes, their shaders, the palettes.

A bone is drawn as a capsule (a cylinder with hemispherical caps) of radius ``r`` around the
segment from its parent joint to its joint. The capsule mesh is stored once per level of
detail in a *bone frame*: each vertex has a unit direction ``offset`` (x, y radial, z along the
bone) and an ``end`` flag (0 = the cap at the parent joint, 1 = the cap at the joint). The vertex
shader places it at ``mix(start, end, flag) + r · B · offset`` with ``B`` an orthonormal basis
whose z axis is the bone direction, so one mesh fits every bone length exactly (caps stay round)
and its normal is simply ``B · offset``. Joints shared by two bones are covered by both caps.

Obstacles and walls are prisms (:func:`prism_mesh`): the blocked area extruded from the ground
to :data:`OBSTACLE_HEIGHT_M`, its top triangulated (constrained Delaunay), lit like the bones.

The ground is one square at y = 0 whose grid (1 m minor, 10 m major lines) is drawn in the
fragment shader with screen-space derivatives, so lines stay one pixel wide at any distance
and fade before they alias; the square fades into the background towards its edge.
"""

from __future__ import annotations

import numpy as np
import shapely
from jaxtyping import Float, Int

from jcrowd.errors import RenderError

__all__ = [
    "CAPSULE_FRAGMENT",
    "CAPSULE_VERTEX",
    "GROUND_FRAGMENT",
    "GROUND_VERTEX",
    "GROUP_COLORS",
    "LEVEL_COLORS",
    "OBSTACLE_COLOR",
    "OBSTACLE_HEIGHT_M",
    "OBSTACLE_VERTEX",
    "capsule_detail",
    "capsule_mesh",
    "ground_mesh",
    "palette_colors",
    "prism_mesh",
]

OBSTACLE_HEIGHT_M = 1.0
"""Height obstacles and walls are drawn at (m): a barrier's, low enough to see people over."""

OBSTACLE_COLOR = (0.58, 0.52, 0.47)
"""Obstacles' colour (RGB in [0, 1]), a warm grey apart from the ground and the level ramp."""

LEVEL_COLORS: Float[np.ndarray, "10 3"] = np.array(
    [
        (0.86, 0.20, 0.16),  # level 0 (nearest, full skeleton): red
        (0.95, 0.55, 0.12),  # orange
        (0.90, 0.80, 0.18),  # yellow
        (0.38, 0.72, 0.30),  # green
        (0.16, 0.66, 0.64),  # teal
        (0.22, 0.58, 0.88),  # sky blue
        (0.20, 0.38, 0.86),  # blue
        (0.34, 0.30, 0.78),  # indigo
        (0.52, 0.30, 0.72),  # violet
        (0.40, 0.22, 0.56),  # deep purple (coarsest)
    ],
    np.float32,
)
"""One colour per LOD level, a hue ramp from red (near, full skeleton) through yellow and green
to blue and violet (far, coarse), as in paper 000 Fig. 6; neighbouring levels stay easy to tell
apart. Levels past the end reuse the last colour (``palette_colors(..., cycle=False)``)."""

GROUP_COLORS: Float[np.ndarray, "8 3"] = np.array(
    [
        (0.89, 0.33, 0.33),  # red
        (0.28, 0.52, 0.85),  # blue
        (0.34, 0.70, 0.38),  # green
        (0.96, 0.64, 0.18),  # orange
        (0.60, 0.40, 0.76),  # purple
        (0.22, 0.74, 0.76),  # cyan
        (0.86, 0.44, 0.70),  # pink
        (0.55, 0.44, 0.33),  # brown
    ],
    np.float32,
)
"""Distinct colours for agent groups (scenario spawn groups); group ``g`` uses entry
``g mod 8``."""


def palette_colors(
    indices: Int[np.ndarray, " C"], palette: Float[np.ndarray, "K 3"], *, cycle: bool = True
) -> Float[np.ndarray, "C 3"]:
    """Per-agent colours ``(C, 3)`` float32 from a palette: ``palette[indices]``.

    Args:
        indices: non-negative level or group index per agent.
        palette: ``(K, 3)`` colours in [0, 1], e.g. :data:`LEVEL_COLORS`.
        cycle: indices past the end wrap around (groups); False clamps to the last colour
            (levels, so a deeper level still looks "far").
    """
    idx = np.asarray(indices)
    pal = np.asarray(palette, np.float32)
    if pal.ndim != 2 or pal.shape[1] != 3 or len(pal) == 0:
        raise RenderError(f"palette_colors: expected a (K, 3) palette, found {pal.shape}")
    if idx.size and (not np.issubdtype(idx.dtype, np.integer) or idx.min() < 0):
        raise RenderError("palette_colors: expected non-negative integer indices")
    idx = idx % len(pal) if cycle else np.minimum(idx, len(pal) - 1)
    return pal[idx]


def capsule_detail(level: int) -> tuple[int, int]:
    """``(segments, rings)`` of the capsule mesh for LOD ``level``.

    ``segments`` vertices around the bone, ``rings`` latitude rings per cap. LOD levels are
    ordered from near to far, so deeper levels (smaller on screen) get fewer triangles: 64 per
    bone at level 0, 48 at level 1, 24 at level 2 and 16 from level 3 on. Software rasterisers
    spend their time in proportion to triangles, and finer capsules show nothing more at crowd
    scale (``bench/render.py --detail`` times a frame at another tessellation).
    """
    return ((8, 2), (6, 2), (6, 1))[level] if level < 3 else (4, 1)


def capsule_mesh(
    segments: int, rings: int
) -> tuple[Float[np.ndarray, "V 4"], Int[np.ndarray, "T 3"]]:
    """The unit capsule in its bone frame (see the module docstring).

    Args:
        segments: vertices around each ring (≥ 3).
        rings: latitude rings per hemispherical cap, the equator included (≥ 1).

    Returns:
        ``(vertices, triangles)``: ``vertices (V, 4)`` float32 rows ``(ox, oy, oz, end)`` with
        ``(ox, oy, oz)`` a unit vector, ``V = 2 + 2 · rings · segments``; ``triangles (T, 3)``
        uint32, counter-clockwise seen from outside (front faces for back-face culling).
    """
    if segments < 3 or rings < 1:
        raise RenderError(
            f"capsule_mesh: expected segments ≥ 3 and rings ≥ 1, found {segments}, {rings}"
        )
    theta = 2.0 * np.pi * np.arange(segments) / segments
    # Polar angle from the start pole (-z) to the end pole (+z); the equator appears twice,
    # once per cap, and the band between the two copies is the cylinder.
    polar = np.concatenate(
        [
            np.arange(1, rings + 1) / rings * (np.pi / 2),
            np.pi - np.arange(rings, 0, -1) / rings * (np.pi / 2),
        ]
    )
    ends = np.repeat([0.0, 1.0], rings)
    ring_xyz = np.stack(
        [
            np.sin(polar)[:, None] * np.cos(theta)[None, :],
            np.sin(polar)[:, None] * np.sin(theta)[None, :],
            np.broadcast_to(-np.cos(polar)[:, None], (2 * rings, segments)),
        ],
        axis=-1,
    )
    ring_rows = np.concatenate(
        [ring_xyz, np.broadcast_to(ends[:, None, None], (2 * rings, segments, 1))], axis=-1
    ).reshape(-1, 4)
    vertices = np.concatenate([[(0.0, 0.0, -1.0, 0.0)], ring_rows, [(0.0, 0.0, 1.0, 1.0)]])

    m = np.arange(segments)
    m1 = (m + 1) % segments
    last = len(vertices) - 1
    tris = [np.stack([np.zeros(segments, np.int64), 1 + m1, 1 + m], axis=-1)]  # start-pole fan
    for i in range(2 * rings - 1):
        a, b = 1 + i * segments + m, 1 + i * segments + m1  # ring i (towards the start)
        c, d = b + segments, a + segments  # ring i + 1 (towards the end)
        tris += [np.stack([a, b, c], axis=-1), np.stack([a, c, d], axis=-1)]
    base = 1 + (2 * rings - 1) * segments
    tris.append(np.stack([base + m, base + m1, np.full(segments, last)], axis=-1))  # end fan
    return vertices.astype(np.float32), np.concatenate(tris).astype(np.uint32)


def _facing(tri: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The triangles ``(T, 3, 3)`` wound counter-clockwise seen from where ``normal`` points
    (``(T, 3)``), the side GL draws with ``front_face = "ccw"``."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.sum(n * normal, axis=1) < 0
    out = tri.copy()
    out[flip, 1], out[flip, 2] = tri[flip, 2], tri[flip, 1]
    return out


def prism_mesh(
    area: shapely.Geometry, height: float = OBSTACLE_HEIGHT_M
) -> Float[np.ndarray, "V 6"]:
    """``area`` (polygons on the ground, ``[x, z]``) extruded to ``height``: triangle vertices as
    rows ``(x, y, z, nx, ny, nz)``, three per triangle — the top facing up, a wall outwards
    along every edge of every ring (holes included). Empty for an empty area."""
    polys = [g for g in getattr(area, "geoms", [area]) if isinstance(g, shapely.Polygon)]
    rows: list[np.ndarray] = []
    for poly in polys:
        if poly.is_empty:
            continue
        poly = shapely.geometry.polygon.orient(poly, sign=1.0)  # exterior CCW, holes CW in (x, z)
        tris = shapely.constrained_delaunay_triangles(poly)
        top = np.array([np.asarray(t.exterior.coords)[:3] for t in tris.geoms], np.float64)
        top3 = np.stack([top[..., 0], np.full(top.shape[:2], height), top[..., 1]], axis=-1)
        up = np.tile([0.0, 1.0, 0.0], (len(top3), 1))
        rows.append(_with_normals(_facing(top3, up), up))
        for ring in [poly.exterior, *poly.interiors]:
            xy = np.asarray(ring.coords)
            p, q = xy[:-1], xy[1:]
            d = q - p
            # Exterior CCW and holes CW (in x, z): the outside of the solid is on the right.
            out = np.stack([d[:, 1], np.zeros(len(d)), -d[:, 0]], axis=1)
            out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
            p0 = np.stack([p[:, 0], np.zeros(len(p)), p[:, 1]], axis=1)
            q0 = np.stack([q[:, 0], np.zeros(len(q)), q[:, 1]], axis=1)
            lift = np.array([0.0, height, 0.0])
            p1, q1 = p0 + lift, q0 + lift
            quads = np.concatenate([np.stack([p0, q0, q1], 1), np.stack([p0, q1, p1], 1)])
            normals = np.concatenate([out, out])
            rows.append(_with_normals(_facing(quads, normals), normals))
    if not rows:
        return np.zeros((0, 6), np.float32)
    return np.concatenate(rows).reshape(-1, 6).astype(np.float32)


def _with_normals(tri: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """``(T, 3, 6)``: each vertex of each triangle with its triangle's normal."""
    return np.concatenate([tri, np.repeat(normal[:, None, :], 3, axis=1)], axis=2)


def ground_mesh(size: float) -> Float[np.ndarray, "6 3"]:
    """Two triangles covering ``[-size/2, size/2]²`` at y = 0, facing up (CCW from above)."""
    h = size / 2.0
    a, b, c, d = (-h, 0.0, -h), (-h, 0.0, h), (h, 0.0, h), (h, 0.0, -h)
    return np.array([a, b, c, a, c, d], np.float32)


CAPSULE_VERTEX = """
#version 330 core
uniform mat4 u_view_proj;
uniform float u_radius;
in vec3 in_offset;   // unit direction in the bone frame (z along the bone)
in float in_end;     // 0: cap around the start (parent) joint, 1: around the end joint
in vec3 a_start;     // per instance (one bone of one agent)
in vec3 a_end;
in vec3 a_color;
out vec3 v_normal;
out vec3 v_color;
void main() {
    vec3 axis = a_end - a_start;
    float len = length(axis);
    vec3 w = len > 1e-6 ? axis / len : vec3(0.0, 1.0, 0.0);
    vec3 helper = abs(w.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    vec3 u = normalize(cross(helper, w));
    vec3 v = cross(w, u);  // (u, v, w) right-handed, so the mesh's winding is kept
    vec3 n = in_offset.x * u + in_offset.y * v + in_offset.z * w;
    vec3 p = (in_end > 0.5 ? a_end : a_start) + u_radius * n;
    v_normal = n;
    v_color = a_color;
    gl_Position = u_view_proj * vec4(p, 1.0);
}
"""

CAPSULE_FRAGMENT = """
#version 330 core
uniform vec3 u_light_dir;  // unit, towards the light
uniform float u_ambient;
in vec3 v_normal;
in vec3 v_color;
out vec4 f_color;
void main() {
    vec3 n = normalize(v_normal);
    // Lambert plus a hemispheric ambient (brighter facing the sky) so unlit sides keep shape.
    float sky = u_ambient * (0.75 + 0.25 * n.y);
    float lambert = (1.0 - u_ambient) * max(dot(n, u_light_dir), 0.0);
    f_color = vec4(v_color * (sky + lambert), 1.0);
}
"""

OBSTACLE_VERTEX = """
#version 330 core
uniform mat4 u_view_proj;
uniform vec3 u_color;
in vec3 in_position;
in vec3 in_normal;
out vec3 v_normal;
out vec3 v_color;
void main() {
    v_normal = in_normal;
    v_color = u_color;
    gl_Position = u_view_proj * vec4(in_position, 1.0);
}
"""
"""Obstacle prisms (:func:`prism_mesh`), shaded by :data:`CAPSULE_FRAGMENT`."""

GROUND_VERTEX = """
#version 330 core
uniform mat4 u_view_proj;
in vec3 in_position;
out vec3 v_world;
void main() {
    v_world = in_position;
    gl_Position = u_view_proj * vec4(in_position, 1.0);
}
"""

GROUND_FRAGMENT = """
#version 330 core
uniform vec3 u_ground;
uniform vec3 u_line;
uniform vec3 u_background;
uniform float u_half_size;
in vec3 v_world;
out vec4 f_color;

// 1 on a grid line of the given spacing, 0 away from it; lines about `width` pixels wide.
float grid(vec2 xz, float spacing, float width) {
    vec2 c = xz / spacing;
    vec2 px = max(fwidth(c), vec2(1e-6));
    vec2 dist = abs(fract(c - 0.5) - 0.5) / px;  // distance to the nearest line, in pixels
    return 1.0 - clamp(min(dist.x, dist.y) / width, 0.0, 1.0);
}

void main() {
    vec2 xz = v_world.xz;
    // Minor lines fade out where they come closer than ~5 pixels apart (before moiré).
    float density = max(fwidth(xz.x), fwidth(xz.y));
    float minor = grid(xz, 1.0, 1.0) * clamp(1.0 - (density - 0.1) / 0.15, 0.0, 1.0);
    float major = grid(xz, 10.0, 1.5) * clamp(1.0 - (density - 1.0) / 1.5, 0.0, 1.0);
    vec3 color = mix(u_ground, u_line, max(0.5 * minor, 0.9 * major));
    float edge = max(abs(xz.x), abs(xz.y)) / u_half_size;
    f_color = vec4(mix(color, u_background, smoothstep(0.6, 1.0, edge)), 1.0);
}
"""
