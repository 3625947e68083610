"""Joint simplification into levels (paper 003 §4–5): analysis → freezing → SQP → rotations.

:func:`simplify_motion` returns, per level, a normal :class:`~jcrowd.motion.clip.Motion` on the
level's skeleton (it can be written as BVH), the kept joint ids, and its errors. The per-frame
position problems of a level are solved together: one ``vmap``-ped, ``jit``-compiled SQP per
(skeleton, level) structure.

Local rotations are recovered from the optimised positions by :mod:`jcrowd.simplify.recover`.

Errors are measured on the full original skeleton (frozen joints at their key rotation, riding
with their kept ancestor) against the capture; bone-length variation is measured on the
optimised positions (what the paper's Fig. 7 reports), relative to each bone's key-posture
length.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache, partial
from itertools import pairwise
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jcrowd.errors import MotionError
from jcrowd.motion.clip import Motion
from jcrowd.motion.skeleton import forward_kinematics
from jcrowd.simplify.analysis import analyse_motion, elimination_order, key_posture
from jcrowd.simplify.levels import (
    LevelPlan,
    PositionProblem,
    Weights,
    angle_cosines,
    joint_counts,
    pair_safe_counts,
    plan_level,
    position_problem,
)
from jcrowd.simplify.recover import expand_rotations, recover_rotations
from jcrowd.simplify.sqp import RESULT, sqp_solve

DEFAULT_WEIGHTS = Weights()

__all__ = ["SimplifiedLevel", "SimplifiedLevels", "simplify_motion", "solve_positions"]


@dataclass(frozen=True)
class SimplifiedLevel:
    """One level of a simplified clip.

    Attributes:
        motion: the clip on the level's skeleton.
        kept: original indices of the kept joints.
        mean_error_m, max_error_m: joint position error against the capture over every
            non-root joint of the original skeleton (frozen joints ride rigidly with their
            parent), so a coarser level never looks better by having fewer joints to measure.
        bone_variation_mean_pct, bone_variation_max_pct: ``|len − b(0)| / b(0)`` of the
            optimised positions over bones and frames, in %.
        iterations: ``(F,)`` SQP iterations per frame; ``result``: ``(F,)`` :class:`RESULT`.
        optimised: ``(F, J, 3)`` the optimised positions of every original joint, relative to
            the root (frozen joints included; they are dropped from ``motion``).
    """

    motion: Motion
    kept: tuple[int, ...]
    mean_error_m: float
    max_error_m: float
    bone_variation_mean_pct: float
    bone_variation_max_pct: float
    iterations: np.ndarray
    result: np.ndarray
    optimised: np.ndarray

    @property
    def num_joints(self) -> int:
        return len(self.kept)

    @property
    def converged(self) -> bool:
        return bool(np.all(self.result == RESULT.CONVERGED))


@dataclass(frozen=True)
class SimplifiedLevels:
    """All levels of a clip, with the joint order and key frames they were built from."""

    levels: tuple[SimplifiedLevel, ...]
    order: tuple[int, ...]
    key_frames: np.ndarray
    importance: np.ndarray


def _objective_and_constraints(problem: PositionProblem, mode: str, w: Weights) -> tuple[Any, Any]:
    bones, angles = problem.bones, problem.angles

    def full(x: jax.Array) -> jax.Array:  # unknowns are every non-root joint, root at 0
        return jnp.concatenate([jnp.zeros((1, 3), x.dtype), x.reshape(-1, 3)])

    def residuals(x: jax.Array, params: tuple) -> jax.Array:
        # αE_d is the solver's closed-form prior term (see _solver); these are the other rows.
        _, b0, cos0 = params
        parts = [jnp.zeros((0,), x.dtype)]
        pos = full(x)
        if len(angles):
            parts.append(jnp.sqrt(w.gamma) * (angle_cosines(pos, angles) - cos0))
        if mode == "weighted" and len(bones):
            d = pos[bones[:, 0]] - pos[bones[:, 1]]
            lengths = jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-18)
            parts.append(jnp.sqrt(w.beta) * (lengths - b0))
        return jnp.concatenate(parts)

    rigid = bones[problem.bone_lengths > 1e-6]
    tied = bones[problem.bone_lengths <= 1e-6]

    def constraints(x: jax.Array, params: tuple) -> jax.Array:
        _, b0, _ = params
        pos = full(x)
        d = pos[rigid[:, 0]] - pos[rigid[:, 1]]
        # A zero-length bone (a helper joint on its parent) is a point-to-point tie, three
        # linear rows; its squared length would have a zero gradient and a singular KKT matrix.
        tie = (pos[tied[:, 0]] - pos[tied[:, 1]]).reshape(-1)
        return jnp.concatenate(
            [jnp.sum(d * d, axis=-1) - b0[problem.bone_lengths > 1e-6] ** 2, tie]
        )

    return residuals, (constraints if mode == "hard" and len(bones) else None)


def _bone_curvature(problem: PositionProblem) -> Any:
    """``Σ|λ_k| ∇²c_k`` of the rigid-bone constraints in closed form.

    ``c_k = ‖x_c − x_p‖² − b²`` has Hessian ``2 (e_c − e_p)(e_c − e_p)ᵀ ⊗ I₃``, so the sum is
    ``2 Dᵀ diag|λ| D ⊗ I₃`` with ``D`` the bones' incidence matrix over the unknown joints (the
    root is fixed and has no column); tie rows are linear and add nothing.
    """
    rigid = problem.bones[problem.bone_lengths > 1e-6]
    n_unknown = problem.num_joints - 1
    d = np.zeros((len(rigid), n_unknown))
    for k, (c, p) in enumerate(rigid):
        if c > 0:
            d[k, c - 1] += 1.0
        if p > 0:
            d[k, p - 1] -= 1.0
    d_j = jnp.asarray(d, jnp.float32)
    eye3 = jnp.eye(3, dtype=jnp.float32)

    def curvature(x: jax.Array, lam_abs: jax.Array) -> jax.Array:
        m = 2.0 * (d_j.T * lam_abs[: len(rigid)]) @ d_j
        return jnp.kron(m, eye3).astype(x.dtype)

    return curvature


@lru_cache(maxsize=64)
def _solver(key: tuple) -> Any:
    bones, rigid_mask, angles, mode, weights, n_joints, max_iter, tol = key
    problem = PositionProblem(
        np.asarray(bones, np.int64).reshape(-1, 2),
        np.asarray(rigid_mask, np.float64),
        np.asarray(angles, np.int64).reshape(-1, 3),
        np.zeros(len(angles)),
        n_joints,
    )
    residuals, constraints = _objective_and_constraints(problem, mode, weights)
    rigid = int(np.count_nonzero(problem.bone_lengths > 1e-6))
    m = rigid + 3 * (len(problem.bones) - rigid) if constraints is not None else 0

    curvature = _bone_curvature(problem) if constraints is not None else None

    def one(x0: jax.Array, b0: jax.Array, cos0: jax.Array) -> Any:
        return sqp_solve(
            residuals,
            constraints,
            x0,
            (x0, b0, cos0),
            num_constraints=m,
            max_iter=max_iter,
            tol=tol,
            prior_weight=weights.alpha,
            prior=x0,
            curvature=curvature,
        )

    return jax.jit(jax.vmap(one, in_axes=(0, None, None)))


def solve_positions(
    problem: PositionProblem,
    positions: np.ndarray,
    *,
    mode: str = "hard",
    weights: Weights = DEFAULT_WEIGHTS,
    max_iter: int = 30,
    tol: float = 1e-5,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Optimised positions ``(F, J, 3)`` (root-relative), iterations and result per frame.

    ``positions`` are the captured joint positions ``(F, J, 3)`` relative to the root.
    """
    if mode not in ("hard", "weighted"):
        raise MotionError(f"simplify: expected mode 'hard' or 'weighted', found {mode!r}")
    key = (
        tuple(map(tuple, problem.bones.tolist())),
        tuple((problem.bone_lengths > 1e-6).astype(float).tolist()),
        tuple(map(tuple, problem.angles.tolist())),
        mode,
        weights,
        problem.num_joints,
        max_iter,
        tol,
    )
    solve = _solver(key)
    f = positions.shape[0]
    x0 = jnp.asarray(positions[:, 1:].reshape(f, -1), jnp.float32)
    sol = solve(
        x0,
        jnp.asarray(problem.bone_lengths, jnp.float32),
        jnp.asarray(problem.angle_cos, jnp.float32),
    )
    x = np.asarray(sol.x, np.float64).reshape(f, -1, 3)
    out = np.concatenate([np.zeros((f, 1, 3)), x], axis=1)
    return out, np.asarray(sol.iterations), np.asarray(sol.result)


