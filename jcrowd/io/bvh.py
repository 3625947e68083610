"""BVH motion files: read any channel layout into a :class:`~jcrowd.motion.clip.Motion`, write one
back.

NumPy only (no jax operation runs here). Conventions (DESIGN §3):

- Rotation channels ``Zrotation Yrotation Xrotation`` mean ``R = Rz @ Ry @ Rx`` (intrinsic, in
  listed order): degrees in the file, unit quaternions ``(w, x, y, z)`` in the clip, converted in
  float64 by :mod:`jcrowd.motion.rotation`. Every joint may have its own order, with its position
  channels anywhere in the list.
- Lengths become metres by a per-file ``scale`` (file units → metres). ``scale=None`` detects the
  unit from the rest-pose height ``H`` (max − min y of joints and End Sites): ``H < 3`` metres,
  ``14–46`` CMU units (0.056444 m), ``46–110`` inches, ``110–300`` cm, ``800–3000`` mm; any other
  height is an error asking for an explicit ``scale=``.
- The root's position channels are ``Motion.root_positions``; the root OFFSET is
  ``skeleton.offsets[0]``, which forward kinematics adds (world root = channels + OFFSET, as in
  the format). Writing puts each back where it came from, so read → write → read is exact.

Choices: missing rotation axes (fewer than three rotation channels) read as 0° and no rotation
channel means the identity; writing raises if the motion turns about an axis the channels lack.
Position channels on a non-root joint must be constant (their value joins that joint's offset
and is written back as zeros); varying ones raise. ``fps = 1 / Frame Time``, snapped to a
whole number when within 1e-5 of one (1/120 s printed to 7 decimals reads back as 120.0005 fps).
Frame values are one token stream (line breaks do not matter) of exactly ``Frames × channels``
values; no frame is dropped (that is :func:`jcrowd.motion.clip.drop_tpose_frames`'s job). Every
malformed input raises :class:`~jcrowd.errors.BVHError` citing ``path:line``; nothing is half-read.
Writing goes to a temporary file in the target folder, renamed into place.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from jcrowd.errors import BVHError, where
from jcrowd.motion.clip import Motion
from jcrowd.motion.rotation import euler_to_quat, quat_to_euler
from jcrowd.motion.skeleton import Skeleton, rest_positions

__all__ = ["UNIT_SCALES", "BVHClip", "load_bvh", "read_bvh"]

UNIT_SCALES: dict[str, float] = {"m": 1.0, "cmu": 0.056444, "in": 0.0254, "cm": 0.01, "mm": 0.001}
"""Known file units and their size in metres (DESIGN §4.1)."""

# The rest-pose heights [low, high) in file units that identify each unit.
_HEIGHTS = {"m": (0, 3), "cmu": (14, 46), "in": (46, 110), "cm": (110, 300), "mm": (800, 3000)}
# What write_bvh gives the root and every other joint when no channel lists are passed.
DEFAULT_ROOT_CHANNELS = (
    "Xposition",
    "Yposition",
    "Zposition",
    "Zrotation",
    "Yrotation",
    "Xrotation",
)
DEFAULT_JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")
_Pairs = list[tuple[int, int]]  # (column in a joint's channel list, axis 0-2)


@dataclass(frozen=True)
class BVHClip:
    """A BVH file as read: the clip in metres plus what it takes to write it back alike.

    Attributes:
        motion: every frame of the file; lengths in metres.
        channels: each joint's channel names exactly as in the file.
        scale: file units → metres factor used.
        units: ``"m"``, ``"cmu"``, ``"in"``, ``"cm"``, ``"mm"`` or ``"custom"``.
        path: the file read.
    """

    motion: Motion
    channels: tuple[tuple[str, ...], ...]
    scale: float
    units: str
    path: str


def load_bvh(path: str | os.PathLike[str], *, scale: float | None = None) -> BVHClip:
    """Read a BVH file.

    Args:
        path: the file.
        scale: file units → metres; ``None`` detects it from the rest-pose height.

    Returns:
        the clip (all frames, metres, float32 arrays), channel names, scale and unit name.
    """
    p = os.fspath(path)
    try:  # text mode turns CRLF and CR into "\n"; "-sig" drops a byte-order mark
        with open(p, encoding="utf-8-sig", errors="replace") as f:
            rd = _Reader(f.read().splitlines(), p)
    except OSError as e:
        raise BVHError(f"{where(p)}: cannot read the file: {e.strerror or e}") from e
    nodes = _parse_hierarchy(rd)
    joints = [n for n in nodes if n.kind != "End Site"]
    ends = [n for n in nodes if n.kind == "End Site"]
    values, frame_time = _parse_motion(rd, sum(len(n.channels) for n in joints))
    frames = len(values)

    offsets = np.array([n.offset for n in joints], np.float64)
    root_pos, angles = np.zeros((frames, 3)), np.zeros((frames, len(joints), 3))
    orders, col = [], 0
    for j, node in enumerate(joints):
        pos, rot, order = classify_channels(node.channels, where(p, node.channels_line))
        block = values[:, col : col + len(node.channels)]
        col += len(node.channels)
        for c, axis in pos:
            v = block[:, c]
            if j == 0:
                root_pos[:, axis] = v
                continue
            varies = np.ptp(v) > 1e-6 * max(1.0, float(np.abs(v).max()))
            msg = f"expected constant {node.channels[c]} on joint {node.name!r}, found it varying"
            rd.need(not varies, f"{msg} (not supported)", node.channels_line)
            offsets[j, axis] += v[0]
        angles[:, j, : len(rot)] = block[:, [c for c, _ in rot]]
        orders.append(order)

    index = {id(n): j for j, n in enumerate(joints)}
    names = tuple(n.name for n in joints)
    parents = tuple(-1 if n.parent is None else index[id(n.parent)] for n in joints)
    end_parents = tuple(index[id(n.parent)] for n in ends)
    end_offsets = np.array([n.offset for n in ends], np.float64).reshape(-1, 3)
    sk = Skeleton(names, parents, _f32(offsets), end_parents, _f32(end_offsets))  # file units
    scale, units = _detect_units(sk, p) if scale is None else (scale, check_scale(scale, p))
    sk = Skeleton(names, parents, _f32(offsets * scale), end_parents, _f32(end_offsets * scale))
    rotations = _f32(convert_euler(angles, orders, to_quat=True))
    motion = Motion(sk, rotations, _f32(root_pos * scale), _frame_rate(frame_time))
    return BVHClip(motion, tuple(n.channels for n in joints), float(scale), units, p)


def read_bvh(path: str | os.PathLike[str], *, scale: float | None = None) -> Motion:
    """The :class:`Motion` of a BVH file (see :func:`load_bvh`)."""
    return load_bvh(path, scale=scale).motion


@dataclass(eq=False)
class _Node:
    kind: str  # "ROOT", "JOINT" or "End Site" (the only kind without a name)
    name: str
    parent: _Node | None
    offset: list[float] | None = None
    channels: tuple[str, ...] = ()
    channels_line: int = 0


class _Reader:
    """The whitespace tokens of some lines one at a time, with 1-based line numbers for errors."""

    def __init__(self, lines: list[str], path: str) -> None:
        self.lines, self.path = lines, path
        self.row, self.col = 0, 0  # the last token read is toks[col - 1], on line ``row``
        self.toks: list[str] = []

    def err(self, msg: str, line: int | None = None) -> BVHError:
        return BVHError(f"{where(self.path, self.row if line is None else line)}: {msg}")

    def need(self, ok: object, msg: str, line: int | None = None) -> None:
        require(ok, str(self.err(msg, line)))

    def next(self, what: str | None = None) -> str:
        """The next token; ``""`` at the end of the file, or an error if ``what`` was due."""
        while self.col >= len(self.toks):
            if self.row >= len(self.lines):
                self.need(what is None, f"truncated file: expected {what}, found the end")
                return ""
            self.toks, self.col, self.row = self.lines[self.row].split(), 0, self.row + 1
        self.col += 1
        return self.toks[self.col - 1]

    def line_args(self) -> list[str]:
        """The tokens left on the current line, up to a brace."""
        start = self.col
        while self.col < len(self.toks) and self.toks[self.col] not in ("{", "}"):
            self.col += 1
        return self.toks[start : self.col]


def require(ok: object, msg: str) -> None:
    """Raise :class:`~jcrowd.errors.BVHError` with ``msg`` unless ``ok``."""
    if not ok:
        raise BVHError(msg)


def _f32(a: np.ndarray) -> Any:
    """A float32 copy (typed ``Any``: Skeleton and Motion hold NumPy or jax arrays)."""
    return np.asarray(a, np.float32)


def _float(token: str) -> float | None:
    try:
        return float(token)
    except ValueError:
        return None


def _parse_hierarchy(rd: _Reader) -> list[_Node]:
    """Joints and End Sites in file order; stops after the MOTION keyword."""
    tok = rd.next()
    found = repr(tok) if tok else "an empty file"
    rd.need(tok.upper() == "HIERARCHY", f"expected HIERARCHY first, found {found}", max(rd.row, 1))
    nodes: list[_Node] = []
    stack: list[_Node] = []
    seen: dict[str, int] = {}
    while tok := rd.next():
        kw, top = tok.upper(), stack[-1] if stack else None
        rd.need(nodes or kw == "ROOT", f"expected ROOT after HIERARCHY, found {tok!r}")
        if tok in ("{", "}"):
            rd.need(tok == "}" and top, f"unbalanced braces: found a stray {tok!r}")
            o = stack.pop()
            rd.need(o.offset, f"expected an OFFSET in {o.kind} {o.name}, found none")
        elif kw in ("ROOT", "JOINT", "END"):
            name = " ".join(rd.line_args())
            rd.need(kw != "ROOT" or not nodes, "expected one ROOT, found a second (not supported)")
            rd.need(top or kw == "ROOT", f"expected {tok} inside braces, found it outside")
            rd.need(not top or top.name, f"expected only an OFFSET in an End Site, found {tok}")
            if kw == "END":
                rd.need(name.upper() == "SITE", f"expected 'End Site', found {tok} {name!r}")
                kw, name = "End Site", ""
            else:
                dup = f" (first on line {seen[name]})" if name in seen else ""
                rd.need(name and not dup, f"expected a unique joint name, found {name!r}{dup}")
                seen[name] = rd.row
            brace = rd.next(f"'{{' after {kw} {name}")
            rd.need(brace == "{", f"expected '{{' after {kw} {name}, found {brace!r}")
            nodes.append(_Node(kw, name, top))
            stack.append(nodes[-1])
        elif kw in ("OFFSET", "CHANNELS"):
            args = rd.line_args()
            if top is None or (kw == "CHANNELS" and not top.name):
                found = "in an End Site" if top else "outside"
                raise rd.err(f"expected {tok} in a joint, found it {found}")
            if kw == "OFFSET":
                vals = [_float(a) for a in args]
                rd.need(top.offset is None, f"expected one OFFSET in {top.kind}, found a second")
                ok = len(vals) == 3 and all(v is not None and math.isfinite(v) for v in vals)
                rd.need(ok, f"expected 3 finite numbers after OFFSET, found {' '.join(args)!r}")
                top.offset = [v or 0.0 for v in vals]
            else:
                n, names = args[0] if args else "", tuple(args[1:])
                rd.need(not top.channels_line, f"expected one CHANNELS in {top.name}, found two")
                rd.need(n.isdigit(), f"expected a channel count after CHANNELS, found {n!r}")
                rd.need(len(names) == int(n), f"expected {n} channel names, found {len(names)}")
                classify_channels(names, where(rd.path, rd.row))
                top.channels, top.channels_line = names, rd.row
        elif kw == "MOTION":
            rd.need(not top, f"expected '}}' closing {top and top.name} before MOTION, found none")
            return nodes
        else:
            raise rd.err(f"expected a BVH keyword, found unknown keyword {tok!r}")
    rd.need(nodes, "expected ROOT after HIERARCHY, found the end of the file")
    rd.need(not stack, f"truncated file: expected '}}' closing {stack and stack[-1].name}")
    raise rd.err("expected MOTION after the hierarchy, found the end of the file")


def classify_channels(names: Sequence[str], ctx: str) -> tuple[_Pairs, _Pairs, str]:
    """A channel list's position and rotation ``(column, axis)`` pairs, and its Euler order:
    the rotation axes in listed order, then the missing ones (read as 0°), e.g. ``YX`` → ``YXZ``."""
    pos: _Pairs = []
    rot: _Pairs = []
    for c, name in enumerate(names):
        low = name.lower()
        ok = len(low) == 9 and low[0] in "xyz" and low[1:] in ("position", "rotation")
        require(ok, f"{ctx}: expected channels X/Y/Z + position/rotation, found {name!r}")
        group, axis = rot if low[1:] == "rotation" else pos, "xyz".index(low[0])
        require(all(a != axis for _, a in group), f"{ctx}: expected one {name!r}, found two")
        group.append((c, axis))
    letters = "".join("XYZ"[a] for _, a in rot)
    return pos, rot, letters + "".join(a for a in "XYZ" if a not in letters)


def _parse_motion(rd: _Reader, width: int) -> tuple[np.ndarray, float]:
    """``(values (Frames, width) float64, Frame Time)``, all checked, after the MOTION keyword."""

    def value(label: str) -> str:
        for key in label.split():
            tok = rd.next(repr(label))
            rd.need(tok.upper() == key.upper(), f"expected {label!r}, found {tok!r}")
        return rd.next(f"a value after {label!r}")

    raw = value("Frames:")
    frames = int(raw) if raw.isdigit() else 0
    rd.need(frames > 0, f"expected a positive whole number after 'Frames:', found {raw!r}")
    raw = value("Frame Time:")
    dt = _float(raw) or math.nan
    rd.need(math.isfinite(dt) and dt > 0, f"expected seconds > 0 for 'Frame Time:', found {raw!r}")
    head, first = rd.toks[rd.col :], rd.row
    tokens = head + " ".join(rd.lines[first:]).split()

    def line_of(k: int) -> int:  # only on the error path: count tokens line by line
        k -= len(head)
        for r in range(first, len(rd.lines)):
            if k < 0:
                return r
            k -= len(rd.lines[r].split())
        return len(rd.lines)

    try:  # one NumPy pass; the token-by-token scan only locates an error
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        k = next((k for k, t in enumerate(tokens) if _float(t) is None), 0)
        raise rd.err(f"expected a number, found {tokens[k]!r}", line_of(k)) from None
    if not np.all(finite := np.isfinite(values)):
        k = int(np.argmin(finite))
        raise rd.err(f"expected finite values, found {tokens[k]!r}", line_of(k))
    need, have = frames * width, len(values)
    if have != need:
        short = have < need
        msg = f"{frames} frames × {width} channels = {need} values, found {have}"
        msg = f"truncated file: expected {msg}" if short else f"expected {msg}; extra from here"
        raise rd.err(msg, line_of(have - 1 if short else need))
    return values.reshape(frames, width), dt


def _detect_units(skeleton: Skeleton, path: str) -> tuple[float, str]:
    joints, ends = rest_positions(skeleton)
    ys = np.concatenate([joints[:, 1], ends[:, 1]])
    height = float(ys.max() - ys.min())
    for units, (low, high) in _HEIGHTS.items():
        if low <= height < high:
            return UNIT_SCALES[units], units
    known = ", ".join(f"{u} {lo}–{hi}" for u, (lo, hi) in _HEIGHTS.items())
    raise BVHError(
        f"{where(path)}: expected a rest-pose height in a known unit's range ({known}), "
        f"found {height:g} file units; pass an explicit scale= (file units → metres)"
    )


def _frame_rate(frame_time: float) -> float:
    """``1 / Frame Time``, snapped to a whole rate the printed time rounds from (1/120 s → 120)."""
    fps = 1.0 / frame_time
    whole = round(fps)
    return float(whole) if whole > 0 and abs(fps / whole - 1.0) < 1e-5 else fps


def check_scale(scale: float, ctx: str) -> str:
    """The unit name of a valid explicit scale (``"custom"`` unless it is a known one)."""
    ok = isinstance(scale, numbers.Real) and not isinstance(scale, bool)
    ok = ok and math.isfinite(scale) and scale > 0
    require(ok, f"{ctx}: expected scale (file units → metres) > 0, found {scale!r}")
    return next((u for u, v in UNIT_SCALES.items() if math.isclose(scale, v)), "custom")


def convert_euler(x: np.ndarray, orders: list[str], *, to_quat: bool) -> np.ndarray:
    """Degrees ``(F, J, 3)`` in each joint's full order ↔ unit quaternions ``(F, J, 4)``."""
    out = np.empty((*x.shape[:2], 4 if to_quat else 3))
    for order in set(orders):
        idx = [j for j, o in enumerate(orders) if o == order]
        if to_quat:
            out[:, idx] = euler_to_quat(np.radians(x[:, idx]), order)
        else:
            out[:, idx] = np.degrees(quat_to_euler(x[:, idx], order))
    return out
