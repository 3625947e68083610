"""Benchmark of kriging (papers 000 §3.3, 001): cross-validated accuracy, throughput, fit time.

- Leave-one-clip-out at level 0 on ``cmu/walk`` and ``cmu16`` (:mod:`jcrowd.model.evaluate`): mean
  and max joint error in the root frame, end-of-cycle root error, and foot skate (per-frame
  slide of a planted foot at the model rate, cm) for tensor kriging, paper 001's per-pose and
  per-element kriging of whole aligned motions, RBF and nearest. ``skate_cm`` is the delivered
  motion (foot-locked, as the crowd step and ``jcrowd eval`` do), ``skate_raw_cm`` the decode
  before locking; ``captures`` is the left-out samples' own aligned data decoded the same way.
- Throughput: kriging weights for 100,000 queries with our batched, jitted
  ``kriging_weights_batch`` vs PyKrige ``OrdinaryKriging`` (vectorized backend) on the same 2-D
  controls, the same samples and the same fixed spherical variogram, in this process; compile
  timed apart; medians of ``--repeats``.
- Fit time: ``jcrowd fit`` on ``cmu/walk`` (compilation included).
- Anisotropy (issue 21): leave-one-clip-out core-space error of the isotropic fit against a
  grid of geometric anisotropies, the drift system and RBF (:func:`anisotropy`).

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
from jcrowd.io import load_dataset
from jcrowd.kriging import fit_kriging, kriging_weights_batch, make_variogram
from jcrowd.model import ALL_CV_METHODS, build_tensor_model, leave_one_clip_out


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


ANISOTROPY_GRID = (0.25, 0.5, 1.0, 2.0)
"""Scales tried on the 2nd and 3rd normalised control (dz, dyaw) relative to the 1st (dx)."""


def anisotropy(tensor: Any) -> dict[str, Any]:
    """Does geometric anisotropy help kriging on unseen takes? (issue 21, item 3)

    Level-0 cores, leave-one-clip-out, error ‖K* − K‖_F in core space (no decode: the joint
    error follows it, and it is cheap enough for a grid). The isotropic fit is jcrowd's
    (controls standardised, p chosen by leave-one-out, θ by Eq. 4); each anisotropic
    candidate multiplies the standardised dz and dyaw by a scale from ``ANISOTROPY_GRID`` and
    refits θ at the same p; RBF and the drift system run on the same folds.
    """
    from jcrowd.kriging import predict
    from jcrowd.kriging.rbf import fit_rbf, predict_rbf
    from jcrowd.kriging.universal import normalise_controls
    from jcrowd.model.motion_model import clamp_controls, sample_cores
    from jcrowd.model.samples import CONTROL_NAMES

    lv = tensor.levels[0]
    cores = sample_cores(lv.tucker.core, lv.tucker.factors[2])
    idx = [CONTROL_NAMES.index(k) for k in ("dx", "dz", "dyaw")]
    base, _, _ = normalise_controls(tensor.controls[:, idx])

    def loco(c: np.ndarray, method: str, vario: Any = None, system: str = "residual") -> float:
        errs = []
        for g in np.unique(tensor.groups):
            out = tensor.groups == g
            train = ~out
            box = np.stack([c[train].min(axis=0), c[train].max(axis=0)], axis=1)
            q = jnp.asarray(clamp_controls(c[out], box), jnp.float32)
            if method == "rbf":
                pred = predict_rbf(fit_rbf(c[train], cores[train]), q)
            else:
                km = fit_kriging(c[train], cores[train], vario, normalise=False, system=system)
                pred = predict(km, q)
            miss = (np.asarray(pred, np.float64) - cores[out]).reshape(int(out.sum()), -1)
            errs += np.linalg.norm(miss, axis=1).tolist()
        return float(np.mean(errs))

    iso = fit_kriging(base, cores, normalise=False).variogram
    p = float(iso.p)
    grid = {}
    for a1 in ANISOTROPY_GRID:
        for a2 in ANISOTROPY_GRID:
            c = base * np.array([1.0, a1, a2])
            vario = fit_kriging(c, cores, normalise=False, exponents=(p,)).variogram
            grid[f"{a1},{a2}"] = loco(c, "kriging", vario)
    best = min(grid, key=grid.__getitem__)
    return {
        "iso": loco(base, "kriging", iso),
        "best": grid[best],
        "best_scales": [1.0, *map(float, best.split(","))],
        "drift": loco(base, "kriging", iso, "drift"),
        "rbf": loco(base, "rbf"),
        "grid": grid,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    data = data_root()
    names = {m: NAMES.get(m, m) for m in ALL_CV_METHODS}
    cv, cv_max, cv_root, skate, skate_raw, aniso = {}, {}, {}, {}, {}, {}
    for name, folder in (("cmu/walk", data / "cmu" / "walk"), ("cmu16", data / "cmu16")):
        tensor = build_tensor_model(load_dataset(folder))
        res = leave_one_clip_out(tensor, methods=ALL_CV_METHODS, skate=True)
        cv[name] = {names[m]: res[m]["joint_m"] for m in ALL_CV_METHODS}
        cv_max[name] = {names[m]: res[m]["max_joint_m"] for m in ALL_CV_METHODS}
        cv_root[name] = {names[m]: res[m]["root_m"] for m in ALL_CV_METHODS}
        skate[name] = {names[m]: res[m]["skate_cm"] for m in ALL_CV_METHODS}
        skate[name]["captures"] = res["captures"]["skate_cm"]
        skate_raw[name] = {names[m]: res[m]["skate_raw_cm"] for m in ALL_CV_METHODS}
        aniso[name] = anisotropy(tensor)
        if name == "cmu16":
            tp = throughput(tensor.controls, args.repeats)
    t = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the bench prints only its own table
        jcrowd_main(["fit", str(data / "cmu" / "walk"), "--out", "/tmp/jcrowd-bench-walk.jcm"])
    fit_s = time.perf_counter() - t
    out = {
        "cv": cv["cmu/walk"],
        "cv_cmu16": cv["cmu16"],
        "cv_max": cv_max,
        "cv_root": cv_root,
        "skate_cm": skate["cmu/walk"],
        "skate_cm_cmu16": skate["cmu16"],
        "skate_raw_cm": skate_raw,
        "anisotropy": aniso,
        **tp,
        "fit_seconds": fit_s,
        "machine": machine(),
        "jax": jax.__version__,
    }
    text = _table(out)
    report(
        "kriging", f"{out['machine']}, jax {out['jax']}", out, text, args.json, not args.no_record
    )


NAMES = {"kriging": "tensor_kriging"}
"""JSON names of :func:`jcrowd.model.evaluate.leave_one_clip_out` methods (the issue's keys)."""


def _table(out: dict[str, Any]) -> str:
    cols = ("tensor_kriging", "per_pose", "per_element", "rbf", "nearest")
    lines = [
        "| data | measure | " + " | ".join(c.replace("_", " ") for c in cols) + " | captures |",
        "|---|---|" + "---|" * (len(cols) + 1),
    ]
    for name, cv, sk in (
        ("cmu/walk", out["cv"], out["skate_cm"]),
        ("cmu16", out["cv_cmu16"], out["skate_cm_cmu16"]),
    ):
        rows = (
            ("mean joint cm", cv, 100, ""),
            ("max joint cm", out["cv_max"][name], 100, ""),
            ("root cm", out["cv_root"][name], 100, ""),
            ("skate cm/frame", sk, 1, f"{sk['captures']:.2f}"),
            ("skate before lock", out["skate_raw_cm"][name], 1, ""),
        )
        for label, vals, k, last in rows:
            cells = " | ".join(f"{k * vals[c]:.2f}" for c in cols)
            lines.append(f"| {name} | {label} | {cells} | {last} |")
    lines += [
        "",
        "| data | core-space LOCO error | isotropic (ours) | best anisotropic | "
        "scales dx:dz:dyaw | drift system | RBF |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, a in out["anisotropy"].items():
        lines.append(
            f"| {name} | ‖K* − K‖ | {a['iso']:.3f} | {a['best']:.3f} | "
            f"{':'.join(f'{x:g}' for x in a['best_scales'])} | {a['drift']:.3f} | {a['rbf']:.3f} |"
        )
    lines += [
        "",
        f"kriging weights for {out['queries']:,} queries over {out['samples']} samples: ours "
        f"{out['ours_s'] * 1e3:.1f} ms (compile {out['ours_compile_s']:.1f} s), PyKrige "
        f"{out['pykrige_s'] * 1e3:.1f} ms → {out['throughput_ratio_vs_pykrige']:.1f}×",
        f"jcrowd fit cmu/walk: {out['fit_seconds']:.1f} s wall (compilation included)",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
