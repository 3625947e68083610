"""``jcrowd demo [--out-dir out]``: the shipped model walks the shipped plaza; MP4 + PNG.

Runs the plaza scenario shipped in the package (a copy of ``examples/plaza.toml``: 3000 walkers in
five groups, paths with 90° corners) with the shipped default model, renders it headless as skinned
bodies in varied clothes (``jcrowd render --color-by level`` colours them by level of detail
instead), and writes ``OUT/demo.mp4`` and ``OUT/demo.png`` (the middle frame). Defaults
are sized for a small machine without a GPU: 10 seconds of scenario time at 960×540. Prints both
paths (``--json``: one object with ``mp4``, ``png``, ``frames``, ``agents``,
``ms_per_frame_median``, ``ms_per_step_median``, ``seconds``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "demo", help="render the shipped plaza scenario to out/demo.mp4", description=__doc__
    )
    p.add_argument("--out-dir", default="out", help="folder for demo.mp4 and demo.png")
    p.add_argument("--seconds", type=float, default=10.0, help="scenario seconds to render")
    p.add_argument("--size", default="960x540", help="WIDTHxHEIGHT")
    return p


def run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.output import emit
    from jcrowd.cli.render import parse_size, render_scenario
    from jcrowd.errors import JcrowdError
    from jcrowd.io.model_file import load_default_model
    from jcrowd.io.resources import demo_scenario_path
    from jcrowd.scenario.parse import load_scenario

    if not args.seconds > 0:
        raise JcrowdError(f"--seconds: expected a positive number, found {args.seconds}")
    t0 = time.perf_counter()
    scenario = load_scenario(demo_scenario_path())
    out = Path(args.out_dir)
    mp4, png = out / "demo.mp4", out / "demo.png"
    frames = max(1, round(args.seconds * scenario.fps))
    result = render_scenario(
        scenario,
        load_default_model(),
        str(mp4),
        parse_size(args.size, (960, 540)),
        frames,
        "tint",
        still=str(png),
    )
    result = {
        "mp4": str(mp4),
        "png": str(png),
        **{k: result[k] for k in ("frames", "agents", "ms_per_frame_median", "renderer")},
        "ms_per_step_median": result["ms_per_step_median"],
        "seconds": time.perf_counter() - t0,
    }
    emit(result, args.json, _print)
    return result


def _print(result: dict[str, Any]) -> None:
    sys.stdout.write(f"{result['mp4']}\n{result['png']}\n")
    sys.stderr.write(
        f"{result['agents']:,} walkers, {result['frames']} frames in {result['seconds']:.0f} s "
        f"({result['renderer']})\n"
    )
