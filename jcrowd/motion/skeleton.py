"""Skeletons and forward kinematics.

A :class:`Skeleton` is a joint tree: names and parent indices are static (they fix shapes and
the order of computation), offsets are an array leaf (metres, in the parent's frame at rest,
DESIGN §3). Joints are in topological order: joint 0 is the single root and every parent comes
before its children. BVH "End Sites" are kept apart (``end_parents``/``end_offsets``): they carry
no rotation but mark the tip of a chain (toe tip, head top), which foot contacts and the
character's height use.

Forward kinematics composes rotations one tree depth at a time, as MuJoCo MJX does: at trace
time the joints are grouped by depth with NumPy, and each depth is one gather of the parents'
global rotations and one batched product, so a 31-joint skeleton costs ~8 vectorised steps
rather than 31 scalar chains (DESIGN §7 explains why the per-joint form is slow under XLA on
CPU); positions are then one sum of bone vectors along each joint's path.
"""

from __future__ import annotations

from functools import cached_property
from itertools import pairwise
from typing import Any

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, Float

from jcrowd.errors import SkeletonError
from jcrowd.motion.rotation import array_module, quat_mul, quat_rotate

__all__ = [
    "Skeleton",
    "bone_lengths",
    "end_site_positions",
    "forward_kinematics",
    "joint_bone_lengths",
    "kept_ancestor_frame",
    "rest_positions",
]

ArrayLike = Any
HostOrDevice = Array | np.ndarray
"""Data leaves hold NumPy arrays on the offline (fit) path and jax arrays in compiled code."""


class Skeleton(eqx.Module):
    """A joint tree with static topology and array offsets.

    Attributes:
        names: joint names, unique, in topological order.
        parents: parent index per joint; ``-1`` for the root (joint 0 only).
        offsets: ``(J, 3)`` offset of each joint from its parent at rest (m); the root's offset
            is added to the root position.
        end_parents: for each End Site, the index of the joint it hangs from.
        end_offsets: ``(E, 3)`` End Site offsets (m).
    """

    names: tuple[str, ...] = eqx.field(static=True)
    parents: tuple[int, ...] = eqx.field(static=True)
    offsets: Float[HostOrDevice, "J 3"]
    end_parents: tuple[int, ...] = eqx.field(static=True, default=())
    end_offsets: Float[HostOrDevice, "E 3"] | None = None

    def __check_init__(self) -> None:
        names, parents = self.names, self.parents
        if len(names) == 0:
            raise SkeletonError("skeleton: expected at least one joint, found none")
        if len(parents) != len(names):
            raise SkeletonError(
                f"skeleton: expected one parent per joint ({len(names)}), found {len(parents)}"
            )
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise SkeletonError(f"skeleton: expected unique joint names, found duplicates {dup}")
        if parents[0] != -1:
            raise SkeletonError(
                f"skeleton: expected joint 0 to be the root (parent -1), found {parents[0]}"
            )
        for j, p in enumerate(parents[1:], start=1):
            if p == -1:
                raise SkeletonError(
                    f"skeleton: expected one root, found a second at joint {j} {names[j]!r}"
                )
            if not 0 <= p < j:
                raise SkeletonError(
                    f"skeleton: expected topological order (parent before child), joint {j} "
                    f"{names[j]!r} has parent {p}"
                )
        for e, p in enumerate(self.end_parents):
            if not 0 <= p < len(names):
                raise SkeletonError(
                    f"skeleton: End Site {e} has parent {p}, expected 0..{len(names) - 1}"
                )
        shape = getattr(self.offsets, "shape", None)
        if shape is not None and tuple(shape) != (len(names), 3):
            raise SkeletonError(
                f"skeleton: expected offsets of shape ({len(names)}, 3), found {shape}"
            )
        end_shape = None if self.end_offsets is None else getattr(self.end_offsets, "shape", None)
        if end_shape is not None and tuple(end_shape) != (len(self.end_parents), 3):
            raise SkeletonError(
                f"skeleton: expected end_offsets of shape ({len(self.end_parents)}, 3), "
                f"found {end_shape}"
            )

    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of the joint called ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise SkeletonError(
                f"skeleton: expected a joint named {name!r}, found {list(self.names)}"
            ) from None

    @cached_property
    def depths(self) -> np.ndarray:
        """Tree depth of every joint (root = 0), ``(J,)`` int."""
        d = np.zeros(len(self.parents), np.int32)
        for j, p in enumerate(self.parents[1:], start=1):
            d[j] = d[p] + 1
        return d

    @cached_property
    def depth_groups(self) -> tuple[np.ndarray, ...]:
        """Joint indices at each depth, root first: the FK schedule."""
        return tuple(
            np.nonzero(self.depths == k)[0].astype(np.int32)
            for k in range(int(self.depths.max()) + 1)
        )

    @cached_property
    def path_matrix(self) -> np.ndarray:
        """``(J, J − 1)`` 0/1: entry ``[j, k − 1]`` is 1 when joint ``k`` (not the root) lies
        on the path from the root to ``j`` (``j`` included), so a joint's position is the
        root's plus the sum of the bone vectors along its path."""
        a = np.zeros((len(self.parents), len(self.parents) - 1), np.float32)
        for j in range(1, len(self.parents)):
            k = j
            while k > 0:
                a[j, k - 1] = 1.0
                k = self.parents[k]
        return a

    def children(self, j: int) -> tuple[int, ...]:
        """Direct children of joint ``j``."""
        return tuple(c for c, p in enumerate(self.parents) if p == j)

    def end_offsets_or_empty(self) -> Any:
        if self.end_offsets is None:
            return np.zeros((0, 3), np.float32)
        return self.end_offsets

    def scaled(self, factor: float) -> Skeleton:
        """The same skeleton with every offset multiplied by ``factor``."""
        return Skeleton(
            self.names,
            self.parents,
            self.offsets * factor,
            self.end_parents,
            None if self.end_offsets is None else self.end_offsets * factor,
        )


