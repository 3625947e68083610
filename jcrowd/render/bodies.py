"""Skinned bodies, blob shadows and the sky for :class:`~jcrowd.render.CrowdRenderer`.

A level drawn as bodies (:class:`~jcrowd.motion.skinning.SkinnedLevel`) has every resolution of the
body. Per frame the host finds each valid agent's kept-joint frames in the points the step
placed (:func:`~jcrowd.motion.skinning.frames_from_points`) and its height on screen, sorts the
agents by the mesh that height asks for (:data:`MESH_PIXELS`), and writes one texture row per
agent (allocated once for the level's capacity): three RGBA32F texels per kept joint, the rows
of ``[h R | p]``, then three for its skin, top and bottom colours. One instanced draw per mesh
in use reads rows ``u_row0 + gl_InstanceID``; the vertex shader blends its four joints,
``Σ_k w_k (h R_k l_k + p_k)`` (linear-blend skinning, :func:`jcrowd.motion.skinning.skin`), and its
normal by ``Σ_k w_k R_k``. Each vertex has a clothing region (skin, top, bottom, shoes);
``colors`` of a level are ``(C, 3)`` (the top; the bottom is it darkened, the skin a fixed tone)
or ``(C, 3, 3)`` (skin, top, bottom).

Why per agent: on a software rasteriser (llvmpipe, this project's CI and demo) a frame costs
about what its triangles do, and a level is a band of distances, not of sizes on screen: a
close-up needs the fine mesh at level 0, while most agents of a level are small enough for a
coarser one (``docs/design/render.md`` has the plaza demo's frame times).

Blob shadows: a soft dark disc on the ground under each body (radius 0.28 × height), drawn
after the ground with blending. The sky: a gradient from the background colour at the horizon
to a deeper blue overhead, from each pixel's view ray (so it meets the ground's fade).
"""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np

from jcrowd.errors import RenderError
from jcrowd.motion.skinning import SkinnedLevel, frames_from_points
from jcrowd.render.levels import LevelInstances

__all__ = [
    "BLOB_FRAGMENT",
    "BLOB_VERTEX",
    "BODY_VERTEX",
    "MESH_PIXELS",
    "SHOE_COLOR",
    "SKIN_TONE",
    "SKY_FRAGMENT",
    "SKY_VERTEX",
    "BodyLevel",
    "body_colors",
    "pick_meshes",
    "stage_bodies",
    "tint_palette",
]

SKIN_TONE = (0.80, 0.62, 0.50)
"""The skin colour when a level's colours give only the clothes' (RGB in [0, 1])."""
SHOE_COLOR = (0.16, 0.15, 0.14)
BOTTOM_SHADE = 0.55
"""Trousers are the top's colour times this when a level gives one colour per agent."""
SHADOW_RADIUS = 0.28
"""Blob shadow radius as a fraction of the agent's height."""

MESH_PIXELS = (600.0, 250.0, 120.0, 60.0)
"""An agent at least ``MESH_PIXELS[m]`` pixels tall on screen is drawn with mesh ``m`` (finest
first), a smaller one with the next; below the last, the coarsest. With the shipped body that
is 5–12 triangles per pixel of height below 600 px: on the plaza demo these draw the fewest
triangles of the thresholds compared in ``docs/design/render.md``, with no visible difference
at 2× zoom."""

