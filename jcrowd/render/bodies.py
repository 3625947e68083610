"""Skinned bodies, blob shadows and the sky for :class:`~jcrowd.render.CrowdRenderer` (issue 20).

A level drawn as bodies (:class:`~jcrowd.motion.body.SkinnedLevel`) owns one mesh and one
instanced draw. Per frame the host finds each valid agent's kept-joint frames in the points the
step placed (:func:`~jcrowd.motion.body.frames_from_points`) and writes them, as the rows of
``[h R | p]`` (three RGBA32F texels per joint, one texture row per agent), into a float
texture allocated once for the level's capacity; the vertex shader blends its four joints,
``Σ_k w_k (h R_k l_k + p_k)`` (linear-blend skinning, :func:`jcrowd.motion.body.skin`), and its
normal by ``Σ_k w_k R_k``. Each vertex has a clothing region (skin, top, bottom, shoes) coloured
per agent: ``colors`` of a level are ``(C, 3)`` (the top; the bottom is it darkened, the skin a
fixed tone) or ``(C, 3, 3)`` (skin, top, bottom).

Blob shadows: a soft dark disc on the ground under each body (radius 0.28 × height), drawn
after the ground with blending. The sky: a gradient from the background colour at the horizon
to a deeper blue overhead, from each pixel's view ray (so it meets the ground's fade).
"""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np

from jcrowd.errors import RenderError
from jcrowd.motion.body import SkinnedLevel, frames_from_points

__all__ = [
    "BLOB_FRAGMENT",
    "BLOB_VERTEX",
    "BODY_VERTEX",
    "SHOE_COLOR",
    "SKIN_TONE",
    "SKY_FRAGMENT",
    "SKY_VERTEX",
    "BodyLevel",
    "body_colors",
    "tint_palette",
]

SKIN_TONE = (0.80, 0.62, 0.50)
"""The skin colour when a level's colours give only the clothes' (RGB in [0, 1])."""
SHOE_COLOR = (0.16, 0.15, 0.14)
BOTTOM_SHADE = 0.55
"""Trousers are the top's colour times this when a level gives one colour per agent."""
SHADOW_RADIUS = 0.28
"""Blob shadow radius as a fraction of the agent's height."""

