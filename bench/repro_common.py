"""What the sections of bench/reproduce.py share: output paths, the kriged controls, timing.

The sections (``repro_000`` key levels, ``repro_001`` kriging, ``repro_003`` joint
simplification, ``repro_004`` DTW and natural modes) each measure one paper's experiment and
render its part of docs/REPRODUCTION.md; :mod:`reproduce` runs them and writes the file.
Timing follows STYLE.md's benchmark rule: compilation is measured apart from the run, and the
run time quoted is the median of several repeats.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "REPRODUCTION.md"
FIGS = ROOT / "docs" / "reproduction"
CONTROLS = ("dx", "dz", "dyaw")
"""The kriged controls, as in the shipped model (``jcrowd.model.motion_model.fit_motion_model``'s
default)."""


def compile_and_median_s(fn: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """``(compile s, run s)`` of a jitted call: the first call's extra time over the median of
    ``repeats`` later calls, and that median. Results are waited for (``block_until_ready``).

    The garbage collector is run first and paused while timing, as :mod:`timeit` does, so a
    collection of what a preceding fit left behind does not land inside the timed calls.
    """
    gc.collect()
    gc.disable()
    try:
        t = time.perf_counter()
        jax.block_until_ready(fn())
        first = time.perf_counter() - t
        times = []
        for _ in range(max(1, repeats)):
            t = time.perf_counter()
            jax.block_until_ready(fn())
            times.append(time.perf_counter() - t)
    finally:
        gc.enable()
    run = float(np.median(times))
    return max(first - run, 0.0), run


def median_s(fn: Callable[[], Any], repeats: int) -> float:
    """Median seconds of ``fn()`` over ``repeats`` calls after one warm-up (compiling) call."""
    return compile_and_median_s(fn, repeats)[1]


def save_figure(fig: Any, name: str) -> str:
    """Write ``fig`` to docs/reproduction/``name`` and close it; returns ``name``."""
    import matplotlib.pyplot as plt

    FIGS.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(FIGS / name, dpi=90)
    plt.close(fig)
    return name
