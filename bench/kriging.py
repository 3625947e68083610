"""Benchmark of kriging (papers 000 §3.3, 001): cross-validated accuracy, throughput, fit time.

- Leave-one-clip-out at level 0 on ``cmu/walk`` and ``cmu16`` (:mod:`jcrowd.evaluate`): mean
  joint error in the root frame and end-of-cycle root error for tensor kriging, paper 001's
  per-pose kriging of whole aligned motions, RBF and nearest. Per-element kriging is not
  implemented yet (reported as null).
- Foot skate (per-frame slide of a planted foot, cm) of the model's predictions of ``cmu16``'s
  own cycles and of the captures (:func:`jcrowd.evaluate.evaluate_captures`).
- Throughput: kriging weights for 100,000 queries with our batched, jitted
  ``kriging_weights_batch`` vs PyKrige ``OrdinaryKriging`` (vectorized backend) on the same 2-D
  controls, the same samples and the same fixed spherical variogram, in this process; compile
  timed apart; medians of ``--repeats``.
- Fit time: ``jcrowd fit`` on ``cmu/walk`` (compilation included).

    python bench/kriging.py [--json] [--repeats 3] [--no-record]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see bench/dtw.py

import jax
import jax.numpy as jnp
import numpy as np
from pykrige.ok import OrdinaryKriging

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import data_root, machine, report

from jcrowd.cli import main as jcrowd_main
from jcrowd.data import load_dataset
from jcrowd.evaluate import ALL_METHODS, evaluate_captures, leave_one_clip_out
from jcrowd.kriging import fit_kriging, kriging_weights_batch, make_variogram
from jcrowd.model import fit_motion_model
from jcrowd.tensor_model import build_tensor_model


def _median(fn: Any, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def throughput(controls: np.ndarray, repeats: int, queries: int = 100_000) -> dict[str, float]:
    """Weights for ``queries`` 2-D controls: ours (jit + vmap) vs PyKrige, same variogram."""
    c = controls[:, :2]
    rng = np.random.default_rng(0)
    q = rng.uniform(c.min(0), c.max(0), size=(queries, 2))
    values = rng.normal(size=len(c))
    sill, rng_, nugget = 1.0, float(np.ptp(c, axis=0).max()), 0.0
    vario = make_variogram(np.array([nugget, sill, rng_]), 0.0)  # spherical, fixed
    model = fit_kriging(c, values, vario, normalise=False)
    qj = jnp.asarray(q, jnp.float32)
    t = time.perf_counter()
    jax.block_until_ready(kriging_weights_batch(model, qj))
    compile_s = time.perf_counter() - t
    ours = _median(lambda: kriging_weights_batch(model, qj), repeats)
    ok = OrdinaryKriging(
        c[:, 0],
        c[:, 1],
        values,
        variogram_model="spherical",
        variogram_parameters={"psill": sill, "range": rng_, "nugget": nugget},
    )
    theirs = _median(lambda: ok.execute("points", q[:, 0], q[:, 1], backend="vectorized"), repeats)
    return {
        "queries": queries,
        "samples": len(c),
        "ours_s": ours,
        "ours_compile_s": compile_s,
        "pykrige_s": theirs,
        "throughput_ratio_vs_pykrige": theirs / ours,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    data = data_root()
    cv, cv_root = {}, {}
    for name, folder in (("cmu/walk", data / "cmu" / "walk"), ("cmu16", data / "cmu16")):
        tensor = build_tensor_model(load_dataset(folder))
        res = leave_one_clip_out(tensor, methods=ALL_METHODS)
        cv[name] = {
            "tensor_kriging": res["kriging"]["joint_m"],
            "per_pose": res["per_pose"]["joint_m"],
            "per_element": res["per_element"]["joint_m"],
            "rbf": res["rbf"]["joint_m"],
            "nearest": res["nearest"]["joint_m"],
        }
        cv_root[name] = {k: res[k]["root_m"] for k in res}
        if name == "cmu16":
            model = fit_motion_model(tensor)
            cycles = evaluate_captures(model, load_dataset(folder))
            skate = {
                "tensor_kriging": float(np.mean([c["skate_pred_cm"] for c in cycles])),
                "captures": float(np.mean([c["skate_true_cm"] for c in cycles])),
            }
            tp = throughput(tensor.controls, args.repeats)
    t = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the bench prints only its own table
        jcrowd_main(["fit", str(data / "cmu" / "walk"), "--out", "/tmp/jcrowd-bench-walk.jcm"])
    fit_s = time.perf_counter() - t
    out = {
        "cv": cv["cmu/walk"],
        "cv_cmu16": cv["cmu16"],
        "cv_root": cv_root,
        "skate_cm": skate,
        **tp,
        "fit_seconds": fit_s,
        "machine": machine(),
        "jax": jax.__version__,
    }
    text = _table(out)
    report(
        "kriging", f"{out['machine']}, jax {out['jax']}", out, text, args.json, not args.no_record
    )


def _table(out: dict[str, Any]) -> str:
    lines = [
        "| data | tensor kriging cm | per-pose cm | per-element cm | RBF cm | nearest cm | "
        "root: kriging / RBF / nearest cm |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, cv in (("cmu/walk", out["cv"]), ("cmu16", out["cv_cmu16"])):
        r = out["cv_root"][name]
        lines.append(
            f"| {name} | {100 * cv['tensor_kriging']:.2f} | {100 * cv['per_pose']:.2f} | "
            f"{100 * cv['per_element']:.2f} | "
            f"{100 * cv['rbf']:.2f} | "
            f"{100 * cv['nearest']:.2f} | {100 * r['kriging']:.1f} / {100 * r['rbf']:.1f} / "
            f"{100 * r['nearest']:.1f} |"
        )
    lines += [
        "",
        f"foot skate (cmu16, per frame): predicted {out['skate_cm']['tensor_kriging']:.2f} cm, "
        f"captures {out['skate_cm']['captures']:.2f} cm",
        f"kriging weights for {out['queries']:,} queries over {out['samples']} samples: ours "
        f"{out['ours_s'] * 1e3:.1f} ms (compile {out['ours_compile_s']:.1f} s), PyKrige "
        f"{out['pykrige_s'] * 1e3:.1f} ms → {out['throughput_ratio_vs_pykrige']:.1f}×",
        f"jcrowd fit cmu/walk: {out['fit_seconds']:.1f} s wall (compilation included)",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