def forward_kinematics(
    skeleton: Skeleton,
    local_rotations: Float[ArrayLike, "*batch J 4"],
    root_position: Float[ArrayLike, "*batch 3"],
) -> tuple[Float[ArrayLike, "*batch J 4"], Float[ArrayLike, "*batch J 3"]]:
    """Global rotations and positions of every joint.

    ``R_j = R_parent ⊗ q_j``, evaluated one tree depth at a time (all joints of a depth in one
    batched step); then every bone vector ``b_j = R_parent o_j`` at once, and
    ``p_j = p_root + o_root + Σ_{k on the root→j path} b_k`` as one product with the skeleton's
    :attr:`Skeleton.path_matrix` (the same sums as the recursion ``p_j = p_parent + b_j``). On
    XLA:CPU the recursion per depth fuses into one kernel that recomputes each ancestor's
    position for every descendant; the product is a small GEMM.

    Args:
        skeleton: topology and offsets ``(J, 3)``.
        local_rotations: unit quaternions ``(*batch, J, 4)``.
        root_position: ``(*batch, 3)`` root translation (m).

    Returns:
        ``(global_rotations (*batch, J, 4), global_positions (*batch, J, 3))``; NumPy in gives
        NumPy out (float64 kept), otherwise jax arrays.
    """
    xp = array_module(local_rotations, root_position, skeleton.offsets)
    offsets = xp.asarray(skeleton.offsets, dtype=local_rotations.dtype)
    batch = local_rotations.shape[:-2]
    groups = skeleton.depth_groups
    parents = np.asarray(skeleton.parents)
    # Every parent of a depth-d joint sits at depth d-1, so each step gathers from the previous
    # block only; the blocks are joined and put back in joint order once at the end (a
    # functional scatter per depth would copy the whole (J, 4) array at every depth).
    rots = [local_rotations[..., groups[0], :]]
    for prev, idx in pairwise(groups):
        par = np.searchsorted(prev, parents[idx])
        rots.append(quat_mul(rots[-1][..., par, :], local_rotations[..., idx, :]))
    order = np.argsort(np.concatenate(groups), kind="stable")
    grot = xp.concatenate(rots, axis=-2)[..., order, :]
    root = root_position[..., None, :] + offsets[:1]
    if len(parents) == 1:
        return grot, root
    bones = quat_rotate(
        grot[..., parents[1:], :], xp.broadcast_to(offsets[1:], (*batch, len(parents) - 1, 3))
    )
    path = xp.asarray(skeleton.path_matrix, dtype=bones.dtype)
    if xp is np:
        return grot, root + path @ bones
    return grot, root + xp.matmul(path, bones, precision=jax.lax.Precision.HIGHEST)


