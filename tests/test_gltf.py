"""Whole-crowd glTF export (issue 20): the file, read back with pygltflib and evaluated as a glTF
client does (node TRS → 4×4 world matrices → joint matrix × inverse bind matrix, weighted),
draws the same skin as :func:`jcrowd.motion.skinning.skin` on the FK."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest

from jcrowd.errors import JcrowdError
from jcrowd.io.body_file import load_body
from jcrowd.io.gltf_write import CrowdAgent, write_crowd_glb
from jcrowd.io.resources import body_path
from jcrowd.motion import character_height, procedural_walk, rest_forward, walker_skeleton
from jcrowd.motion.body import bind_body
from jcrowd.motion.clip import Motion
from jcrowd.motion.skeleton import forward_kinematics
from jcrowd.motion.skinning import rest_offsets, skin

FPS = 30.0


@pytest.fixture(scope="module")
def crowd(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[CrowdAgent], object]:
    skeleton = walker_skeleton(1.0)
    skeleton = skeleton.scaled(1.0 / character_height(skeleton))  # a 1 m model skeleton
    bound = bind_body(load_body(body_path()), skeleton, rest_forward(skeleton))
    agents = []
    for k, (h, x) in enumerate(((1.62, 0.0), (1.85, 2.0), (1.71, -1.5))):
        walk, _ = procedural_walk(cycles=1, fps=FPS, seed=k)
        rot = np.asarray(walk.rotations, np.float32)
        root = np.asarray(walk.root_positions, np.float64)
        root = root / character_height(walk.skeleton) * h + [x, 0.0, 0.0]
        motion = Motion(skeleton.scaled(h), rot, root.astype(np.float32), FPS)
        alive = np.ones(motion.num_frames, bool)
        alive[:3] = k != 1  # the second agent enters at frame 3
        colors = np.array([[0.8, 0.6, 0.5], [0.2, 0.3, 0.7], [0.3, 0.3, 0.3]], np.float32)
        agents.append(CrowdAgent(motion, h, alive, colors))
    path = tmp_path_factory.mktemp("glb") / "crowd.glb"
    write_crowd_glb(path, agents, bound.meshes[-1], bound.rest, FPS)
    return path, agents, bound


def _read(doc: gl.GLTF2, blob: bytes, index: int) -> np.ndarray:
    acc = doc.accessors[index]
    view = doc.bufferViews[acc.bufferView]
    dtype = {gl.FLOAT: np.float32, gl.UNSIGNED_SHORT: np.uint16, gl.UNSIGNED_INT: np.uint32}[
        acc.componentType
    ]
    width = {gl.SCALAR: 1, gl.VEC3: 3, gl.VEC4: 4, gl.MAT4: 16}[acc.type]
    start = view.byteOffset + (acc.byteOffset or 0)
    return np.frombuffer(blob, dtype, acc.count * width, start).reshape(acc.count, width)


def _trs(t: np.ndarray, q_xyzw: np.ndarray, s: np.ndarray) -> np.ndarray:
    x, y, z, w = q_xyzw
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def _client_pose(path: Path, agent: int, frame: int):  # type: ignore[no-untyped-def]
    """A glTF client's view of ``agent`` at ``frame``: the document, its binary blob, the
    agent's body node and the world matrix of every node (rest TRS overridden by the
    animation's values at that frame)."""
    doc = gl.GLTF2().load(str(path))
    blob = doc.binary_blob()
    trs = {
        i: [
            np.array(n.translation or [0, 0, 0]),
            np.array(n.rotation or [0, 0, 0, 1]),
            np.array(n.scale or [1, 1, 1]),
        ]
        for i, n in enumerate(doc.nodes)
    }
    anim = doc.animations[0]
    for ch in anim.channels:
        values = _read(doc, blob, anim.samplers[ch.sampler].output)[frame]
        slot = {"translation": 0, "rotation": 1, "scale": 2}[ch.target.path]
        trs[ch.target.node][slot] = values.astype(np.float64)
    parent = {c: i for i, n in enumerate(doc.nodes) for c in n.children}

    def world(i: int) -> np.ndarray:
        m = _trs(*trs[i])
        return world(parent[i]) @ m if i in parent else m

    body = next(n for n in doc.nodes if n.name == f"agent{agent}/body")
    return doc, blob, body, world


