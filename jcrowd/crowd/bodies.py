"""Skinned bodies per level of detail (paper 003 §5.1): a bound body's meshes skinned
to each level's kept joints, for a renderer that has the step's points.

Every level gets every resolution of the body (the renderer picks one per agent by its size on
screen, :mod:`jcrowd.render.bodies`); each resolution's weights move from the joints the level
drops to their kept ancestor through the dropped joints' reference rotations
(:func:`jcrowd.motion.skinning.level_skin`), so the skin follows the points the step places rigidly
off a kept joint. Host code, once per model.
"""

from __future__ import annotations

import numpy as np

from jcrowd.crowd.synthesis import Decoders, build_decoders
from jcrowd.model.motion_model import MotionModel
from jcrowd.motion.body import BoundBody
from jcrowd.motion.rotation import quat_mul
from jcrowd.motion.skeleton import kept_ancestor_frame
from jcrowd.motion.skinning import SkinnedLevel, SkinnedMesh, level_skin

__all__ = ["skinned_levels"]


def skinned_levels(
    model: MotionModel, bound: BoundBody, decoders: Decoders | None = None
) -> tuple[SkinnedLevel, ...]:
    """One :class:`~jcrowd.motion.skinning.SkinnedLevel` per level of ``model``, each with every
    mesh of ``bound``."""
    dec = build_decoders(model) if decoders is None else decoders
    skel = model.skeleton
    reference = np.asarray(model.layout.reference, np.float64)
    out = []
    for lv, level in enumerate(dec.levels):
        kept = [0, *sorted(j for j in model.levels[lv].joints if j != 0)]
        kept_set = set(kept)
        anchor = np.array(level.anchor[: skel.num_joints], np.int64)
        f_rot = np.tile([1.0, 0.0, 0.0, 0.0], (skel.num_joints, 1))
        f_pos = np.zeros((skel.num_joints, 3))
        for j in range(skel.num_joints):
            if j not in kept_set:
                _, rot, off = kept_ancestor_frame(skel, reference, kept_set, j)
                f_rot[j] = quat_mul(rot, reference[j])
                f_pos[j] = off
        meshes = []
        for mesh in bound.meshes:
            bones, weights, offsets = level_skin(mesh, bound.rest, anchor, f_rot, f_pos)
            region = np.ones(len(mesh.vertices), np.int8) if mesh.region is None else mesh.region
            meshes.append(
                SkinnedMesh(mesh.triangles, mesh.normals, region, bones, weights, offsets)
            )
        # The points each kept joint's frame carries: kept children, then anchored points.
        parents = tuple(int(p) for p in level.skeleton.parents)
        offs_level = np.asarray(level.skeleton.offsets, np.float64)
        point_off = np.asarray(level.point_offset, np.float64)
        carried: list[list[tuple[int, np.ndarray]]] = [[] for _ in kept]
        for c, p in enumerate(parents):
            if p >= 0:
                carried[p].append((kept[c], offs_level[c]))
        for point, a in enumerate(level.anchor):
            if not (point < skel.num_joints and point in kept_set):  # placed off its anchor
                carried[a].append((point, point_off[point]))
        width = max(1, max(len(c) for c in carried))
        ref_points = np.full((len(kept), width), -1, np.int32)
        ref_offsets = np.zeros((len(kept), width, 3), np.float32)
        for k, items in enumerate(carried):
            for m, (point, off) in enumerate(items):
                ref_points[k, m] = point
                ref_offsets[k, m] = off
        out.append(
            SkinnedLevel(
                meshes=tuple(meshes),
                kept=np.asarray(kept, np.int32),
                parents=parents,
                local_ref=np.asarray(level.local_ref, np.float64),
                ref_points=ref_points,
                ref_offsets=ref_offsets,
            )
        )
    return tuple(out)
