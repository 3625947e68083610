"""Time warps from DTW paths, resampling onto the reference timeline, and ΔA (paper 001 §3.5).

Notation (paper 001 §3.5): sample ``i`` is aligned to the reference motion ``M_1`` by the
time-warp ``A_{1→i}``, which maps a reference time to the sample time showing the same moment of
the motion. In jcrowd both times are measured in *frames* (the reference's and the sample's,
both at the model rate after DESIGN §4 step 1), so:

- :func:`time_warp` — ``A(t)`` for every integer reference frame ``t``, a fractional sample
  frame, from a DTW path whose first column indexes the reference and whose second the sample.
- :func:`resample_warp` — the same map on the reference timeline resampled to ``T`` output
  frames (default 100): output frame ``u`` is reference time ``u (N−1)/(T−1)``; the result is
  the sample's fractional frame for every output frame, the times at which the sample is
  resampled to build its aligned pose vectors (:func:`sample_motion`).
- :func:`warp_increments` — the incremental inverse time-warp of paper 001 §3.5,
  ``ΔA_i(t) = A_{1→i}(t) − A_{1→i}(t−1)`` on the output frames. What is stored: *sample frames
  per output frame*, with ``ΔA(0) = A(0)`` (the sample frame matched to the first output frame,
  0 for a DTW path, which starts at the corner), so that ``A = cumsum(ΔA)`` exactly. ``ΔA`` is
  ≥ 0 (A is monotone) and is larger where the sample is slower than the reference; it is the
  extra pose element of DESIGN §4 step 5. Kriging interpolates it across samples (paper 001
  kriges the increments rather than ``A`` itself "to ensure a monotonically increasing
  sequence"), and :func:`warp_from_increments` integrates an interpolated ``ΔA`` back to a time
  map, so the synthesized motion's speed and duration interpolate: its output frame ``u`` is
  shown at sample time ``A(u)``, i.e. at ``A(u)/fps`` seconds, and the clip lasts
  ``A(T−1)/fps``.
- :func:`invert_warp` — the other direction, a sample (or synthesized) time to the output frame
  to show, for playback at a fixed frame rate.

Reading taken for turning a path into a function: the path is a staircase, not a function. Where
it is horizontal (one reference frame matched to several sample frames) ``A`` takes the mean of
those sample frames; where it is vertical (several reference frames matched to one sample
frame) the run is replaced by one knot at its mean reference frame, and ``A`` is linear between
knots. The result is monotone, strictly increasing between the first and the last knot, and
the identity for a diagonal path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from jaxtyping import Float

from jcrowd.align.costs import AlignError, Metric, as_sequence
from jcrowd.align.dtw import DTWResult, dtw
from jcrowd.align.multiscale import multiscale_dtw
from jcrowd.motion.clip import Motion
from jcrowd.motion.rotation import quat_slerp

__all__ = [
    "Alignment",
    "align_to_reference",
    "invert_warp",
    "resample_warp",
    "sample_motion",
    "time_warp",
    "warp_from_increments",
    "warp_increments",
]


def _check_path(path: np.ndarray) -> np.ndarray:
    p = np.asarray(path)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise AlignError(f"time_warp: expected a (K, 2) path, found shape {p.shape}")
    steps = np.diff(p, axis=0)
    ok = np.all((steps >= 0) & (steps <= 1), axis=1) & np.any(steps > 0, axis=1)
    if p[0, 0] != 0 or p[0, 1] != 0 or not np.all(ok):
        raise AlignError(
            "time_warp: expected a path from (0, 0) with steps (1,0), (0,1), (1,1), found "
            f"start {tuple(p[0])} and {int(np.sum(~ok))} other steps"
        )
    return p.astype(np.int64)


def time_warp(path: np.ndarray) -> Float[np.ndarray, " N"]:
    """``A(t)``: the (fractional) sample frame matched to each reference frame ``t``.

    Args:
        path: ``(K, 2)`` DTW path ``(reference frame, sample frame)`` from ``(0, 0)`` to
            ``(N−1, M−1)``, e.g. :attr:`DTWResult.path` of ``dtw(reference, sample)``.

    Returns:
        ``(N,)`` float64, non-decreasing, ``A(t) ∈ [0, M−1]`` (see the module doc for how
        horizontal and vertical runs are averaged).
    """
    p = _check_path(path)
    n = int(p[-1, 0]) + 1
    # Horizontal runs: one knot per reference frame at the mean of its sample frames.
    per_row = np.bincount(p[:, 0], weights=p[:, 1], minlength=n) / np.bincount(p[:, 0], minlength=n)
    # Vertical runs: reference frames sharing a value collapse to one knot at their mean.
    starts = np.flatnonzero(np.r_[True, per_row[1:] != per_row[:-1]])
    sizes = np.diff(np.r_[starts, n])
    knot_t = starts + 0.5 * (sizes - 1)
    knot_a = per_row[starts]
    return np.interp(np.arange(n, dtype=np.float64), knot_t, knot_a)


def resample_warp(warp: Float[np.ndarray, " N"], num_frames: int = 100) -> Float[np.ndarray, " T"]:
    """``A`` on ``num_frames`` output frames spanning the reference: frame ``u`` ↔ reference
    time ``u (N−1)/(T−1)``; linear between reference frames. Returns sample frames ``(T,)``."""
    a = np.asarray(warp, np.float64)
    if a.ndim != 1 or len(a) == 0 or not np.all(np.isfinite(a)):
        raise AlignError(f"resample_warp: expected a finite (N,) warp, found shape {a.shape}")
    if not (isinstance(num_frames, int | np.integer) and num_frames >= 2):
        raise AlignError(f"resample_warp: expected num_frames >= 2, found {num_frames!r}")
    t = np.linspace(0.0, len(a) - 1.0, int(num_frames))
    return np.interp(t, np.arange(len(a), dtype=np.float64), a)


def warp_increments(warp: Float[np.ndarray, " T"]) -> Float[np.ndarray, " T"]:
    """``ΔA(t) = A(t) − A(t−1)`` with ``ΔA(0) = A(0)`` (paper 001 §3.5), sample frames per
    output frame, so that ``cumsum(ΔA) = A``."""
    a = np.asarray(warp, np.float64)
    if a.ndim != 1 or len(a) == 0:
        raise AlignError(f"warp_increments: expected a (T,) warp, found shape {a.shape}")
    return np.diff(a, prepend=0.0)


def warp_from_increments(
    increments: Float[np.ndarray, " T"], *, min_increment: float | None = 0.0
) -> Float[np.ndarray, " T"]:
    """The time map ``A = cumsum(ΔA)`` of a (possibly interpolated) ``ΔA`` curve.

    Args:
        increments: ``(T,)`` ΔA as :func:`warp_increments` stores it.
        min_increment: increments after the first are clamped to at least this (sample frames
            per output frame) so the map stays monotone when interpolation overshoots below
            zero (paper 001 §3.5 interpolates increments for exactly this reason); None keeps
            them as they are.

    Returns:
        ``(T,)`` sample time (frames) of every output frame.
    """
    d = np.asarray(increments, np.float64)
    if d.ndim != 1 or len(d) == 0 or not np.all(np.isfinite(d)):
        raise AlignError(
            f"warp_from_increments: expected finite (T,) increments, found shape {d.shape}"
        )
    if min_increment is not None:
        d = np.concatenate([d[:1], np.maximum(d[1:], min_increment)])
    return np.cumsum(d)


def invert_warp(
    warp: Float[np.ndarray, " T"], times: Float[np.ndarray, " S"]
) -> Float[np.ndarray, " S"]:
    """``A⁻¹``: the (fractional) output frame shown at each sample time in ``times`` (frames).

    ``warp`` must be non-decreasing; flat stretches (several output frames at one sample time)
    map to their middle. Times outside ``[A(0), A(T−1)]`` clamp to the first/last frame.
    """
    a = np.asarray(warp, np.float64)
    if a.ndim != 1 or len(a) == 0 or np.any(np.diff(a) < 0):
        raise AlignError("invert_warp: expected a non-decreasing (T,) warp")
    starts = np.flatnonzero(np.r_[True, a[1:] != a[:-1]])
    sizes = np.diff(np.r_[starts, len(a)])
    return np.interp(np.asarray(times, np.float64), a[starts], starts + 0.5 * (sizes - 1))


def sample_motion(
    motion: Motion, frames: Float[np.ndarray, " T"], fps: float | None = None
) -> Motion:
    """The clip at fractional ``frames``: rotations slerped, root positions linearly
    interpolated between the two nearest frames (clamped to the clip).

    Args:
        motion: the sample.
        frames: ``(T,)`` fractional frame indices, e.g. :func:`resample_warp`'s output.
        fps: frame rate recorded on the result (default: the sample's; the timing of an
            aligned sample lives in its ΔA, not in this number).
    """
    f = np.clip(np.asarray(frames, np.float64), 0.0, motion.num_frames - 1.0)
    if f.ndim != 1 or len(f) == 0:
        raise AlignError(f"sample_motion: expected (T,) frames, found shape {f.shape}")
    i0 = np.floor(f).astype(np.int64)
    i1 = np.minimum(i0 + 1, motion.num_frames - 1)
    rot = np.asarray(motion.rotations)
    pos = np.asarray(motion.root_positions)
    w = (f - i0).astype(rot.dtype)
    out_rot = quat_slerp(rot[i0], rot[i1], w[:, None])
    out_pos = pos[i0] * (1 - w[:, None]) + pos[i1] * w[:, None]
    return Motion(motion.skeleton, out_rot, out_pos, float(fps or motion.fps))


AUTO_EXACT_CELLS = 500_000
"""Largest ``N·M`` that :func:`align_to_reference` aligns exactly under ``method="auto"``
(``bench/dtw.py``: exact is faster at 300 frames, multiscale from ~1000)."""


@dataclass(frozen=True)
class Alignment:
    """A sample aligned to a reference (DESIGN §4 step 4).

    Attributes:
        frames: ``(T,)`` the sample's fractional frame at each output frame (``A``).
        increments: ``(T,)`` ``ΔA`` (sample frames per output frame; ``cumsum`` gives
            ``frames``).
        result: the DTW path and cost between reference and sample.
    """

    frames: np.ndarray
    increments: np.ndarray
    result: DTWResult


def align_to_reference(
    reference: Float[np.ndarray, "N D"],
    sample: Float[np.ndarray, "M D"],
    *,
    num_frames: int = 100,
    metric: Metric = "euclidean",
    method: Literal["auto", "exact", "multiscale"] = "auto",
    band: float | None = None,
    radius: int = 12,
) -> Alignment:
    """Align ``sample`` to ``reference`` by DTW on their features and resample the warp.

    Args:
        reference, sample: per-frame features (:func:`pose_features` or
            :func:`physics_features`) of the reference and the sample.
        num_frames: output frames ``T`` on the reference timeline.
        metric: local cost (:func:`dtw`).
        method: ``"exact"`` (:func:`dtw`, with ``band``), ``"multiscale"``
            (:func:`multiscale_dtw`, with ``radius``), or ``"auto"``: exact up to
            ``AUTO_EXACT_CELLS`` cells (about 700 × 700 frames, where exact is as fast; a gait
            cycle is 60–140 frames at 60 Hz), multiscale beyond.

    Returns:
        :class:`Alignment`.
    """
    ref = as_sequence(reference, "align_to_reference")
    smp = as_sequence(sample, "align_to_reference")
    if method == "auto":
        method = "exact" if len(ref) * len(smp) <= AUTO_EXACT_CELLS else "multiscale"
    if method == "multiscale":
        result = multiscale_dtw(ref, smp, metric=metric, radius=radius)
    elif method == "exact":
        result = dtw(ref, smp, metric=metric, band=band)
    else:
        raise AlignError(
            f"align_to_reference: expected method 'auto', 'exact' or 'multiscale', found {method!r}"
        )
    frames = resample_warp(time_warp(result.path), num_frames)
    return Alignment(frames, warp_increments(frames), result)
