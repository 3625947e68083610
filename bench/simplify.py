"""Benchmark of joint simplification (paper 003) against SciPy SLSQP on the same problem.

For ``07_03`` (31 joints, 415 frames after the T-pose) and a longer clip, 8 levels: seconds for
all levels after compilation (median of repeats; the first call, which compiles, is timed
apart), error and bone-length variation per level. In the same process, on the same per-frame
problems (hard mode), SciPy ``minimize(method="SLSQP")`` in float64, given exact gradients and
constraint Jacobians (jax, compiled before timing), solves a fixed subset of frames of every
level (``--scipy-frames`` evenly spaced frames per level); its time is scaled to all frames for
``scipy_seconds``. ``objective_ratio_vs_scipy`` compares our objective with
SciPy's on the frames both solved (mean of per-frame ratios; < 1 means ours is lower).

    python bench/simplify.py [--json] [--repeats 3] [--scipy-frames 40]

Prints one table (or one JSON object) and appends a dated row to ``bench/RESULTS.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import append_result, data_root, machine

from jcrowd.io import read_bvh
from jcrowd.motion import drop_tpose_frames, forward_kinematics
from jcrowd.simplify import analyse_motion, elimination_order, joint_counts, key_posture
from jcrowd.simplify.levels import Weights, plan_level, position_problem
from jcrowd.simplify.pipeline import simplify_motion


def _objective(x, x0, problem, w: Weights):
    """αE_d + γE_a (paper 003 Eq. 6, 8), jnp so SciPy gets exact float64 gradients."""
    pos = jnp.concatenate([jnp.zeros((1, 3)), x.reshape(-1, 3)])
    e = w.alpha * jnp.sum((x - x0) ** 2)
    a = problem.angles
    if len(a):
        u = pos[a[:, 0]] - pos[a[:, 1]]
        v = pos[a[:, 2]] - pos[a[:, 1]]
        cos = jnp.sum(u * v, -1) / jnp.sqrt(jnp.sum(u * u, -1) * jnp.sum(v * v, -1) + 1e-18)
        e += w.gamma * jnp.sum((cos - problem.angle_cos) ** 2)
    return e


def _constraints(x, problem):
    """Rigid bones ``|x_c − x_p|² = b²``; zero-length bones tie the two points."""
    pos = jnp.concatenate([jnp.zeros((1, 3)), x.reshape(-1, 3)])
    b, b0 = problem.bones, problem.bone_lengths
    rigid = b0 > 1e-6
    d = pos[b[rigid, 0]] - pos[b[rigid, 1]]
    tie = (pos[b[~rigid, 0]] - pos[b[~rigid, 1]]).ravel()
    return jnp.concatenate([jnp.sum(d * d, -1) - b0[rigid] ** 2, tie])


def _compiled(problem, w: Weights):
    """Objective, gradient, constraints and their Jacobian, jitted once per level (float64)."""
    fun = jax.jit(lambda x, x0: _objective(x, x0, problem, w))
    grad = jax.jit(jax.grad(lambda x, x0: _objective(x, x0, problem, w)))
    con = jax.jit(lambda x: _constraints(x, problem))
    jac = jax.jit(jax.jacfwd(lambda x: _constraints(x, problem)))
    return fun, grad, con, jac


def scipy_levels(motion, levels: int, frames_per_level: int, ours) -> dict:
    """SLSQP on a subset of frames of every simplified level; seconds and objective ratios."""
    sk = motion.skeleton
    analysis = analyse_motion(motion)
    order = elimination_order(sk, analysis.importance)
    key = key_posture(motion, analysis.key_frames)
    _, pos = forward_kinematics(
        sk, np.asarray(motion.rotations, np.float64), np.asarray(motion.root_positions, np.float64)
    )
    rel = pos - pos[:, :1]
    w = Weights()
    frames = np.linspace(0, motion.num_frames - 1, frames_per_level).round().astype(int)
    seconds, ratios, solved = 0.0, [], 0
    for index, count in enumerate(joint_counts(sk.num_joints, levels)[1:], start=1):
        plan = plan_level(sk, order, sk.num_joints - count, key)
        problem = position_problem(sk, plan, key)
        opt = ours.levels[index].optimised
        with jax.enable_x64(True):
            fun, grad, con, jac = _compiled(problem, w)
            for f in frames:
                x0 = jnp.asarray(rel[f, 1:].ravel())
                fun(x0, x0), grad(x0, x0), con(x0), jac(x0)  # compile outside the timing
                t = time.perf_counter()
                res = minimize(
                    lambda x, x0=x0, fun=fun: float(fun(x, x0)),
                    np.asarray(x0),
                    jac=lambda x, x0=x0, grad=grad: np.asarray(grad(x, x0)),
                    method="SLSQP",
                    constraints=[
                        {
                            "type": "eq",
                            "fun": lambda x, con=con: np.asarray(con(x)),
                            "jac": lambda x, jac=jac: np.asarray(jac(x)),
                        }
                    ],
                    options={"maxiter": 200, "ftol": 1e-12},
                )
                seconds += time.perf_counter() - t
                solved += 1
                theirs = float(fun(jnp.asarray(res.x), x0))
                mine = float(fun(jnp.asarray(opt[f, 1:].ravel()), x0))
                if theirs > 1e-12:
                    ratios.append(mine / theirs)
    per_frame = seconds / solved
    total = per_frame * motion.num_frames * (levels - 1)
    return {"scipy_seconds": total, "scipy_ms_per_frame": 1e3 * per_frame, "ratios": ratios}


def bench_clip(path: Path, levels: int, repeats: int) -> tuple[dict, object]:
    motion, _ = drop_tpose_frames(read_bvh(path))
    t = time.perf_counter()
    simplify_motion(motion, levels)
    first = time.perf_counter() - t
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        result = simplify_motion(motion, levels)
        runs.append(time.perf_counter() - t)
    med = float(np.median(runs))
    row = {
        "clip": path.name,
        "joints": motion.skeleton.num_joints,
        "frames": motion.num_frames,
        "compile_seconds": first - med,
        "seconds_after_compile": med,
        "levels": [
            {
                "joints": lv.num_joints,
                "mean_error_m": lv.mean_error_m,
                "max_error_m": lv.max_error_m,
                "bone_length_variation_pct": lv.bone_variation_max_pct,
                "converged": int(np.sum(lv.result == 0)),
            }
            for lv in result.levels
        ],
    }
    return row, (motion, result)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--levels", type=int, default=8)
    ap.add_argument("--scipy-frames", type=int, default=40)
    ap.add_argument("--long-clip", default="walk/07_05.bvh")
    ap.add_argument("--no-record", action="store_true", help="do not append to RESULTS.md")
    args = ap.parse_args()
    data = data_root() / "cmu"
    main_row, (motion, result) = bench_clip(data / "walk" / "07_03.bvh", args.levels, args.repeats)
    long_row, _ = bench_clip(data / args.long_clip, args.levels, args.repeats)
    ref = scipy_levels(motion, args.levels, args.scipy_frames, result)
    out = {
        "clip": main_row,
        "long_clip": long_row,
        "seconds_after_compile": main_row["seconds_after_compile"],
        "compile_seconds": main_row["compile_seconds"],
        "scipy_seconds": ref["scipy_seconds"],
        "scipy_ms_per_frame": ref["scipy_ms_per_frame"],
        "scipy_frames_per_level": args.scipy_frames,
        "speedup_vs_scipy": ref["scipy_seconds"] / main_row["seconds_after_compile"],
        "objective_ratio_vs_scipy": float(np.mean(ref["ratios"])),
        "objective_ratio_vs_scipy_max": float(np.max(ref["ratios"])),
        "max_bone_variation_pct": max(lv["bone_length_variation_pct"] for lv in main_row["levels"]),
        "machine": machine(),
        "device": str(jax.devices()[0]),
        "jax": jax.__version__,
    }
    if args.json:
        sys.stdout.write(json.dumps(out, indent=2) + "\n")
    else:
        print(_table(out))
    if not args.no_record:
        _record(out)


def _table(out: dict) -> str:
    lines = []
    for key in ("clip", "long_clip"):
        c = out[key]
        lines.append(
            f"{c['clip']}: {c['joints']} joints × {c['frames']} frames — "
            f"{c['seconds_after_compile']:.2f} s for all levels after compile "
            f"(compile {c['compile_seconds']:.1f} s)"
        )
        lines.append(f"  {'joints':>6} {'mean cm':>8} {'max cm':>8} {'bone var %':>10} {'conv':>5}")
        for lv in c["levels"]:
            lines.append(
                f"  {lv['joints']:>6} {100 * lv['mean_error_m']:>8.2f} "
                f"{100 * lv['max_error_m']:>8.2f} "
                f"{lv['bone_length_variation_pct']:>10.4f} {lv['converged']:>5}"
            )
    lines.append(
        f"SciPy SLSQP: {out['scipy_ms_per_frame']:.1f} ms/frame → {out['scipy_seconds']:.1f} s for "
        f"all levels; ours {out['speedup_vs_scipy']:.1f}× faster; objective ratio (ours/SciPy) "
        f"{out['objective_ratio_vs_scipy']:.4f} mean, {out['objective_ratio_vs_scipy_max']:.4f} max"
    )
    return "\n".join(lines)


def _record(out: dict) -> None:
    c = out["clip"]
    row = (
        f"| clip | joints×frames | levels | s after compile | compile s | SciPy s (scaled) | "
        f"speed-up | objective ours/SciPy | max bone var % | mean error per level (cm) |\n"
        f"|---|---|---|---|---|---|---|---|---|---|\n"
        f"| {c['clip']} | {c['joints']}×{c['frames']} | {len(c['levels'])} | "
        f"{c['seconds_after_compile']:.2f} | {c['compile_seconds']:.1f} | "
        f"{out['scipy_seconds']:.1f} ({out['scipy_frames_per_level']} frames/level) | "
        f"{out['speedup_vs_scipy']:.1f}× | {out['objective_ratio_vs_scipy']:.4f} | "
        f"{out['max_bone_variation_pct']:.4f} | "
        + ", ".join(f"{100 * lv['mean_error_m']:.2f}" for lv in c["levels"])
        + " |\n"
    )
    lc = out["long_clip"]
    row += (
        f"| {lc['clip']} | {lc['joints']}×{lc['frames']} | {len(lc['levels'])} | "
        f"{lc['seconds_after_compile']:.2f} | {lc['compile_seconds']:.1f} | | | | "
        f"{max(lv['bone_length_variation_pct'] for lv in lc['levels']):.4f} | "
        + ", ".join(f"{100 * lv['mean_error_m']:.2f}" for lv in lc["levels"])
        + " |\n"
    )
    append_result("simplify", f"{out['machine']}, {out['device']}, jax {out['jax']}", row)


if __name__ == "__main__":
    main()
