"""Helpers several test modules share: captured clips, a synthetic motion-like tensor, the
crowd step's test model and XLA's full optimisation for the fits. Fixtures are in conftest.py;
the multi-device tests' child processes in on_devices.py.

Clips are read once per test process and shared by every module that asks for them: tests
read them and build new motions, never change them in place.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from functools import cache
from pathlib import Path

import jax
import numpy as np

from jcrowd.io import load_default_model, read_bvh
from jcrowd.model import MotionModel
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


# The shipped model's finest, a middle and the coarsest of its six levels.
STEP_LEVELS = (0, 3, 5)


@cache
def step_model() -> MotionModel:
    """The shipped motion model with three of its six levels (``STEP_LEVELS``), for the tests of
    the crowd step's mechanics (buckets, jit, hand-overs, budgets, sources, devices).

    Every per-level path of the step runs with three levels as with six (the finest with its
    blending and foot locking, a middle one, the coarsest with its cached cores); the compiled
    step is half the size and compiles in half the time. The scenario, CLI and docs tests run
    the shipped model itself.
    """
    model = load_default_model()
    return replace(model, levels=tuple(model.levels[i] for i in STEP_LEVELS))


@contextmanager
def fully_optimised() -> Iterator[None]:
    """Compile what runs inside with XLA's full optimisation (conftest lowers it for the tests).

    For the fits: a few programs run over every frame of every capture (the per-level refit's
    Levenberg–Marquardt), so their run time, not their compile time, decides how long a fit
    takes. The in-memory jit caches keep whatever was compiled, inside or outside.
    """
    before = jax.config.read("jax_disable_most_optimizations")
    jax.config.update("jax_disable_most_optimizations", False)
    try:
        yield
    finally:
        jax.config.update("jax_disable_most_optimizations", before)
