"""Gait-cycle samples of a dataset: the rows of the motion tensor (DESIGN §4 steps 1–3).

Every clip is resampled to the model rate, its left-started gait cycles become samples (each
cut out, root-normalised to start above the origin facing +Z) with their control parameters,
and — when ``mirror`` is on (the default for walks) — the clip's mirror image adds its own
left-started cycles, which are the original's right-started ones reflected. Mirroring doubles
the samples and balances left and right turns. Cycles of one clip and its mirror share a
``group`` id, so cross-validation can leave a whole take out at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from jcrowd.errors import DataError
from jcrowd.motion.clip import Clip, Motion, mirror, normalize_root, resample, slice_frames
from jcrowd.motion.gait import GaitCycle, character_height, gait_cycles
from jcrowd.motion.skeleton import Skeleton

__all__ = ["CONTROL_NAMES", "Sample", "gait_samples", "reference_skeleton"]

CONTROL_NAMES = ("dx", "dz", "dyaw", "speed", "height")
"""Control parameters every sample carries (m, m, rad, m/s, m); a model picks a subset."""


@dataclass(frozen=True)
class Sample:
    """One gait cycle (two steps from a left heel strike) ready for alignment.

    Attributes:
        motion: the cycle's frames ``start..end`` (both heel strikes), root-normalised, at the
            model rate.
        cycle: the cycle's frames and control parameters in its (resampled, maybe mirrored) clip.
        source: the clip's path; ``mirrored`` whether this is the mirror image.
        group: clip index (a clip and its mirror share it).
        height: the character's standing height (m).
        actor, style, repetition: labels from ``labels.csv`` (or None).
    """

    motion: Motion
    cycle: GaitCycle
    source: str
    mirrored: bool
    group: int
    height: float
    actor: str | None
    style: str | None
    repetition: int | None

    def controls(self, names: Sequence[str] = CONTROL_NAMES) -> np.ndarray:
        """The sample's control parameters in the order of ``names``."""
        values = {
            "dx": self.cycle.dx,
            "dz": self.cycle.dz,
            "dyaw": self.cycle.dyaw,
            "speed": self.cycle.speed,
            "height": self.height,
        }
        try:
            return np.array([values[n] for n in names], np.float64)
        except KeyError as e:
            raise DataError(
                f"controls: expected names from {CONTROL_NAMES}, found {e.args[0]!r}"
            ) from None


def gait_samples(
    clips: Sequence[Clip], *, fps: float = 60.0, mirrored: bool = True
) -> list[Sample]:
    """Left-started gait cycles of every clip (and of its mirror) as samples at ``fps``."""
    if not clips:
        raise DataError("samples: expected at least one clip, found none")
    names = clips[0].motion.skeleton.names
    out: list[Sample] = []
    for group, clip in enumerate(clips):
        if clip.motion.skeleton.names != names:
            raise DataError(
                f"{clip.path}: expected the dataset's skeleton (joints {list(names)}), found "
                f"{list(clip.motion.skeleton.names)}"
            )
        motion = resample(clip.motion, fps)
        height = character_height(motion.skeleton)
        variants = [(motion, False)] + ([(mirror(motion), True)] if mirrored else [])
        for variant, is_mirror in variants:
            for cycle in gait_cycles(variant):
                cut = normalize_root(slice_frames(variant, cycle.start, cycle.end + 1))
                out.append(
                    Sample(
                        cut,
                        cycle,
                        clip.path,
                        is_mirror,
                        group,
                        height,
                        clip.actor,
                        clip.style,
                        clip.repetition,
                    )
                )
    if not out:
        raise DataError(
            "samples: no complete gait cycle (two steps from a left heel strike) in any clip"
        )
    return out


def reference_skeleton(samples: Sequence[Sample]) -> Skeleton:
    """The model's skeleton for a height of 1 m: every sample's offsets ÷ its height, averaged.

    An agent of height ``h`` uses ``reference_skeleton(...).scaled(h)``.
    """
    first = samples[0].motion.skeleton
    offs = np.mean(
        [np.asarray(s.motion.skeleton.offsets, np.float64) / s.height for s in samples], axis=0
    )
    ends = np.mean(
        [
            np.asarray(s.motion.skeleton.end_offsets_or_empty(), np.float64) / s.height
            for s in samples
        ],
        axis=0,
    )
    return Skeleton(
        first.names,
        first.parents,
        offs.astype(np.float32),
        first.end_parents,
        ends.reshape(-1, 3).astype(np.float32),
    )
