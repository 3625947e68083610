"""``jcrowd inspect FILE.bvh|MODEL.jcm``: a capture's gait cycles, or a motion model's levels.

For a BVH file: skeleton, frames, foot contacts, gait cycles and their parameters. With no file
it inspects the sample walk shipped inside the package (made by the procedural walker, so it
needs no data folder). Frame indices are counted after the dropped T-pose frame(s), which are
reported as ``dropped_frames``. For a model file (``jcrowd fit``'s output): levels with ranks,
joints and bytes, the controls and their ranges, the variogram, and the fit's own report.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from jcrowd.errors import JcrowdError

__all__ = ["add_parser", "inspect_bvh", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "inspect",
        help="show a BVH file's skeleton, foot contacts and gait cycles",
        description=__doc__,
    )
    p.add_argument(
        "file", nargs="?", help="a .bvh file (default: the sample walk shipped with jcrowd)"
    )
    p.add_argument(
        "--scale", type=float, default=None, help="file units → metres (default: detect)"
    )
    return p


def inspect_bvh(path: str | Path, scale: float | None = None) -> dict[str, Any]:
    """Everything ``jcrowd inspect`` reports about one BVH file, as plain JSON-ready data."""
    from jcrowd.io.bvh import load_bvh
    from jcrowd.motion.clip import drop_tpose_frames
    from jcrowd.motion.gait import character_height, foot_contacts, gait_cycles
    from jcrowd.motion.skeleton import bone_lengths

    clip = load_bvh(path, scale=scale)
    motion, dropped = drop_tpose_frames(clip.motion)
    skel = motion.skeleton
    lengths = np.asarray(bone_lengths(skel), np.float64)
    result: dict[str, Any] = {
        "file": str(path),
        "joints": skel.num_joints,
        "joint_names": list(skel.names),
        "frames": motion.num_frames,
        "dropped_frames": dropped,
        "fps": round(motion.fps, 6),
        "duration_s": round(motion.num_frames / motion.fps, 6),
        "units": clip.units,
        "scale": clip.scale,
        "height_m": round(character_height(skel), 4),
        "bone_lengths_m": {n: round(float(v), 5) for n, v in zip(skel.names, lengths, strict=True)},
    }
    try:
        contacts = foot_contacts(motion)
        cycles = gait_cycles(motion, contacts, foot="both")
    except JcrowdError as err:  # no feet on this skeleton: report the rest
        result.update(contacts=None, gait_cycles=[], gait_note=str(err))
        return result
    result["contacts"] = {
        "left": [list(iv) for iv in contacts.intervals("left")],
        "right": [list(iv) for iv in contacts.intervals("right")],
        "feet": {
            "left": [skel.names[contacts.feet.left_ankle], skel.names[contacts.feet.left_toe]],
            "right": [skel.names[contacts.feet.right_ankle], skel.names[contacts.feet.right_toe]],
        },
    }
    result["gait_cycles"] = [
        {
            "foot": c.foot,
            "start": c.start,
            "end": c.end,
            "duration_s": round(c.duration, 5),
            "dx": round(c.dx, 5),
            "dz": round(c.dz, 5),
            "dyaw": round(c.dyaw, 5),
            "dyaw_deg": round(math.degrees(c.dyaw), 3),
            "speed": round(c.speed, 5),
        }
        for c in cycles
    ]
    return result


def inspect_model(path: str | Path) -> dict[str, Any]:
    """What ``jcrowd inspect`` reports about a motion-model file."""
    from jcrowd.io.model_file import load_motion_model

    model, extra = load_motion_model(path)
    levels = []
    for lv in model.levels:
        k = lv.kriging
        arrays = [lv.u_pose, lv.u_time, k.residuals, k.trend, k.gamma_operator, k.controls]
        levels.append(
            {
                "core": [int(lv.u_pose.shape[1]), int(lv.u_time.shape[1])],
                "samples": int(k.num_samples),
                "joints": len(lv.joints),
                "bytes": int(sum(np.asarray(a).nbytes for a in arrays)),
                "variogram": {
                    "p": float(k.variogram.p),
                    "theta": np.asarray(k.variogram.theta).tolist(),
                },
            }
        )
    return {
        "file": str(path),
        "kind": "motion-model",
        "joints": model.skeleton.num_joints,
        "joint_names": list(model.skeleton.names),
        "controls": list(model.control_names),
        "control_ranges": np.asarray(model.control_ranges).tolist(),
        "fps": model.fps,
        "levels": levels,
        "bytes_file": Path(path).stat().st_size,
        "fit": extra.get("fit"),
    }


def _render_model(result: dict[str, Any]) -> None:
    lines = [
        f"{result['file']}: motion model, {result['joints']} joints, {result['fps']:g} fps, "
        f"{result['bytes_file']:,} bytes",
        "controls: "
        + ", ".join(
            f"{n} [{lo:.2f}, {hi:.2f}]"
            for n, (lo, hi) in zip(result["controls"], result["control_ranges"], strict=True)
        ),
    ]
    for i, lv in enumerate(result["levels"]):
        v = lv["variogram"]
        lines.append(
            f"level {i}: core {'×'.join(map(str, lv['core']))} kriged over "
            f"{lv['samples']} samples, {lv['joints']} joints, "
            f"{lv['bytes']:,} bytes, variogram p={v['p']:.1f} θ={np.round(v['theta'], 3).tolist()}"
        )
    sys.stdout.write("\n".join(lines) + "\n")


def _render(result: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(file=sys.stdout)
    console.print(f"[bold]{result['file']}[/bold]")
    console.print(
        f"{result['joints']} joints, {result['frames']} frames at {result['fps']:g} fps "
        f"({result['duration_s']:.2f} s; {result['dropped_frames']} leading T-pose frame(s) "
        "dropped), "
        f"units {result['units']} (×{result['scale']:g} → m), height {result['height_m']:.2f} m"
    )
    bones = Table(title="bone lengths (m)", show_edge=False)
    bones.add_column("joint")
    bones.add_column("length", justify="right")
    for name, length in result["bone_lengths_m"].items():
        bones.add_row(name, f"{length:.3f}")
    console.print(bones)
    if result.get("contacts"):
        for side in ("left", "right"):
            ivs = ", ".join(f"{a}–{b}" for a, b in result["contacts"][side])
            feet = "/".join(result["contacts"]["feet"][side])
            console.print(f"{side} foot ({feet}) contacts: {ivs or 'none'}")
    else:
        console.print(f"no foot contacts: {result.get('gait_note', '')}")
    table = Table(title="gait cycles (two steps from a heel strike)", show_edge=False)
    for col in ("foot", "start", "end", "s", "dx m", "dz m", "dyaw °", "speed m/s"):
        table.add_column(col, justify="right")
    for c in result["gait_cycles"]:
        table.add_row(
            c["foot"],
            str(c["start"]),
            str(c["end"]),
            f"{c['duration_s']:.2f}",
            f"{c['dx']:+.3f}",
            f"{c['dz']:+.3f}",
            f"{c['dyaw_deg']:+.1f}",
            f"{c['speed']:.2f}",
        )
    console.print(table if result["gait_cycles"] else "no complete gait cycle found")


def run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.output import emit
    from jcrowd.io.resources import sample_bvh_path

    path = args.file
    if path is None:
        path = sample_bvh_path()
        sys.stderr.write(f"jcrowd inspect: no file given, inspecting the shipped sample {path}\n")
    if str(path).lower().endswith(".bvh"):
        result = inspect_bvh(path, scale=args.scale)
        emit(result, args.json, _render)
    else:
        result = inspect_model(path)
        emit(result, args.json, _render_model)
    return result