def end_site_positions(
    skeleton: Skeleton,
    global_rotations: Float[ArrayLike, "*batch J 4"],
    global_positions: Float[ArrayLike, "*batch J 3"],
) -> Float[ArrayLike, "*batch E 3"]:
    """World positions of the End Sites, ``(*batch, E, 3)``."""
    xp = array_module(global_rotations, global_positions)
    par = np.asarray(skeleton.end_parents, np.int64)
    eo = xp.asarray(skeleton.end_offsets_or_empty(), dtype=global_positions.dtype)
    batch = global_positions.shape[:-2]
    return global_positions[..., par, :] + quat_rotate(
        global_rotations[..., par, :], xp.broadcast_to(eo, (*batch, len(par), 3))
    )


def rest_positions(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Joint and End Site positions at rest (identity rotations, root at origin), NumPy float64."""
    off = np.asarray(skeleton.offsets, np.float64)
    pos = np.zeros_like(off)
    for j, p in enumerate(skeleton.parents):
        pos[j] = off[j] + (pos[p] if p >= 0 else 0.0)
    eo = np.asarray(skeleton.end_offsets_or_empty(), np.float64)
    ends = pos[np.asarray(skeleton.end_parents, np.int64)] + eo if len(eo) else np.zeros((0, 3))
    return pos, ends


def kept_ancestor_frame(
    skeleton: Skeleton, reference: np.ndarray, kept: set[int], j: int
) -> tuple[int, np.ndarray, np.ndarray]:
    """The nearest kept ancestor of joint ``j`` when only the joints ``kept`` move, with the
    rotation of ``j``'s parent frame and ``j``'s position, both in that ancestor's frame: the
    dropped joints between them hold their ``reference`` rotations ``(J, 4)`` (NumPy, host)."""
    path = []
    p = skeleton.parents[j]
    while p not in kept:
        path.append(p)
        p = skeleton.parents[p]
    rot = np.array([1.0, 0.0, 0.0, 0.0])
    off = np.zeros(3)
    offsets = np.asarray(skeleton.offsets, np.float64)
    for d in reversed(path):  # from just below the kept ancestor down to j's parent
        off = off + quat_rotate(rot, offsets[d])
        rot = quat_mul(rot, reference[d])
    off = off + quat_rotate(rot, offsets[j])
    return p, rot, off


def bone_lengths(skeleton: Skeleton) -> Float[ArrayLike, " J"]:
    """Length of each joint's offset from its parent (m); the root's entry is 0."""
    xp = array_module(skeleton.offsets)
    lengths = xp.sqrt(xp.sum(skeleton.offsets * skeleton.offsets, axis=-1))
    return xp.where(xp.arange(len(skeleton.parents)) == 0, 0.0, lengths)


def joint_bone_lengths(
    skeleton: Skeleton, positions: Float[ArrayLike, "*batch J 3"]
) -> Float[ArrayLike, "*batch J"]:
    """Distance from each joint to its parent in posed ``positions``; the root's entry is 0."""
    xp = array_module(positions)
    par = np.asarray(skeleton.parents, np.int64)
    par = np.where(par < 0, 0, par)
    d = positions - positions[..., par, :]
    return xp.sqrt(xp.sum(d * d, axis=-1))
