"""Foot contacts, gait cycles and their control parameters (DESIGN §4.2–4.3; paper 004 §4.2).

A *gait cycle* (one sample of the motion model) is two steps: it starts at a left heel strike
and ends at the next left heel strike, with exactly one right heel strike in between
(DESIGN §4.2). A cycle that starts at a *right* heel strike is the same thing for the mirrored
clip; :func:`gait_cycles` can list those too (``foot="both"``), which ``jcrowd inspect`` does so
that a short clip shows all the two-step cycles it holds. The fit takes left-started cycles
and gets the right-started ones by mirroring, so nothing is counted twice.

Foot contacts are found per foot from two joints, the ankle ("heel") and the toe, on any
skeleton: the joints are picked by name among left/right pairs (``*foot*``/``*ankle*`` and
``*toe*``), falling back to the lowest joint of each side at rest and its parent. A joint is in
contact while it is near its own planted height and
slow horizontally; entering needs both thresholds at their tight values, leaving needs one at
its loose value (hysteresis), so noise at a threshold cannot make a contact flicker. The planted
level is taken locally (the lowest height within ±0.8 s), since captured floors are not level.
A foot is
in contact when either joint is; a *heel strike* is the onset of a foot's contact. Thresholds
scale with the character's height (defaults are for a 1.75 m person).

Control parameters of a cycle, in the heading frame at its start (z forward, x to the
character's left, Y up; DESIGN §3): ``dx, dz`` root displacement (m), ``dyaw`` heading change
(radians, + = left turn), ``speed`` mean speed along the path (m/s), ``height`` the character's
standing height (m). The heading is the root's yaw (:func:`jcrowd.motion.clip.headings`); since a
cycle starts and ends at the same gait phase, the pelvis' own yaw oscillation cancels out.

Everything here runs on NumPy: it is offline analysis with data-dependent lengths.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from jcrowd.errors import MotionError
from jcrowd.motion.clip import Motion, headings, joint_positions, left_right_pairs
from jcrowd.motion.skeleton import Skeleton, rest_positions

__all__ = [
    "ContactThresholds",
    "FootContacts",
    "FootJoints",
    "GaitCycle",
    "character_height",
    "contacts_from_positions",
    "find_feet",
    "foot_contacts",
    "gait_cycles",
]

REFERENCE_HEIGHT = 1.75
"""Height (m) the default contact thresholds are tuned for; they scale linearly with height."""


@dataclass(frozen=True)
class FootJoints:
    """Joint indices of each foot's ankle (heel) and toe."""

    left_ankle: int
    left_toe: int
    right_ankle: int
    right_toe: int


@dataclass(frozen=True)
class ContactThresholds:
    """Contact detection thresholds for a 1.75 m character (scaled by height).

    A joint enters contact when its height above its planted level is below ``height_on`` and
    its horizontal speed below ``speed_on``; it leaves when either exceeds its ``_off`` value.
    Contacts shorter than ``min_contact_s`` are dropped and gaps shorter than ``min_gap_s``
    filled.
    """

    height_on: float = 0.04
    height_off: float = 0.08
    speed_on: float = 0.35
    speed_off: float = 0.7
    min_contact_s: float = 0.06
    min_gap_s: float = 0.05


@dataclass(frozen=True)
class FootContacts:
    """Per-frame contact flags ``(F,)`` of each foot, and the heel-strike frames."""

    left: np.ndarray
    right: np.ndarray
    feet: FootJoints
    first_strike: int = 1
    """Onsets before this frame are not strikes: the speeds there rest on one-sided differences."""

    @property
    def left_strikes(self) -> np.ndarray:
        return _onsets(self.left, self.first_strike)

    @property
    def right_strikes(self) -> np.ndarray:
        return _onsets(self.right, self.first_strike)

    def intervals(self, side: str) -> list[tuple[int, int]]:
        """Contact intervals ``[(first, last), ...]`` (inclusive) of ``"left"`` or ``"right"``."""
        flags = self.left if side == "left" else self.right
        return _runs(flags)


@dataclass(frozen=True)
class GaitCycle:
    """One gait cycle (two steps from a left heel strike).

    Attributes:
        foot: ``"left"`` or ``"right"``, the foot whose heel strike opens the cycle.
        start: frame of the heel strike that opens the cycle.
        end: frame of that foot's next heel strike (the cycle spans ``start..end``; ``end`` is
            also the next cycle's ``start``).
        dx, dz: root displacement over the cycle in the start heading frame (m; x left, z forward).
        dyaw: heading change over the cycle (radians, + = left turn).
        speed: mean speed along the path (m/s).
        duration: ``(end - start) / fps`` (s).
        height: the character's standing height (m).
    """

    foot: str
    start: int
    end: int
    dx: float
    dz: float
    dyaw: float
    speed: float
    duration: float
    height: float


