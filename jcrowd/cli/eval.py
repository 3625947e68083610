"""``jcrowd eval MODEL DATA_DIR``: how well a model predicts captures it never saw.

For every left-started gait cycle in DATA_DIR: its control parameters, the model's reliability
there, mean and max joint position error of the prediction against the capture after DTW time
alignment (root frame, m), and foot skate (mean horizontal slide of a planted foot per frame at
the model rate, cm) of the prediction, of the decoded motion before foot locking, and of the
capture. The prediction is what jcrowd delivers: foot-locked, as in the crowd step and
``jcrowd export`` (``--no-foot-lock`` reports the raw decode as the prediction). ``--method``
predicts with the model's kriging or with a baseline (RBF, nearest sample) fitted on the
model's own samples. ``--json`` prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "eval", help="compare a model's predictions with unseen captures", description=__doc__
    )
    p.add_argument("model", help="a model file written by jcrowd fit")
    p.add_argument("data_dir", help="folder of .bvh files (the model's skeleton)")
    p.add_argument("--level", type=int, default=0)
    p.add_argument("--method", choices=("kriging", "rbf", "nearest"), default="kriging")
    p.add_argument(
        "--foot-lock",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="lock planted feet in the prediction, as the crowd step does (default: on)",
    )
    return p


def run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.output import emit
    from jcrowd.errors import DataError
    from jcrowd.io.dataset import load_dataset
    from jcrowd.io.model_file import load_motion_model
    from jcrowd.model.evaluate import evaluate_captures

    model, _ = load_motion_model(args.model)
    cycles = evaluate_captures(
        model,
        load_dataset(args.data_dir),
        level=args.level,
        method=args.method,
        foot_lock=args.foot_lock,
    )
    if not cycles:
        raise DataError(
            f"{args.data_dir}: expected at least one gait cycle to evaluate, found none"
        )
    result = {
        "model": str(args.model),
        "data_dir": str(args.data_dir),
        "level": args.level,
        "method": args.method,
        "foot_lock": args.foot_lock,
        "cycles": cycles,
        "mean_error_m": float(np.mean([c["mean_error_m"] for c in cycles])),
        "skate_pred_cm": float(np.mean([c["skate_pred_cm"] for c in cycles])),
        "skate_raw_cm": float(np.mean([c["skate_raw_cm"] for c in cycles])),
        "skate_true_cm": float(np.mean([c["skate_true_cm"] for c in cycles])),
    }
    emit(result, args.json, _print)
    return result


def _print(result: dict[str, Any]) -> None:
    lines = [
        f"{'file':>12} {'start':>5} {'controls':>24} {'ρ':>5} {'mean cm':>8} {'max cm':>7} "
        f"{'skate pred/true cm':>19}"
    ]
    for c in result["cycles"]:
        ctl = ", ".join(f"{v:+.2f}" for v in c["c"])
        lines.append(
            f"{c['file'].rsplit('/', 1)[-1]:>12} {c['start']:>5} {ctl:>24} "
            f"{c['reliability']:>5.2f} "
            f"{100 * c['mean_error_m']:>8.2f} {100 * c['max_error_m']:>7.2f} "
            f"{c['skate_pred_cm']:>9.2f} / {c['skate_true_cm']:<7.2f}"
        )
    lines.append(
        f"mean: {100 * result['mean_error_m']:.2f} cm joint error; foot skate "
        f"{result['skate_pred_cm']:.2f} cm predicted ({result['skate_raw_cm']:.2f} cm before foot "
        f"locking) vs {result['skate_true_cm']:.2f} cm captured"
    )
    sys.stdout.write("\n".join(lines) + "\n")