BODY_VERTEX = """
#version 330 core
uniform mat4 u_view_proj;
uniform sampler2D u_bones;   // row: an agent; texels 3k..3k+2: rows of [h R_k | p_k]
uniform int u_row0;          // the first agent row of this draw
uniform int u_colors_at;     // texel of the agent's skin colour (then top, bottom)
uniform vec3 u_shoes;
in vec3 in_off0;
in vec3 in_off1;
in vec3 in_off2;
in vec3 in_off3;
in vec3 in_normal;
in vec4 in_bones;
in vec4 in_weights;
in float in_region;          // 0 skin, 1 top, 2 bottom, 3 shoes
out vec3 v_normal;
out vec3 v_color;
void main() {
    vec3 offs[4] = vec3[4](in_off0, in_off1, in_off2, in_off3);
    int row = u_row0 + gl_InstanceID;
    vec3 p = vec3(0.0);
    vec3 n = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        int j = int(in_bones[k] + 0.5);
        vec4 r0 = texelFetch(u_bones, ivec2(3 * j, row), 0);
        vec4 r1 = texelFetch(u_bones, ivec2(3 * j + 1, row), 0);
        vec4 r2 = texelFetch(u_bones, ivec2(3 * j + 2, row), 0);
        vec3 o = offs[k];
        vec3 moved = vec3(dot(r0.xyz, o) + r0.w, dot(r1.xyz, o) + r1.w, dot(r2.xyz, o) + r2.w);
        p += in_weights[k] * moved;
        n += in_weights[k] * vec3(dot(r0.xyz, in_normal), dot(r1.xyz, in_normal),
                                  dot(r2.xyz, in_normal));
    }
    int region = int(in_region + 0.5);
    v_color = region < 3 ? texelFetch(u_bones, ivec2(u_colors_at + region, row), 0).rgb : u_shoes;
    v_normal = n;
    gl_Position = u_view_proj * vec4(p, 1.0);
}
"""

BLOB_VERTEX = """
#version 330 core
uniform mat4 u_view_proj;
in vec2 in_corner;   // [-1, 1]²
in vec3 a_center;    // per instance: x, z, radius
out vec2 v_uv;
void main() {
    v_uv = in_corner;
    vec2 xz = a_center.xy + a_center.z * in_corner;
    vec3 p = vec3(xz.x, 0.004, xz.y);
    gl_Position = u_view_proj * vec4(p, 1.0);
}
"""

BLOB_FRAGMENT = """
#version 330 core
in vec2 v_uv;
out vec4 f_color;
void main() {
    float r2 = dot(v_uv, v_uv);
    float a = 0.42 * (1.0 - smoothstep(0.15, 1.0, r2));
    f_color = vec4(0.0, 0.0, 0.0, a);
}
"""

SKY_VERTEX = """
#version 330 core
in vec2 in_corner;
out vec2 v_ndc;
void main() {
    v_ndc = in_corner;
    gl_Position = vec4(in_corner, 0.9999, 1.0);
}
"""

SKY_FRAGMENT = """
#version 330 core
uniform mat4 u_inv_view_proj;
uniform vec3 u_horizon;
uniform vec3 u_zenith;
in vec2 v_ndc;
out vec4 f_color;
void main() {
    vec4 a = u_inv_view_proj * vec4(v_ndc, -1.0, 1.0);
    vec4 b = u_inv_view_proj * vec4(v_ndc, 1.0, 1.0);
    vec3 dir = normalize(b.xyz / b.w - a.xyz / a.w);
    float up = clamp(dir.y, 0.0, 1.0);
    f_color = vec4(mix(u_horizon, u_zenith, sqrt(up)), 1.0);
}
"""

_FLOATS_PER_VERTEX = 12 + 3 + 4 + 4 + 1


