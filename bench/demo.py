"""How long ``jcrowd demo`` takes, end to end, on this machine (issue 20: ≤ 90 s).

Runs ``jcrowd demo --json`` in a fresh Python process (imports, model and scenario loading, the
step's compilation, 300 frames stepped and drawn at 960×540, MP4 and PNG written) and times
the process's wall clock; reports it beside the demo's own ``seconds``, ``ms_per_frame_median``
(drawing) and ``ms_per_step_median``. ``--repeats`` runs (median); the JIT cache is not
persisted between runs, so each pays the compilation as a fresh clone does.

``python bench/demo.py [--repeats 1] [--json] [--no-record]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time

import numpy as np
from common import ROOT, machine, report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    runs = []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as out:
            t = time.perf_counter()
            done = subprocess.run(
                [sys.executable, "-m", "jcrowd.cli", "demo", "--out-dir", out, "--json"],
                check=True,
                capture_output=True,
                text=True,
                cwd=ROOT,
            )
            wall = time.perf_counter() - t
        runs.append({**json.loads(done.stdout), "wall_s": wall})
    med = {k: float(np.median([r[k] for r in runs])) for k in ("wall_s", "seconds")}
    last = runs[-1]
    out = {
        "wall_s": round(med["wall_s"], 1),
        "demo_seconds": round(med["seconds"], 1),
        "ms_per_frame_median": round(last["ms_per_frame_median"], 1),
        "ms_per_step_median": round(last["ms_per_step_median"], 1),
        "frames": last["frames"],
        "agents": last["agents"],
        "renderer": last["renderer"],
        "repeats": args.repeats,
        "machine": machine(),
    }
    text = (
        "| wall s (process) | demo's own s | draw ms/frame | step ms | frames | agents |\n"
        "|---|---|---|---|---|---|\n"
        f"| {out['wall_s']} | {out['demo_seconds']} | {out['ms_per_frame_median']} | "
        f"{out['ms_per_step_median']} | {out['frames']} | {out['agents']:,} |"
    )
    report("demo", f"{out['machine']}, {out['renderer']}", out, text, args.json, not args.no_record)


if __name__ == "__main__":
    main()
