"""One capsule-drawn level of :class:`~jcrowd.render.renderer.CrowdRenderer`: its GL objects
and the gather of its valid agents' bones into a staging array (step 1 of a frame there).

A level's instance buffer is sized once for ``capacity × bones`` rows of
``(start xyz, end xyz, colour rgb)`` and never reallocated; invalid (padding) slots are
dropped by the gather, so they draw nothing whatever they hold.
"""

from __future__ import annotations

import moderngl
import numpy as np

from jcrowd.errors import RenderError
from jcrowd.render.levels import LevelInstances, LevelMesh

__all__ = ["CapsuleLevel", "stage_capsules"]

_FLOATS_PER_BONE = 9  # start xyz, end xyz, colour rgb


class CapsuleLevel:
    """GL objects and the staging array of one capsule-drawn level."""

    def __init__(
        self,
        ctx: moderngl.Context,
        prog: moderngl.Program,
        mesh: LevelMesh,
        capacity: int,
        geometry: tuple[moderngl.Buffer, moderngl.Buffer],
    ) -> None:
        self.mesh = mesh
        self.capacity = capacity
        self.parent_idx, self.joint_idx = mesh.bones
        self.num_bones = len(self.joint_idx)
        self.staging = np.zeros((capacity, self.num_bones, _FLOATS_PER_BONE), np.float32)
        vbo, ibo = geometry
        self.instances = ctx.buffer(reserve=max(self.staging.nbytes, 4))
        self.vao = ctx.vertex_array(
            prog,
            [
                (vbo, "3f 1f", "in_offset", "in_end"),
                (self.instances, "3f 3f 3f/i", "a_start", "a_end", "a_color"),
            ],
            index_buffer=ibo,
            index_element_size=4,
        )

    def release(self) -> None:
        """Free this level's vertex array and instance buffer."""
        self.vao.release()
        self.instances.release()


def stage_capsules(level: CapsuleLevel, data: LevelInstances, index: int) -> int:
    """Check one level's input and gather its valid agents' bones into ``level.staging``.

    Returns the number of valid agents staged.
    """
    where = f"CrowdRenderer.render: level {index}"
    joints = np.asarray(data.joints)
    valid = np.asarray(data.valid)
    colors = np.asarray(data.colors)
    c, j = joints.shape[0] if joints.ndim else 0, level.mesh.num_joints
    if joints.shape != (c, j, 3):
        raise RenderError(f"{where}: expected joints of shape (C, {j}, 3), found {joints.shape}")
    if c > level.capacity:
        raise RenderError(f"{where}: {c} slots passed, capacity is {level.capacity}")
    if valid.shape != (c,) or valid.dtype != np.bool_:
        raise RenderError(
            f"{where}: expected valid of shape ({c},) bool, found {valid.shape} {valid.dtype}"
        )
    if colors.shape != (c, 3):
        raise RenderError(f"{where}: expected colors of shape ({c}, 3), found {colors.shape}")
    rows = np.flatnonzero(valid)
    n = len(rows)
    if n == 0 or level.num_bones == 0:
        return n
    # Only valid slots are checked: padding slots may hold anything (e.g. stale or NaN poses).
    picked = joints[rows].astype(np.float32, copy=False)
    picked_colors = colors[rows].astype(np.float32, copy=False)
    if not np.all(np.isfinite(picked)):
        bad = int(rows[np.flatnonzero(~np.isfinite(picked).all(axis=(1, 2)))[0]])
        raise RenderError(f"{where}: non-finite joint positions in valid slot {bad}")
    if not np.all(np.isfinite(picked_colors)):
        raise RenderError(f"{where}: non-finite colours in a valid slot")
    out = level.staging[:n]
    out[:, :, 0:3] = picked[:, level.parent_idx]
    out[:, :, 3:6] = picked[:, level.joint_idx]
    out[:, :, 6:9] = picked_colors[:, None, :]
    return n
