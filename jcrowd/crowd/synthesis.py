"""Per-agent, per-level pose synthesis for the crowd step (paper 000 §4.3, Eqs. 4–5, 8).

A clip is fixed by its control vector ``c``; what the step keeps per agent is the clip's
*mixing vector* ``a = [b(c); 1; ĉ]`` — the kriging weights (001 Eq. 3) followed by the trend
basis — because the model's one variogram makes ``b(c)`` the same at every level
(:mod:`jcrowd.model.motion_model`). At level ``l`` the core is ``K(c) = Σ_k a_k V_k`` with ``V``
the residual cores and the trend planes (000 Eq. 8), and the pose vector at aligned frame ``τ`` is
``y = U_P K(c) w_T(τ)`` with ``w_T(τ)`` the linear interpolation of rows of ``U_T`` (000 Eq. 5).

Per agent-frame: ``K(c) = a V`` (``A × R_P R_T``; under ``vmap`` one GEMM for a whole bucket;
``V`` is stored as two factors of its rank, :func:`_factor_cores`), ``w_T(τ)`` from two rows of
``U_T``, ``g = K w_T`` and ``y = U_P g``, closed over the cycle in its pose rows: minus
``(τ / (T−1)) U_P K d`` there (:func:`jcrowd.model.posevec.cycle_closing`), so that the pose at
the cycle's last aligned frame is its first and a hand-over to the next cycle does not jump.
Finer levels keep no per-agent core between steps (a
full-level core per agent at 100k agents would be 480 MB, DESIGN §5, and reading cores back
from memory is no cheaper in the step's chunks than computing them); only the coarsest level's
small core is kept while a clip plays (:func:`jcrowd.crowd.state.refresh_far_cores`). Nor is a
precomputed ``V U_Tᵀ`` table read per agent: that takes a gather of two of its rows per agent,
and XLA's CPU gather materialises every row.

Forward kinematics runs on the level's *kept* joints only: a dropped joint keeps its reference
rotation, so the chain from a kept joint's nearest kept ancestor is a constant rotation and
offset folded into the kept joint (003 §5.1: frozen joints follow their parent). Every joint and
End Site of the full skeleton is then placed rigidly in the frame of its nearest kept joint, so
a coarse agent is drawn with the whole body, moving only where the level moves it.

Units: ``u_pose`` carries the layout's element scales; lengths are for
a 1 m character and are multiplied by the agent's height. Heading ``θ`` faces
``(sin θ, 0, cos θ)``; + yaw turns left (towards +x).
"""

from __future__ import annotations

from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jcrowd.kriging.model import KrigingModel
from jcrowd.kriging.universal import kriging_weights
from jcrowd.model.motion_model import MotionModel
from jcrowd.model.posevec import cycle_closing
from jcrowd.motion.rotation import quat_from_expmap, quat_mul, quat_rotate, quat_to_matrix, yaw_quat
from jcrowd.motion.skeleton import Skeleton, forward_kinematics, kept_ancestor_frame

__all__ = [
    "Decoders",
    "LevelDecoder",
    "RootRates",
    "build_decoders",
    "clip_core",
    "clip_weights",
    "coeffs_at",
    "decode_coeffs",
    "level_points",
    "pose_from_coeffs",
    "root_rates",
]

_HI = jax.lax.Precision.HIGHEST
_ROOT_ROWS = 7  # height, velocity (2), yaw rate, tilt (3): the first rows of every pose vector


