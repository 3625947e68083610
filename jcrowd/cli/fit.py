"""``jcrowd fit DATA_DIR``: the whole offline fit of a motion model from a folder of BVH files.

Gait cycles (mirrored by default) → time alignment → motion tensor with key levels → universal
kriging of each level's cores over the controls → leave-one-clip-out cross-validation of
kriging, RBF and nearest sample (every cycle of a clip and of its mirror leave together) → the
model file. ``--report DIR`` writes ``report.txt`` and PNG plots (error and size per level, the
level-0 reliability over the first two controls with the samples marked, the fitted
variogram). Progress goes to stderr; ``--json`` prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import numpy as np

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "fit", help="fit a motion model from a folder of BVH files", description=__doc__
    )
    p.add_argument("data_dir", help="folder of .bvh files (searched recursively)")
    p.add_argument("--labels", default=None, help="labels.csv (default: DATA_DIR/labels.csv)")
    p.add_argument("--levels", type=int, default=6, help="number of key levels")
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--controls", default="dx,dz,dyaw", help="comma-separated control names")
    p.add_argument("--out", default="model.jcm", help="model file to write")
    p.add_argument("--report", default=None, help="folder for report.txt and plots")
    p.add_argument("--no-cv", action="store_true", help="skip the cross-validation")
    return p


def run(args: argparse.Namespace) -> dict[str, Any]:
    from rich.console import Console
    from rich.progress import Progress

    from jcrowd.cli.output import emit
    from jcrowd.io.dataset import load_dataset
    from jcrowd.io.model_file import save_motion_model
    from jcrowd.model.evaluate import leave_one_clip_out
    from jcrowd.model.motion_model import fit_motion_model
    from jcrowd.model.tensor_model import (
        TensorModelConfig,
        build_tensor_model,
        level_errors,
        storage,
    )
    from jcrowd.tensor.keylevels import tucker_nbytes

    controls = tuple(c.strip() for c in args.controls.split(",") if c.strip())
    start = time.perf_counter()
    with Progress(console=Console(file=sys.stderr), transient=True) as bar:
        task = bar.add_task("loading captures", total=4)
        clips = load_dataset(args.data_dir, labels=args.labels)
        bar.update(task, advance=1, description="motion tensor and key levels")
        cfg = TensorModelConfig(key_levels=args.levels, mirror=args.mirror)
        tensor = build_tensor_model(clips, cfg)
        bar.update(task, advance=1, description="kriging every level")
        model = fit_motion_model(tensor, controls)
        bar.update(task, advance=1, description="leave-one-clip-out cross-validation")
        cv = None if args.no_cv else leave_one_clip_out(tensor, controls)
        bar.update(task, advance=1)
    rep = storage(tensor)
    errors = [level_errors(tensor, i) for i in range(len(tensor.levels))]
    vario = model.levels[0].kriging.variogram
    result: dict[str, Any] = {
        "data_dir": str(args.data_dir),
        "clips": len(clips),
        "samples": int(tensor.tensor.shape[2]),
        "tensor_shape": list(tensor.tensor.shape),
        "controls": list(controls),
        "control_ranges": np.asarray(model.control_ranges).tolist(),
        "levels": [
            {
                "ranks": list(lv.tucker.ranks),
                "joints": len(lv.joints),
                "bytes": tucker_nbytes(lv.tucker),
                "error_m": err[0],
                "root_error_m": err[1],
            }
            for lv, err in zip(tensor.levels, errors, strict=True)
        ],
        "bytes_total": rep.total_bytes,
        "bytes_raw": rep.raw_bytes,
        "variogram": {"p": float(vario.p), "theta": np.asarray(vario.theta).tolist()},
        "cv": None if cv is None else {f"{m}_m": v["joint_m"] for m, v in cv.items()},
        "cv_root": None if cv is None else {f"{m}_m": v["root_m"] for m, v in cv.items()},
        "cv_z_rms": None if cv is None else cv["kriging"].get("z_rms"),
        "out": str(args.out),
    }
    result["seconds"] = time.perf_counter() - start
    save_motion_model(args.out, model, extra={"fit": stored_fit(result, clips, args.data_dir)})
    if args.report:
        from jcrowd.io.report import write_fit_report

        result["report"] = str(write_fit_report(args.report, result, tensor, model))
    emit(result, args.json, _print_summary)
    return result


def stored_fit(result: dict[str, Any], clips: Any, data_dir: str) -> dict[str, Any]:
    """The fit's report as the model file keeps it: no path of the machine that fitted it (the
    dataset by its folder's name, the output by its file name) and every clip's SHA-256 by its
    path inside the dataset, so a model names the data it came from and a rebuild can be
    checked against it."""
    import hashlib
    from pathlib import Path

    root = Path(data_dir).resolve()
    sums = {}
    for clip in clips:
        path = Path(clip.path).resolve()
        name = path.relative_to(root).as_posix() if path.is_relative_to(root) else path.name
        sums[name] = hashlib.sha256(path.read_bytes()).hexdigest()
    stored = {k: v for k, v in result.items() if k not in ("data_dir", "out", "report")}
    return {
        **stored,
        "dataset": root.name,
        "clip_sha256": dict(sorted(sums.items())),
        "out": Path(str(result["out"])).name,
    }


def _print_summary(result: dict[str, Any]) -> None:
    from jcrowd.io.report import summary_text

    sys.stdout.write(summary_text(result))
