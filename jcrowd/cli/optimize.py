"""``jcrowd optimize SCENARIO.toml --vary KEY_PATH…``: move obstacles so the room empties fastest.

Each ``--vary`` names a number of an ``[[obstacles]]`` table by its key path, with optional
bounds: ``obstacles[1].center[0]`` (±1 m round its value; sizes and radii ×0.5 … ×1.5) or
``obstacles[1].center[0]=4.6:5.5``. The objective (``--objective``): ``travel_time`` (mean time
until each agent is within 1 m of its goal, s), ``evacuation`` (soft time until the last is,
s) or ``flow`` (agents out per second by the end); :mod:`jcrowd.rollouts.layout_opt` defines them
and the optimiser: projected gradient descent with a line search on the forward objective, the
navigation field rebuilt at each iterate and held fixed inside the gradient.

The crowd is the scenario's, spawned once (its seed), walking to its goals for the scenario's
duration; every group needs a goal, and ``[[sources]]`` are refused.

The optimised scenario is written (``--out``, default ``NAME.optimized.toml`` beside the input,
atomically) as a copy of the input with only the varied numbers changed (rounded to 0.1 mm),
comments kept. ``--json`` prints one object: the start and optimum of each key, the objective at
both, every point evaluated, the number of gradient evaluations (each one forward and one
backward simulation) and the time taken.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run", "set_toml_values"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "optimize", help="optimise obstacle positions and sizes", description=__doc__
    )
    p.add_argument("scenario", help="a scenario file (TOML)")
    p.add_argument(
        "--vary",
        nargs="+",
        required=True,
        metavar="KEY_PATH[=LO:HI]",
        help="numbers of [[obstacles]] tables to vary, e.g. 'obstacles[1].center[0]=4.6:5.5'",
    )
    p.add_argument(
        "--objective", choices=("evacuation", "flow", "travel_time"), default="travel_time"
    )
    p.add_argument("--out", help="where to write the optimised scenario (TOML)")
    p.add_argument(
        "--max-evaluations", type=int, default=6, help="gradient evaluations at most (default 6)"
    )
    p.add_argument(
        "--adjoint-decay",
        type=float,
        default=1.0,
        help="γ of truncated backpropagation through time (1: the exact gradient)",
    )
    return p


def _spec(text: str) -> tuple[str, tuple[float, float] | None]:
    from jcrowd.errors import JcrowdError

    key, eq, bounds = text.partition("=")
    if not eq:
        return key, None
    m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*:\s*([-+0-9.eE]+)\s*", bounds)
    if m is None:
        raise JcrowdError(f"--vary {text}: expected KEY_PATH=LO:HI with numbers, found {bounds!r}")
    try:
        return key, (float(m.group(1)), float(m.group(2)))
    except ValueError:
        raise JcrowdError(f"--vary {text}: expected numbers LO:HI, found {bounds!r}") from None


def run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.output import emit

    result = _optimize(args)
    emit(result, args.json, _print)
    return result


def _optimize(args: argparse.Namespace) -> dict[str, Any]:
    import numpy as np
    from rich.console import Console

    from jcrowd.errors import JcrowdError
    from jcrowd.io.atomic import write_atomic
    from jcrowd.rollouts.layout_opt import layout_problem, value_and_gradient
    from jcrowd.rollouts.search import projected_gradient
    from jcrowd.scenario.keys import varied_parameter
    from jcrowd.scenario.parse import load_scenario

    path = Path(args.scenario)
    scenario = load_scenario(path)
    varied = [varied_parameter(scenario, *_spec(text)) for text in args.vary]
    if args.max_evaluations < 1:
        raise JcrowdError(f"--max-evaluations: expected ≥ 1, found {args.max_evaluations}")
    problem = layout_problem(scenario, varied, args.objective, adjoint_decay=args.adjoint_decay)
    sign = -1.0 if args.objective == "flow" else 1.0  # flow is maximised: report it positive
    console = Console(file=sys.stderr)
    t0 = time.perf_counter()

    def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
        value, grad = value_and_gradient(problem, x)
        shown = ", ".join(f"{v.key} = {a:.4g}" for v, a in zip(varied, x, strict=True))
        console.print(
            f"{args.objective} {sign * value:.4g} at {shown} ({time.perf_counter() - t0:.0f} s)"
        )
        return value, grad

    start = problem.start
    res = projected_gradient(
        fun, start, problem.lower, problem.upper, max_evaluations=args.max_evaluations
    )
    out = Path(args.out) if args.out else path.with_name(f"{path.stem}.optimized.toml")
    text = path.read_text(encoding="utf-8")
    values = {v.key: round(float(x), 4) for v, x in zip(varied, res.x, strict=True)}
    write_atomic(out, set_toml_values(text, values, str(path)))
    return {
        "scenario": str(path),
        "out": str(out),
        "objective": args.objective,
        "varied": [
            {
                "key": v.key,
                "lower": v.lower,
                "upper": v.upper,
                "start": float(a),
                "optimum": values[v.key],
            }
            for v, a in zip(varied, start, strict=True)
        ],
        "value_start": sign * res.path[0][1],
        "value_optimum": sign * res.value,
        "gradient_optimum": res.gradient.tolist(),
        "evaluations": res.evaluations,
        "iterations": res.iterations,
        "message": res.message,
        "path": [[*x.tolist(), sign * f] for x, f in res.path],
        "seconds": round(time.perf_counter() - t0, 2),
    }


def set_toml_values(text: str, values: dict[str, float], source: str = "<text>") -> str:
    """``text`` with the number at each key path (``obstacles[1].center[0]``) replaced, the rest
    of the file as it was; the result is parsed back and compared with what was asked.

    Raises:
        JcrowdError: a key that is not in a ``[[table]]`` written with its header, or a
            result that does not parse back to the values asked for.
    """
    from jcrowd.errors import JcrowdError
    from jcrowd.scenario.keys import parse_key_path

    expected = tomllib.loads(text)
    for key, value in values.items():
        path = parse_key_path(key)
        if len(path) < 3 or not isinstance(path[0], str) or not isinstance(path[1], int):
            raise JcrowdError(f"{source}: {key}: expected TABLE[i].KEY…, found {key!r}")
        table, i, field, index = path[0], path[1], str(path[2]), path[3:]
        start, end = _value_span(text, table, i, field, source, key)
        node: Any = expected[table][i]
        holder: Any = node
        last: str | int = field
        for k in index:
            holder, last = holder[last], k
        holder[last] = value
        text = text[:start] + _toml(node[field]) + text[end:]
    if tomllib.loads(text) != expected:
        raise JcrowdError(f"{source}: expected the rewritten file to hold {values}, it does not")
    return text


def _value_span(
    text: str, table: str, i: int, field: str, source: str, key: str
) -> tuple[int, int]:
    """Where the value of ``field`` in the ``i``-th ``[[table]]`` lies in ``text``."""
    from jcrowd.errors import JcrowdError

    headers = [m for m in re.finditer(r"(?m)^[ \t]*\[\[\s*" + re.escape(table) + r"\s*\]\]", text)]
    if i >= len(headers):
        raise JcrowdError(
            f"{source}: {key}: expected a [[{table}]] header for table {i}, found {len(headers)}"
        )
    begin = headers[i].end()
    after = re.search(r"(?m)^[ \t]*\[", text[begin:])
    stop = begin + after.start() if after else len(text)
    m = re.search(r"(?m)^[ \t]*" + re.escape(field) + r"[ \t]*=[ \t]*", text[begin:stop])
    if m is None:
        raise JcrowdError(f"{source}: {key}: expected a line '{field} = …' in [[{table}]] {i}")
    start = begin + m.end()
    if text[start] != "[":
        number = re.match(r"[-+0-9._eE]+", text[start:])
        if number is None:
            raise JcrowdError(
                f"{source}: {key}: expected a number, found {text[start : start + 20]!r}"
            )
        return start, start + number.end()
    depth, k = 0, start
    while k < len(text):
        c = text[k]
        if c == "#":
            k = text.find("\n", k)
            k = len(text) if k < 0 else k
            continue
        depth += (c == "[") - (c == "]")
        k += 1
        if depth == 0:
            return start, k
    raise JcrowdError(f"{source}: {key}: expected a closed array, found none")


def _toml(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"not a number: {value!r}")
    return repr(float(value)) if isinstance(value, float) else str(value)


def _print(result: dict[str, Any]) -> None:
    lines = [
        f"{result['objective']}: {result['value_start']:.4g} → {result['value_optimum']:.4g} "
        f"in {result['evaluations']} gradient evaluations ({result['seconds']:.0f} s; "
        f"{result['message']})"
    ]
    lines += [
        f"  {v['key']}: {v['start']:g} → {v['optimum']:g} (bounds {v['lower']:g} … {v['upper']:g})"
        for v in result["varied"]
    ]
    lines.append(f"written: {result['out']}")
    sys.stdout.write("\n".join(lines) + "\n")