BODY_VERTEX = """
#version 330 core
uniform mat4 u_view_proj;
uniform sampler2D u_bones;   // row i: agent i; texels 3k..3k+2: rows of [h R_k | p_k]
uniform vec3 u_shoes;
in vec3 in_off0;
in vec3 in_off1;
in vec3 in_off2;
in vec3 in_off3;
in vec3 in_normal;
in vec4 in_bones;
in vec4 in_weights;
in float in_region;          // 0 skin, 1 top, 2 bottom, 3 shoes
in vec3 a_skin;              // per instance
in vec3 a_top;
in vec3 a_bottom;
out vec3 v_normal;
out vec3 v_color;
void main() {
    vec3 offs[4] = vec3[4](in_off0, in_off1, in_off2, in_off3);
    vec3 p = vec3(0.0);
    vec3 n = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        int j = int(in_bones[k] + 0.5);
        vec4 r0 = texelFetch(u_bones, ivec2(3 * j, gl_InstanceID), 0);
        vec4 r1 = texelFetch(u_bones, ivec2(3 * j + 1, gl_InstanceID), 0);
        vec4 r2 = texelFetch(u_bones, ivec2(3 * j + 2, gl_InstanceID), 0);
        vec3 o = offs[k];
        vec3 moved = vec3(dot(r0.xyz, o) + r0.w, dot(r1.xyz, o) + r1.w, dot(r2.xyz, o) + r2.w);
        p += in_weights[k] * moved;
        n += in_weights[k] * vec3(dot(r0.xyz, in_normal), dot(r1.xyz, in_normal),
                                  dot(r2.xyz, in_normal));
    }
    int region = int(in_region + 0.5);
    v_color = region == 0 ? a_skin : region == 1 ? a_top : region == 2 ? a_bottom : u_shoes;
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
        self.capacity = capacity
        self.num_kept = len(level.kept)
        self.num_points = int(max(level.kept.max(), level.ref_points.max())) + 1
        v = len(level.normals)
        data = np.concatenate(
            [
                np.asarray(level.offsets, np.float32).reshape(v, 12),
                np.asarray(level.normals, np.float32),
                np.asarray(level.bones, np.float32),
                np.asarray(level.weights, np.float32),
                np.asarray(level.region, np.float32)[:, None],
            ],
            axis=1,
        )
        self.vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(level.triangles, np.int32).tobytes())
        self.texture = ctx.texture((3 * self.num_kept, max(capacity, 1)), 4, dtype="f4")
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.staging = np.zeros((max(capacity, 1), 3 * self.num_kept, 4), np.float32)
        self.colors = ctx.buffer(reserve=max(capacity, 1) * 9 * 4)
        self.vao = ctx.vertex_array(
            prog,
            [
                (
                    self.vbo,
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
                (self.colors, "3f 3f 3f/i", "a_skin", "a_top", "a_bottom"),
            ],
            index_buffer=self.ibo,
            index_element_size=4,
        )
        self.count = 0
        self.roots = np.zeros((0, 3), np.float32)

    def stage(
        self, points: np.ndarray, valid: np.ndarray, colors: Any, heights: Any, where: str
    ) -> int:
        """Find the valid agents' frames and write them and their colours; returns how many."""
        rows = np.flatnonzero(valid)
        n = len(rows)
        self.count = n
        if n == 0:
            self.roots = np.zeros((0, 3), np.float32)
            return 0
        if heights is None:
            raise RenderError(f"{where}: a level drawn as bodies needs the agents' heights")
        h = np.asarray(heights, np.float64)[rows]
        pts = np.asarray(points)[rows]
        if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(h)) and np.all(h > 0)):
            raise RenderError(f"{where}: non-finite points or non-positive heights in a valid slot")
        rot, pos = frames_from_points(self.level, pts, h)
        mats = np.concatenate([rot * h[:, None, None, None], pos[..., None]], axis=-1)  # (n,K,3,4)
        self.staging[:n] = mats.reshape(n, 3 * self.num_kept, 4)
        self.texture.write(self.staging[:n].tobytes(), viewport=(0, 0, 3 * self.num_kept, n))
        cols = body_colors(np.asarray(colors)[rows])
        if not np.all(np.isfinite(cols)):
            raise RenderError(f"{where}: non-finite colours in a valid slot")
        self.colors.write(np.ascontiguousarray(cols, np.float32).tobytes())
        root = pts[:, 0]
        self.roots = np.stack([root[:, 0], root[:, 2], SHADOW_RADIUS * h], axis=1).astype(
            np.float32
        )
        return n

    def draw(self) -> None:
        if self.count:
            self.texture.use(location=0)
            self.vao.render(moderngl.TRIANGLES, instances=self.count)

    def release(self) -> None:
        for obj in (self.vao, self.colors, self.texture, self.ibo, self.vbo):
            obj.release()


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


def tint_palette(n: int, seed: int = 0) -> np.ndarray:
    """``(n, 3, 3)`` skin, top and trousers for agents ``0..n−1`` (``--color-by tint``): drawn
    from fixed palettes by a generator seeded with ``seed``, so an agent keeps its clothes from
    frame to frame and run to run; each colour varied by ±8 % in brightness."""
    rng = np.random.default_rng(seed)
    out = np.empty((n, 3, 3), np.float32)
    out[:, 0] = _SKIN_TONES[rng.integers(len(_SKIN_TONES), size=n)]
    out[:, 1] = _CLOTHES[rng.integers(len(_CLOTHES), size=n)]
    out[:, 2] = _TROUSERS[rng.integers(len(_TROUSERS), size=n)]
    out *= rng.uniform(0.92, 1.08, size=(n, 3, 1)).astype(np.float32)
    return np.clip(out, 0.0, 1.0)
