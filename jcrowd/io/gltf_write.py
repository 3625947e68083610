"""A whole crowd as one glTF 2.0 binary (``.glb``): a skinned body per agent, its animation, the
ground. Written with pygltflib, atomically.

Layout of the file:

- **One body mesh, shared.** Its vertices, normals, joint ids and weights are stored once (the
  body bound to the motion model's skeleton, for a 1 m skeleton: :mod:`jcrowd.motion.body`),
  split into four index lists by clothing region (skin, top, bottom, shoes). Each agent has a
  ``mesh`` of its own whose four primitives share those accessors and differ only in their
  materials (its clothes; materials of equal colour are shared).
- **A skeleton and a skin per agent.** Joint nodes named ``agent<i>/<joint>``; the root's
  translation is the recorded root, every other joint's is its offset times the agent's
  skeleton scale ``h``, so the rest pose is the skeleton's. The inverse bind matrix of joint
  ``j`` is ``[h I | −h p̄_j]`` (``p̄_j`` its rest position for a 1 m skeleton): it maps the shared
  1 m mesh into the joint's frame of a skeleton ``h`` tall, so one mesh serves every height.
  ``h`` is the agent's stature over the model's ``body_height``: the body drawn is the agent's
  ``height`` tall.
- **One animation.** Per agent, every joint's rotation and the root's translation at each
  frame (linear), and the root's scale, 1 while the agent is in the scene and 0 otherwise
  (step): glTF has no visibility, and a skin scaled to nothing draws nothing.
- **The ground**, a grey square at ``y = 0``.

Units metres, ``y`` up, as jcrowd's world (glTF's own convention); frame times in seconds at the
run's frame rate. glTF stores quaternions ``(x, y, z, w)``; jcrowd's are ``(w, x, y, z)``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pygltflib as gl

from jcrowd.errors import JcrowdError
from jcrowd.io.atomic import write_atomic
from jcrowd.motion.body import SHOES, SKIN, TOP, BodyMesh
from jcrowd.motion.clip import Motion

__all__ = ["CrowdAgent", "write_crowd_glb"]

_SHOE = (0.16, 0.15, 0.14)
_GROUND = (0.74, 0.74, 0.70)


@dataclass(frozen=True)
class CrowdAgent:
    """One agent to export: its full-detail motion (skeleton scaled by ``height``), that
    skeleton scale ``height`` (m; the stature over the model's ``body_height``), whether it is
    in the scene at each frame ``(F,)``, and its skin, top and bottom colours ``(3, 3)``."""

    motion: Motion
    height: float
    alive: np.ndarray
    colors: np.ndarray


class _Blob:
    """The binary buffer, its buffer views and accessors, appended to as arrays come."""

    def __init__(self, doc: gl.GLTF2) -> None:
        self.doc = doc
        self.data = bytearray()

    def add(self, array: np.ndarray, kind: str, component: int, target: int | None = None) -> int:
        a = np.ascontiguousarray(array)
        while len(self.data) % 4:
            self.data.append(0)
        view = gl.BufferView(buffer=0, byteOffset=len(self.data), byteLength=a.nbytes)
        if target is not None:
            view.target = target
        self.data += a.tobytes()
        self.doc.bufferViews.append(view)
        acc = gl.Accessor(
            bufferView=len(self.doc.bufferViews) - 1,
            componentType=component,
            count=int(a.shape[0]),
            type=kind,
        )
        if kind in (gl.VEC3, gl.SCALAR) and component == gl.FLOAT and a.size:
            flat = a.reshape(a.shape[0], -1)
            acc.min = [float(x) for x in flat.min(axis=0)]
            acc.max = [float(x) for x in flat.max(axis=0)]
        self.doc.accessors.append(acc)
        return len(self.doc.accessors) - 1


def write_crowd_glb(
    path: str | os.PathLike[str],
    agents: Sequence[CrowdAgent],
    mesh: BodyMesh,
    rest: np.ndarray,
    fps: float,
    ground_size: float = 40.0,
    ground_center: tuple[float, float] = (0.0, 0.0),
) -> int:
    """Write ``agents`` skinned with ``mesh`` (bound to their skeleton; ``rest`` its joints'
    rest positions for a 1 m skeleton) to ``path``; returns the file's size in bytes."""
    if not agents:
        raise JcrowdError(f"{os.fspath(path)}: expected at least one agent to export, found none")
    frames = agents[0].motion.num_frames
    names = agents[0].motion.skeleton.names
    for k, a in enumerate(agents):
        if a.motion.skeleton.names != names:
            raise JcrowdError(
                f"{os.fspath(path)}: agent {k}: expected the skeleton of the first agent (one "
                "body mesh is shared), found another"
            )
        if a.motion.num_frames != frames or len(a.alive) != frames:
            raise JcrowdError(
                f"{os.fspath(path)}: agent {k}: expected {frames} frames like the first, found "
                f"{a.motion.num_frames} (alive: {len(a.alive)})"
            )
    doc = gl.GLTF2(asset=gl.Asset(generator="jcrowd", version="2.0"))
    doc.scene = 0
    doc.scenes = [gl.Scene(nodes=[])]
    blob = _Blob(doc)
    shared = _shared_mesh(blob, mesh)
    materials: dict[tuple[float, ...], int] = {}
    times = blob.add((np.arange(frames) / fps).astype(np.float32), gl.SCALAR, gl.FLOAT)
    doc.accessors[times].min, doc.accessors[times].max = [0.0], [float((frames - 1) / fps)]
    animation = gl.Animation(name="crowd", samplers=[], channels=[])
    scene_nodes = doc.scenes[0].nodes
    for k, agent in enumerate(agents):
        joint_nodes = _skeleton_nodes(doc, agent.motion.skeleton, agent, k)
        scene_nodes.append(joint_nodes[0])
        ibm = np.zeros((len(joint_nodes), 4, 4), np.float32)
        h = agent.height
        ibm[:, 0, 0] = ibm[:, 1, 1] = ibm[:, 2, 2] = h
        ibm[:, :3, 3] = -h * np.asarray(rest, np.float64)
        ibm[:, 3, 3] = 1.0
        # glTF matrices are column-major: store each transposed.
        ibm_acc = blob.add(np.transpose(ibm, (0, 2, 1)).reshape(-1, 16), gl.MAT4, gl.FLOAT)
        doc.skins.append(gl.Skin(joints=joint_nodes, inverseBindMatrices=ibm_acc))
        colors = np.asarray(agent.colors, np.float64)
        prims = []
        for region, indices in shared["regions"].items():
            color = _SHOE if region == SHOES else tuple(colors[min(region - SKIN, 2)])
            prims.append(
                gl.Primitive(
                    attributes=gl.Attributes(**shared["attributes"]),
                    indices=indices,
                    material=_material(doc, materials, color),
                )
            )
        doc.meshes.append(gl.Mesh(name=f"agent{k}", primitives=prims))
        doc.nodes.append(
            gl.Node(name=f"agent{k}/body", mesh=len(doc.meshes) - 1, skin=len(doc.skins) - 1)
        )
        scene_nodes.append(len(doc.nodes) - 1)
        _animate(blob, animation, times, joint_nodes, agent)
    doc.animations.append(animation)
    scene_nodes.append(_ground(blob, doc, materials, ground_size, ground_center))
    doc.buffers = [gl.Buffer(byteLength=len(blob.data))]
    doc.set_binary_blob(bytes(blob.data))
    data = b"".join(doc.save_to_bytes())
    write_atomic(path, data)
    return len(data)


def _shared_mesh(blob: _Blob, mesh: BodyMesh) -> dict:
    v = np.asarray(mesh.vertices, np.float32)
    n = np.asarray(mesh.normals, np.float32)
    attributes = {
        "POSITION": blob.add(v, gl.VEC3, gl.FLOAT, gl.ARRAY_BUFFER),
        "NORMAL": blob.add(n, gl.VEC3, gl.FLOAT, gl.ARRAY_BUFFER),
        # A slot with no weight names joint 0, as the glTF validator asks.
        "JOINTS_0": blob.add(
            np.where(np.asarray(mesh.weights) > 0, np.asarray(mesh.bones), 0).astype(np.uint16),
            gl.VEC4,
            gl.UNSIGNED_SHORT,
            gl.ARRAY_BUFFER,
        ),
        "WEIGHTS_0": blob.add(
            np.asarray(mesh.weights, np.float32), gl.VEC4, gl.FLOAT, gl.ARRAY_BUFFER
        ),
    }
    region = np.full(len(v), TOP) if mesh.region is None else np.asarray(mesh.region)
    tri = np.asarray(mesh.triangles, np.uint32)
    by_tri = region[tri[:, 0]]
    regions = {}
    for r in np.unique(by_tri):
        idx = tri[by_tri == r].reshape(-1)
        regions[int(r)] = blob.add(idx, gl.SCALAR, gl.UNSIGNED_INT, gl.ELEMENT_ARRAY_BUFFER)
    return {"attributes": attributes, "regions": regions}


def _material(doc: gl.GLTF2, cache: dict, color: tuple) -> int:
    key = tuple(round(float(c), 3) for c in color)
    if key not in cache:
        pbr = gl.PbrMetallicRoughness(
            baseColorFactor=[*key, 1.0], metallicFactor=0.0, roughnessFactor=0.8
        )
        doc.materials.append(gl.Material(pbrMetallicRoughness=pbr))
        cache[key] = len(doc.materials) - 1
    return cache[key]


def _skeleton_nodes(doc: gl.GLTF2, skeleton, agent: CrowdAgent, k: int) -> list[int]:
    """The agent's joint nodes in joint order (children linked); returns their indices."""
    first = len(doc.nodes)
    offsets = np.asarray(skeleton.offsets, np.float64)  # already scaled to the agent's height
    for j, name in enumerate(skeleton.names):
        node = gl.Node(name=f"agent{k}/{name}")
        if j > 0:
            node.translation = [float(x) for x in offsets[j]]
        doc.nodes.append(node)
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            doc.nodes[first + p].children.append(first + j)
    return list(range(first, first + skeleton.num_joints))


def _animate(
    blob: _Blob, animation: gl.Animation, times: int, joints: list[int], agent: CrowdAgent
) -> None:
    motion = agent.motion
    rot = np.asarray(motion.rotations, np.float64)
    xyzw = np.concatenate([rot[..., 1:], rot[..., :1]], axis=-1).astype(np.float32)
    root = (
        np.asarray(motion.root_positions, np.float64)
        + np.asarray(motion.skeleton.offsets, np.float64)[0]
    )
    scale = np.where(np.asarray(agent.alive, bool)[:, None], 1.0, 0.0).astype(np.float32)
    tracks = [(joints[0], "translation", root.astype(np.float32), "LINEAR")]
    tracks.append((joints[0], "scale", np.repeat(scale, 3, axis=1), "STEP"))
    tracks += [(node, "rotation", xyzw[:, j], "LINEAR") for j, node in enumerate(joints)]
    for node, path, values, interp in tracks:
        kind = gl.VEC4 if values.shape[1] == 4 else gl.VEC3
        out = blob.add(values, kind, gl.FLOAT)
        animation.samplers.append(
            gl.AnimationSampler(input=times, output=out, interpolation=interp)
        )
        animation.channels.append(
            gl.AnimationChannel(
                sampler=len(animation.samplers) - 1,
                target=gl.AnimationChannelTarget(node=node, path=path),
            )
        )


def _ground(
    blob: _Blob, doc: gl.GLTF2, materials: dict, size: float, center: tuple[float, float]
) -> int:
    h = size / 2.0
    cx, cz = center
    v = np.array(
        [[cx - h, 0, cz - h], [cx - h, 0, cz + h], [cx + h, 0, cz + h], [cx + h, 0, cz - h]],
        np.float32,
    )
    n = np.tile(np.array([0.0, 1.0, 0.0], np.float32), (4, 1))
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint32)
    prim = gl.Primitive(
        attributes=gl.Attributes(
            POSITION=blob.add(v, gl.VEC3, gl.FLOAT, gl.ARRAY_BUFFER),
            NORMAL=blob.add(n, gl.VEC3, gl.FLOAT, gl.ARRAY_BUFFER),
        ),
        indices=blob.add(idx, gl.SCALAR, gl.UNSIGNED_INT, gl.ELEMENT_ARRAY_BUFFER),
        material=_material(doc, materials, _GROUND),
    )
    doc.meshes.append(gl.Mesh(name="ground", primitives=[prim]))
    doc.nodes.append(gl.Node(name="ground", mesh=len(doc.meshes) - 1))
    return len(doc.nodes) - 1
