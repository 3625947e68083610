"""Benchmark: exact vs multiscale DTW (paper 004 §3.2), with dtaidistance side by side.

Data (``--sequences cycles``, the default): gait cycles (two steps from a left heel strike,
:func:`jcrowd.motion.gait.gait_cycles`) of the shared CMU walks, subject 07 for sequence A and
subject 08 for sequence B, ``K ≈ frames / 130`` cycles each (cycling through the list when short),
concatenated, then linearly resampled to ``frames`` (A) and ``1.1 · frames`` (B) frames — two
long walks with the same number of steps in the same order, as in paper 004's Figure 2
(two walks of six steps). ``--sequences clips`` instead concatenates whole clips and cuts both
at ``frames``: the step counts then differ and many paths are almost equally good, a harder case
for any coarse-to-fine method.

Features: the joint point cloud (93 dims, Euclidean cost; DESIGN's pose distance) for the main
table, and physics features (15 dims, paper 004's inner-product cost) as a second table.

For each size: exact DTW (:func:`jcrowd.align.dtw`), multiscale DTW
(:func:`jcrowd.align.multiscale_dtw`, default radius and levels) and dtaidistance's C
``dtw_ndim.warping_path`` (squared Euclidean cells, path included; pose table only, since it has
no inner-product cost) are timed in this process on the same arrays: median of ``--repeats``
runs after one warm-up run. ``cost_ratio`` = multiscale path cost / exact path cost (≥ 1).
Nothing is compiled (NumPy), so there is no compile column.

    python bench/dtw.py [--json] [--repeats 3] [--sequences cycles|clips] [--no-record]

Prints one table (or one JSON object) and appends a dated row to ``bench/RESULTS.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

# One BLAS thread: on a shared 2-core machine OpenBLAS threads that spin between the many
# small matrix products slowed the inner-product cost 2-6x and made timings erratic. Set
# before NumPy loads; an explicit OPENBLAS_NUM_THREADS in the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from dtaidistance import dtw_ndim

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import append_result, data_root, machine

from jcrowd.align import dtw, multiscale_dtw, physics_features, pose_features
from jcrowd.io import read_bvh
from jcrowd.motion import drop_tpose_frames, gait_cycles

SIZES = (300, 1000, 3000)


def _resample(x: np.ndarray, frames: int) -> np.ndarray:
    t = np.linspace(0.0, len(x) - 1.0, frames)
    i0 = np.floor(t).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(x) - 1)
    w = (t - i0)[:, None]
    return x[i0] * (1 - w) + x[i1] * w


def _pieces(subject: str, feature: Callable[..., np.ndarray], cycles: bool) -> list[np.ndarray]:
    out = []
    for path in sorted((data_root() / "cmu" / "walk").glob(f"{subject}_*.bvh")):
        motion = drop_tpose_frames(read_bvh(path))[0]
        f = feature(motion)
        if cycles:
            out += [f[c.start : c.end] for c in gait_cycles(motion)]
        else:
            out.append(f)
    return out


def _sequences(
    frames: int, a_pieces: list[np.ndarray], b_pieces: list[np.ndarray], cycles: bool
) -> tuple[np.ndarray, np.ndarray]:
    if cycles:
        k = max(2, round(frames / 130))
        a = np.concatenate([a_pieces[i % len(a_pieces)] for i in range(k)])
        b = np.concatenate([b_pieces[i % len(b_pieces)] for i in range(k)])
        return _resample(a, frames), _resample(b, round(1.1 * frames))
    a = np.concatenate(a_pieces * (1 + frames // sum(map(len, a_pieces))))[:frames]
    b = np.concatenate(b_pieces * (1 + frames // sum(map(len, b_pieces))))[:frames]
    return a, b


def _median_time(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    out = fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def bench(kind: str, repeats: int, cycles: bool) -> list[dict[str, Any]]:
    feature: Callable[..., np.ndarray] = pose_features if kind == "pose" else physics_features
    metric = "euclidean" if kind == "pose" else "inner"
    a_pieces, b_pieces = _pieces("07", feature, cycles), _pieces("08", feature, cycles)
    rows = []
    for frames in SIZES:
        a, b = _sequences(frames, a_pieces, b_pieces, cycles)
        exact_s, exact = _median_time(lambda a=a, b=b: dtw(a, b, metric=metric), repeats)
        ms_s, ms = _median_time(lambda a=a, b=b: multiscale_dtw(a, b, metric=metric), repeats)
        row: dict[str, Any] = {
            "frames": frames,
            "frames_b": len(b),
            "dims": a.shape[1],
            "exact_s": exact_s,
            "multiscale_s": ms_s,
            "speedup": exact_s / ms_s,
            "cost_ratio": ms.cost / exact.cost,
            "cells_fraction": ms.cells / exact.cells,
            "levels": ms.levels,
        }
        if kind == "pose":
            dtai_s, _ = _median_time(
                lambda a=a, b=b: dtw_ndim.warping_path(a, b, use_c=True), repeats
            )
            row["dtaidistance_s"] = dtai_s
        rows.append(row)
    return rows


def _table(title: str, rows: list[dict[str, Any]]) -> str:
    head = (
        f"{title}\n| frames (A×B) | dims | exact s | multiscale s | speed-up | cost ratio | "
        "cells % | levels | dtaidistance C s |\n|---|---|---|---|---|---|---|---|---|\n"
    )
    body = "".join(
        f"| {r['frames']}×{r['frames_b']} | {r['dims']} | {r['exact_s']:.4f} | "
        f"{r['multiscale_s']:.4f} | {r['speedup']:.1f} | {r['cost_ratio']:.5f} | "
        f"{100 * r['cells_fraction']:.2f} | {r['levels']} | "
        + (f"{r['dtaidistance_s']:.4f} |\n" if "dtaidistance_s" in r else "— |\n")
        for r in rows
    )
    return head + body


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sequences", choices=("cycles", "clips"), default="cycles")
    ap.add_argument("--no-record", action="store_true", help="do not append to RESULTS.md")
    args = ap.parse_args()
    cycles = args.sequences == "cycles"
    pose_rows = bench("pose", args.repeats, cycles)
    physics_rows = bench("physics", args.repeats, cycles)
    at_3000 = next(r for r in pose_rows if r["frames"] == 3000)
    out = {
        "rows": pose_rows,
        "rows_physics": physics_rows,
        "dtw_multiscale_speedup_3000": at_3000["speedup"],
        "dtw_multiscale_cost_ratio": at_3000["cost_ratio"],
        "sequences": args.sequences,
        "repeats": args.repeats,
        "machine": machine(),
        "numpy": np.__version__,
        "blas_threads": os.environ["OPENBLAS_NUM_THREADS"],
        "python": platform.python_version(),
    }
    tables = (
        _table("pose features (point cloud, Euclidean cost)", pose_rows)
        + "\n"
        + _table(
            "physics features (COM acceleration + foot/hand momenta, inner-product cost)",
            physics_rows,
        )
    )
    if args.json:
        print(json.dumps(out))
    else:
        print(tables)
        print(
            f"multiscale at 3000 frames: {at_3000['speedup']:.1f}x faster than exact, "
            f"cost ratio {at_3000['cost_ratio']:.5f}"
        )
    if not args.no_record:
        _record(out, tables)


def _record(out: dict[str, Any], tables: str) -> None:
    try:
        import jax

        jax_version = jax.__version__
    except ImportError:  # the bench itself does not need jax
        jax_version = "absent"
    append_result(
        "dtw",
        f"{out['machine']}, numpy {out['numpy']}, jax {jax_version} (unused), OpenBLAS threads "
        f"{out['blas_threads']}, sequences={out['sequences']}, median of {out['repeats']} after "
        "a warm-up",
        tables,
    )


if __name__ == "__main__":
    main()