def character_height(skeleton: Skeleton) -> float:
    """Standing height at rest (m): top minus bottom of joints and End Sites along Y."""
    joints, ends = rest_positions(skeleton)
    ys = np.concatenate([joints[:, 1], ends[:, 1]])
    return float(ys.max() - ys.min())


def find_feet(skeleton: Skeleton) -> FootJoints:
    """The ankle and toe joints of both feet, by name, else by rest-pose height."""
    pairs = left_right_pairs(skeleton.names)
    if not pairs:
        raise MotionError(
            "feet: expected left/right joint names (Left*/Right*, L*/R*, l*/r*), found none in "
            f"{list(skeleton.names)}"
        )

    def by_name(pattern: str) -> tuple[int, int] | None:
        hits = [lr for lr in pairs if re.search(pattern, skeleton.names[lr[0]], re.IGNORECASE)]
        return hits[0] if hits else None

    ankle = by_name(r"foot|ankle")
    toe = by_name(r"toe")
    if ankle is None:
        if toe is None:
            # The lowest left/right pair at rest is the toe; its parent pair is the ankle.
            rest, _ = rest_positions(skeleton)
            toe = min(pairs, key=lambda lr: rest[lr[0], 1])
        ankle = (skeleton.parents[toe[0]], skeleton.parents[toe[1]])
    elif toe is None:
        kids = [lr for lr in pairs if skeleton.parents[lr[0]] == ankle[0]]
        toe = kids[0] if kids else ankle
    return FootJoints(ankle[0], toe[0], ankle[1], toe[1])


def _onsets(flags: np.ndarray, first: int = 1) -> np.ndarray:
    """Frames ``>= first`` where a contact starts (False → True)."""
    f = np.asarray(flags, bool)
    on = np.nonzero(f[1:] & ~f[:-1])[0] + 1
    return on[on >= first]


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    f = np.concatenate([[False], np.asarray(flags, bool), [False]])
    d = np.diff(f.astype(np.int8))
    starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0] - 1
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]


def _hysteresis(h: np.ndarray, v: np.ndarray, t: ContactThresholds, s: float) -> np.ndarray:
    on = (h < t.height_on * s) & (v < t.speed_on * s)
    off = (h > t.height_off * s) | (v > t.speed_off * s)
    out = np.zeros(len(h), bool)
    state = bool(on[0])
    for i in range(len(h)):
        state = (state and not off[i]) or (not state and bool(on[i]))
        out[i] = state
    return out


