"""Benchmark of the motion-tensor fit (paper 000 §3.2, §4; paper 004 §2–3) on the shared walks.

For ``cmu/walk`` and ``cmu16`` (a second skeleton at 30 fps with turns): sample count, tensor
shape, seconds per stage (samples, joint importance, features, DTW alignment, pose vectors, key
levels), the storage table (bytes per key level, total, raw float32 samples, ratio; a matrix-PCA
model at level 0's error), and per key level the mean joint position error in the root frame and
the end-of-cycle root displacement error (m), for the default fit and for ``level_fit="freeze"``
(issue 21's before/after table of the per-level refit). In the same run: TensorLy ``tucker``
on the same tensor at level 0's ranks (time and relative error) beside our HOOI, and exact vs
multiscale DTW at 300, 1000 and 3000 frames (``bench/dtw.py``'s sequences). Everything here is
NumPy, no compilation but the level refit's (inside its column). Medians of ``--repeats`` for
HOOI and TensorLy.

    python bench/tensor.py [--json] [--repeats 3] [--no-record]

Prints one table (or, with ``--json``, one JSON object whose top-level keys describe
``cmu/walk``; ``cmu16`` is under ``"cmu16"``) and appends a dated row to ``bench/RESULTS.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see bench/dtw.py

import numpy as np
import tensorly
from tensorly.decomposition import tucker as tl_tucker

sys.path.insert(0, str(Path(__file__).resolve().parent))
import dtw as dtw_bench  # bench/dtw.py: the DTW sequences and timing
from common import append_result, data_root, machine

from jcrowd.align import align_to_reference
from jcrowd.io import load_dataset
from jcrowd.model import PoseLayout, encode_sample, gait_samples, mean_rotations, reference_skeleton
from jcrowd.model.tensor_model import (
    TensorModelConfig,
    _features,
    _medoid,
    build_tensor_model,
    level_errors,
    storage,
)
from jcrowd.motion import resample
from jcrowd.simplify import elimination_order, joint_importance
from jcrowd.tensor import hooi, reconstruct, relative_error


def _stages(folder: Path) -> dict[str, float]:
    """Seconds of each fit stage, run one after the other as build_tensor_model does."""
    cfg = TensorModelConfig()
    t = {}
    t0 = time.perf_counter()
    clips = load_dataset(folder)
    samples = gait_samples(clips, fps=cfg.fps, mirrored=cfg.mirror)
    t["samples_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    skel = reference_skeleton(samples)
    elimination_order(skel, joint_importance([resample(c.motion, cfg.fps) for c in clips]))
    t["importance_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    feats = [_features(s) for s in samples]
    t["features_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref = _medoid(feats, cfg.frames)
    warps = [align_to_reference(feats[ref], f, num_frames=cfg.frames).frames for f in feats]
    t["dtw_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    layout = PoseLayout(
        skel.num_joints,
        mean_rotations([np.asarray(s.motion.rotations) for s in samples]),
        np.ones(1),
    )
    for s, w in zip(samples, warps, strict=True):
        encode_sample(s.motion, w, layout, s.height)
    t["pose_vectors_s"] = time.perf_counter() - t0
    return t


def bench_dataset(folder: Path, repeats: int) -> dict[str, Any]:
    stages = _stages(folder)
    clips = load_dataset(folder)
    t0 = time.perf_counter()
    frozen = build_tensor_model(clips, TensorModelConfig(level_fit="freeze"))
    freeze_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    model = build_tensor_model(clips)
    build_s = time.perf_counter() - t0
    stages["key_levels_s"] = freeze_s - sum(stages.values())
    stages["refit_s"] = build_s - freeze_s
    before = [level_errors(frozen, i) for i in range(len(frozen.levels))]
    rep = storage(model)
    errors = [level_errors(model, i) for i in range(len(model.levels))]
    ranks = model.levels[0].tucker.ranks
    hooi_times, tl_times = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ours = hooi(model.tensor, ranks)
        hooi_times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        core, factors = tl_tucker(
            tensorly.tensor(model.tensor), rank=list(ranks), init="svd", tol=1e-8, n_iter_max=100
        )
        tl_times.append(time.perf_counter() - t0)
    ours_err = relative_error(model.tensor, reconstruct(ours.tucker))
    tl_err = float(
        np.linalg.norm(model.tensor - tensorly.tucker_to_tensor((core, factors)))
        / np.linalg.norm(model.tensor)
    )
    return {
        "folder": folder.name if folder.name != "walk" else "cmu/walk",
        "samples": int(model.tensor.shape[2]),
        "tensor_shape": list(model.tensor.shape),
        "build_seconds": build_s,
        "stages": stages,
        "level_ranks": [list(lv.tucker.ranks) for lv in model.levels],
        "level_joints": [len(lv.joints) for lv in model.levels],
        "level_bytes": list(rep.level_bytes),
        "bytes_total": rep.total_bytes,
        "bytes_raw": rep.raw_bytes,
        "storage_ratio": rep.raw_bytes / rep.total_bytes,
        "pca_rank": rep.pca_rank,
        "pca_bytes": rep.pca_bytes,
        "pca_ratio": rep.pca_bytes / rep.level_bytes[0],
        "level_errors_m": [e[0] for e in errors],
        "root_errors_m": [e[1] for e in errors],
        "freeze_level_errors_m": [e[0] for e in before],
        "freeze_root_errors_m": [e[1] for e in before],
        "freeze_build_seconds": freeze_s,
        "hooi_seconds": float(np.median(hooi_times)),
        "tensorly_seconds": float(np.median(tl_times)),
        "hooi_relative_error": ours_err,
        "tensorly_relative_error": tl_err,
        "hooi_error_ratio_vs_tensorly": ours_err / tl_err,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    data = data_root()
    walk = bench_dataset(data / "cmu" / "walk", args.repeats)
    c16 = bench_dataset(data / "cmu16", args.repeats)
    dtw_rows = dtw_bench.bench("pose", args.repeats, cycles=True)
    at3000 = next(r for r in dtw_rows if r["frames"] == 3000)
    out = {
        **walk,
        "cmu16": c16,
        "dtw_rows": dtw_rows,
        "dtw_multiscale_speedup_3000": at3000["speedup"],
        "dtw_multiscale_cost_ratio": at3000["cost_ratio"],
        "machine": machine(),
        "numpy": np.__version__,
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
    }
    text = _tables(out)
    if args.json:
        sys.stdout.write(json.dumps(out, indent=2) + "\n")
    else:
        print(text)
    if not args.no_record:
        _record(out, text)


def _tables(out: dict[str, Any]) -> str:
    lines = []
    for d in (out, out["cmu16"]):
        st = d["stages"]
        lines += [
            f"### {d['folder']}: {d['samples']} samples, tensor "
            f"{'×'.join(map(str, d['tensor_shape']))}, built in {d['build_seconds']:.1f} s",
            "",
            "| stage | samples | importance | features | DTW | pose vectors | key levels (HOOI) "
            "| level refit |",
            "|---|---|---|---|---|---|---|---|",
            f"| s | {st['samples_s']:.2f} | {st['importance_s']:.2f} | {st['features_s']:.2f} | "
            f"{st['dtw_s']:.2f} | {st['pose_vectors_s']:.2f} | {st['key_levels_s']:.2f} | "
            f"{st['refit_s']:.2f} |",
            "",
            "Whole-body joint error (every joint of the full skeleton, dropped ones placed by the "
            "level's FK, root frame) and end-of-cycle root error, before (`level_fit=freeze`: mean "
            "references, kept joints as captured) and after (default: 003 key posture, kept "
            "joints refitted):",
            "",
            "| key level | ranks | joints | bytes | joint error before → after (cm) "
            "| root error before → after (cm) |",
            "|---|---|---|---|---|---|",
        ]
        for i, (r, j, b, e0, e, r0, re) in enumerate(
            zip(
                d["level_ranks"],
                d["level_joints"],
                d["level_bytes"],
                d["freeze_level_errors_m"],
                d["level_errors_m"],
                d["freeze_root_errors_m"],
                d["root_errors_m"],
                strict=True,
            )
        ):
            lines.append(
                f"| {i} | {'×'.join(map(str, r))} | {j} | {b:,} | {100 * e0:.2f} → {100 * e:.2f} "
                f"| {100 * r0:.2f} → {100 * re:.2f} |"
            )
        lines += [
            "",
            f"storage: {d['bytes_total']:,} B for all key levels vs {d['bytes_raw']:,} B raw "
            f"float32 (ratio {d['storage_ratio']:.1f}); PCA at level 0's error: rank "
            f"{d['pca_rank']}, {d['pca_bytes']:,} B ({d['pca_ratio']:.2f}× level 0)",
            f"HOOI at level 0 ranks: {d['hooi_seconds']:.2f} s, rel. error "
            f"{d['hooi_relative_error']:.5f}; "
            f"TensorLy tucker: {d['tensorly_seconds']:.2f} s, {d['tensorly_relative_error']:.5f} "
            f"(ratio {d['hooi_error_ratio_vs_tensorly']:.4f})",
            "",
        ]
    lines += [
        "| DTW frames | exact s | multiscale s | speed-up | cost ratio |",
        "|---|---|---|---|---|",
    ]
    for r in out["dtw_rows"]:
        lines.append(
            f"| {r['frames']} | {r['exact_s']:.4f} | {r['multiscale_s']:.4f} | "
            f"{r['speedup']:.1f} | {r['cost_ratio']:.5f} |"
        )
    return "\n".join(lines)


def _record(out: dict[str, Any], text: str) -> None:
    import jax

    append_result(
        "tensor",
        f"{out['machine']}, numpy {out['numpy']}, jax {jax.__version__} (the level refit), "
        f"OpenBLAS threads {out['blas_threads']}",
        text,
    )


if __name__ == "__main__":
    main()
