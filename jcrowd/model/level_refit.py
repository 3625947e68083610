"""Per-level refit of the kept joints (paper 003 §5.2, read in rotation coordinates).

A coarse level freezes its dropped joints at the key posture (003 §5.1, Eq. 2) and, without a
refit, keeps the captured rotations of the joints it keeps; every frozen joint's error then
propagates down its sub-tree (a frozen spine tips the head, a frozen knee moves the foot).
Paper 003 re-optimises the kept joints so that the body keeps its shape: Eq. 5 minimises the
distance of every joint to its captured position (E_d, Eq. 6) under rigid bones (E_s, Eq. 7) and
the frozen joints' key angles (E_a, Eq. 8), in joint *positions*, then recovers rotations.

Reading taken: the same objective, solved in the level's own coordinates. With the unknowns the
kept joints' local rotations, ``q_j = q°_j ⊗ exp(ω_j)`` (the root's too: its orientation in the
heading frame, i.e. its tilt), and the frozen joints at their key
rotations, every bone is rigid and every frozen angle is the key's by construction, so Eq. 7 and
Eq. 8 vanish and Eq. 5 reduces to Eq. 6 over *every* non-root joint of the full skeleton::

    min_ω  Σ_{j ≠ root} ‖FK_j(q(ω)) − x°_j‖²      (positions relative to the root, heading frame)

solved per frame by Levenberg–Marquardt (analytic Jacobian) from ω = 0, the un-refitted level. The
position-space route of :mod:`jcrowd.simplify` needs a second step (rotation recovery) that
does not see the frozen joints' positions, so it can leave a coarse level's whole-body error
above the un-refitted one; this form can only lower it (LM never accepts a step that raises the
sum of squares). The root turns as well because at the coarsest levels, with the spine frozen,
only the pelvis can carry the trunk (``docs/design/model.md`` gives the cmu16 figures for both).
The root's position, height, velocity and yaw rate are the sample's: the controls and the clip
scheduler read them.

Pure: arrays in, arrays out; one ``jit``-compiled solve over every frame per (skeleton, kept set).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from jcrowd.errors import MotionError
from jcrowd.motion.rotation import quat_from_expmap, quat_mul, quat_to_matrix
from jcrowd.motion.skeleton import Skeleton, forward_kinematics

__all__ = ["refit_kept_rotations", "whole_body_error"]


def _positions(skeleton: Skeleton, rotations: jax.Array) -> jax.Array:
    """Joint positions relative to the root ``(..., J, 3)`` (root at the origin)."""
    zero = jnp.zeros((*rotations.shape[:-2], 3), rotations.dtype)
    return forward_kinematics(skeleton, rotations, zero)[1]


def _ancestors(skeleton: Skeleton) -> np.ndarray:
    """``(J, J)`` bool: ``[k, a]`` when joint ``a`` is a strict ancestor of joint ``k`` (the
    skeleton's :attr:`~Skeleton.path_matrix` with the root added and each joint itself taken
    out)."""
    j = skeleton.num_joints
    out = np.zeros((j, j), bool)
    out[:, 1:] = np.asarray(skeleton.path_matrix) > 0
    out[1:, 0] = True
    np.fill_diagonal(out, False)
    return out


@eqx.filter_jit
def _refit(
    skeleton: Skeleton,
    moving: tuple[int, ...],
    start: jax.Array,
    target: jax.Array,
    max_steps: int,
) -> jax.Array:
    """Levenberg–Marquardt on every frame at once, ``max_steps`` damped Gauss–Newton steps.

    ``moving`` (the joints that turn) and ``max_steps`` are static: one trace per level, whose
    normal equations have only the moving joints' unknowns (a traced mask over every joint would
    solve 3J unknowns per frame; ``docs/design/model.md``). Each step linearises at the current
    pose: turning a moving joint ``m`` by ``exp(ω)`` on the right turns its sub-tree about its
    world axes ``G_m e_a``, so ``∂p_k/∂ω_{m,a} = (G_m e_a) × (p_k − p_m)`` for every descendant
    ``k`` (0 otherwise) — the analytic Jacobian from one forward kinematics. The step solves
    ``(JᵀJ + λ diag JᵀJ) δ = −Jᵀr`` and is taken (``q_m ← q_m ⊗ exp(δ_m)``) only if it lowers
    ‖r‖²; λ halves after a taken step and rises tenfold after a refused one (Marquardt 1963), so
    the cost never rises.
    """
    idx = np.asarray(moving, np.int64)
    mask = jnp.asarray(_ancestors(skeleton)[1:][:, idx], start.dtype)  # (J-1, M)
    goal = target[:, 1:]

    def cost(pose: jax.Array) -> jax.Array:
        return jnp.sum((_positions(skeleton, pose)[:, 1:] - goal) ** 2, axis=(1, 2))

    def step(_: int, state: tuple) -> tuple:
        pose, c, lam = state
        f = pose.shape[0]
        zero = jnp.zeros((f, 3), pose.dtype)
        grot, pos = forward_kinematics(skeleton, pose, zero)
        axes = jnp.swapaxes(quat_to_matrix(grot[:, idx]), -1, -2)  # (F, M, axis, xyz)
        arm = pos[:, 1:, None, :] - pos[:, None, idx, :]  # (F, J-1, M, 3)
        jac = jnp.cross(axes[:, None], arm[:, :, :, None, :]) * mask[None, :, :, None, None]
        jm = jnp.transpose(jac, (0, 1, 4, 2, 3)).reshape(f, -1, 3 * len(idx))
        jtj = jnp.einsum("fkm,fkn->fmn", jm, jm)
        g = jnp.einsum("fkm,fk->fm", jm, (pos[:, 1:] - goal).reshape(f, -1))
        damp = jnp.maximum(jnp.diagonal(jtj, axis1=1, axis2=2), 1e-9) * lam[:, None]
        lhs = jtj + damp[:, :, None] * jnp.eye(jtj.shape[-1], dtype=jtj.dtype)
        delta = jnp.linalg.solve(lhs, -g[..., None])[..., 0]
        turned = quat_mul(pose[:, idx], quat_from_expmap(delta.reshape(f, -1, 3)))
        trial = pose.at[:, idx].set(turned)
        new = cost(trial)
        better = new < c
        return (
            jnp.where(better[:, None, None], trial, pose),
            jnp.where(better, new, c),
            jnp.where(better, lam * 0.5, lam * 10.0),
        )

    lam0 = jnp.full(start.shape[:1], 1e-2, start.dtype)
    pose, _, _ = jax.lax.fori_loop(0, max_steps, step, (start, cost(start), lam0))
    return pose


def refit_kept_rotations(
    skeleton: Skeleton,
    rotations: Float[Any, "F J 4"],
    kept: tuple[int, ...],
    key: Float[Any, "J 4"],
    *,
    max_steps: int = 12,
) -> Float[np.ndarray, "F J 4"]:
    """Local rotations ``(F, J, 4)`` of a level: frozen joints at ``key``, kept ones refitted.

    Args:
        skeleton: the full skeleton the captured ``rotations`` ``(F, J, 4)`` belong to.
        rotations: captured local rotations (the root's row is kept as given).
        kept: the level's kept joint indices (the root included); the others are frozen.
        key: ``(J, 4)`` key-posture local rotations of the frozen joints.
        max_steps: Levenberg–Marquardt steps per frame (taken or refused).

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
    moving = tuple(sorted(kept))
    out = _refit(skeleton, moving, jnp.asarray(start), jnp.asarray(target), max_steps)
    return np.asarray(out, np.float32)


def whole_body_error(
    skeleton: Skeleton, rotations: Float[Any, "F J 4"], captured: Float[Any, "F J 4"]
) -> Float[np.ndarray, "F J-1"]:
    """Distance of every non-root joint to its captured place, root-relative ``(F, J − 1)``."""
    a = _positions(skeleton, jnp.asarray(rotations, jnp.float32))
    b = _positions(skeleton, jnp.asarray(captured, jnp.float32))
    return np.linalg.norm(np.asarray(a - b), axis=-1)[:, 1:]
