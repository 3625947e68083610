"""Per-frame features that time alignment compares (DESIGN §4 step 4; papers 001 §3.5, 004 §3.1).

Two kinds, both invariant to where the clip is on the floor and which way it heads:

- :func:`pose_features` — the joint point cloud in the heading frame: every joint's position
  relative to the root joint, turned by minus the root's heading so the character faces +Z. The
  Euclidean distance between two such vectors is the point-cloud pose distance that paper 001
  takes from Kovar & Gleicher. Reading taken: Kovar & Gleicher align two clouds with the
  rigid 2-D transform (yaw + floor translation) that fits them best and sum over a window of
  frames; we fix the transform to the one that puts each root at the origin facing +Z, which is
  what DESIGN §2 asks for ("point-cloud distance") and makes the feature a per-frame vector, so
  DTW can use any metric and multiscale DTW can average it.
- :func:`physics_features` — paper 004 §3.1: the whole-body centre-of-mass (COM) acceleration
  and the angular momenta of chosen segments (feet and hands by default, as in its Figure 2),
  expressed in the heading frame.

Everything runs on NumPy float64: these feed the offline fit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from jaxtyping import Float

from jcrowd.align.anthropometry import BodySegments, body_segments
from jcrowd.errors import MotionError
from jcrowd.motion.clip import Motion, headings
from jcrowd.motion.gait import character_height
from jcrowd.motion.skeleton import end_site_positions, forward_kinematics

__all__ = ["GRAVITY", "center_of_mass", "physics_features", "pose_features", "to_heading_frame"]

GRAVITY = 9.81
"""Standard gravity (m/s²); COM acceleration features are in units of g."""


def _as_float64(motion: Motion) -> Motion:
    """The clip in float64 with exactly unit quaternions.

    A float32 clip's quaternions are unit only to ~1e-7; FK with a quaternion of norm s maps an
    offset o to ``(1 − s²) o + s² R o``, which is not turn-equivariant, so they are renormalised.
    """
    rot = np.asarray(motion.rotations, np.float64)
    return Motion(
        motion.skeleton,
        rot / np.linalg.norm(rot, axis=-1, keepdims=True),
        np.asarray(motion.root_positions, np.float64),
        motion.fps,
    )


def to_heading_frame(
    vectors: Float[np.ndarray, "F *n 3"], heading: Float[np.ndarray, " F"]
) -> Float[np.ndarray, "F *n 3"]:
    """Turn per-frame vectors by minus the frame's heading about +Y (so heading 0 faces +Z).

    A yaw θ maps +Z to (sin θ, 0, cos θ) (:func:`jcrowd.motion.rotation.quat_yaw`); its inverse maps
    (x, y, z) to (x cos θ − z sin θ, y, x sin θ + z cos θ).
    """
    v = np.asarray(vectors, np.float64)
    h = np.asarray(heading, np.float64).reshape((len(v),) + (1,) * (v.ndim - 2))
    c, s = np.cos(h), np.sin(h)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([x * c - z * s, y, x * s + z * c], axis=-1)


def pose_features(
    motion: Motion, weights: Float[np.ndarray, " J"] | None = None
) -> Float[np.ndarray, "F D"]:
    """Joint point cloud in the heading frame, ``(F, 3J)`` (m).

    Row ``t`` holds ``√w_j · R_y(−θ_t)(p_j(t) − p_root(t))`` for every joint ``j``, where ``θ_t``
    is the root heading (:func:`jcrowd.motion.clip.headings`). The squared Euclidean distance of two
    rows is then the weighted point-cloud distance ``Σ_j w_j |Δp_j|²`` (paper 001 §3.4–3.5,
    after Kovar & Gleicher; see the module doc for the reading taken).

    Args:
        motion: any skeleton.
        weights: optional non-negative ``(J,)`` joint weights (default 1 each).

    Returns:
        ``(F, 3J)`` float64.
    """
    m = _as_float64(motion)
    _, pos = forward_kinematics(m.skeleton, m.rotations, m.root_positions)
    rel = to_heading_frame(pos - pos[:, :1], np.asarray(headings(m)))
    if weights is not None:
        w = np.asarray(weights, np.float64)
        if w.shape != (m.skeleton.num_joints,) or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise MotionError(
                f"pose_features: expected {m.skeleton.num_joints} finite non-negative joint "
                f"weights, found shape {w.shape} with min {w.min() if w.size else 'n/a'}"
            )
        rel = rel * np.sqrt(w)[None, :, None]
    return rel.reshape(len(rel), -1)


def _points(motion: Motion) -> np.ndarray:
    """World positions of joints then End Sites, ``(F, J + E, 3)``."""
    grot, gpos = forward_kinematics(motion.skeleton, motion.rotations, motion.root_positions)
    ends = end_site_positions(motion.skeleton, grot, gpos)
    return np.concatenate([gpos, ends], axis=1)


def _segment_coms(segments: BodySegments, points: np.ndarray) -> np.ndarray:
    """COM of every bone, ``(F, S, 3)``."""
    prox = points[:, segments.proximal]
    return prox + segments.com_fraction[None, :, None] * (points[:, segments.distal] - prox)


def center_of_mass(motion: Motion) -> Float[np.ndarray, "F 3"]:
    """Whole-body COM per frame (m): ``Σ_s m_s c_s`` with the de Leva masses (paper 004 §3.1).

    Masses are fractions of body mass summing to 1 (:func:`body_segments`), so no division by
    the total is needed.
    """
    m = _as_float64(motion)
    segs = body_segments(m.skeleton)
    return np.einsum("s,fsk->fk", segs.mass, _segment_coms(segs, _points(m)))


def _smooth(x: np.ndarray, sigma_frames: float) -> np.ndarray:
    """Gaussian smoothing along axis 0; odd reflection at the ends keeps a linear trend.

    Twice differentiating raw captured positions amplifies marker noise by ``fps²``, so the
    trajectories are smoothed first (paper 004 does not say how it differentiates).
    """
    if sigma_frames <= 0 or len(x) < 3:
        return x
    radius = max(1, min(int(np.ceil(4.0 * sigma_frames)), len(x) - 1))
    taps = np.arange(-radius, radius + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (taps / sigma_frames) ** 2)
    kernel /= kernel.sum()
    pad = [(radius, radius)] + [(0, 0)] * (x.ndim - 1)
    xp = np.pad(x, pad, mode="reflect", reflect_type="odd")
    out = np.zeros_like(x)
    for k, w in enumerate(kernel):
        out += w * xp[k : k + len(x)]
    return out


def physics_features(
    motion: Motion,
    *,
    momentum: Sequence[str] = ("foot", "hand"),
    about: Literal["com", "joint"] = "com",
    smoothing_s: float = 0.025,
) -> Float[np.ndarray, "F D"]:
    """COM acceleration and segment angular momenta in the heading frame (paper 004 §3.1).

    Columns: the whole-body COM acceleration divided by g (3), then for each category in
    ``momentum`` the left and the right limb's angular momentum (3 each), so ``D = 3 + 6·k``.

    Angular momentum of a limb (all bones of that category and side, e.g. the foot's
    ankle→toe base→toe tip) is ``L = Σ_s m_s r_s × u_s`` with, for ``about``:

    - ``"com"`` (default): ``r_s = c_s − c_body``, ``u_s = v_s − v_body`` — the limb's share of
      the whole-body angular momentum about the COM (point-mass terms; bones have no spin
      inertia here). Relative velocities make it independent of walking speed's frame.
    - ``"joint"``: the paper's own words — "the cross product between the vector from the point
      the segment rotates around to the segment's COM and the vector expressing the linear
      momentum": ``r_s = c_s − p_joint`` (the limb's proximal joint, e.g. the ankle) and
      ``u_s = v_s`` (world velocity, since linear momentum is ``m v``).

    Scaling (the paper does not say how it weighs the two kinds): accelerations in g and each
    ``L`` divided by ``m_limb · h · √(g h)`` (``h`` = standing height), so both are
    dimensionless, of order 0.1–1 in walking, and the same for characters of any size.

    Args:
        motion: any skeleton whose names :func:`body_segments` recognises when ``momentum``
            is not empty (the COM alone works on any skeleton).
        momentum: categories of :data:`~jcrowd.align.anthropometry.DE_LEVA_MALE` whose left and
            right angular momenta are wanted, e.g. ``("foot",)`` for walks.
        about: reference point and velocity, see above.
        smoothing_s: σ (seconds) of the Gaussian applied to trajectories before differencing.

    Returns:
        ``(F, 3 + 6·len(momentum))`` float64, finite.
    """
    if about not in ("com", "joint"):
        raise MotionError(f"physics_features: expected about='com' or 'joint', found {about!r}")
    m = _as_float64(motion)
    if m.num_frames < 3:
        raise MotionError(
            f"physics_features: expected at least 3 frames to differentiate, found {m.num_frames}"
        )
    segs = body_segments(m.skeleton)
    dt = 1.0 / m.fps
    points = _smooth(_points(m), smoothing_s * m.fps)
    coms = _segment_coms(segs, points)
    vel = np.gradient(coms, dt, axis=0, edge_order=2)
    com = np.einsum("s,fsk->fk", segs.mass, coms)
    com_vel = np.einsum("s,fsk->fk", segs.mass, vel)
    com_acc = np.gradient(com_vel, dt, axis=0, edge_order=2)
    heading = np.asarray(headings(m))
    blocks = [to_heading_frame(com_acc / GRAVITY, heading)]

    h = character_height(m.skeleton)
    scale_l = h * np.sqrt(GRAVITY * h)
    for category in momentum:
        for side in ("left", "right"):
            idx = segs.select(category, side)
            idx = idx[segs.mass[idx] > 0]  # zero-length bones (CMU's finger joints) carry none
            if len(idx) == 0:
                found = sorted({c for c in segs.category if c != "none"})
                raise MotionError(
                    f"physics_features: expected {side} {category!r} bones for the angular "
                    f"momentum, found none among {found}; pass momentum=() for the COM alone"
                )
            mass = segs.mass[idx]
            if about == "com":
                r = coms[:, idx] - com[:, None]
                u = vel[:, idx] - com_vel[:, None]
            else:
                root_bone = idx[np.argmin(m.skeleton.depths[segs.proximal[idx]])]
                r = coms[:, idx] - points[:, segs.proximal[root_bone]][:, None]
                u = vel[:, idx]
            ang = np.einsum("s,fsk->fk", mass, np.cross(r, u))
            blocks.append(to_heading_frame(ang / (mass.sum() * scale_l), heading))
    return np.concatenate(blocks, axis=1)