class LevelDecoder(eqx.Module):
    """What one level needs to turn ``(a, τ)`` into joint positions.

    Attributes:
        cores: ``(Q, R_P·R_T)``: with ``mix_basis`` ``M``, the residual cores then the trend
            planes (``A`` rows, flattened) are ``V = M · cores`` (:func:`_factor_cores`);
            without it ``cores`` is ``V`` itself (``Q = A``).
        u_time: ``(T, R_T)``.
        u_pose: ``(P_l, R_P)`` scaled rows of ``U_P`` the level decodes: the 7 root rows, the
            kept joints' exp-map rows, then ΔA.
        u_rates: ``(4, R_P)`` the rate rows of ``u_pose`` (velocity, yaw rate, ΔA).
        u_poses: ``(P_l − 4, R_P)`` its pose rows (root height and tilt, kept joints), which
            a cycle closes in (:func:`jcrowd.model.posevec.cycle_closing`).
        closing: ``(R_T,)`` the time basis's move over the cycle, ``Ũ_T[T−1] − Ũ_T[0]``.
        local_ref: ``(K, 4)`` constant left factor of each kept joint's local rotation (the
            dropped ancestors' reference rotations, then the joint's own reference).
        skeleton: the kept joints as a skeleton (offsets through dropped ancestors), 1 m tall.
        anchor: static, nearest kept joint (index into the kept list) of every output point.
        direct: static, per output point the kept joint it *is* (its anchor, at offset 0), or
            −1 for a point placed rigidly off its anchor (dropped joints, End Sites).
        point_offset: ``(J + E, 3)`` each output point in its anchor's frame (1 m character).
        mix_basis: ``(A, Q)`` or ``None``.
    """

    cores: Float[Array, "Q RR"]
    u_time: Float[Array, "T RT"]
    u_pose: Float[Array, "P R"]
    u_rates: Float[Array, "4 R"]
    u_poses: Float[Array, "Pp R"]
    closing: Float[Array, " RT"]
    local_ref: Float[Array, "K 4"]
    skeleton: Skeleton
    anchor: tuple[int, ...] = eqx.field(static=True)
    point_offset: Float[Array, "N 3"]
    direct: tuple[int, ...] = eqx.field(static=True, default=())
    mix_basis: Float[Array, "A Q"] | None = None

    @property
    def num_kept(self) -> int:
        return self.skeleton.num_joints

    @property
    def ranks(self) -> tuple[int, int]:
        return int(self.u_pose.shape[1]), int(self.u_time.shape[1])

    def mix_cores(self) -> Float[Array, "A RR"]:
        """``V``, one flattened core per entry of the mixing vector."""
        if self.mix_basis is None:
            return self.cores
        return jnp.dot(self.mix_basis, self.cores, precision=_HI)


class Decoders(eqx.Module):
    """Every level's decoder plus the shared kriging (level 0's system) and clip constants.

    Attributes:
        kriging: the kriging model whose weights serve every level.
        levels: finest first.
        frames: T, aligned frames per cycle (a cycle runs over τ ∈ [0, T − 1]).
        fps: the model clock (sample frames per second) that ΔA counts in.
    """

    kriging: KrigingModel
    levels: tuple[LevelDecoder, ...]
    frames: int = eqx.field(static=True)
    fps: float = eqx.field(static=True)

    @property
    def mix_size(self) -> int:
        lv = self.levels[0]
        return int((lv.cores if lv.mix_basis is None else lv.mix_basis).shape[0])