def _local_floor(h: np.ndarray, window: int) -> np.ndarray:
    """The joint's planted height near each frame: the 2nd-lowest value within ±window/2.

    Captured floors are not level (CMU 07_01's planted toe is 3 cm higher at the end than at the
    start), so one clip-wide floor would miss late contacts. The window spans more than one
    gait cycle, so it always holds a stance of this foot; the 2nd-lowest value ignores one
    outlier sample.
    """
    half = max(1, window // 2)
    padded = np.pad(h, half, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    return np.partition(windows, 1, axis=-1)[:, 1]


def _clean(flags: np.ndarray, min_len: int, min_gap: int) -> np.ndarray:
    out = flags.copy()
    runs = _runs(out)
    for (_, a_end), (b_start, _) in pairwise(runs):
        if b_start - a_end - 1 < min_gap:
            out[a_end + 1 : b_start] = True
    for a, b in _runs(out):
        if b - a + 1 < min_len:
            out[a : b + 1] = False
    return out


def foot_contacts(motion: Motion, thresholds: ContactThresholds | None = None) -> FootContacts:
    """Contact flags of both feet per frame (see the module docstring for the rule)."""
    if motion.num_frames < 3:
        raise MotionError(f"foot contacts: expected at least 3 frames, found {motion.num_frames}")
    pos = np.asarray(joint_positions(motion), np.float64)
    return contacts_from_positions(pos, motion.skeleton, motion.fps, thresholds)


def contacts_from_positions(
    pos: np.ndarray,
    skeleton: Skeleton,
    fps: float,
    thresholds: ContactThresholds | None = None,
) -> FootContacts:
    """:func:`foot_contacts` of joint positions ``(F, J, 3)`` (metres) of ``skeleton`` at
    ``fps``: for motion given as points, such as what the crowd step draws."""
    if pos.shape[0] < 3:
        raise MotionError(f"foot contacts: expected at least 3 frames, found {pos.shape[0]}")
    t = thresholds or ContactThresholds()
    floor_window_s = 1.6
    feet = find_feet(skeleton)
    scale = character_height(skeleton) / REFERENCE_HEIGHT
    if not np.all(np.isfinite(pos)):
        raise MotionError("foot contacts: the clip has non-finite joint positions")
    # A moving average over ~1/30 s takes the capture's marker jitter out of the speeds.
    win = max(1, round(fps / 30.0))
    kernel = np.ones(win) / win
    flags = []
    for ankle, toe in ((feet.left_ankle, feet.left_toe), (feet.right_ankle, feet.right_toe)):
        joint_flags = []
        for j in {ankle, toe}:
            p = pos[:, j]
            h = p[:, 1] - _local_floor(p[:, 1], round(floor_window_s * fps))
            xz = np.stack([np.convolve(p[:, k], kernel, mode="same") for k in (0, 2)], axis=-1)
            xz[: win // 2 + 1] = p[: win // 2 + 1][:, [0, 2]]
            xz[-(win // 2 + 1) :] = p[-(win // 2 + 1) :][:, [0, 2]]
            v = np.linalg.norm(np.gradient(xz, axis=0), axis=-1) * fps
            joint_flags.append(_hysteresis(h, v, t, scale))
        flags.append(np.logical_or.reduce(joint_flags))
    min_len = max(1, round(t.min_contact_s * fps))
    min_gap = max(1, round(t.min_gap_s * fps))
    left, right = (_clean(f, min_len, min_gap) for f in flags)
    return FootContacts(left, right, feet, first_strike=max(2, round(0.05 * fps)))


def gait_cycles(
    motion: Motion,
    contacts: FootContacts | None = None,
    *,
    foot: str = "left",
    min_duration: float = 0.5,
    max_duration: float = 2.5,
) -> list[GaitCycle]:
    """Gait cycles of a clip with their control parameters, in order of their start frame.

    A cycle runs from a heel strike of ``foot`` (``"left"``, ``"right"`` or ``"both"``) to that
    foot's next one, and is kept when exactly one strike of the other foot lies in between
    (two steps) and its duration is within ``[min_duration, max_duration]`` s (a stop, a
    shuffle or a missed strike is skipped).

    ``speed`` is the arc length of a constant-curvature path through the start and end root
    positions with the cycle's heading change, divided by the duration:
    ``|d| · (θ/2) / sin(θ/2) / T`` — the chord alone would under-count turning cycles, and the
    sampled root path would add the pelvis' lateral sway.
    """
    if foot not in ("left", "right", "both"):
        raise MotionError(f"gait cycles: expected foot 'left', 'right' or 'both', found {foot!r}")
    c = contacts or foot_contacts(motion)
    yaw = np.unwrap(np.asarray(headings(motion), np.float64))
    root = np.asarray(motion.root_positions, np.float64)
    height = character_height(motion.skeleton)
    sides = ("left", "right") if foot == "both" else (foot,)
    cycles = []
    for side in sides:
        own, other = (
            (c.left_strikes, c.right_strikes)
            if side == "left"
            else (c.right_strikes, c.left_strikes)
        )
        for a, b in pairwise(own):
            steps = np.count_nonzero((other > a) & (other < b))
            duration = (b - a) / motion.fps
            if steps != 1 or not min_duration <= duration <= max_duration:
                continue
            h0 = yaw[a]
            d = root[b] - root[a]
            dz = d[0] * np.sin(h0) + d[2] * np.cos(h0)
            dx = d[0] * np.cos(h0) - d[2] * np.sin(h0)
            dyaw = yaw[b] - yaw[a]
            half = 0.5 * abs(dyaw)
            arc = np.hypot(dx, dz) * (half / np.sin(half) if half > 1e-6 else 1.0)
            cycles.append(
                GaitCycle(
                    side,
                    int(a),
                    int(b),
                    float(dx),
                    float(dz),
                    float(dyaw),
                    float(arc / duration),
                    duration,
                    height,
                )
            )
    return sorted(cycles, key=lambda cy: (cy.start, cy.foot))
