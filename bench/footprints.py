"""Benchmark of footprints → controls (issue 22 item 4; paper 001 §5.3, Fig. 12).

Footprints are taken from captured gait cycles the model never saw (their planted feet:
:func:`jcrowd.model.cycle_footprints`, ankle at each heel strike, in the cycle's start frame),
the controls are solved for them (:func:`jcrowd.model.controls_for_footprints`) and set by the
forward rule (controls from the footprints' displacement alone), and each is synthesized as
delivered (:func:`jcrowd.model.synthesize_clip`, no foot locking) and measured the way the
captures are (:func:`jcrowd.model.footprint_errors`: mean distance of the right and closing
left footprints, relative to the opening one, cm). Two splits:

- ``held back``: tensor *and* kriging fitted without four takes (veer right, straight, 90° left,
  90° right), every cycle of those takes and of their mirrors.
- ``k-fold``: the clips dealt into ``--folds`` folds; per fold the kriging is refitted without
  it (the tensor bases, fitted on every clip, are shared, as in ``leave_one_clip_out``); every
  cycle of every clip once.

"turning" is the cycles whose captured heading change exceeds 0.3 rad. Timing: the first solve
of a fold (compile included) apart from the median per-cycle time of a repeat.

    python bench/footprints.py [--dataset cmu16] [--level 0] [--folds 4] [--json] [--no-record]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import data_root, machine, report

from jcrowd.io import load_dataset
from jcrowd.model import (
    MotionModel,
    Sample,
    build_tensor_model,
    controls_for_footprints,
    cycle_footprints,
    fit_motion_model,
    footprint_errors,
    gait_samples,
)

HELD_BACK = ("16_13.bvh", "16_15.bvh", "16_17.bvh", "16_30.bvh")
TURNING = 0.3  # rad per cycle


def _evaluate(model: MotionModel, samples: list[Sample], level: int) -> dict[str, Any]:
    """Solve and measure every cycle of ``samples`` (module doc); errors in cm per cycle."""
    rows: dict[str, list[Any]] = {"solved": [], "forward": [], "dyaw": [], "converged": []}
    first_s, per_cycle = [], []
    heights = sorted({s.height for s in samples})
    for h in heights:
        group = [s for s in samples if s.height == h]
        fp = np.stack([cycle_footprints(s.motion)[0] for s in group])
        t = time.perf_counter()
        sol = controls_for_footprints(model, fp, level, height=h)
        first_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        controls_for_footprints(model, fp, level, height=h)
        per_cycle.append((time.perf_counter() - t) / len(fp))
        rows["solved"] += (
            100 * footprint_errors(model, sol.controls, fp, level, height=h)
        ).tolist()
        rows["forward"] += (
            100 * footprint_errors(model, sol.forward, fp, level, height=h)
        ).tolist()
        rows["dyaw"] += [s.cycle.dyaw for s in group]
        rows["converged"] += sol.converged.tolist()
    return {
        **rows,
        "first_solve_s": max(first_s),
        "ms_per_cycle": 1e3 * float(np.median(per_cycle)),
    }


def _summary(name: str, clips: int, ev: dict[str, Any]) -> dict[str, Any]:
    solved, forward = np.array(ev["solved"]), np.array(ev["forward"])
    turning = np.abs(np.array(ev["dyaw"])) > TURNING
    out = {
        "split": name,
        "clips": clips,
        "cycles": len(solved),
        "turning_cycles": int(turning.sum()),
        "forward_cm": float(forward.mean()),
        "solved_cm": float(solved.mean()),
        "ratio": float(solved.mean() / forward.mean()),
        "solved_p90_cm": float(np.percentile(solved, 90)),
        "forward_p90_cm": float(np.percentile(forward, 90)),
        "converged": int(np.sum(ev["converged"])),
        "first_solve_s": round(ev["first_solve_s"], 2),
        "ms_per_cycle": round(ev["ms_per_cycle"], 2),
    }
    for tag, mask in (("straight", ~turning), ("turning", turning)):
        out[f"{tag}_forward_cm"] = float(forward[mask].mean()) if mask.any() else None
        out[f"{tag}_solved_cm"] = float(solved[mask].mean()) if mask.any() else None
    return out


def held_back(folder: Path, level: int) -> dict[str, Any]:
    clips = load_dataset(folder)
    train = [c for c in clips if Path(c.path).name not in HELD_BACK]
    test = [c for c in clips if Path(c.path).name in HELD_BACK]
    model = fit_motion_model(build_tensor_model(train))
    samples = gait_samples(test, fps=model.fps)
    return _summary("held back (tensor + kriging)", len(test), _evaluate(model, samples, level))


def k_fold(folder: Path, level: int, folds: int) -> dict[str, Any]:
    clips = load_dataset(folder)
    tensor = build_tensor_model(clips)
    merged: dict[str, list[Any]] = {"solved": [], "forward": [], "dyaw": [], "converged": []}
    first, per = [], []
    for k in range(folds):
        out = np.arange(len(clips)) % folds == k
        model = fit_motion_model(tensor, samples=np.nonzero(~out[tensor.groups])[0])
        test = [c for c, o in zip(clips, out, strict=True) if o]
        ev = _evaluate(model, gait_samples(test, fps=model.fps), level)
        for key in merged:
            merged[key] += ev[key]
        first.append(ev["first_solve_s"])
        per.append(ev["ms_per_cycle"])
    ev_all = {
        **merged,
        "first_solve_s": float(np.median(first)),
        "ms_per_cycle": float(np.median(per)),
    }
    return _summary(f"{folds}-fold (kriging)", len(clips), ev_all)


def _table(rows: list[dict[str, Any]]) -> str:
    def cm(x: float | None) -> str:
        return "n/a" if x is None else f"{x:.2f}"

    lines = [
        "| split | clips | cycles (turning) | forward cm | solved cm | solved / forward | "
        "p90 forward / solved cm | straight fwd / solved cm | turning fwd / solved cm | "
        "converged | first solve s (compile) | ms per cycle |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['split']} | {r['clips']} | {r['cycles']} ({r['turning_cycles']}) | "
            f"{r['forward_cm']:.2f} | {r['solved_cm']:.2f} | {r['ratio']:.2f}× | "
            f"{r['forward_p90_cm']:.2f} / {r['solved_p90_cm']:.2f} | "
            f"{cm(r['straight_forward_cm'])} / {cm(r['straight_solved_cm'])} | "
            f"{cm(r['turning_forward_cm'])} / {cm(r['turning_solved_cm'])} | "
            f"{r['converged']}/{r['cycles']} | {r['first_solve_s']:.1f} | {r['ms_per_cycle']:.1f} |"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", default="cmu16")
    ap.add_argument("--level", type=int, default=0)
    ap.add_argument("--folds", type=int, default=4)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    folder = data_root() / args.dataset
    rows = []
    if args.dataset == "cmu16":
        rows.append(held_back(folder, args.level))
    rows.append(k_fold(folder, args.level, args.folds))
    out = {"dataset": args.dataset, "level": args.level, "rows": rows}
    details = f"{machine()}, jax {jax.__version__}, {args.dataset} level {args.level}"
    text = _table(rows) + (
        "\n\nPlanted-foot error: mean distance of the right and closing left footprints "
        "(ankle at heel strike, relative to the opening left one) of the delivered clip from "
        "the held-back capture's. Forward rule: (dx, dz) = left foot displacement, "
        "dyaw = 2·atan2(dx, dz)."
    )
    report("footprints", details, out, text, args.json, not args.no_record)


if __name__ == "__main__":
    main()