def _level_decoder(model: MotionModel, level: int) -> LevelDecoder:
    lv = model.levels[level]
    k = lv.kriging
    r_p, r_t = lv.u_pose.shape[1], lv.u_time.shape[1]
    terms = np.concatenate(
        [np.asarray(k.residuals, np.float64), np.asarray(k.trend, np.float64)], axis=0
    ).reshape(-1, r_p * r_t)
    layout, skel = model.layout, model.skeleton
    kept = [0, *sorted(j for j in lv.joints if j != 0)]
    rows = np.concatenate(
        [np.arange(_ROOT_ROWS), layout.joint_elements(kept[1:]), [layout.delta_a]]
    ).astype(int)
    u_pose = (np.asarray(lv.u_pose, np.float64) * layout.scale[:, None])[rows]
    poses = layout.pose_rows()[rows]
    reference = np.asarray(layout.reference, np.float64)
    kept_set = set(kept)
    parents = [-1]
    offsets = [np.asarray(skel.offsets, np.float64)[0]]
    local_ref = [np.array([1.0, 0.0, 0.0, 0.0])]
    for j in kept[1:]:
        anc, rot, off = kept_ancestor_frame(skel, reference, kept_set, j)
        parents.append(kept.index(anc))
        offsets.append(off)
        local_ref.append(quat_mul(rot, reference[j]))
    anchor, point_offset = [], []
    end_offsets = np.asarray(skel.end_offsets_or_empty(), np.float64)
    ends = list(zip(skel.end_parents, end_offsets, strict=True))
    for j in range(skel.num_joints):
        if j in kept_set:
            anchor.append(kept.index(j))
            point_offset.append(np.zeros(3))
        else:
            anc, _, off = kept_ancestor_frame(skel, reference, kept_set, j)
            anchor.append(kept.index(anc))
            point_offset.append(off)
    for parent, end in ends:
        # An End Site hangs in its parent joint's frame: the parent's own (dynamic) frame if it
        # is kept, else a constant frame inside the parent's nearest kept ancestor.
        if parent in kept_set:
            anchor.append(kept.index(parent))
            point_offset.append(end)
        else:
            anc, rot, off = kept_ancestor_frame(skel, reference, kept_set, parent)
            anchor.append(kept.index(anc))
            point_offset.append(off + quat_rotate(quat_mul(rot, reference[parent]), end))
    names = tuple(skel.names[j] for j in kept)
    f32 = np.float32
    basis, cores = _factor_cores(terms)
    return LevelDecoder(
        cores=jnp.asarray(cores, f32),
        mix_basis=None if basis is None else jnp.asarray(basis, f32),
        u_time=jnp.asarray(lv.u_time, f32),
        u_pose=jnp.asarray(u_pose, f32),
        u_rates=jnp.asarray(u_pose[~poses], f32),
        u_poses=jnp.asarray(u_pose[poses], f32),
        closing=jnp.asarray(cycle_closing(lv.u_time), f32),
        local_ref=jnp.asarray(np.stack(local_ref), f32),
        skeleton=Skeleton(names, tuple(parents), jnp.asarray(np.stack(offsets), f32)),
        anchor=tuple(anchor),
        point_offset=jnp.asarray(np.stack(point_offset), f32),
        direct=tuple(
            anchor[j] if j in kept_set else -1 for j in range(skel.num_joints + len(ends))
        ),
    )


FACTOR_RTOL = 1e-6
"""Singular values of ``V`` below this fraction of the largest count as zero."""


