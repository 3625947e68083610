"""An agent's ``height`` is the stature of the body drawn for it (issue 39 item 3): the crowd
step scales the skeleton by ``height / body_height``, with ``body_height`` the shipped body's
rest height on the model's 1 m skeleton.

Reading taken: stature is the standing height (sole to crown, upright). A walker's drawn body
is lower than that (bent knees, forward lean of the captured gait): over a cycle its top reaches
0.977–0.982 × ``height`` here, and it can never reach above it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jcrowd import load_default_model
from jcrowd.crowd import prepare
from jcrowd.crowd.bodies import skinned_levels
from jcrowd.io import with_body_height
from jcrowd.io.body_file import load_body
from jcrowd.io.resources import body_path
from jcrowd.motion.body import bind_body
from jcrowd.motion.clip import rest_forward
from jcrowd.motion.rotation import quat_from_matrix
from jcrowd.motion.skeleton import rest_positions
from jcrowd.motion.skinning import frames_from_points, skin
from jcrowd.scenario import parse_scenario

SCENE = """
model = "default"
seed = 5
duration = 3.0
fps = 30
[ground]
center = [0, 0]
size = [40, 40]
[camera]
eye = [0, 1.7, -6]
target = [0, 1.0, 0]
fov = 60
[lod]
capacities = [4, 1, 1, 1, 1, 1]
[[groups]]
name = "walkers"
count = 4
speed = [1.2, 1.4]
height = [1.55, 1.95]
spawn = { shape = "rect", center = [0, 0], size = [3, 3] }
path = { waypoints = [[0, 15], [15, 15]], loop = false }
"""


@pytest.fixture(scope="module")
def model():  # type: ignore[no-untyped-def]
    return load_default_model()


@pytest.fixture(scope="module")
def bound(model):  # type: ignore[no-untyped-def]
    return bind_body(load_body(body_path()), model.skeleton, rest_forward(model.skeleton))


def test_loading_measures_the_body_on_the_skeleton(model, bound) -> None:  # type: ignore[no-untyped-def]
    """``body_height`` is the bound mesh's rest extent along Y (a loop over every vertex of
    every resolution: the finest is what is measured, the others agree within 1 %), taller than
    the skeleton's joints and End Sites (1 m); a model fitted in memory keeps 1.0 until bound."""
    tops = [
        max(float(v[1]) for v in m.vertices) - min(float(v[1]) for v in m.vertices)
        for m in bound.meshes
    ]
    assert model.body_height == pytest.approx(tops[0], rel=1e-6)
    assert all(abs(t / tops[0] - 1) < 0.01 for t in tops)
    joints, ends = rest_positions(model.skeleton)
    span = np.ptp(np.concatenate([joints[:, 1], ends[:, 1]]))
    assert span == pytest.approx(1.0, abs=1e-4)  # the model's skeleton is 1 m tall
    assert 1.05 < model.body_height < 1.3  # crown above the top joint, soles below the ankles
    bare = dataclasses.replace(model, body_height=1.0)
    assert with_body_height(bare).body_height == model.body_height


def test_a_walker_is_drawn_as_tall_as_its_height(model, bound) -> None:  # type: ignore[no-untyped-def]
    """Agents of 1.55–1.95 m walk through the compiled step; each frame's level-0 points are
    skinned with the finest mesh as the renderer skins them (:func:`frames_from_points`,
    :func:`skin`, float64) at the skeleton scale the renderer gets. Over 1.5 s (more than a
    cycle) the body's extent along Y peaks within 3 % below the agent's ``height`` and never
    above it; and in the rest pose at the same scale it is ``height`` itself. Without the
    division by ``body_height`` the body is 15 % taller; applied twice, 13 % shorter."""
    sim, state = prepare(parse_scenario(SCENE, "stature.toml"), model)
    scale = np.asarray(sim.spawn.height, np.float64) / model.body_height
    np.testing.assert_allclose(np.asarray(state.height), scale, rtol=1e-6)
    level = skinned_levels(model, bound, sim.crowd.decoders)[0]
    mesh = level.meshes[0]
    step = sim.compiled()
    tallest = np.zeros(sim.num_agents)
    for f in range(45):
        state, frame = step(state, sim.view_at(f * sim.dt), sim.dt)
        slots, valid = np.asarray(frame.slots[0]), np.asarray(frame.valid[0])
        points = np.asarray(frame.points[0], np.float64)
        for s in np.flatnonzero(valid):
            a = int(slots[s])
            rot, pos = frames_from_points(level, points[s : s + 1], scale[a : a + 1])
            v = skin(mesh.bones, mesh.weights, mesh.offsets, quat_from_matrix(rot), pos, scale[a])
            tallest[a] = max(tallest[a], float(np.ptp(v[0, :, 1])))
    ratio = tallest / np.asarray(sim.spawn.height)
    assert ((ratio > 0.97) & (ratio <= 1.0)).all(), ratio
    rest = np.asarray(bound.meshes[0].vertices, np.float64)[None] * scale[:, None, None]
    np.testing.assert_allclose(np.ptp(rest[..., 1], axis=1), sim.spawn.height, rtol=1e-5)
