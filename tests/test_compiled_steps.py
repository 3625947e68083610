"""Many frames per compiled call (``Simulation.compiled_steps``) equal single steps, bit for bit.

Oracle: the single compiled step (``Simulation.compiled``), called once per frame with the
camera at that frame, and the state read before each call. The K-step side runs the same
frames in calls of ``K`` (a last call with fewer), its camera from ``Simulation.views``. A
scene with every stage of the step on: a moving camera (levels change), crowd dynamics round a
pillar (navigation fields, walls), and sources filling a pool of slots. Split over two devices
the same comparison runs in a child Python (``tests/on_devices.py``).

Bugs caught: a frame stepped with another frame's camera, a record of the state after the step
instead of before, a call that runs ``K`` frames when fewer were asked, a state not carried
between calls, a recompile for a shorter call.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from on_devices import run_child, single_and_k_steps

from jcrowd.crowd import prepare
from jcrowd.scenario import parse_scenario

SCENE = """
seed = 4
duration = 4.0
fps = 10
[ground]
center = [0, 0]
size = [40, 20]
[[camera.keys]]
time = 0.0
eye = [-12, 1.7, -6]
target = [0, 1.0, 0]
[[camera.keys]]
time = 2.0
eye = [6, 6, -18]
target = [0, 0, 0]
[lod]
thresholds = [6, 12]
[dynamics]
avoid = true
[[obstacles]]
shape = "circle"
center = [0, 0.5]
radius = 1.2
[[groups]]
name = "crossers"
count = 6
speed = [1.3, 1.5]
spawn = { shape = "rect", center = [-8, 0], size = [3, 6] }
goal = { shape = "rect", center = [15, 0], size = [2, 6] }
[[sources]]
group = "crossers"
rate = 4.0
start = 0.5
count = 6
region = { shape = "rect", center = [-12, 0], size = [2, 6] }
"""

FRAMES, CHUNK = 23, 10


def _same(a, b, what):
    for (path, x), y in zip(
        jax.tree_util.tree_leaves_with_path(a), jax.tree.leaves(b), strict=True
    ):
        np.testing.assert_array_equal(
            np.asarray(x), np.asarray(y), err_msg=f"{what}{jax.tree_util.keystr(path)}"
        )


def test_k_steps_equal_single_steps_on_one_device(step_model):
    sim, state = prepare(parse_scenario(SCENE, "t.toml"), step_model)
    assert sim.pool is not None and sim.world is not None  # sources and walls in the step
    out = single_and_k_steps(sim, state, FRAMES, CHUNK)
    (rec1, state1), (reck, statek) = out["single"], out["k"]
    _same(rec1, reck, "record")
    _same(state1, statek, "state")
    assert out["compilations"] == 1  # calls of 10, 10 and 3 frames: one program
    levels = rec1["frame"].level
    assert len(np.unique(levels[levels < 3])) >= 2  # bodies at two levels of the three
    assert np.ptp(rec1["eye"][:, 0]) > 10  # and each frame saw its own camera
    assert np.asarray(statek.alive).sum() > 6  # sources added agents


@pytest.mark.slow
def test_k_steps_equal_single_steps_split_over_two_devices():
    out = run_child("steps", 2, str(FRAMES), str(CHUNK), stdin=SCENE)
    assert out["devices"] == 2 and out["shards"] == 2
    assert out["records_equal"] and out["states_equal"]
    assert out["compilations"] == 1
