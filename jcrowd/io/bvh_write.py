"""Writing BVH files (the reader and the format's conventions are in :mod:`jcrowd.io.bvh`)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from jcrowd.errors import BVHError
from jcrowd.io.atomic import write_atomic
from jcrowd.io.bvh import (
    DEFAULT_JOINT_CHANNELS,
    DEFAULT_ROOT_CHANNELS,
    check_scale,
    classify_channels,
    convert_euler,
    require,
)
from jcrowd.motion.clip import Motion
from jcrowd.motion.skeleton import Skeleton

__all__ = ["write_bvh"]


def write_bvh(
    path: str | os.PathLike[str],
    motion: Motion,
    *,
    channels: Sequence[Sequence[str]] | None = None,
    scale: float = 1.0,
    precision: int = 6,
) -> None:
    """Write a clip as a BVH file, atomically (temporary file in the same folder, then rename).

    Args:
        path: target file; its folder must exist.
        motion: the clip (metres).
        channels: per-joint channel names (e.g. a :class:`BVHClip`'s); ``None`` gives the root
            ``Xposition Yposition Zposition Zrotation Yrotation Xrotation`` and every other joint
            ``Zrotation Yrotation Xrotation``.
        scale: file units → metres, so the file holds ``metres / scale`` (1 = metres).
        precision: decimals of every number written (degrees and file units).

    Joints are written depth first, as the format nests them; a skeleton in another topological
    order reads back in depth-first order.
    """
    p = os.fspath(path)
    ctx = f"write_bvh({p!r})"
    check_scale(scale, ctx)
    ok = isinstance(precision, int) and not isinstance(precision, bool) and 0 <= precision <= 12
    require(ok, f"{ctx}: expected precision an int in 0..12, found {precision!r}")
    sk, n = motion.skeleton, motion.skeleton.num_joints
    chans: list[tuple[str, ...]] = [DEFAULT_ROOT_CHANNELS] + [DEFAULT_JOINT_CHANNELS] * (n - 1)
    if channels is not None:
        chans = [tuple(c) for c in channels]
    require(len(chans) == n, f"{ctx}: expected channels for {n} joints, found {len(chans)}")
    require(motion.num_frames > 0, f"{ctx}: expected at least one frame, found none")
    for name in sk.names:
        ok = bool(name) and name == " ".join(name.split()) and not {"{", "}"} & set(name)
        require(ok, f"{ctx}: expected joint names without braces or line breaks, found {name!r}")
    layout = [
        classify_channels(c, f"{ctx}: joint {m!r}") for c, m in zip(chans, sk.names, strict=True)
    ]
    offsets = np.asarray(sk.offsets, np.float64) / scale
    end_offsets = np.asarray(sk.end_offsets_or_empty(), np.float64) / scale
    q = np.asarray(motion.rotations, np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    root_pos = np.asarray(motion.root_positions, np.float64) / scale
    ok = all(np.isfinite(a).all() for a in (offsets, end_offsets, norm, root_pos))
    require(ok, f"{ctx}: expected finite offsets, rotations and positions, found NaN or inf")
    require(np.all(norm > 1e-9), f"{ctx}: expected unit quaternions, found a zero quaternion")
    angles = convert_euler(q / norm, [order for _, _, order in layout], to_quat=False)

    columns = []
    for j, (pos, rot, _) in enumerate(layout):
        block = np.zeros((motion.num_frames, len(chans[j])))
        for c, axis in pos:  # a non-root joint's positions are in its OFFSET: write zeros
            block[:, c] = root_pos[:, axis] if j == 0 else 0.0
        if len(rot) == 2:  # a middle angle past ±90° comes out as e3 = ±180°: use the twin
            e1, e2, e3 = angles[:, j].T
            twin = np.stack([e1 + 180, np.copysign(180, e2) - e2, e3 - np.copysign(180, e3)], 1)
            flip = (np.abs(e3) > 90)[:, None]
            angles[:, j] = np.where(flip, (twin + 180) % 360 - 180, angles[:, j])
        for k, (c, _) in enumerate(rot):
            block[:, c] = angles[:, j, k]
        # 1e-3°: far above float32 round-off (~1e-5°), far below any real rotation.
        lost = np.abs(angles[:, j, len(rot) :]).max(initial=0.0)
        require(lost < 1e-3, f"{ctx}: {sk.names[j]!r} turns {lost:.3g}° about an axis it lacks")
        missing = [a for a in range(3) if j == 0 and a not in [ax for _, ax in pos]]
        moved = np.abs(root_pos[:, missing]).max(initial=0.0) * scale > 1e-6
        require(not moved, f"{ctx}: the root moves along an axis its channels {chans[0]} lack")
        columns.append(block)
    header, order = _hierarchy_text(sk, chans, offsets, end_offsets, precision)
    data = np.round(np.concatenate([columns[j] for j in order], axis=1), precision) + 0.0  # no -0
    row = " ".join([f"%.{precision}f"] * data.shape[1])
    body = "\n".join(row % tuple(r) for r in data.tolist())
    timing = f"Frames: {motion.num_frames}\nFrame Time: {1.0 / motion.fps:.10g}"
    write_atomic(p, f"{header}MOTION\n{timing}\n{body}\n", error=BVHError)


def _hierarchy_text(
    sk: Skeleton, chans: list[tuple[str, ...]], offsets: np.ndarray, ends: np.ndarray, prec: int
) -> tuple[str, list[int]]:
    """The HIERARCHY section and the depth-first joint order it lists."""
    kids: list[list[int]] = [[] for _ in sk.names]
    for j, par in enumerate(sk.parents[1:], start=1):
        kids[par].append(j)
    out, order = ["HIERARCHY"], []

    def emit(j: int, ind: str) -> None:
        order.append(j)
        out.extend([f"{ind}{'JOINT' if j else 'ROOT'} {sk.names[j]}", ind + "{"])
        out.append(f"{ind}\tOFFSET {_vec(offsets[j], prec)}")
        out.append(f"{ind}\tCHANNELS {len(chans[j])} {' '.join(chans[j])}".rstrip())
        for c in kids[j]:
            emit(c, ind + "\t")
        for e in (e for e, par in enumerate(sk.end_parents) if par == j):
            offset = f"{ind}\t\tOFFSET {_vec(ends[e], prec)}"
            out.extend([f"{ind}\tEnd Site", f"{ind}\t{{", offset, f"{ind}\t}}"])
        out.append(ind + "}")

    emit(0, "")
    return "\n".join(out) + "\n", order


def _vec(v: np.ndarray, prec: int) -> str:
    return " ".join(f"{x:.{prec}f}" for x in np.round(v, prec) + 0.0)  # + 0.0: no "-0.000"
