"""``jcrowd calibrate DATA… --out params.toml``: fit the dynamics to measured trajectories.

``DATA`` are HERMES corridor runs (``uo-<entrance>-<corridor>-<exit>.txt``, centimetres, 16 fps,
as in the shared data's ``hermes_uo``) or folders holding them; each run's steady-state frames
come from ``steady_state.csv`` beside it (the whole run where it is not listed). The fit is
:func:`jcrowd.rollouts.calibrate.calibrate`: Levenberg–Marquardt through short differentiable
rollouts from the measured states (that module's docstring says what is compared and why).

``--fit`` names the parameters (default ``time_gap,radius``, as
:data:`jcrowd.rollouts.calibrate.DEFAULT_NAMES`, whose module says why; any field of
:class:`~jcrowd.pedestrians.params.AvoidanceParams`, ``radius`` or ``desired_speed``),
``--start NAME=VALUE`` moves a start value from the model's default. The fitted values are
written (atomically) to ``--out`` as TOML: ``[avoidance]`` (what a scenario's ``[dynamics]
params = "params.toml"`` sets), ``[body]`` (a fitted ``radius``: that scenario's ``[dynamics]
radius`` unless it names its own), ``[population]`` (the fitted free speed: set your groups'
``speed`` to it to walk like the measured people) and ``[calibration]`` (the runs, the start,
the residuals). Levenberg–Marquardt starts at the best point of a coarse grid
(:data:`jcrowd.rollouts.calibrate.COARSE_GRID`) and the start (``--no-search``: at the start).
``--json`` prints one object: the start, the point the fit started from
(``searched_from``) and the fitted values, the residual RMS at each, the steps, the Jacobian's
singular values and the seconds taken.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

__all__ = ["add_parser", "params_toml", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "calibrate",
        help="fit the crowd dynamics' parameters to measured trajectories",
        description=__doc__,
    )
    p.add_argument("data", nargs="+", help="HERMES run files uo-*.txt, or folders of them")
    p.add_argument("--out", default="params.toml", help="parameters file to write (TOML)")
    p.add_argument(
        "--fit",
        # jcrowd.rollouts.calibrate.DEFAULT_NAMES (the parser loads no jax)
        default="time_gap,radius",
        help="comma-separated parameters to fit",
    )
    p.add_argument(
        "--start",
        nargs="*",
        default=[],
        metavar="NAME=VALUE",
        help="start values (default: the model's)",
    )
    p.add_argument(
        "--residual",
        default="person",
        choices=("person", "speed"),
        help="compare every person's velocity, or each window's mean speed",
    )
    p.add_argument("--horizon", type=float, default=0.5, help="seconds simulated per window")
    p.add_argument("--every", type=float, default=1.0, help="seconds between windows")
    p.add_argument("--max-steps", type=int, default=100, help="Levenberg–Marquardt steps at most")
    p.add_argument(
        "--no-search",
        action="store_true",
        help="start Levenberg–Marquardt at the start values, not at the coarse grid's best",
    )
    return p


def run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.output import emit

    result = _calibrate(args)
    emit(result, args.json, _print)
    return result


def _start_values(names: list[str], given: list[str]) -> dict[str, float]:
    from jcrowd.errors import JcrowdError
    from jcrowd.pedestrians.params import AvoidanceParams
    from jcrowd.rollouts.calibrate import RADIUS_NAME, SPEED_NAME
    from jcrowd.rollouts.windows import RADIUS

    defaults = AvoidanceParams()
    start: dict[str, float] = {}
    for name in names:
        if name == SPEED_NAME:
            start[name] = 1.34
        elif name == RADIUS_NAME:
            start[name] = RADIUS
        elif name in AvoidanceParams.__dataclass_fields__:
            start[name] = float(getattr(defaults, name))
        else:
            fields = sorted([*AvoidanceParams.__dataclass_fields__, SPEED_NAME, RADIUS_NAME])
            raise JcrowdError(f"--fit: expected names among {', '.join(fields)}, found {name!r}")
    for text in given:
        name, eq, value = text.partition("=")
        if not eq or name not in start:
            raise JcrowdError(f"--start: expected NAME=VALUE with NAME in --fit, found {text!r}")
        try:
            start[name] = float(value)
        except ValueError:
            raise JcrowdError(f"--start {text}: expected a number, found {value!r}") from None
    return start


def _calibrate(args: argparse.Namespace) -> dict[str, Any]:
    from rich.console import Console
    from rich.progress import Progress

    from jcrowd.errors import JcrowdError
    from jcrowd.io.atomic import write_atomic
    from jcrowd.io.trajectories import load_hermes_runs
    from jcrowd.rollouts.calibrate import COARSE_GRID, calibrate
    from jcrowd.rollouts.windows import make_windows, merge_windows

    names = [n.strip() for n in args.fit.split(",") if n.strip()]
    start = _start_values(names, args.start)
    if args.max_steps < 1:
        raise JcrowdError(f"--max-steps: expected ≥ 1, found {args.max_steps}")
    t0 = time.perf_counter()
    runs = load_hermes_runs(args.data)
    batches = []
    with Progress(transient=True, console=Console(file=sys.stderr)) as progress:
        task = progress.add_task("windows", total=len(runs) + 1)
        for r in runs:
            frames = r.steady or (int(r.rows[:, 1].min()), int(r.rows[:, 1].max()))
            batch, _ = make_windows(
                r.rows,
                r.fps,
                frames,
                r.corridor_m,
                r.exit_m,
                horizon_s=args.horizon,
                every_s=args.every,
            )
            batches.append(batch)
            progress.advance(task)
        progress.update(task, description="fitting (compile, then Levenberg–Marquardt)")
        cal = calibrate(
            merge_windows(batches),
            start,
            max_steps=args.max_steps,
            residual=args.residual,
            grid=None if args.no_search else COARSE_GRID,
        )
        progress.advance(task)
    result = {
        "data": [r.name for r in runs],
        "windows": int(sum(b.position.shape[0] for b in batches)),
        "horizon_s": args.horizon,
        "residual": args.residual,
        "names": list(cal.names),
        "start": dict(zip(cal.names, (round(float(v), 6) for v in cal.start), strict=True)),
        "searched_from": dict(
            zip(cal.names, (round(float(v), 4) for v in cal.searched_from), strict=True)
        ),
        "fitted": dict(zip(cal.names, (round(float(v), 4) for v in cal.values), strict=True)),
        "residual_rms_start_m_s": round(cal.rms_start, 4),
        "residual_rms_searched_m_s": round(cal.rms_searched, 4),
        "residual_rms_m_s": round(cal.rms, 4),
        "steps": cal.steps,
        "converged": cal.converged,
        "singular_values": [round(float(s), 5) for s in cal.singular_values],
        "out": str(args.out),
        "seconds": round(time.perf_counter() - t0, 2),
    }
    write_atomic(args.out, params_toml(result))
    return result


def params_toml(result: dict[str, Any]) -> str:
    """The parameters file: ``[avoidance]``, ``[body]``, ``[population]`` and ``[calibration]``."""
    from jcrowd.rollouts.calibrate import EXTRA_NAMES, RADIUS_NAME, SPEED_NAME

    fitted = result["fitted"]
    lines = ["# jcrowd calibrate: fitted to measured trajectories", "", "[avoidance]"]
    lines += [f"{k} = {v!r}" for k, v in fitted.items() if k not in EXTRA_NAMES]
    if RADIUS_NAME in fitted:
        lines += ["", "[body]", f"{RADIUS_NAME} = {fitted[RADIUS_NAME]!r}"]
    if SPEED_NAME in fitted:
        lines += ["", "[population]", f"{SPEED_NAME} = {fitted[SPEED_NAME]!r}"]
    lines += [
        "",
        "[calibration]",
        "data = [" + ", ".join(f'"{d}"' for d in result["data"]) + "]",
        f"horizon_s = {result['horizon_s']!r}",
        f"residual = {result['residual']!r}",
        f"residual_rms_start_m_s = {result['residual_rms_start_m_s']!r}",
        f"residual_rms_searched_m_s = {result['residual_rms_searched_m_s']!r}",
        f"residual_rms_m_s = {result['residual_rms_m_s']!r}",
        f"steps = {result['steps']}",
    ]
    return "\n".join(lines) + "\n"


def _print(result: dict[str, Any]) -> None:
    for name in result["names"]:
        print(
            f"{name:>22}: {result['start'][name]:.4g} (searched from "
            f"{result['searched_from'][name]:.4g}) -> {result['fitted'][name]:.4g}"
        )
    print(
        f"residual RMS {result['residual_rms_start_m_s']:.4f} -> {result['residual_rms_m_s']:.4f} "
        f"m/s over {result['windows']} windows of {len(result['data'])} runs, "
        f"{result['steps']} steps, {result['seconds']:.0f} s; wrote {result['out']}"
    )
