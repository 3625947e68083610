"""What the renderer draws per level of detail: the level's skeleton topology
(:class:`LevelMesh`) and its agents in a frame (:class:`LevelInstances`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from jaxtyping import Bool, Float

from jcrowd.errors import RenderError

__all__ = ["LevelInstances", "LevelMesh"]


@dataclass(frozen=True)
class LevelMesh:
    """The skeleton topology one LOD level is drawn with.

    Attributes:
        parents: parent index of each joint of that level's skeleton, -1 for a root; parents
            come before their children (``parents[j] < j``). Every joint with a parent is the
            end of one bone (drawn as a capsule from the parent to it).
    """

    parents: tuple[int, ...]

    def __post_init__(self) -> None:
        p = tuple(int(x) for x in self.parents)
        if len(p) == 0:
            raise RenderError("LevelMesh: expected at least one joint, found none")
        bad = [j for j, q in enumerate(p) if not -1 <= q < j]
        if bad:
            raise RenderError(
                f"LevelMesh: expected parents[j] in [-1, j) (topological order), found "
                f"parents[{bad[0]}] = {p[bad[0]]}"
            )
        object.__setattr__(self, "parents", p)

    @property
    def num_joints(self) -> int:
        """Joints in this level's skeleton."""
        return len(self.parents)

    @property
    def bones(self) -> tuple[np.ndarray, np.ndarray]:
        """``(parent_index, joint_index)`` int64 arrays, one entry per bone."""
        joints = np.array([j for j, q in enumerate(self.parents) if q >= 0], np.int64)
        return np.asarray(self.parents, np.int64)[joints], joints


@dataclass(frozen=True)
class LevelInstances:
    """One LOD level's agents in a frame, in fixed-capacity slots.

    Attributes:
        joints: ``(C, J, 3)`` world positions (m, y up) of that level's ``J`` joints; NumPy or
            device arrays (copied to the host once).
        valid: ``(C,)`` bool, the slots to draw; padding slots are False and may hold anything.
        colors: ``(C, 3)`` RGB in [0, 1] per slot (e.g. from ``LEVEL_COLORS``); a level drawn
            as bodies also takes ``(C, 3, 3)``: skin, top and bottom per slot.
        heights: ``(C,)`` each slot's agent height (m); needed by a level drawn as bodies.
    """

    joints: Float[Any, "C J 3"]
    valid: Bool[Any, " C"]
    colors: Float[Any, "C 3"]
    heights: Float[Any, " C"] | None = None
