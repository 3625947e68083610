"""``CrowdRenderer``: one instanced draw per LOD level into an MSAA framebuffer, read back.

Per level the renderer owns one capsule mesh (:mod:`jcrowd.render.meshes`), one instance
buffer sized in ``__init__`` for ``capacity × bones`` instances and never reallocated, and one
vertex array binding both. A frame is:

1. per level, gather the valid agents' bones into a preallocated NumPy staging array of rows
   ``(start xyz, end xyz, colour rgb)`` (one host copy of the joints; device arrays are fine),
   and ``buffer.write`` it;
2. clear, draw each level with ``instances = valid agents × bones`` (one draw call), draw the
   ground, resolve the multisampled framebuffer into a plain one and read it back flipped so
   row 0 is the top of the image;
3. check the GL error flag.

Invalid (padding) slots are dropped by the gather, so they draw nothing whatever they hold;
points behind the camera are removed by ordinary clipping.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import TracebackType
from typing import Any

import moderngl
import numpy as np
from jaxtyping import Float

from jcrowd.errors import RenderError
from jcrowd.motion.skinning import SkinnedLevel
from jcrowd.render.bodies import (
    BLOB_FRAGMENT,
    BLOB_VERTEX,
    BODY_VERTEX,
    SHOE_COLOR,
    SKY_FRAGMENT,
    SKY_VERTEX,
    BodyLevel,
    stage_bodies,
)
from jcrowd.render.camera import View, projection_matrix, view_matrix
from jcrowd.render.capsules import CapsuleLevel, stage_capsules
from jcrowd.render.context import check_gl, gl_renderer, make_context
from jcrowd.render.levels import LevelInstances, LevelMesh
from jcrowd.render.meshes import (
    CAPSULE_FRAGMENT,
    CAPSULE_VERTEX,
    GROUND_FRAGMENT,
    GROUND_VERTEX,
    OBSTACLE_COLOR,
    OBSTACLE_VERTEX,
    capsule_detail,
    capsule_mesh,
    ground_mesh,
)

__all__ = ["CrowdRenderer"]

_LIGHT_DIR = np.array([0.35, 0.85, 0.40]) / np.linalg.norm([0.35, 0.85, 0.40])  # sun, from above
_AMBIENT = 0.40
_GROUND = (0.74, 0.74, 0.70)
_GRID_LINE = (0.52, 0.52, 0.50)
_ZENITH = (0.42, 0.60, 0.86)  # the sky overhead (sky=True); the horizon is the background


class CrowdRenderer:
    """Headless renderer of crowds of stick-capsule characters, one instanced draw per level.

    Args:
        levels: per LOD level, the parent index of each joint of that level's skeleton.
        width, height: image size in pixels.
        capacity: per level, the most agents (slots) a frame may pass; the instance buffers
            are allocated once with this size.
        samples: MSAA samples (0 or 1 = no multisampling; at most ``ctx.max_samples``).
        ctx: a moderngl context to draw with (left open by :meth:`release`); by default one
            is made with :func:`make_context` and released with the renderer.
        bone_radius: capsule radius (m), sized for a 1.7 m character.
        ground_size: side of the square ground plane centred on the origin (m).
        background: clear colour, RGB in [0, 1].
        ground: draw the ground plane and its grid.
        obstacles: triangles of obstacles and walls to draw every frame, rows ``(x, y, z, nx,
            ny, nz)`` three per triangle (:func:`~jcrowd.render.meshes.prism_mesh`); None or
            empty: none.
        detail: per level, the capsule tessellation ``(segments, rings)``; by default
            :func:`~jcrowd.render.meshes.capsule_detail` of the level (64 triangles per bone at
            level 0, fewer for farther levels). Coarser capsules render faster, most of all on
            a software rasteriser.
        bodies: per level, a :class:`~jcrowd.motion.skinning.SkinnedLevel` to draw that level's
            agents as skinned bodies (:mod:`jcrowd.render.bodies`; their
            :class:`LevelInstances` then carry every point of the step and the heights), or
            None to draw capsules; None: capsules everywhere. Bodies cast blob shadows.
        sky: draw a sky gradient behind everything instead of the plain background.
    """

    def __init__(
        self,
        levels: Sequence[Sequence[int]],
        width: int = 1280,
        height: int = 720,
        *,
        capacity: Sequence[int],
        samples: int = 4,
        ctx: moderngl.Context | None = None,
        bone_radius: float = 0.05,
        ground_size: float = 200.0,
        background: tuple[float, float, float] = (0.85, 0.88, 0.92),
        ground: bool = True,
        obstacles: Float[np.ndarray, "V 6"] | None = None,
        detail: Sequence[tuple[int, int]] | None = None,
        bodies: Sequence[SkinnedLevel | None] | None = None,
        sky: bool = False,
    ) -> None:
        meshes = [LevelMesh(tuple(p)) for p in levels]
        self._body_specs = list(bodies) if bodies is not None else [None] * len(meshes)
        if len(self._body_specs) != len(meshes):
            raise RenderError(
                f"CrowdRenderer: expected {len(meshes)} bodies entries (one per level), found "
                f"{len(self._body_specs)}"
            )
        self._sky = bool(sky)
        caps = [int(c) for c in capacity]
        _check_args(meshes, caps, width, height, samples, bone_radius, ground_size, background)
        details = [capsule_detail(i) for i in range(len(meshes))] if detail is None else detail
        if len(details) != len(meshes):
            raise RenderError(
                f"CrowdRenderer: expected {len(meshes)} capsule details (one per level), found "
                f"{len(details)}"
            )
        details = [(int(seg), int(rings)) for seg, rings in details]
        for seg, rings in details:
            capsule_mesh(seg, rings)  # validates before any GL object exists
        self.width, self.height = int(width), int(height)
        r, g, b = (float(c) for c in background)
        self.background = (r, g, b)
        self.bone_radius = float(bone_radius)
        self.ground_size = float(ground_size)
        self._draw_ground = bool(ground)
        self._obstacles = np.zeros((0, 6), np.float32) if obstacles is None else obstacles
        if self._obstacles.ndim != 2 or self._obstacles.shape[1] != 6 or len(self._obstacles) % 3:
            raise RenderError(
                "CrowdRenderer: obstacles: expected rows (x, y, z, nx, ny, nz), three per "
                f"triangle, found an array of shape {self._obstacles.shape}"
            )
        if not np.isfinite(self._obstacles).all():
            raise RenderError("CrowdRenderer: obstacles: expected finite numbers, found NaN/inf")
        self.samples = samples if samples > 1 else 0
        self._owns_ctx = ctx is None
        self.ctx = make_context() if ctx is None else ctx
        self._released = False
        self._objects: list[Any] = []
        self._levels: list[CapsuleLevel | BodyLevel] = []
        try:
            self._build(meshes, caps, details)
        except BaseException:
            self.release()  # frees whatever was made, and the context if it is ours
            raise

    def _build(
        self, meshes: list[LevelMesh], caps: list[int], details: list[tuple[int, int]]
    ) -> None:
        """Compile the shaders and allocate every buffer and framebuffer (once, here)."""
        ctx = self.ctx
        if self.samples > ctx.max_samples:
            raise RenderError(
                f"CrowdRenderer: {self.samples} MSAA samples asked, the driver allows at most "
                f"{ctx.max_samples}"
            )
        self._capsule = ctx.program(vertex_shader=CAPSULE_VERTEX, fragment_shader=CAPSULE_FRAGMENT)
        self._objects.append(self._capsule)
        self._ground_prog = ctx.program(
            vertex_shader=GROUND_VERTEX, fragment_shader=GROUND_FRAGMENT
        )
        self._objects.append(self._ground_prog)
        geometries: dict[tuple[int, int], tuple[moderngl.Buffer, moderngl.Buffer]] = {}
        self._body_prog = None
        if any(b is not None for b in self._body_specs):
            self._body_prog = ctx.program(
                vertex_shader=BODY_VERTEX, fragment_shader=CAPSULE_FRAGMENT
            )
            self._objects.append(self._body_prog)
            self._blob_prog = ctx.program(vertex_shader=BLOB_VERTEX, fragment_shader=BLOB_FRAGMENT)
            self._objects.append(self._blob_prog)
            quad = np.array([[-1, -1], [1, -1], [1, 1], [-1, -1], [1, 1], [-1, 1]], np.float32)
            quad_vbo = ctx.buffer(quad.tobytes())
            self._blob_instances = ctx.buffer(reserve=max(4, 12 * sum(caps)))
            self._objects += [quad_vbo, self._blob_instances]
            self._blob_vao = ctx.vertex_array(
                self._blob_prog,
                [(quad_vbo, "2f", "in_corner"), (self._blob_instances, "3f/i", "a_center")],
            )
            self._objects.append(self._blob_vao)
        if self._sky:
            self._sky_prog = ctx.program(vertex_shader=SKY_VERTEX, fragment_shader=SKY_FRAGMENT)
            tri = np.array([[-1, -1], [3, -1], [-1, 3]], np.float32)
            sky_vbo = ctx.buffer(tri.tobytes())
            self._sky_vao = ctx.vertex_array(self._sky_prog, [(sky_vbo, "2f", "in_corner")])
            self._objects += [self._sky_prog, sky_vbo, self._sky_vao]
        for mesh, cap, detail, body in zip(meshes, caps, details, self._body_specs, strict=True):
            if body is not None and self._body_prog is not None:
                self._levels.append(BodyLevel(ctx, self._body_prog, body, cap))
                continue
            if detail not in geometries:
                vertices, triangles = capsule_mesh(*detail)
                vbo, ibo = ctx.buffer(vertices.tobytes()), ctx.buffer(triangles.tobytes())
                self._objects += [vbo, ibo]
                geometries[detail] = (vbo, ibo)
            self._levels.append(CapsuleLevel(ctx, self._capsule, mesh, cap, geometries[detail]))
        ground_vbo = ctx.buffer(ground_mesh(self.ground_size).tobytes())
        self._objects.append(ground_vbo)
        self._ground_vao = ctx.vertex_array(self._ground_prog, [(ground_vbo, "3f", "in_position")])
        self._objects.append(self._ground_vao)
        self._obstacle_vao = None
        if len(self._obstacles):
            self._obstacle_prog = ctx.program(
                vertex_shader=OBSTACLE_VERTEX, fragment_shader=CAPSULE_FRAGMENT
            )
            self._objects.append(self._obstacle_prog)
            vbo = ctx.buffer(np.ascontiguousarray(self._obstacles, np.float32).tobytes())
            self._objects.append(vbo)
            self._obstacle_vao = ctx.vertex_array(
                self._obstacle_prog, [(vbo, "3f 3f", "in_position", "in_normal")]
            )
            self._objects.append(self._obstacle_vao)
        size = (self.width, self.height)
        self._resolved = ctx.simple_framebuffer(size, components=4)
        self._objects.append(self._resolved)
        self._target = self._resolved
        if self.samples:
            color = ctx.renderbuffer(size, components=4, samples=self.samples)
            self._objects.append(color)
            depth = ctx.depth_renderbuffer(size, samples=self.samples)
            self._objects.append(depth)
            self._target = ctx.framebuffer(color, depth)
            self._objects.append(self._target)
        self._set_constant_uniforms()
        check_gl(ctx, "renderer setup")

    @property
    def renderer_name(self) -> str:
        """The GL driver's ``GL_RENDERER`` string (e.g. ``llvmpipe (…)`` or a GPU's name)."""
        return gl_renderer(self.ctx)

    @property
    def num_levels(self) -> int:
        """Number of LOD levels this renderer was made for."""
        return len(self._levels)

    def render(self, view: View, levels: Sequence[LevelInstances]) -> np.ndarray:
        """Draw one frame and return it as a ``(height, width, 3)`` uint8 RGB array, row 0 on top.

        Args:
            view: the camera.
            levels: one :class:`LevelInstances` per level, in the constructor's order.

        Raises:
            RenderError: wrong number of levels, shapes that do not match the level's skeleton
                or capacity, non-finite joints or colours in a valid slot, a released renderer,
                or a GL error.
        """
        if self._released:
            raise RenderError("CrowdRenderer.render: the renderer has been released")
        if len(levels) != len(self._levels):
            raise RenderError(
                f"CrowdRenderer.render: expected {len(self._levels)} levels, found {len(levels)}"
            )
        view_proj = projection_matrix(view, self.width, self.height) @ view_matrix(view)
        counts = [
            stage_bodies(level, data, i, view_proj, self.height)
            if isinstance(level, BodyLevel)
            else stage_capsules(level, data, i)
            for i, (level, data) in enumerate(zip(self._levels, levels, strict=True))
        ]
        vp_bytes = view_proj.T.astype(np.float32).tobytes()  # GL wants column-major
        ctx = self.ctx
        self._target.use()
        self._target.clear(color=(*self.background, 1.0), depth=1.0)
        if self._sky:
            ctx.enable_only(moderngl.NOTHING)
            inv = np.linalg.inv(view_proj).T.astype(np.float32).tobytes()
            _uniform(self._sky_prog, "u_inv_view_proj").write(inv)
            self._sky_vao.render(moderngl.TRIANGLES)
        ctx.enable_only(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.front_face, ctx.cull_face = "ccw", "back"
        _uniform(self._capsule, "u_view_proj").write(vp_bytes)
        if self._body_prog is not None:
            _uniform(self._body_prog, "u_view_proj").write(vp_bytes)
        for level, n in zip(self._levels, counts, strict=True):
            if isinstance(level, BodyLevel):
                level.draw()
                continue
            if n * level.num_bones == 0:
                continue
            level.instances.write(level.staging[:n])
            level.vao.render(moderngl.TRIANGLES, instances=n * level.num_bones)
        if self._obstacle_vao is not None:
            _uniform(self._obstacle_prog, "u_view_proj").write(vp_bytes)
            self._obstacle_vao.render(moderngl.TRIANGLES)
        if self._draw_ground:
            _uniform(self._ground_prog, "u_view_proj").write(vp_bytes)
            self._ground_vao.render(moderngl.TRIANGLES)
        roots = [lv.roots for lv in self._levels if isinstance(lv, BodyLevel) and lv.count]
        if roots and self._draw_ground:
            blobs = np.concatenate(roots)
            self._blob_instances.write(np.ascontiguousarray(blobs, np.float32).tobytes())
            ctx.enable_only(moderngl.DEPTH_TEST | moderngl.BLEND)
            ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
            self._target.depth_mask = False
            _uniform(self._blob_prog, "u_view_proj").write(vp_bytes)
            self._blob_vao.render(moderngl.TRIANGLES, instances=len(blobs))
            self._target.depth_mask = True
        if self.samples:
            ctx.copy_framebuffer(self._resolved, self._target)
        raw = self._resolved.read(components=3, alignment=1)
        check_gl(ctx, "render")
        image = np.frombuffer(raw, np.uint8).reshape(self.height, self.width, 3)
        return np.ascontiguousarray(image[::-1])  # GL rows start at the bottom

    def release(self) -> None:
        """Free every GL object (and the context if the renderer made it). Idempotent."""
        if self._released:
            return
        self._released = True
        bound = self.ctx.fbo
        ours = {obj.glo for obj in self._objects if isinstance(obj, moderngl.Framebuffer)}
        if bound is not None and bound.glo in ours:
            # moderngl re-binds the last used framebuffer after creating another one; if that
            # is ours and deleted, a later renderer on a shared context gets
            # GL_INVALID_OPERATION. Bind the default framebuffer (0) instead.
            self.ctx.detect_framebuffer(0).use()
        for level in self._levels:
            level.release()
        for obj in reversed(self._objects):
            obj.release()
        self._release_ctx()

    def __enter__(self) -> CrowdRenderer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()

    def _release_ctx(self) -> None:
        if self._owns_ctx:
            self.ctx.release()

    def _capsule_fragment_uniforms(self, prog: moderngl.Program) -> None:
        _uniform(prog, "u_light_dir").value = tuple(float(x) for x in _LIGHT_DIR)
        _uniform(prog, "u_ambient").value = _AMBIENT

    def _set_constant_uniforms(self) -> None:
        _uniform(self._capsule, "u_radius").value = self.bone_radius
        _uniform(self._capsule, "u_light_dir").value = tuple(float(x) for x in _LIGHT_DIR)
        _uniform(self._capsule, "u_ambient").value = _AMBIENT
        if self._body_prog is not None:
            _uniform(self._body_prog, "u_shoes").value = SHOE_COLOR
            _uniform(self._body_prog, "u_bones").value = 0
            self._capsule_fragment_uniforms(self._body_prog)
        if self._sky:
            _uniform(self._sky_prog, "u_horizon").value = self.background
            _uniform(self._sky_prog, "u_zenith").value = _ZENITH
        if self._obstacle_vao is not None:
            o = self._obstacle_prog
            _uniform(o, "u_light_dir").value = tuple(float(x) for x in _LIGHT_DIR)
            _uniform(o, "u_ambient").value = _AMBIENT
            _uniform(o, "u_color").value = OBSTACLE_COLOR
        g = self._ground_prog
        _uniform(g, "u_ground").value = _GROUND
        _uniform(g, "u_line").value = _GRID_LINE
        _uniform(g, "u_background").value = self.background
        _uniform(g, "u_half_size").value = self.ground_size / 2.0


def _uniform(prog: moderngl.Program, name: str) -> moderngl.Uniform:
    """The uniform ``name`` of ``prog`` (a shader bug if it is missing or not a uniform)."""
    member = prog.get(name, None)
    if not isinstance(member, moderngl.Uniform):
        raise RenderError(f"shader program has no uniform {name!r} (found {member!r})")
    return member


def _check_args(
    meshes: list[LevelMesh],
    capacity: list[int],
    width: int,
    height: int,
    samples: int,
    bone_radius: float,
    ground_size: float,
    background: tuple[float, float, float],
) -> None:
    """Raise :class:`RenderError` for constructor arguments that cannot work."""
    checks = (
        (len(meshes) >= 1, "at least one level", len(meshes)),
        (len(capacity) == len(meshes), f"{len(meshes)} capacities (one per level)", capacity),
        (all(c >= 0 for c in capacity), "non-negative capacities", capacity),
        (int(width) >= 1 and int(height) >= 1, "a positive image size", f"{width}×{height}"),
        (int(samples) >= 0, "samples ≥ 0", samples),
        (bone_radius > 0, "a positive bone radius (m)", bone_radius),
        (ground_size > 0, "a positive ground size (m)", ground_size),
        (
            len(background) == 3 and all(0.0 <= float(c) <= 1.0 for c in background),
            "a background RGB in [0, 1]",
            background,
        ),
    )
    for ok, expected, found in checks:
        if not ok:
            raise RenderError(f"CrowdRenderer: expected {expected}, found {found}")
