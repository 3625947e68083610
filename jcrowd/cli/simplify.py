"""``jcrowd simplify CLIP.bvh --levels N --out-dir DIR``: motion levels of detail (paper 003).

Writes one BVH per level (``<clip>_L<level>_<joints>j.bvh``; each opens in any BVH viewer) and
``report.txt`` / ``report.json`` with, per level, the joint count, mean and max joint position
error (m), bone-length variation (% of each bone's key length, mean and max, on the optimised
positions), SQP iterations and convergence, and seconds. Any leading T-pose frame is dropped
first. Seconds include JAX compilation (the first level of each new shape compiles);
``bench/simplify.py`` times compile and run apart.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from jcrowd.errors import JcrowdError

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "simplify", help="joint levels of detail of a BVH clip (paper 003)", description=__doc__
    )
    p.add_argument("clip", help="a .bvh file")
    p.add_argument("--levels", type=int, default=8, help="number of levels incl. the full one")
    p.add_argument("--out-dir", required=True, help="folder for the per-level BVH files")
    p.add_argument(
        "--mode",
        choices=("hard", "weighted"),
        default="hard",
        help="rigid bones as constraints (hard) or the paper's weighted Eq. 5",
    )
    p.add_argument(
        "--scale", type=float, default=None, help="file units → metres (default: detect)"
    )
    return p


def run(args: argparse.Namespace) -> dict[str, Any]:
    from rich.progress import Progress

    from jcrowd.cli.output import emit
    from jcrowd.io.atomic import write_atomic
    from jcrowd.io.bvh import read_bvh
    from jcrowd.io.bvh_write import write_bvh
    from jcrowd.motion.clip import drop_tpose_frames
    from jcrowd.simplify import RESULT, simplify_motion

    out_dir = Path(args.out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise JcrowdError(f"{out_dir}: cannot create the output folder: {e.strerror or e}") from e
    motion, dropped = drop_tpose_frames(read_bvh(args.clip, scale=args.scale))
    stem = Path(args.clip).stem
    rows: list[dict[str, Any]] = []
    start = time.perf_counter()
    last = [start]
    with Progress(transient=True, console=_stderr_console()) as bar:
        task = bar.add_task("simplifying", total=args.levels)

        def on_level(index: int, level: Any) -> None:
            now = time.perf_counter()
            path = out_dir / f"{stem}_L{index}_{level.num_joints}j.bvh"
            write_bvh(path, level.motion)
            rows.append(
                {
                    "level": index,
                    "joints": level.num_joints,
                    "mean_error_m": level.mean_error_m,
                    "max_error_m": level.max_error_m,
                    "bone_length_variation_pct": level.bone_variation_max_pct,
                    "bone_length_variation_mean_pct": level.bone_variation_mean_pct,
                    "iterations_mean": float(np.mean(level.iterations)),
                    "iterations_max": int(np.max(level.iterations)),
                    "frames_converged": int(np.sum(level.result == RESULT.CONVERGED)),
                    "frames": int(level.result.size),
                    "seconds": now - last[0],
                    "file": str(path),
                }
            )
            last[0] = now
            bar.advance(task)

        result = simplify_motion(motion, args.levels, mode=args.mode, on_level=on_level)
    seconds = time.perf_counter() - start
    report = {
        "clip": str(args.clip),
        "frames": motion.num_frames,
        "dropped_frames": dropped,
        "mode": args.mode,
        "elimination_order": [motion.skeleton.names[j] for j in result.order],
        "levels": rows,
        "seconds": seconds,
        "out_dir": str(out_dir),
    }
    write_atomic(out_dir / "report.json", json.dumps(report, indent=2) + "\n")
    write_atomic(out_dir / "report.txt", _text(report))
    emit(report, args.json, _print_text)
    return report


def _print_text(report: dict[str, Any]) -> None:
    sys.stdout.write(_text(report))


def _stderr_console() -> Any:
    from rich.console import Console

    return Console(file=sys.stderr)


def _text(report: dict[str, Any]) -> str:
    lines = [
        f"{report['clip']}: {report['frames']} frames, mode {report['mode']}, "
        f"{report['seconds']:.1f} s (JAX compilation included)",
        f"{'level':>5} {'joints':>6} {'mean cm':>8} {'max cm':>8} {'bone var % (mean/max)':>22} "
        f"{'iters':>6} {'converged':>10} {'s':>6}",
    ]
    for r in report["levels"]:
        lines.append(
            f"{r['level']:>5} {r['joints']:>6} {100 * r['mean_error_m']:>8.2f} "
            f"{100 * r['max_error_m']:>8.2f} "
            f"{r['bone_length_variation_mean_pct']:>10.4f} / "
            f"{r['bone_length_variation_pct']:<9.4f} {r['iterations_max']:>6} "
            f"{r['frames_converged']:>5}/{r['frames']:<4} {r['seconds']:>6.2f}"
        )
    lines.append("elimination order: " + ", ".join(report["elimination_order"]))
    return "\n".join(lines) + "\n"
