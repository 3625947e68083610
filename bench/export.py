"""Whole-crowd glTF export (issue 20): seconds and bytes for 100 agents × 300 frames, checked by
real clients.

Scene: ``examples/counterflow.toml`` with 50 people in each group (100 in all), run for 300
steps (10 s at 30 fps) with ``jcrowd run --record all``; then ``jcrowd export --format glb`` of
every agent over every frame, at each ``--meshes`` resolution (default 1: 1,229 vertices, and
4: 152). Timed: the export command alone (re-synthesizing every agent at full detail and
writing the file), median of ``--repeats``.

Checked, when the tools are on the machine (a column says ``—`` when not):

- ``validator``: the Khronos glTF validator (npm ``gltf-validator``; ``--validator DIR`` is the
  folder holding its ``node_modules``): errors and warnings.
- ``blender``: Blender (the Debian package, headless) imports the file: meshes, armatures and
  actions it made, and the height of the first agent's body (its evaluated mesh's vertical
  extent, m) at frame 100 — a body standing on its feet, not collapsed or exploded.

``python bench/export.py [--meshes 1,4] [--repeats 3] [--validator DIR] [--json]
[--no-record]``; prints one table (or one JSON object with ``rows``) and appends it to
bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from common import ROOT, machine, report

AGENTS_PER_GROUP = 50
STEPS = 300

_VALIDATE_JS = """
const fs = require('fs');
const v = require('gltf-validator');
v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])), {maxIssues: 20}).then(r => {
  console.log(JSON.stringify({errors: r.issues.numErrors, warnings: r.issues.numWarnings,
    first: r.issues.messages.slice(0, 3).map(m => m.code + ' ' + m.pointer)}));
});
"""

_BLENDER_PY = """
import sys, json
import bpy
path = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
objs = bpy.data.objects
meshes = [o for o in objs if o.type == "MESH"]
bpy.context.scene.frame_set(100)
body = [m for m in meshes if m.name.startswith("agent")][0]
e = body.evaluated_get(bpy.context.evaluated_depsgraph_get())
zs = [(e.matrix_world @ v.co).z for v in e.data.vertices]
print("JCROWD", json.dumps({"meshes": len(meshes),
      "armatures": len([o for o in objs if o.type == "ARMATURE"]),
      "actions": len(bpy.data.actions), "body_height_m": max(zs) - min(zs)}))
"""


def _jcrowd(*args: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-m", "jcrowd.cli", *args, "--json"],
        check=True,
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    return json.loads(out.stdout)


def _validator(folder: Path | None, glb: Path) -> dict | None:
    if folder is None or shutil.which("node") is None:
        return None
    script = folder / "jcrowd_validate.js"
    script.write_text(_VALIDATE_JS)
    out = subprocess.run(
        ["node", str(script), str(glb)], capture_output=True, text=True, cwd=folder, check=True
    )
    return json.loads(out.stdout)


def _blender(glb: Path, work: Path) -> dict | None:
    exe = shutil.which("blender")
    if exe is None:
        return None
    script = work / "blender_check.py"
    script.write_text(_BLENDER_PY)
    out = subprocess.run(
        [exe, "-b", "--factory-startup", "--python", str(script), "--", str(glb)],
        capture_output=True,
        text=True,
        check=True,
    )
    line = next(x for x in out.stdout.splitlines() if x.startswith("JCROWD "))
    return json.loads(line[len("JCROWD ") :])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", default="1,4")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--validator", type=Path, help="folder with node_modules/gltf-validator")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="jcrowd_export_"))
    scene = work / "counterflow100.toml"
    text = (ROOT / "examples" / "counterflow.toml").read_text()
    scene.write_text(text.replace("count = 45", f"count = {AGENTS_PER_GROUP}"))
    rec = work / "run.npz"
    run = _jcrowd("run", str(scene), "--steps", str(STEPS), "--record", "all", "--out", str(rec))
    rows = []
    for mesh in (int(m) for m in args.meshes.split(",")):
        glb = work / f"crowd_{mesh}.glb"
        times, result = [], {}
        for _ in range(args.repeats):
            t = time.perf_counter()
            result = _jcrowd(
                "export", str(rec), "--format", "glb", "--out", str(glb), "--mesh", str(mesh)
            )
            times.append(time.perf_counter() - t)
        seconds_agent = result["agents"] * result["frames"] / float(run.get("fps", 30.0) or 30.0)
        rows.append(
            {
                "mesh": mesh,
                "agents": result["agents"],
                "frames": result["frames"],
                "seconds": round(float(np.median(times)), 2),
                "bytes": result["bytes"],
                "kb_per_agent_second": round(result["bytes"] / 1e3 / seconds_agent, 1),
                "validator": _validator(args.validator, glb),
                "blender": _blender(glb, work),
            }
        )
    out = {"rows": rows, "machine": machine()}
    lines = [
        "| mesh | agents × frames | export s (median, incl. start-up) | MB | kB per agent-second "
        "| validator errors / warnings | Blender: meshes, armatures, actions, body height m |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        v, b = r["validator"], r["blender"]
        vtext = "—" if v is None else f"{v['errors']} / {v['warnings']}"
        btext = (
            "—"
            if b is None
            else f"{b['meshes']}, {b['armatures']}, {b['actions']}, {b['body_height_m']:.2f}"
        )
        lines.append(
            f"| {r['mesh']} | {r['agents']} × {r['frames']} | {r['seconds']} | "
            f"{r['bytes'] / 1e6:.1f} | {r['kb_per_agent_second']} | {vtext} | {btext} |"
        )
    report("export", f"{out['machine']}", out, "\n".join(lines), args.json, not args.no_record)


if __name__ == "__main__":
    main()
