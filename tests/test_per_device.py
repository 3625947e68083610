"""The step split over several devices (``jcrowd.crowd.devices.split_step``).

Oracle: the split step on ``K`` devices equals the one-device step run on each device's block
of agents (agents ``k, k + K, …``: :func:`~jcrowd.crowd.devices.agent_order`) separately with
:func:`~jcrowd.crowd.devices.per_device_config`'s share of the budget, the blocks' frames joined
with agent ids and the counters summed — including when the budget binds. When it does not bind, it
also equals the one-device step on the whole crowd. Both sides run in one child Python on 2 CPU
devices (tests/on_devices.py: the one-device side is the one-device process's program, run on
the first device).

Tolerance 1e-5 (m, and aligned frames for τ): the same float32 program per agent; XLA may
fuse or order a block's arithmetic differently from the whole crowd's.
"""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from on_devices import run_child

from jcrowd.crowd import StepConfig, agent_order, in_agent_order, per_device_config

SCENE = """
model = "default"
seed = 5
duration = 10.0
fps = 30
[ground]
center = [0, 0]
size = [200, 200]
[camera]
eye = [0, 1.7, -20]
target = [0, 1.0, 0]
fov = 60
[[groups]]
name = "walkers"
count = 48
speed = [1.1, 1.4]
spawn = { shape = "rect", center = [0, 20], size = [40, 40] }
path = { waypoints = [[0, 60], [60, 60]], loop = false }
"""


def _run(reference: str, caps: list[int] | None = None, scene: str = SCENE) -> dict:
    """The split over 2 devices and ``reference`` (``whole`` or ``blocks``) on one device, in
    one child process (:func:`on_devices.per_device_task`)."""
    return run_child("per_device", 2, reference, json.dumps(caps or []), stdin=scene)


def _same(a: dict, b: dict) -> None:
    np.testing.assert_allclose(a["x"], b["x"], atol=1e-5)
    np.testing.assert_allclose(a["tau"], b["tau"], atol=1e-5)
    assert a["level"] == b["level"] and a["dots"] == b["dots"]
    assert (a["overflow"], a["deferred"]) == (b["overflow"], b["deferred"])
    assert a["points"].keys() == b["points"].keys()
    for k, (lv, p) in a["points"].items():
        assert b["points"][k][0] == lv
        np.testing.assert_allclose(p, b["points"][k][1], atol=1e-5)


@pytest.mark.slow
def test_split_equals_blocks_when_the_budget_binds() -> None:
    """With far fewer near slots than agents (overflow > 0), the split step on 2 devices equals
    each device's block stepped alone with its share of the budget: same levels, dots,
    counters and drawn agents, positions, phases and points to 1e-5; every placed agent is
    drawn once."""
    caps = [2, 2, 48]  # far fewer near slots than the 48 agents 0–40 m away want
    out = _run("blocks", caps)
    split, blocks = out["split"], out["reference"]
    assert out["devices"] == 2 and out["shards"] == 2
    assert split["overflow"] > 0  # the case this test is for
    _same(split, blocks)
    levels = np.asarray(split["level"])
    shown = sum(1 for lv, _ in split["points"].values())
    assert shown == int((levels < len(caps)).sum())  # every placed agent is drawn once


@pytest.mark.slow
def test_split_equals_whole_crowd_when_nothing_overflows() -> None:
    """With the scenario's capacities (nothing overflows on one device) the split step on 2
    devices equals the whole crowd on one device, as :func:`_same` compares."""
    out = _run("whole")
    split, whole = out["split"], out["reference"]
    assert out["devices"] == 2 and out["shards"] == 2
    assert whole["overflow"] == 0
    _same(split, whole)


# Two groups spawned one after the other: agents 0–199 near the camera, 200–399 far from it.
# Split in contiguous blocks, every near agent would sit on device 0.
GROUPED = """
model = "default"
seed = 9
duration = 10.0
fps = 30
[ground]
center = [0, 0]
size = [400, 400]
[camera]
eye = [0, 1.7, -20]
target = [0, 1.0, 0]
fov = 60
[[groups]]
name = "near"
count = 200
spawn = { shape = "rect", center = [0, 0], size = [16, 8] }
path = { waypoints = [[0, 150]], loop = false }
[[groups]]
name = "far"
count = 200
spawn = { shape = "rect", center = [0, 140], size = [16, 8] }
path = { waypoints = [[0, 190]], loop = false }
"""


@pytest.mark.slow
def test_grouped_near_agents_fill_the_near_levels_as_on_one_device() -> None:
    """With agents interleaved over the devices, each device's share of level 0 serves near
    agents: 100 level-0 slots, 200 near agents — one device places 100 at level 0, two devices
    (64 slots each: a share is at least one 64-slot chunk) place 128, all near agents. In
    contiguous blocks all 200 near agents would sit on device 0, which would place 64."""
    caps = [100, 100, 400]
    out = _run("whole", caps, GROUPED)
    split, whole = out["split"], out["reference"]
    assert out["devices"] == 2 and out["shards"] == 2
    level0 = [sum(1 for v in run["level"] if v == 0) for run in (split, whole)]
    assert level0 == [128, 100]
    assert {int(k) for k, (lv, _) in split["points"].items() if lv == 0} <= set(range(200))


@given(st.integers(1, 40), st.integers(1, 6))
def test_agent_order_interleaves_and_in_agent_order_inverts(per: int, devices: int) -> None:
    n = per * devices
    order = agent_order(n, devices)
    assert sorted(order.tolist()) == list(range(n))  # a permutation
    for k in range(devices):  # device k's block: agents k, k + K, ...
        assert order[k * per : (k + 1) * per].tolist() == list(range(k, n, devices))
    placed = np.arange(n)[order] * 10  # a per-agent array as shard_state lays it out
    layout = SimpleNamespace(interleave=devices)
    np.testing.assert_array_equal(in_agent_order(placed, layout), np.arange(n) * 10)  # type: ignore[arg-type]


@given(
    st.lists(st.integers(1, 100_000), min_size=1, max_size=7),
    st.integers(0, 10_000),
    st.integers(0, 10_000),
    st.integers(1, 16),
)
def test_per_device_config_covers_the_budget(
    caps: list[int], refresh: int, krige: int, devices: int
) -> None:
    config = StepConfig(
        capacities=tuple(caps),
        thresholds=(30.0,) * (len(caps) - 1),
        refresh=refresh,
        krige_budget=krige,
    )
    local = per_device_config(config, devices)
    for whole, share in zip(config.capacities, local.capacities, strict=True):
        assert share * devices >= whole  # never less room in all than on one device
        assert min(whole, config.chunk) <= share <= whole
        assert share * devices < whole + devices or share == min(whole, config.chunk)
    assert local.refresh * devices >= refresh and local.krige_budget * devices >= krige
    assert (local.refresh == 0) == (refresh == 0)  # 0 stays "automatic", from the block's N
    assert per_device_config(config, 1) == config
    assert replace(local, capacities=config.capacities, refresh=refresh, krige_budget=krige) == (
        config
    )
