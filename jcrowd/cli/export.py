"""``jcrowd export RUN.npz --agent ID [ID ...] --out-dir DIR``: agents of a run as BVH files.

The run must be recorded with ``jcrowd run --record all``. Each chosen agent is re-synthesized
at full detail from its recorded clips and phases (:func:`jcrowd.crowd.export.agent_motion`) and
written as ``DIR/agent_ID.bvh`` (metres, the run's frame rate, every joint of the model's
skeleton), which Blender and MotionBuilder import. ``--model`` overrides the model file the
recording names. ``--json`` prints ``files`` and ``frames``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "export", help="write agents of a recorded run as BVH files", description=__doc__
    )
    p.add_argument("recording", help="a .npz written by jcrowd run --record all")
    p.add_argument("--agent", type=int, nargs="+", required=True, help="agent ids")
    p.add_argument("--out-dir", required=True)
    p.add_argument("--model", help="model file (default: the one the recording names)")
    return p


def run(args: argparse.Namespace) -> dict[str, Any]:
    import numpy as np

    from jcrowd.cli import emit
    from jcrowd.crowd.export import agent_motion
    from jcrowd.errors import JcrowdError
    from jcrowd.io.bvh_write import write_bvh
    from jcrowd.io.model_file import load_motion_model

    try:
        rec = dict(np.load(args.recording))
    except (OSError, ValueError) as e:
        raise JcrowdError(f"{args.recording}: cannot read the recording: {e}") from e
    model_path = args.model or str(rec.get("model", ""))
    if not model_path:
        raise JcrowdError(f"{args.recording}: names no model; pass --model")
    model, _ = load_motion_model(model_path)
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files, frames = [], 0
    for agent in args.agent:
        motion = agent_motion(model, rec, agent)
        path = out / f"agent_{agent}.bvh"
        write_bvh(path, motion)
        files.append(str(path))
        frames = motion.num_frames
    result = {"files": files, "frames": frames, "model": model_path}
    emit(result, args.json, _print)
    return result


def _print(result: dict[str, Any]) -> None:
    sys.stdout.write("\n".join(result["files"]) + "\n")
