"""Helpers several test modules share: captured clips and a synthetic motion-like tensor.
Fixtures are in conftest.py; the multi-device tests' child processes in on_devices.py.

Clips are read once per test process and shared by every module that asks for them: tests
read them and build new motions, never change them in place.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np

from jcrowd.io import read_bvh
from jcrowd.motion import Motion, drop_tpose_frames
from jcrowd.tensor import multi_mode_product


@cache
def load_clip(path: Path) -> Motion:
    """The capture at ``path`` (BVH) without its T-pose frames, as read (float32)."""
    return drop_tpose_frames(read_bvh(path))[0]


@cache
def load_clip64(path: Path) -> Motion:
    """:func:`load_clip` in float64, its quaternions renormalised to unit length."""
    m = load_clip(path)
    rot = np.asarray(m.rotations, np.float64)
    return Motion(
        m.skeleton,
        rot / np.linalg.norm(rot, axis=-1, keepdims=True),  # float64 unit quaternions
        np.asarray(m.root_positions, np.float64),
        m.fps,
    )


def _orthogonal(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.linalg.qr(rng.standard_normal((n, n)))[0]


def smooth_tensor(shape: tuple[int, ...], seed: int, decay: float = 0.12) -> np.ndarray:
    """A tensor with a smooth, decaying multilinear spectrum (like a motion tensor)."""
    rng = np.random.default_rng(seed)
    grids = np.meshgrid(*(np.arange(i) for i in shape), indexing="ij")
    core = rng.standard_normal(shape) * np.exp(-decay * sum(grids))
    return multi_mode_product(core, [_orthogonal(rng, i) for i in shape])