def body_colors(colors: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` skin, top, bottom per agent from ``(n, 3)`` (module docstring) or
    ``(n, 3, 3)`` colours."""
    c = np.asarray(colors, np.float32)
    if c.ndim == 3:
        return c
    out = np.empty((len(c), 3, 3), np.float32)
    out[:, 0] = SKIN_TONE
    out[:, 1] = c
    out[:, 2] = BOTTOM_SHADE * c
    return out


class BodyLevel:
    """GL objects of one level drawn as skinned bodies (internal to the renderer)."""

    def __init__(
        self, ctx: moderngl.Context, prog: moderngl.Program, level: SkinnedLevel, capacity: int
    ) -> None:
        self.level = level
        self.prog = prog
        self.capacity = capacity
        self.num_kept = len(level.kept)
        self.num_points = int(max(level.kept.max(), level.ref_points.max())) + 1
        self.width = 3 * self.num_kept + 3
        self.texture = ctx.texture((self.width, max(capacity, 1)), 4, dtype="f4")
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.staging = np.zeros((max(capacity, 1), self.width, 4), np.float32)
        self._objects: list[Any] = [self.texture]
        self.vaos = []
        for mesh in level.meshes:
            v = len(mesh.normals)
            data = np.concatenate(
                [
                    np.asarray(mesh.offsets, np.float32).reshape(v, 12),
                    np.asarray(mesh.normals, np.float32),
                    np.asarray(mesh.bones, np.float32),
                    np.asarray(mesh.weights, np.float32),
                    np.asarray(mesh.region, np.float32)[:, None],
                ],
                axis=1,
            )
            vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
            ibo = ctx.buffer(np.ascontiguousarray(mesh.triangles, np.int32).tobytes())
            vao = ctx.vertex_array(
                prog,
                [
                    (
                        vbo,
                        "3f 3f 3f 3f 3f 4f 4f 1f",
                        "in_off0",
                        "in_off1",
                        "in_off2",
                        "in_off3",
                        "in_normal",
                        "in_bones",
                        "in_weights",
                        "in_region",
                    ),
                ],
                index_buffer=ibo,
                index_element_size=4,
            )
            self._objects += [vbo, ibo, vao]
            self.vaos.append(vao)
        self.runs: list[tuple[int, int, int]] = []  # (mesh, first row, agents)
        self.count = 0
        self.roots = np.zeros((0, 3), np.float32)

    def stage(
        self,
        points: np.ndarray,
        valid: np.ndarray,
        colors: Any,
        heights: Any,
        view_proj: np.ndarray,
        image_height: int,
        where: str,
    ) -> int:
        """Find the valid agents' frames and sizes on screen and write their rows; returns how
        many."""
        rows = np.flatnonzero(valid)
        n = len(rows)
        self.count = n
        self.runs = []
        if n == 0:
            self.roots = np.zeros((0, 3), np.float32)
            return 0
        if heights is None:
            raise RenderError(f"{where}: a level drawn as bodies needs the agents' heights")
        h = np.asarray(heights, np.float64)[rows]
        pts = np.asarray(points)[rows]
        if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(h)) and np.all(h > 0)):
            raise RenderError(f"{where}: non-finite points or non-positive heights in a valid slot")
        cols = body_colors(np.asarray(colors)[rows])
        if not np.all(np.isfinite(cols)):
            raise RenderError(f"{where}: non-finite colours in a valid slot")
        root = pts[:, 0]
        mesh = pick_meshes(root, h, view_proj, image_height, len(self.vaos))
        order = np.argsort(mesh, kind="stable")
        rot, pos = frames_from_points(self.level, pts[order], h[order])
        hk = h[order][:, None, None, None]
        mats = np.concatenate([rot * hk, pos[..., None]], axis=-1)  # (n, K, 3, 4)
        k3 = 3 * self.num_kept
        self.staging[:n, :k3] = mats.reshape(n, k3, 4)
        self.staging[:n, k3:, :3] = cols[order]
        self.texture.write(self.staging[:n].tobytes(), viewport=(0, 0, self.width, n))
        counts = np.bincount(mesh, minlength=len(self.vaos))
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.runs = [(m, int(first[m]), int(counts[m])) for m in range(len(self.vaos)) if counts[m]]
        self.roots = np.stack([root[:, 0], root[:, 2], SHADOW_RADIUS * h], axis=1).astype(
            np.float32
        )
        return n

    def draw(self) -> None:
        if not self.count:
            return
        self.texture.use(location=0)
        colors_at, row0 = self.prog["u_colors_at"], self.prog["u_row0"]
        if not (isinstance(colors_at, moderngl.Uniform) and isinstance(row0, moderngl.Uniform)):
            raise RenderError("the body shader lost its u_colors_at / u_row0 uniforms")
        colors_at.value = 3 * self.num_kept
        for m, first, count in self.runs:
            row0.value = first
            self.vaos[m].render(moderngl.TRIANGLES, instances=count)

    def release(self) -> None:
        for obj in reversed(self._objects):
            obj.release()


def stage_bodies(
    level: BodyLevel, data: LevelInstances, index: int, view_proj: np.ndarray, height: int
) -> int:
    """Check one body level's input and stage its valid agents' joint frames and colours."""
    where = f"CrowdRenderer.render: level {index}"
    points = np.asarray(data.joints)
    valid = np.asarray(data.valid)
    c = points.shape[0] if points.ndim else 0
    if points.ndim != 3 or points.shape[2] != 3 or points.shape[1] < level.num_points:
        raise RenderError(
            f"{where}: expected the step's points of shape (C, ≥{level.num_points}, 3), found "
            f"{points.shape}"
        )
    if c > level.capacity:
        raise RenderError(f"{where}: {c} slots passed, capacity is {level.capacity}")
    if valid.shape != (c,) or valid.dtype != np.bool_:
        raise RenderError(
            f"{where}: expected valid of shape ({c},) bool, found {valid.shape} {valid.dtype}"
        )
    colors = np.asarray(data.colors)
    if colors.shape not in ((c, 3), (c, 3, 3)):
        raise RenderError(
            f"{where}: expected colors of shape ({c}, 3) or ({c}, 3, 3), found {colors.shape}"
        )
    return level.stage(points, valid, colors, data.heights, view_proj, height, where)


def pick_meshes(
    root: np.ndarray, height: np.ndarray, view_proj: np.ndarray, image_height: int, meshes: int
) -> np.ndarray:
    """Each agent's mesh index (0 finest) from its height on screen (:data:`MESH_PIXELS`): the
    projected distance, in pixels, between its root on the ground and a point ``height`` above
    (an agent behind the camera takes the coarsest)."""
    n = len(root)
    feet = np.stack([root[:, 0], np.zeros(n), root[:, 2], np.ones(n)], axis=1)
    head = feet.copy()
    head[:, 1] = height
    a, b = feet @ view_proj.T, head @ view_proj.T
    ok = (a[:, 3] > 1e-6) & (b[:, 3] > 1e-6)
    ya = a[:, 1] / np.where(ok, a[:, 3], 1.0)
    yb = b[:, 1] / np.where(ok, b[:, 3], 1.0)
    px = np.where(ok, 0.5 * image_height * np.abs(yb - ya), 0.0)
    pick = np.searchsorted(-np.asarray(MESH_PIXELS), -px, side="right")
    return np.minimum(pick, meshes - 1).astype(np.int64)


_SKIN_TONES = np.array(
    [
        (0.96, 0.80, 0.69),
        (0.89, 0.69, 0.56),
        (0.80, 0.62, 0.50),
        (0.66, 0.48, 0.37),
        (0.49, 0.34, 0.25),
        (0.36, 0.25, 0.19),
    ],
    np.float32,
)
_CLOTHES = np.array(
    [
        (0.80, 0.22, 0.20),  # red
        (0.20, 0.36, 0.62),  # navy
        (0.93, 0.92, 0.88),  # white
        (0.20, 0.20, 0.22),  # black
        (0.36, 0.55, 0.33),  # green
        (0.93, 0.73, 0.24),  # mustard
        (0.55, 0.62, 0.70),  # grey-blue
        (0.62, 0.36, 0.58),  # plum
        (0.85, 0.52, 0.36),  # terracotta
        (0.45, 0.70, 0.82),  # sky
    ],
    np.float32,
)
_TROUSERS = np.array(
    [
        (0.18, 0.24, 0.38),  # denim
        (0.15, 0.15, 0.16),  # black
        (0.42, 0.38, 0.32),  # khaki
        (0.34, 0.34, 0.36),  # grey
        (0.55, 0.48, 0.38),  # sand
    ],
    np.float32,
)


def _mix(x: np.ndarray) -> np.ndarray:
    """A 64-bit integer mixing function (SplitMix64's finaliser) on uint64 arrays."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def tint_palette(n: int, seed: int = 0) -> np.ndarray:
    """``(n, 3, 3)`` skin, top and trousers for agents ``0..n−1`` (``--color-by tint``): each
    agent's picks from fixed palettes and ±8 % brightness come from a hash of its id and
    ``seed``, so an agent keeps its clothes from frame to frame, run to run, and whatever the
    crowd's size."""
    ids = np.arange(n, dtype=np.uint64) + np.uint64(1)
    with np.errstate(over="ignore"):
        h = [_mix(ids * np.uint64(0x9E3779B97F4A7C15) + np.uint64(seed * 7 + k)) for k in range(6)]
    out = np.empty((n, 3, 3), np.float32)
    for part, table in enumerate((_SKIN_TONES, _CLOTHES, _TROUSERS)):
        pick = (h[part] % np.uint64(len(table))).astype(np.int64)
        shade = 0.92 + 0.16 * (h[part + 3] >> np.uint64(11)).astype(np.float64) / 2.0**53
        out[:, part] = table[pick] * shade[:, None].astype(np.float32)
    return np.clip(out, 0.0, 1.0)