def _factor_cores(v: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
    """``V = M W`` with ``M`` ``(A, Q)`` and ``W`` ``(Q, R_P R_T)``, ``Q = rank V``, when that
    makes ``a V = (a M) W`` cheaper; else ``(None, V)``.

    ``V``'s rank is at most the tensor's sample-mode rank, not ``A``: each residual core is the
    HOSVD core contracted with its sample's row of ``U_S`` (000 Eq. 4), and the trend planes
    are linear combinations of the residual cores (a least-squares fit over the samples). The
    default model's level 0 has ``A = 77`` rows of rank 58 (singular values fall from 4e-2 to
    5e-9 of the largest there, float rounding of the stored cores), so the per-agent core GEMM
    of the crowd step shrinks from 92,400 to 74,066 multiply-adds; levels 1–5 (rank 27 … 9)
    shrink 2–4×. The rank threshold (:data:`FACTOR_RTOL`) sits in that gap; the factors come
    from a float64 SVD, ``M = U Σ``, ``W = Vᵀ`` (orthonormal rows, so ``W``'s float32 rounding is
    not amplified).
    """
    a, rr = v.shape
    u, sv, wt = np.linalg.svd(v, full_matrices=False)
    q = int(np.sum(sv > FACTOR_RTOL * sv[0])) if sv.size and sv[0] > 0 else 0
    if q == 0 or q * (a + rr) >= a * rr:
        return None, v
    return u[:, :q] * sv[:q], wt[:q]


def build_decoders(model: MotionModel) -> Decoders:
    """Precompute every level's decoder (host code, once per model)."""
    levels = tuple(_level_decoder(model, level) for level in range(len(model.levels)))
    frames = int(model.levels[0].u_time.shape[0])
    return Decoders(model.levels[0].kriging, levels, frames, float(model.fps))


def point_parents(model: MotionModel) -> tuple[int, ...]:
    """Parent of every output point (joints, then End Sites) for drawing bones; -1 for the root."""
    skel = model.skeleton
    return tuple(skel.parents) + tuple(skel.end_parents)


# ----------------------------------------------------------------------------- per agent


def clip_weights(decoders: Decoders, c: Float[Array, " d"]) -> Float[Array, " A"]:
    """The mixing vector ``a = [b(c); 1; ĉ]`` of the clip with controls ``c`` (one agent)."""
    k = decoders.kriging
    b, _ = kriging_weights(k, c)
    x = (jnp.asarray(c, k.controls.dtype) - k.control_mean) / k.control_scale
    return jnp.concatenate([b, jnp.ones((1,), x.dtype), x])


def clip_core(level: LevelDecoder, a: Float[Array, " A"]) -> Float[Array, "RP RT"]:
    """The clip's core ``K(c) = a V`` at a level (000 Eq. 8), for one agent: ``(a M) W`` when
    the level's ``V`` is stored factored (:func:`_factor_cores`)."""
    if level.mix_basis is not None:
        a = jnp.dot(a, level.mix_basis, precision=_HI)
    return jnp.dot(a, level.cores, precision=_HI).reshape(level.ranks)


def coeffs_at(
    level: LevelDecoder, core: Float[Array, "RP RT"], tau: Float[Array, ""]
) -> Float[Array, " R2"]:
    """``[K w_T(τ); K (w_T(τ) − (τ / (T−1)) d)]`` ``(2 R_P,)`` for one agent's core (000
    Eq. 5; the second for the pose rows, closed over the cycle,
    :func:`jcrowd.model.posevec.cycle_closing`); τ is clamped to ``[0, T − 1]``. Linear in the
    core, so blending two clips' coefficients blends their poses.

    ``w_T(τ)`` interpolates linearly between the rows of ``Ũ_T`` round τ.
    """
    last = level.u_time.shape[0] - 1
    tau = jnp.clip(jnp.asarray(tau, level.u_time.dtype), 0.0, float(last))
    i0 = jnp.minimum(jnp.floor(tau), float(last - 1))
    frac = tau - i0
    w = jax.lax.dynamic_slice_in_dim(level.u_time, i0.astype(jnp.int32), 2, axis=0)
    w_t = w[0] + frac * (w[1] - w[0])
    closed = w_t - (tau / last) * level.closing
    return jnp.concatenate(
        [jnp.dot(core, w_t, precision=_HI), jnp.dot(core, closed, precision=_HI)]
    )


def decode_coeffs(
    level: LevelDecoder, a: Float[Array, " A"], tau: Float[Array, ""]
) -> Float[Array, " R2"]:
    """:func:`coeffs_at` of the clip's core ``K(c)`` (000 Eqs. 5, 8) for one agent
    (:func:`clip_core` first). To evaluate one clip at several phases, compute the core once."""
    return coeffs_at(level, clip_core(level, a), tau)


def pose_from_coeffs(level: LevelDecoder, g: Float[Array, " R2"]) -> Float[Array, " P"]:
    """The level's pose-vector rows (scaled; root rows, kept joints, ΔA) from
    :func:`coeffs_at`'s ``[g; g_closed]``: the rate rows (1–3 and the last) from ``g``, the
    pose rows from ``g_closed``."""
    r_p = level.u_pose.shape[1]
    rates = jnp.dot(level.u_rates, g[:r_p], precision=_HI)
    poses = jnp.dot(level.u_poses, g[r_p:], precision=_HI)
    return jnp.concatenate([poses[:1], rates[:3], poses[1:], rates[3:]])


@dataclass(frozen=True)
class RootRates:
    """Root motion per aligned frame, read from a pose vector (1 m character units)."""

    velocity: Array  # (2,) (x, z) in the heading frame, per aligned frame
    yaw_rate: Array  # radians per aligned frame
    delta_a: Array  # sample frames per aligned frame (> 0)


def root_rates(y: Float[Array, " P"]) -> RootRates:
    """Velocity, yaw rate and ΔA of a level pose vector (ΔA kept ≥ 1e-3 so time moves)."""
    return RootRates(y[1:3], y[3], jnp.maximum(y[-1], 1e-3))


def level_points(
    level: LevelDecoder,
    y: Float[Array, " P"],
    root_xz: Float[Array, " 2"],
    heading: Float[Array, ""],
    height: Float[Array, ""],
) -> Float[Array, "N 3"]:
    """World positions of every joint and End Site of one agent at this level.

    The root sits at ``(x, y_h · height, z)`` with rotation ``yaw(heading) ⊗ exp(tilt)``; the kept
    joints' local rotations are ``local_ref ⊗ exp(e_j)``; FK per depth (:func:`forward_kinematics`)
    on the level skeleton, then each point rigidly in its anchor's frame.
    """
    kept = level.num_kept
    root = quat_mul(yaw_quat(heading), quat_from_expmap(y[4:7]))
    e = y[_ROOT_ROWS : _ROOT_ROWS + 3 * (kept - 1)].reshape(kept - 1, 3)
    joints = quat_mul(level.local_ref[1:], quat_from_expmap(e))
    local = jnp.concatenate([root[None], joints], axis=0)
    rot, pos = forward_kinematics(level.skeleton, local, jnp.zeros(3, local.dtype))
    base = jnp.stack([root_xz[0], y[0] * height, root_xz[1]])
    return base + height * _place_points(level, rot, pos)


def _place_points(
    level: LevelDecoder, rot: Float[Array, "K 4"], pos: Float[Array, "K 3"]
) -> Float[Array, "N 3"]:
    """Every output point from the kept joints' global frames: a kept joint is its own position;
    any other point is ``pos[a] + R[a] · offset`` for its anchor ``a``.

    When the kept joints are the leading points (level 0: every joint kept, only the End Sites
    placed) they are copied rather than multiplied by a zero offset, and only the placed points'
    anchors get a rotation matrix: placing all ``(J + E) × 3`` outputs would spend most of the
    level-0 placement on multiplying kept joints by a zero offset.
    """
    anchor = np.asarray(level.anchor)
    direct = np.asarray(level.direct) if level.direct else np.full(anchor.shape, -1)
    kept_first = np.concatenate([np.flatnonzero(direct >= 0), np.flatnonzero(direct < 0)])
    if not np.array_equal(kept_first, np.arange(direct.size)):
        # The kept joints are not the leading points (coarse levels): putting the points back
        # in order (a permutation of the point axis) costs more than the zero-offset products
        # it saves, so every point is placed.
        direct = np.full(anchor.shape, -1)
    d_idx, e_idx = np.flatnonzero(direct >= 0), np.flatnonzero(direct < 0)
    parts = []
    if d_idx.size:
        src = direct[d_idx]
        parts.append(pos if np.array_equal(src, np.arange(pos.shape[0])) else pos[src])
    if e_idx.size:
        # One matrix per distinct anchor, then three broadcast multiply-adds: the matrix is
        # built once for every point sharing the anchor, where a quaternion rotation per point
        # would redo the quaternion products for each of them.
        uniq, inv = np.unique(anchor[e_idx], return_inverse=True)
        whole = np.array_equal(uniq, np.arange(rot.shape[0]))
        m = quat_to_matrix(rot if whole else rot[uniq])[inv]
        off = level.point_offset[e_idx]
        parts.append(
            pos[anchor[e_idx]]
            + m[:, :, 0] * off[:, 0:1]
            + m[:, :, 1] * off[:, 1:2]
            + m[:, :, 2] * off[:, 2:3]
        )
    return parts[0] if len(parts) == 1 else jnp.concatenate(parts, axis=0)