def _client_skin(path: Path, agent: int, frame: int) -> np.ndarray:
    """What a glTF client draws for ``agent``'s body at ``frame``."""
    doc, blob, body, world = _client_pose(path, agent, frame)
    sk = doc.skins[body.skin]
    ibm = _read(doc, blob, sk.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    joint_m = np.stack([world(j) @ ibm[k] for k, j in enumerate(sk.joints)])
    prim = doc.meshes[body.mesh].primitives[0]
    v = _read(doc, blob, prim.attributes.POSITION).astype(np.float64)
    ids = _read(doc, blob, prim.attributes.JOINTS_0).astype(int)
    w = _read(doc, blob, prim.attributes.WEIGHTS_0).astype(np.float64)
    hv = np.concatenate([v, np.ones((len(v), 1))], axis=1)
    out = np.zeros((len(v), 4))
    for k in range(4):
        out += w[:, k, None] * np.einsum("vij,vj->vi", joint_m[ids[:, k]], hv)
    return out[:, :3]


@pytest.mark.parametrize(("agent", "frame"), [(0, 0), (0, 17), (1, 9)])
def test_a_glb_client_draws_the_same_skin(crowd, agent: int, frame: int) -> None:  # type: ignore[no-untyped-def]
    """float32 storage throughout: 1e-4 m."""
    path, agents, bound = crowd
    a = agents[agent]
    mesh = bound.meshes[-1]
    rot, pos = forward_kinematics(
        a.motion.skeleton,
        np.asarray(a.motion.rotations[frame], np.float64),
        np.asarray(a.motion.root_positions[frame], np.float64),
    )
    want = skin(mesh.bones, mesh.weights, rest_offsets(mesh, bound.rest), rot, pos, a.height)
    np.testing.assert_allclose(_client_skin(path, agent, frame), want, atol=1e-4)


def test_an_agent_not_in_the_scene_collapses(crowd) -> None:  # type: ignore[no-untyped-def]
    path, _, _ = crowd
    drawn = _client_skin(path, 1, 1)
    assert np.ptp(drawn, axis=0).max() < 1e-6  # scaled to nothing before it enters


def test_file_is_valid_gltf_with_one_animation(crowd) -> None:  # type: ignore[no-untyped-def]
    path, agents, _ = crowd
    doc = gl.GLTF2().load(str(path))
    assert doc.asset.version == "2.0" and len(doc.animations) == 1
    assert len(doc.skins) == len(agents)
    assert {n.name for n in doc.nodes} >= {"ground", "agent0/body", "agent1/Hips"}
    times = doc.accessors[doc.animations[0].samplers[0].input]
    assert times.count == agents[0].motion.num_frames
    assert times.max[0] == pytest.approx((times.count - 1) / FPS)


def test_mismatched_agents_raise_and_leave_no_file(crowd, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    _, agents, bound = crowd
    short = agents[1].motion
    cut = Motion(short.skeleton, short.rotations[:5], short.root_positions[:5], FPS)
    bad = [agents[0], CrowdAgent(cut, 1.8, np.ones(5, bool), agents[1].colors)]
    out = tmp_path / "x.glb"
    with pytest.raises(JcrowdError, match="agent 1: expected"):
        write_crowd_glb(out, bad, bound.meshes[-1], bound.rest, FPS)
    assert not out.exists()
    with pytest.raises(JcrowdError, match="at least one agent"):
        write_crowd_glb(out, [], bound.meshes[-1], bound.rest, FPS)


def test_joint_world_positions_equal_the_fk(crowd) -> None:  # type: ignore[no-untyped-def]
    """Each joint node's world position, as a glTF client composes the nodes' animated TRS,
    equals jcrowd's FK of the same agent to 1 mm, for three agents at five frames."""
    path, agents, _ = crowd
    assert len(agents) == 3
    for frame in (3, 4, 11, 19, agents[0].motion.num_frames - 1):
        for k, a in enumerate(agents):
            _, want = forward_kinematics(
                a.motion.skeleton,
                np.asarray(a.motion.rotations[frame], np.float64),
                np.asarray(a.motion.root_positions[frame], np.float64),
            )
            got = _client_joints(path, k, frame)
            np.testing.assert_allclose(got, np.asarray(want), atol=1e-3)


def _client_joints(path: Path, agent: int, frame: int) -> np.ndarray:
    """Each of ``agent``'s joint nodes' world positions at ``frame``, as a client composes them."""
    doc, _, body, world = _client_pose(path, agent, frame)
    return np.stack([world(j)[:3, 3] for j in doc.skins[body.skin].joints])


@pytest.fixture(scope="module")
def validator(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The Khronos glTF validator (npm ``gltf-validator``), installed into a temporary folder.
    Skipped where node or npm is missing or the install fails, except under CI
    (``JCROWD_REQUIRE_DATA=1``), where that is a failure."""
    import os
    import shutil
    import subprocess

    required = os.environ.get("JCROWD_REQUIRE_DATA") == "1"
    if shutil.which("node") is None or shutil.which("npm") is None:
        if required:
            pytest.fail("node and npm are needed for the glTF validator test")
        pytest.skip("node/npm not installed: the Khronos glTF validator cannot run")
    folder = tmp_path_factory.mktemp("gltf_validator")
    done = subprocess.run(
        ["npm", "install", "--no-save", "--prefix", str(folder), "gltf-validator@2.0.0-dev.3.10"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if done.returncode != 0:
        if required:
            pytest.fail(f"npm install gltf-validator failed: {done.stderr[-500:]}")
        pytest.skip("npm could not install gltf-validator")
    return folder


def test_khronos_validator_finds_no_error_or_warning(crowd, validator: Path) -> None:  # type: ignore[no-untyped-def]
    import json
    import subprocess

    path, _, _ = crowd
    script = validator / "check.js"
    script.write_text(
        "const fs = require('fs'); const v = require('gltf-validator');\n"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2]))).then(r => "
        "console.log(JSON.stringify({e: r.issues.numErrors, w: r.issues.numWarnings, "
        "m: r.issues.messages.slice(0, 5).map(x => x.code + ' ' + x.pointer)})));\n"
    )
    out = subprocess.run(
        ["node", str(script), str(path)], capture_output=True, text=True, cwd=validator, timeout=120
    )
    report = json.loads(out.stdout)
    assert report["e"] == 0 and report["w"] == 0, report["m"]