def simplify_motion(
    motion: Motion,
    levels: int = 8,
    *,
    order: tuple[int, ...] | None = None,
    counts: list[int] | None = None,
    mode: str = "hard",
    weights: Weights = DEFAULT_WEIGHTS,
    max_iter: int = 30,
    tol: float = 1e-5,
    on_level: Callable[[int, SimplifiedLevel], None] | None = None,
) -> SimplifiedLevels:
    """Simplify a clip into ``levels`` levels of detail (paper 003).

    Args:
        motion: the clip (at least 2 frames, finite).
        levels: number of levels, level 0 being the clip itself.
        order: elimination order (e.g. from a dataset's summed importance); default: this clip's.
        counts: joints per level (strictly decreasing, first = all, last ≥ 2); default
            :func:`joint_counts`.
        mode: ``"hard"`` (rigid bones as equality constraints) or ``"weighted"`` (Eq. 5).
        weights: α, β, γ.
        on_level: called with ``(level index, level)`` as each level is done (progress bars).
    """
    sk = motion.skeleton
    counts = _checked_counts(motion, levels, order, counts, mode)
    rot = np.asarray(motion.rotations, np.float64)
    root = np.asarray(motion.root_positions, np.float64)
    if not (np.all(np.isfinite(rot)) and np.all(np.isfinite(root))):
        raise MotionError("simplify: the clip has NaN or infinite rotations or positions")
    analysis = analyse_motion(motion)
    order = order or elimination_order(sk, analysis.importance)
    # A level keeps or freezes both joints of a mirrored pair.
    counts = pair_safe_counts(sk, tuple(order), list(counts))
    key = key_posture(motion, analysis.key_frames)
    glob, pos = forward_kinematics(sk, rot, root)
    solve = partial(solve_positions, mode=mode, weights=weights, max_iter=max_iter, tol=tol)
    out = []
    for count in counts:
        plan = plan_level(sk, order, sk.num_joints - count, key)
        level = _simplified_level(motion, plan, key, glob, pos, solve, count == sk.num_joints)
        out.append(level)
        if on_level is not None:
            on_level(len(out) - 1, level)
    return SimplifiedLevels(tuple(out), tuple(order), analysis.key_frames, analysis.importance)


