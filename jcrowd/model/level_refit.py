"""Per-level refit of the kept joints (paper 003 §5.2, read in rotation coordinates).

A coarse level freezes its dropped joints at the key posture (003 §5.1, Eq. 2) and, without a
refit, keeps the captured rotations of the joints it keeps; every frozen joint's error then
propagates down its sub-tree (a frozen spine tips the head, a frozen knee moves the foot).
Paper 003 re-optimises the kept joints so that the body keeps its shape: Eq. 5 minimises the
distance of every joint to its captured position (E_d, Eq. 6) under rigid bones (E_s, Eq. 7) and
the frozen joints' key angles (E_a, Eq. 8), in joint *positions*, then recovers rotations.

Reading taken: the same objective, solved in the level's own coordinates. With the unknowns the
kept joints' local rotations, ``q_j = q°_j ⊗ exp(ω_j)``, and the frozen joints at their key
rotations, every bone is rigid and every frozen angle is the key's by construction, so Eq. 7 and
Eq. 8 vanish and Eq. 5 reduces to Eq. 6 over *every* non-root joint of the full skeleton::

    min_ω  Σ_{j ≠ root} ‖FK_j(q(ω)) − x°_j‖²      (positions relative to the root, root tilt kept)

solved per frame by Levenberg–Marquardt (optimistix) from ω = 0, the un-refitted level. The
position-space route of :mod:`jcrowd.simplify` needs a second step (rotation recovery) that
does not see the frozen joints' positions; measured on the shared ``cmu16`` samples, it *raised*
the whole-body error of the coarse levels (5.1 → 6.3 cm at 3 joints), while this form can only
lower it (LM never accepts a step that raises the sum of squares). The root's tilt is not
refitted: it belongs to the root channels the controls and the clip scheduler rely on.

Pure: arrays in, arrays out; one ``jit``-compiled, ``vmap``-ped solve per (skeleton, kept set).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Float

from jcrowd.errors import MotionError
from jcrowd.motion.rotation import quat_from_expmap, quat_mul
from jcrowd.motion.skeleton import Skeleton, forward_kinematics

__all__ = ["refit_kept_rotations", "whole_body_error"]
ROOT = True


def _positions(skeleton: Skeleton, rotations: jax.Array) -> jax.Array:
    """Joint positions relative to the root ``(..., J, 3)`` (root at the origin)."""
    zero = jnp.zeros((*rotations.shape[:-2], 3), rotations.dtype)
    return forward_kinematics(skeleton, rotations, zero)[1]


@eqx.filter_jit
def _refit(
    skeleton: Skeleton,
    moving: tuple[int, ...],
    start: jax.Array,
    target: jax.Array,
    max_steps: int,
) -> jax.Array:
    """The LM solve of every frame (``moving``, ``max_steps`` static: one trace per level)."""
    idx = np.asarray(moving, np.int64)

    def pose(omega: jax.Array, first: jax.Array) -> jax.Array:
        turned = quat_mul(first[idx], quat_from_expmap(omega.reshape(-1, 3)))
        return first.at[idx].set(turned)

    def residuals(omega: jax.Array, args: tuple[jax.Array, jax.Array]) -> jax.Array:
        first, goal = args
        return (_positions(skeleton, pose(omega, first))[1:] - goal[1:]).reshape(-1)

    solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-7)

    def one(first: jax.Array, goal: jax.Array) -> jax.Array:
        omega0 = jnp.zeros(3 * len(moving), first.dtype)
        sol = optx.least_squares(
            residuals, solver, omega0, args=(first, goal), max_steps=max_steps, throw=False
        )
        return pose(sol.value, first)

    return jax.vmap(one)(start, target)


def refit_kept_rotations(
    skeleton: Skeleton,
    rotations: Float[Any, "F J 4"],
    kept: tuple[int, ...],
    key: Float[Any, "J 4"],
    *,
    max_steps: int = 64,
) -> Float[np.ndarray, "F J 4"]:
    """Local rotations ``(F, J, 4)`` of a level: frozen joints at ``key``, kept ones refitted.

    Args:
        skeleton: the full skeleton the captured ``rotations`` ``(F, J, 4)`` belong to.
        rotations: captured local rotations (the root's row is kept as given).
        kept: the level's kept joint indices (the root included); the others are frozen.
        key: ``(J, 4)`` key-posture local rotations of the frozen joints.
        max_steps: Levenberg–Marquardt steps per frame.

    Returns:
        NumPy float32 rotations on the full skeleton whose FK is the level's (module docstring).
    """
    rot = np.asarray(rotations, np.float32)
    j = skeleton.num_joints
    if rot.ndim != 3 or rot.shape[1:] != (j, 4) or np.shape(key) != (j, 4):
        raise MotionError(
            f"level refit: expected rotations (F, {j}, 4) and key ({j}, 4), found "
            f"{rot.shape} and {np.shape(key)}"
        )
    if 0 not in kept or any(not 0 <= k < j for k in kept):
        raise MotionError(
            f"level refit: expected kept joints in 0..{j - 1} with the root, found {kept}"
        )
    frozen = [k for k in range(j) if k not in kept]
    start = rot.copy()
    start[:, frozen] = np.asarray(key, np.float32)[frozen]
    if len(kept) == 1 or not frozen:
        return start
    target = np.asarray(_positions(skeleton, jnp.asarray(rot)))
    moving = tuple(sorted(kept)) if ROOT else tuple(k for k in sorted(kept) if k != 0)
    out = _refit(skeleton, moving, jnp.asarray(start), jnp.asarray(target), max_steps)
    return np.asarray(out, np.float32)


def whole_body_error(
    skeleton: Skeleton, rotations: Float[Any, "F J 4"], captured: Float[Any, "F J 4"]
) -> Float[np.ndarray, "F J-1"]:
    """Distance of every non-root joint to its captured place, root-relative ``(F, J − 1)``."""
    a = _positions(skeleton, jnp.asarray(rotations, jnp.float32))
    b = _positions(skeleton, jnp.asarray(captured, jnp.float32))
    return np.linalg.norm(np.asarray(a - b), axis=-1)[:, 1:]
