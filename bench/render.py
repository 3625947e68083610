"""Benchmark of the headless renderer (DESIGN §6; paper 003 §6.4): ms per frame vs agents.

Scene: ``N`` procedural walkers (:func:`jcrowd.motion.walker.procedural_walk`, one gait cycle at
30 fps, each agent a random frame of it turned by a random yaw) on a square grid 1.5 m apart,
every agent at level 0 (the full 19-joint skeleton): the worst case, with no LOD. The camera
frames the whole grid from above and in front (:func:`jcrowd.render.frame_points`, 45° vertical
fov), 4× MSAA, ground and grid on. Each count is drawn in each ``--styles``, same scene, same
process: ``capsules`` (18 capsules per agent) and ``body`` (the shipped skinned body bound to
the walker's skeleton, every agent with the mesh its height on screen asks for, sky, blob
shadows; :mod:`jcrowd.render.bodies`; the ``triangles`` column counts what was drawn).

Timed: :meth:`CrowdRenderer.render` alone (gathering bones from the joint array, writing the
instance buffer, drawing, resolving MSAA and reading the image back), median of ``--repeats``
frames after one warm-up frame. The crowd step is not part of this script. Set-up (context,
shader compilation, buffer allocation) and the first frame are separate columns.

    python bench/render.py [--agents 1000,10000] [--styles capsules,body] [--repeats 5]
                           [--size 1280x720] [--detail SEGMENTS,RINGS] [--json] [--no-record]
                           [--png PREFIX]

``--detail`` replaces level 0's capsule (8 segments, 2 rings: 64 triangles) with a coarser or
finer one, e.g. ``6,1`` (24 triangles, what level 2 uses) to see what LOD saves.

Prints one table (or one JSON object with ``rows``) and appends a dated section to
``bench/RESULTS.md``. ``renderer`` is the driver's GL_RENDERER string ("llvmpipe …" is Mesa's
software rasteriser).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import append_result, machine

import jcrowd.render.bodies as bodies_module
from jcrowd.io.body_file import load_body
from jcrowd.io.resources import body_path
from jcrowd.motion import character_height, forward_kinematics, procedural_walk, rest_forward
from jcrowd.motion.body import bind_body
from jcrowd.motion.skeleton import end_site_positions
from jcrowd.motion.skinning import skeleton_level
from jcrowd.render import (
    LEVEL_COLORS,
    CrowdRenderer,
    LevelInstances,
    View,
    frame_points,
    gl_renderer,
    make_context,
    write_png,
)
from jcrowd.render.meshes import capsule_detail, capsule_mesh

SPACING = 1.5  # m between neighbouring agents on the grid


def synthetic_crowd(agents: int, seed: int = 0) -> tuple[np.ndarray, tuple[int, ...]]:
    """Joint then End Site positions ``(agents, 19 + 3, 3)`` float32 of walkers in varied
    poses on a grid, and the parents of those points."""
    motion, _ = procedural_walk(cycles=1, fps=30.0, seed=seed)
    rot, pos = forward_kinematics(motion.skeleton, motion.rotations, motion.root_positions)
    ends = end_site_positions(motion.skeleton, rot, pos)
    poses = np.concatenate([np.asarray(pos, np.float64), np.asarray(ends, np.float64)], axis=1)
    poses -= poses[:, :1] * np.array([1.0, 0.0, 1.0])  # root above the origin
    rng = np.random.default_rng(seed)
    frame = rng.integers(0, len(poses), agents)
    yaw = rng.uniform(-np.pi, np.pi, agents)
    side = int(np.ceil(np.sqrt(agents)))
    ix, iz = np.divmod(np.arange(agents), side)
    centre = (side - 1) * SPACING / 2.0
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    p = poses[frame]
    x = c * p[..., 0] + s * p[..., 2] + (ix * SPACING - centre)[:, None]
    z = -s * p[..., 0] + c * p[..., 2] + (iz * SPACING - centre)[:, None]
    joints = np.stack([x, p[..., 1], z], axis=-1).astype(np.float32)
    return joints, (*motion.skeleton.parents, *motion.skeleton.end_parents)


def bench_one(
    agents: int,
    width: int,
    height: int,
    repeats: int,
    png: str | None,
    detail: tuple[int, int] = capsule_detail(0),
    style: str = "capsules",
) -> dict[str, Any]:
    """Time rendering ``agents`` walkers in ``style``; one result row."""
    points, parents = synthetic_crowd(agents)
    skeleton = procedural_walk(cycles=1, fps=30.0, seed=0)[0].skeleton
    j = skeleton.num_joints
    body = None
    if style == "body":
        unit = skeleton.scaled(1.0 / character_height(skeleton))
        bound = bind_body(load_body(body_path()), unit, rest_forward(unit))
        body = skeleton_level(bound, unit)
        joints, level_parents = points, parents
        colors: np.ndarray = bodies_module.tint_palette(agents)
    else:
        joints, level_parents = points[:, :j], parents[:j]
        colors = np.tile(LEVEL_COLORS[0], (agents, 1))
    heights = np.full(agents, character_height(skeleton), np.float32)
    extent = float(np.ptp(joints[..., [0, 2]], axis=(0, 1)).max())
    view: View = frame_points(joints[:, 0], aspect=width / height)
    instances = LevelInstances(joints, np.ones(agents, bool), colors, heights)
    t = time.perf_counter()
    ctx = make_context()
    renderer = CrowdRenderer(
        [level_parents],
        width,
        height,
        capacity=[agents],
        ctx=ctx,
        ground_size=max(200.0, 1.5 * extent),
        detail=[detail],
        bodies=None if body is None else [body],
        sky=body is not None,
    )
    setup_s = time.perf_counter() - t
    try:
        t = time.perf_counter()
        image = renderer.render(view, [instances])
        first_ms = (time.perf_counter() - t) * 1e3
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            renderer.render(view, [instances])
            times.append(time.perf_counter() - t)
        name = gl_renderer(ctx)
    finally:
        renderer.release()
        ctx.release()
    if png:
        write_png(f"{png}{style}_{agents}.png", image)
    ms = float(np.median(times)) * 1e3
    if body is not None:
        picked = bodies_module.pick_meshes(
            points[:, 0], heights, _view_proj(view, width, height), height, len(body.meshes)
        )
        triangles = int(sum(len(body.meshes[m].triangles) for m in picked))
        meshes = np.bincount(picked, minlength=len(body.meshes)).tolist()
    else:
        triangles = agents * (j - 1) * len(capsule_mesh(*detail)[1])
        meshes = []
    return {
        "style": style,
        "triangles": triangles,
        "agents_per_mesh": meshes,
        "agents": agents,
        "width": width,
        "height": height,
        "ms_per_frame": ms,
        "agents_per_s": agents / (ms / 1e3),
        "renderer": name,
        "bones": agents * (len(parents) - 1),
        "setup_s": setup_s,
        "first_frame_ms": first_ms,
        "repeats": repeats,
        "capsule": {
            "segments": detail[0],
            "rings": detail[1],
            "triangles": len(capsule_mesh(*detail)[1]),
        },
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", default="1000,10000", help="comma-separated counts")
    ap.add_argument("--styles", default="capsules,body", help="capsules and/or body")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--size", default="1280x720", help="WIDTHxHEIGHT")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    ap.add_argument("--detail", default=None, help="level-0 capsule SEGMENTS,RINGS")
    ap.add_argument("--png", default=None, help="write each last frame to PREFIX<agents>.png")
    args = ap.parse_args()
    counts = [int(a) for a in args.agents.split(",") if a.strip()]
    width, height = (int(v) for v in args.size.lower().split("x"))
    detail = capsule_detail(0)
    if args.detail:
        seg, rings = (int(v) for v in args.detail.split(","))
        detail = (seg, rings)
    styles = [s for s in args.styles.split(",") if s.strip()]
    rows = [
        bench_one(n, width, height, args.repeats, args.png, detail, style)
        for n in counts
        for style in styles
    ]
    out = {"rows": rows, "machine": machine(), "samples": 4}
    text = _table(out)
    if args.json:
        sys.stdout.write(json.dumps(out, indent=2) + "\n")
    else:
        print(text)
    if not args.no_record:
        renderer = rows[0]["renderer"] if rows else "none"
        tris = rows[0]["capsule"]["triangles"] if rows else 0
        details = (
            f"{out['machine']}, {renderer}, 4× MSAA, level 0 only, capsule {detail[0]}×"
            f"{detail[1]} ({tris} triangles), styles {args.styles}"
        )
        append_result("render", details, text)


def _view_proj(view: View, width: int, height: int) -> np.ndarray:
    from jcrowd.render import projection_matrix, view_matrix

    return projection_matrix(view, width, height) @ view_matrix(view)


def _table(out: dict[str, Any]) -> str:
    lines = [
        "| agents | style | triangles | size | ms/frame (median) | frames/s | agents/s | "
        "set-up s | first frame ms | repeats |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in out["rows"]:
        lines.append(
            f"| {r['agents']:,} | {r['style']} | {r['triangles']:,} | {r['width']}×{r['height']} | "
            f"{r['ms_per_frame']:.1f} | {1e3 / r['ms_per_frame']:.2f} | "
            f"{r['agents_per_s']:,.0f} | {r['setup_s']:.2f} | {r['first_frame_ms']:.0f} | "
            f"{r['repeats']} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