def _checked_counts(
    motion: Motion,
    levels: int,
    order: tuple[int, ...] | None,
    counts: list[int] | None,
    mode: str,
) -> list[int]:
    """The joints per level (given or :func:`joint_counts`), every argument checked first.

    A bad mode with one level, a count below 2 or an order that is not the non-root joints
    would otherwise pass silently or fail deep inside.
    """
    sk = motion.skeleton
    if motion.num_frames < 2:
        raise MotionError(
            f"simplify: expected a clip of at least 2 frames, found {motion.num_frames}"
        )
    if mode not in ("hard", "weighted"):
        raise MotionError(f"simplify: expected mode 'hard' or 'weighted', found {mode!r}")
    counts = counts or joint_counts(sk.num_joints, levels)
    if (
        len(counts) != levels
        or counts[0] != sk.num_joints
        or any(b >= a for a, b in pairwise(counts))
    ):
        raise MotionError(
            f"simplify: expected {levels} strictly decreasing joint counts from "
            f"{sk.num_joints}, found {counts}"
        )
    if counts[-1] < 2:
        raise MotionError(
            f"simplify: expected every level to keep at least 2 joints, found counts {counts}"
        )
    if order is not None and sorted(order) != list(range(1, sk.num_joints)):
        raise MotionError(
            f"simplify: expected an elimination order listing each non-root joint "
            f"1..{sk.num_joints - 1} once, found {tuple(order)}"
        )
    return counts


def _simplified_level(
    motion: Motion,
    plan: LevelPlan,
    key: np.ndarray,
    glob: np.ndarray,
    pos: np.ndarray,
    solve: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray]],
    full: bool,
) -> SimplifiedLevel:
    """One level: optimised positions (``solve``), recovered rotations and the level's errors.

    ``glob``, ``pos``: the capture's global rotations and joint positions (forward kinematics
    of the whole skeleton). A ``full`` level (nothing frozen) is the capture itself.
    """
    sk = motion.skeleton
    rot = np.asarray(motion.rotations, np.float64)
    root = np.asarray(motion.root_positions, np.float64)
    rel = pos - pos[:, :1]
    problem = position_problem(sk, plan, key)
    if full:
        opt, iters, res = (
            rel,
            np.zeros(motion.num_frames, np.int32),
            np.zeros(motion.num_frames, np.int32),
        )
    else:
        opt, iters, res = solve(problem, rel)
    local = rot if full else recover_rotations(plan, opt + pos[:, :1], glob)
    level_motion = Motion(
        plan.skeleton, local.astype(np.float32), motion.root_positions, motion.fps
    )
    # Error over every joint of the original skeleton: frozen joints ride with their parent.
    _, full_pos = forward_kinematics(sk, expand_rotations(plan, key, local, sk.parents), root)
    err = np.linalg.norm(full_pos - pos, axis=-1)[:, 1:]
    var = _bone_variation_pct(problem, opt)
    return SimplifiedLevel(
        level_motion,
        plan.kept,
        float(err.mean()) if err.size else 0.0,
        float(err.max()) if err.size else 0.0,
        float(var.mean()) if var.size else 0.0,
        float(var.max()) if var.size else 0.0,
        iters,
        res,
        opt,
    )


def _bone_variation_pct(problem: PositionProblem, opt: np.ndarray) -> np.ndarray:
    """``|len − b(0)| / b(0)`` in % of the optimised positions, per frame and rigid bone."""
    b = problem.bones
    if not len(b):
        return np.zeros((1, 1))
    lengths = np.linalg.norm(opt[:, b[:, 0]] - opt[:, b[:, 1]], axis=-1)
    var = np.abs(lengths - problem.bone_lengths) / np.maximum(problem.bone_lengths, 1e-9) * 100
    return var[:, problem.bone_lengths > 1e-6]
