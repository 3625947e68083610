"""Layout optimisation against a brute-force grid search (issue 22, item 3).

The scene: ``examples/two_exits.toml``, a room emptying through two doors that share 2 m of
doorway; the varied number is the middle wall piece's x (``obstacles[1].center[0]``), which
widens one door by what it takes from the other, within ``--bounds`` (default 4.6 … 5.5 m:
door A 0.6 … 1.5 m). The objective (``--objective``, default ``travel_time``) is
:func:`jcrowd.rollouts.layout_opt.layout_objective`.

- **Grid**: ``--grid`` forward simulations at evenly spaced values over the bounds (the world
  and its navigation field rebuilt at each), the best taken.
- **Gradient**: :func:`~jcrowd.rollouts.layout_opt.projected_gradient` from the scenario as written
  (door widths 1 m / 1 m), at most ``--evaluations`` value-and-gradient evaluations. Counted
  as one simulation each in ``gradient simulations``; ``forward-equivalents`` is the same
  count times the measured time of a value-and-gradient over a forward run (the backward pass
  and the checkpoints' recomputation), the honest cost in forward runs.
- The gradient optimum is evaluated again with the grid's forward objective
  (:func:`~jcrowd.rollouts.layout_opt.forward_value`); Done-when: that value within 5 % of the
  grid's best with at least 10× fewer simulations.
- Compile (first call, trace + XLA) and run (median of the calls after it) are timed apart.

Also written: ``docs/optimize.png`` (objective against the parameter over the grid, the
optimiser's points and its optimum marked).

``python bench/optimize.py [--grid 61] [--evaluations 6] [--json] [--no-record] [--no-figure]``
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import jax
import numpy as np
from common import ROOT, machine, report

from jcrowd.rollouts.layout_opt import forward_value, layout_problem, value_and_gradient
from jcrowd.rollouts.search import projected_gradient
from jcrowd.scenario.keys import varied_parameter
from jcrowd.scenario.parse import load_scenario

SCENE = ROOT / "examples" / "two_exits.toml"
KEY = "obstacles[1].center[0]"


def measure(
    grid: int, evaluations: int, bounds: tuple[float, float], objective: str, decay: float
) -> dict[str, Any]:
    scenario = load_scenario(SCENE)
    varied = varied_parameter(scenario, KEY, bounds)
    problem = layout_problem(scenario, [varied], objective, adjoint_decay=decay)
    start = problem.start

    t = time.perf_counter()
    forward_value(problem, start)
    forward_compile_s = time.perf_counter() - t
    t = time.perf_counter()
    value_and_gradient(problem, start)
    grad_compile_s = time.perf_counter() - t

    xs = np.linspace(bounds[0], bounds[1], grid)
    values, forward_s = [], []
    for i, x in enumerate(xs):
        t = time.perf_counter()
        values.append(forward_value(problem, [x]))
        forward_s.append(time.perf_counter() - t)
        print(f"grid {i + 1}/{grid}: {KEY} = {x:.4f}: {values[-1]:.4f}", file=sys.stderr)
    grid_values = np.asarray(values)
    best = int(np.argmin(grid_values))

    grad_s: list[float] = []

    def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
        t = time.perf_counter()
        out = value_and_gradient(problem, x)
        grad_s.append(time.perf_counter() - t)
        print(f"gradient: {KEY} = {x[0]:.4f}: {out[0]:.4f}, d/dx {out[1][0]:.3g}", file=sys.stderr)
        return out

    res = projected_gradient(fun, start, problem.lower, problem.upper, max_evaluations=evaluations)
    checked = forward_value(problem, res.x)
    fwd, vg = float(np.median(forward_s)), float(np.median(grad_s))
    # The slope of the forward objective between grid points vs the gradient at the points
    # the optimiser visited: does the gradient point the way the objective falls?
    slopes = np.gradient(grid_values, xs)
    visited = []
    for x, value in res.path:
        k = int(np.argmin(np.abs(xs - x[0])))
        visited.append({"x": float(x[0]), "value": value, "grid_slope": float(slopes[k])})
    out: dict[str, Any] = {
        "scene": str(SCENE.relative_to(ROOT)),
        "key": KEY,
        "bounds": list(bounds),
        "objective": objective,
        "adjoint_decay": decay,
        "agents": int(problem.peds.position.shape[0]),
        "steps": problem.steps,
        "grid_points": grid,
        "grid_x": xs.tolist(),
        "grid_values": grid_values.tolist(),
        "grid_best_x": float(xs[best]),
        "grid_best": float(grid_values[best]),
        "start_x": float(start[0]),
        "start_value": float(res.path[0][1]),
        "gradient_x": float(res.x[0]),
        "gradient_value_forward": checked,
        "gradient_evaluations": res.evaluations,
        "gradient_iterations": res.iterations,
        "gradient_message": res.message,
        "gradient_path": visited,
        "forward_compile_s": round(forward_compile_s, 2),
        "grad_compile_s": round(grad_compile_s, 2),
        "forward_s": round(fwd, 4),
        "grad_s": round(vg, 4),
        "forward_equivalents": round(res.evaluations * vg / fwd, 1),
    }
    out["within"] = checked / out["grid_best"] - 1.0
    out["fewer"] = grid / res.evaluations
    out["done"] = bool(out["within"] <= 0.05 and out["fewer"] >= 10)
    return out


def figure(out: dict[str, Any], path: Any) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.2), dpi=120)
    ax.plot(
        out["grid_x"],
        out["grid_values"],
        "o-",
        ms=3,
        color="0.45",
        lw=1,
        label=f"grid search: {out['grid_points']} forward runs",
    )
    ax.plot(
        out["grid_best_x"],
        out["grid_best"],
        "s",
        ms=9,
        mfc="none",
        color="tab:blue",
        label=f"grid best {out['grid_best']:.2f} s",
    )
    px = [p["x"] for p in out["gradient_path"]]
    pv = [p["value"] for p in out["gradient_path"]]
    ax.plot(px, pv, "--", color="tab:orange", lw=1)
    for k, (x, v) in enumerate(zip(px, pv, strict=True)):
        ax.annotate(
            str(k),
            (x, v),
            textcoords="offset points",
            xytext=(4, 4),
            fontsize=8,
            color="tab:orange",
        )
    ax.plot(
        px,
        pv,
        "o",
        color="tab:orange",
        ms=5,
        label=f"gradient optimiser: {out['gradient_evaluations']} value-and-gradient runs",
    )
    ax.plot(
        out["gradient_x"],
        out["gradient_value_forward"],
        "*",
        ms=16,
        color="tab:red",
        label=f"gradient optimum {out['gradient_value_forward']:.2f} s",
    )
    ax.set_xlabel("middle wall piece x (m)   ← door A narrower · door A wider →")
    ax.set_ylabel("mean travel time (s)" if out["objective"] == "travel_time" else out["objective"])
    ax.set_title(f"two_exits.toml: {out['agents']} people, two doors sharing 2 m", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _table(out: dict[str, Any]) -> str:
    lines = [
        "| objective | agents × steps | grid: points, best x, best | gradient: evaluations, x, "
        "forward value | within | fewer simulations | forward-equivalents | compile s (forward "
        "/ gradient) | run s (forward / gradient) | done |",
        "|---|---|---|---|---|---|---|---|---|---|",
        f"| {out['objective']} | {out['agents']} × {out['steps']} | {out['grid_points']}, "
        f"{out['grid_best_x']:.3f}, {out['grid_best']:.3f} | {out['gradient_evaluations']}, "
        f"{out['gradient_x']:.3f}, {out['gradient_value_forward']:.3f} | "
        f"{100 * out['within']:+.1f} % | {out['fewer']:.1f}× | {out['forward_equivalents']} | "
        f"{out['forward_compile_s']:.1f} / {out['grad_compile_s']:.1f} | {out['forward_s']:.3f} "
        f"/ {out['grad_s']:.3f} | {out['done']} |",
    ]
    path = "; ".join(
        f"{p['x']:.3f}: {p['value']:.3f} (grid slope {p['grid_slope']:+.2g})"
        for p in out["gradient_path"]
    )
    lines += ["", f"optimiser path: {path} — {out['gradient_message']}"]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=61)
    ap.add_argument("--evaluations", type=int, default=6)
    ap.add_argument("--bounds", type=float, nargs=2, default=(4.6, 5.5))
    ap.add_argument("--objective", default="travel_time")
    ap.add_argument("--adjoint-decay", type=float, default=1.0)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    ap.add_argument("--no-figure", action="store_true")
    args = ap.parse_args()
    out = measure(
        args.grid, args.evaluations, tuple(args.bounds), args.objective, args.adjoint_decay
    )
    out["machine"] = machine()
    out["jax"] = jax.__version__
    if not args.no_figure:
        figure(out, ROOT / "docs" / "optimize.png")
    report(
        "optimize",
        f"{out['machine']}, jax {out['jax']}, float32, adjoint decay {out['adjoint_decay']:g}",
        out,
        _table(out),
        args.json,
        not args.no_record,
    )


if __name__ == "__main__":
    main()
