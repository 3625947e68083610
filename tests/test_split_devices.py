"""A crowd split over several devices equals the whole crowd on one device, scene by scene.

Oracle: the one-device program on the same start — ``split_pedestrian_step`` over the first
device alone, and ``Simulation.compiled()`` built as in a one-device process (a plain ``jit``
of the step) — run in the same child Python as the split (``tests/on_devices.py``,
:func:`~on_devices.run_child`: one process per case). Each device steps its own block of
agents and sees its neighbours on the other devices through an all-gather (positions, radii,
alive flags; with anticipation the velocities too).

Tolerances are per case (:data:`CASES`): the split runs the same float32 program per agent,
but XLA may order a block's sums differently from the whole crowd's, and many steps of
avoidance let a 1e-6 m difference grow; counts, ids and flags are compared exactly. The
per-device LOD budget is checked against blocks run alone in tests/test_per_device.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest
from on_devices import run_child
from test_crowd import SCENE as CROWD_SCENE
from test_pool import SCENE as POOL_SCENE
from test_steering import COUNTERFLOW, PILLAR


@dataclass(frozen=True)
class Case:
    """One scene split over ``devices``: the child task and its input, what must be equal
    (``exact``) and what equal to ``close`` (key → absolute tolerance, m)."""

    task: str
    args: tuple[str, ...]
    devices: int
    exact: tuple[str, ...]
    close: dict[str, float] = field(default_factory=dict)
    stdin: str | None = None
    why: str = ""


CASES = {
    "pedestrians-plain": Case(
        "pedestrians",
        ("plain",),
        2,
        exact=("left", "alive"),
        close={"pos": 1e-4},
        why="split_pedestrian_step (blocks of 20) on a jammed bottleneck: same agents out at "
        "the same steps, positions to 1e-4 m after 200 steps (float32 sums in another "
        "order, grown over the steps)",
    ),
    "pedestrians-anticipating": Case(
        "pedestrians",
        ("anticipating",),
        2,
        exact=("left", "alive"),
        close={"pos": 1e-4, "heading": 1e-3},
        why="as plain, the neighbours' velocities also through the all-gather, bodies whose "
        "heading binds their speed (back_share 0.5) and the standing rule on: headings to "
        "1e-3 rad",
    ),
    "crowd-sources": Case(
        "crowd",
        ("all",),
        2,
        exact=("agent", "alive"),
        close={"x": 1e-4, "z": 1e-4},
        stdin=POOL_SCENE.format(duration=8, avoid="true", count=4),
        why="the crowd step with sources (tests/test_pool.py): each device fills its own "
        "block's slots; same slots, agents and positions to 1e-4 m after 80 avoiding steps",
    ),
    "crowd-avoidance": Case(
        "crowd",
        ("40",),
        2,
        exact=(),
        close={"x": 1e-4, "z": 1e-4},
        stdin=COUNTERFLOW.format(avoid="true", model="anticipation") + PILLAR,
        why="the crowd step with avoidance (tests/test_steering.py), anticipation model "
        "(it gathers positions and velocities); a pillar between the groups puts the "
        "scene's navigation fields and walls under the split: same crowd to 1e-4 m after 40 "
        "steps. The collision-free speed model's gather is the pedestrian cases'",
    ),
    "crowd-four-devices": Case(
        "crowd",
        ("5",),
        4,
        exact=(),
        close={"position": 1e-5, "tau": 1e-5},
        stdin=CROWD_SCENE.format(count=32),
        why="the crowd step without dynamics (tests/test_crowd.py) over 4 devices: positions "
        "and clip phases to 1e-5 after 5 steps (the same float32 program partitioned, "
        "reductions may reorder)",
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_split_over_devices_equals_one_device(name: str) -> None:
    """Every case: the child has the case's devices, the split state ends on all of them and
    the one-device state on one; ``exact`` keys are equal, ``close`` keys within their
    tolerance (``CASES[name].why`` says why each). The crowd step also refuses a state split in
    contiguous blocks by hand (its agent ids assume ``shard_state``'s interleaved blocks), and
    in the pedestrian cases agents do leave (the counts compared are not all zero)."""
    case = CASES[name]
    out = run_child(case.task, case.devices, *case.args, stdin=case.stdin)
    split, one = out["split"], out["one"]
    assert out["devices"] == case.devices
    assert split["shards"] == case.devices and one["shards"] == 1
    for key in case.exact:
        assert split[key] == one[key], key
    for key, atol in case.close.items():
        np.testing.assert_allclose(split[key], one[key], atol=atol, err_msg=key)
    if case.task == "crowd":
        assert "shard_state" in (out["refused"] or ""), out["refused"]
    else:
        assert sum(one["left"]) > 0
