"""``jcrowd export RUN.npz``: agents of a recorded run as BVH files, or the whole crowd as one glTF.

The run must be recorded with ``jcrowd run --record all``. Each chosen agent is re-synthesized
at full detail from its recorded clips and phases (:func:`jcrowd.model.resynthesis.agent_motion`),
its feet planted when the run planted near agents' feet (the recording's ``planted``).

- ``--format bvh`` (default): ``--agent ID [ID ...] --out-dir DIR`` writes ``DIR/agent_ID.bvh``
  (metres, the run's frame rate, every joint of the model's skeleton), which Blender and
  MotionBuilder import.
- ``--format glb``: ``--out crowd.glb [--agents ID ...] [--frames START:STOP] [--mesh R]`` writes
  one glTF 2.0 binary with a skinned body per agent (the shipped body bound to the model's
  skeleton; resolution ``R``, default 1: 1,229 vertices), its animation at the run's frame rate,
  and the ground (:mod:`jcrowd.io.gltf_write`). Without ``--agents``, every agent alive in the
  frames. Clothes as ``jcrowd render --color-by tint``.

``--model`` overrides the model file the recording names. ``--json`` prints ``files`` (or
``out``, ``bytes``, ``agents``) and ``frames``; a progress bar on stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "export",
        help="write agents of a recorded run as BVH files or one glTF",
        description=__doc__,
    )
    p.add_argument("recording", help="a .npz written by jcrowd run --record all")
    p.add_argument("--format", choices=("bvh", "glb"), default="bvh")
    p.add_argument("--agent", "--agents", dest="agent", type=int, nargs="+", help="agent ids")
    p.add_argument("--out-dir", help="folder for the BVH files (--format bvh)")
    p.add_argument("--out", help="the .glb to write (--format glb)")
    p.add_argument("--frames", help="START:STOP, the recorded frames to export (default: all)")
    p.add_argument("--mesh", type=int, default=1, help="body resolution, 0 finest (default 1)")
    p.add_argument("--model", help="model file (default: the one the recording names)")
    return p


def _frames(text: str | None, total: int) -> slice:
    from jcrowd.errors import JcrowdError

    if text is None:
        return slice(0, total)
    try:
        a, b = (int(v) if v else None for v in text.split(":"))
    except ValueError:
        raise JcrowdError(f"--frames: expected START:STOP like 0:300, found {text!r}") from None
    start, stop = a or 0, total if b is None else b
    if not 0 <= start < stop <= total:
        raise JcrowdError(f"--frames: expected 0 ≤ START < STOP ≤ {total}, found {text!r}")
    return slice(start, stop)


def run(args: argparse.Namespace) -> dict[str, Any]:
    import numpy as np

    from jcrowd.cli.output import emit
    from jcrowd.errors import JcrowdError
    from jcrowd.io.model_file import load_motion_model

    try:
        rec = dict(np.load(args.recording))
    except (OSError, ValueError) as e:
        raise JcrowdError(f"{args.recording}: cannot read the recording: {e}") from e
    model_path = args.model or str(rec.get("model", ""))
    if not model_path:
        raise JcrowdError(f"{args.recording}: names no model; pass --model")
    model, _ = load_motion_model(model_path)
    if args.format == "glb":
        result = _glb(args, rec, model)
    else:
        if not args.agent or not args.out_dir:
            raise JcrowdError("--format bvh: expected --agent ID [ID ...] and --out-dir DIR")
        result = _bvh(args, rec, model)
    result["model"] = model_path
    emit(result, args.json, _print)
    return result


def _planted(rec: dict) -> bool:
    """Whether the run planted near agents' feet (recordings from before it could: no)."""
    return bool(rec["planted"]) if "planted" in rec else False


def _bvh(args: argparse.Namespace, rec: dict, model: Any) -> dict[str, Any]:
    from jcrowd.io.bvh_write import write_bvh
    from jcrowd.model.resynthesis import agent_motion

    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files, frames = [], 0
    for agent in args.agent:
        motion = agent_motion(model, rec, agent, _planted(rec))
        path = out / f"agent_{agent}.bvh"
        write_bvh(path, motion)
        files.append(str(path))
        frames = motion.num_frames
    return {"files": files, "frames": frames}


def _glb(args: argparse.Namespace, rec: dict, model: Any) -> dict[str, Any]:
    import time

    import numpy as np
    from rich.console import Console
    from rich.progress import Progress

    from jcrowd.errors import JcrowdError
    from jcrowd.io.body_file import load_body
    from jcrowd.io.gltf_write import CrowdAgent, write_crowd_glb
    from jcrowd.io.resources import body_path
    from jcrowd.model.resynthesis import agent_motion
    from jcrowd.motion.body import bind_body
    from jcrowd.motion.clip import rest_forward, slice_frames
    from jcrowd.render.bodies import tint_palette

    if not args.out:
        raise JcrowdError("--format glb: expected --out crowd.glb")
    t0 = time.perf_counter()
    total = rec["position"].shape[0]
    span = _frames(args.frames, total)
    alive_all = np.asarray(rec["alive"], bool) if "alive" in rec else np.ones_like(rec["tau"], bool)
    n = rec["position"].shape[1]
    ids = list(args.agent) if args.agent else np.flatnonzero(alive_all[span].any(axis=0)).tolist()
    bad = [a for a in ids if not 0 <= a < n]
    if bad:
        raise JcrowdError(f"--agents: expected ids in 0..{n - 1}, found {bad}")
    if not ids:
        raise JcrowdError(f"{args.recording}: nobody is alive in frames {span.start}:{span.stop}")
    bound = bind_body(load_body(body_path()), model.skeleton, rest_forward(model.skeleton))
    if not 0 <= args.mesh < len(bound.meshes):
        raise JcrowdError(f"--mesh: expected 0..{len(bound.meshes) - 1}, found {args.mesh}")
    tints = tint_palette(n)
    agents = []
    with Progress(console=Console(file=sys.stderr), transient=True) as bar:
        task = bar.add_task(f"re-synthesizing {len(ids)} agents", total=len(ids))
        for a in ids:
            motion = agent_motion(model, rec, a, _planted(rec))
            motion = slice_frames(motion, span.start, span.stop)
            scale = float(rec["height"][a]) / model.body_height  # stature → skeleton scale
            agents.append(CrowdAgent(motion, scale, alive_all[span, a], tints[a]))
            bar.advance(task)
    pos = np.asarray(rec["position"])[span][alive_all[span]]
    mid = pos.mean(axis=0) if len(pos) else np.zeros(2)
    center = (float(mid[0]), float(mid[1]))
    extent = float(np.ptp(pos, axis=0).max()) + 10.0 if len(pos) else 40.0
    fps = float(rec["fps"]) if "fps" in rec else 30.0
    size = write_crowd_glb(
        args.out, agents, bound.meshes[args.mesh], bound.rest, fps, extent, center
    )
    return {
        "out": str(args.out),
        "bytes": size,
        "agents": len(ids),
        "frames": span.stop - span.start,
        "seconds": time.perf_counter() - t0,
    }


def _print(result: dict[str, Any]) -> None:
    if "files" in result:
        sys.stdout.write("\n".join(result["files"]) + "\n")
    else:
        sys.stdout.write(
            f"{result['out']} ({result['agents']} agents, {result['frames']} frames, "
            f"{result['bytes'] / 1e6:.1f} MB)\n"
        )
