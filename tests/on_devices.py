"""Child Pythons on K CPU devices, and what they run: the multi-device tests' one helper.

The device count is fixed when JAX starts (``XLA_FLAGS``), so a test of the crowd split over K
devices runs in a child Python started with K CPU devices (:func:`start_python`,
:func:`finish`; the child's stderr is shown when it fails). The child computes both sides of
the comparison in one process (:func:`run_child`): the crowd split over the K devices, and the
whole crowd on one device — the one-device program itself, compiled by the same call
(``Simulation.compiled()``, ``split_pedestrian_step``) with the process's devices cut to the
first (:func:`one_device`), and run on that device. That is the program a one-device process
runs, on the same device, so it computes the same numbers bit for bit; nothing compared depends
on the process: a state's layout over devices (``CrowdState.interleave``) is the state's own. So
a comparison costs one jax import, one scenario ``prepare`` and the two compilations, not a
process per side. (``jcrowd run`` over two processes is compared with one process by running
the command itself: tests/test_crowd.py starts those through :func:`start_python`.)

The child side (from :func:`main` on) imports jax only when it runs: the test process
imports this module for the parent side alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

TESTS = Path(__file__).resolve().parent
TIMEOUT_S = 600


# ------------------------------------------------------------------------------ parent side


def device_env(devices: int, **env_vars: str) -> dict[str, str]:
    """This process's environment for a child on ``devices`` CPU devices (``JAX_PLATFORMS=cpu``:
    forced host devices are CPU devices), with ``env_vars`` set."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
    env.update(env_vars)
    return env


def start_python(args: Sequence[str], devices: int, **env_vars: str) -> subprocess.Popen[str]:
    """``python *args`` on ``devices`` CPU devices, its stdin, stdout and stderr piped."""
    return subprocess.Popen(
        [sys.executable, *args],
        env=device_env(devices, **env_vars),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def finish(proc: subprocess.Popen[str], stdin: str | None = None, what: str = "") -> str:
    """Feed ``stdin`` to a child of :func:`start_python`, wait for it (``TIMEOUT_S``; killed
    after) and return its stdout; a failed child fails the test with its stderr's tail."""
    try:
        out, err = proc.communicate(stdin, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    assert proc.returncode == 0, f"{what or proc.args}: exit {proc.returncode}\n{err[-4000:]}"
    return out


def last_json(stdout: str) -> dict[str, Any]:
    """The JSON object on the last line of a child's stdout."""
    return json.loads(stdout.strip().splitlines()[-1])


def run_on_devices(
    script: str, devices: int, stdin: str | None = None, **env_vars: str
) -> dict[str, Any]:
    """``python -c script`` on ``devices`` CPU devices; the JSON object it prints last."""
    proc = start_python(["-c", script], devices, **env_vars)
    return last_json(finish(proc, stdin, f"{devices} device(s)"))


def run_child(task: str, devices: int, *args: str, stdin: str | None = None) -> dict[str, Any]:
    """One of this module's child tasks (``CHILD_TASKS``) on ``devices`` CPU devices, with
    ``args`` (strings) and ``stdin``; the JSON object it returns."""
    boot = f"import sys; sys.path.insert(0, {str(TESTS)!r}); import on_devices; on_devices.main()"
    proc = start_python(["-c", boot, task, *args], devices)
    return last_json(finish(proc, stdin, f"{task} {' '.join(args)} on {devices} device(s)"))


# ------------------------------------------------------------------------------ child side


def main() -> None:
    """Run ``CHILD_TASKS[argv[1]](*argv[2:])`` and print its result as one JSON line."""
    print(json.dumps(CHILD_TASKS[sys.argv[1]](*sys.argv[2:])))


@contextlib.contextmanager
def one_device() -> Iterator[Any]:
    """Inside: ``jax.devices()`` is the first device alone, so the library builds what it builds
    in a one-device process (``Simulation.compiled()`` a plain ``jit`` of the step,
    ``Simulation.view_at`` arrays left uncommitted on the default device, ``shard_state`` the
    state unchanged). Yields that device. Child processes only."""
    import jax

    every = jax.devices

    def first(*args: Any, **kwargs: Any) -> list[Any]:
        return every(*args, **kwargs)[:1]

    jax.devices = first
    try:
        yield every()[0]
    finally:
        jax.devices = every


def _steps(fn: Any, sim: Any, state: Any, steps: int) -> tuple[Any, Any]:
    """``steps`` calls of a compiled crowd step from ``state``; the last state and frame."""
    frame = None
    for i in range(steps):
        state, frame = fn(state, sim.view_at(i * sim.dt), sim.dt)
    return state, frame


def _refused(fn: Any, sim: Any, state: Any) -> str | None:
    """The error the split step ``fn`` gives a state split in contiguous blocks by hand (not
    by ``shard_state``, whose interleaved blocks the step's agent ids assume); ``None`` on one
    device or if it runs."""
    import jax
    import numpy as np
    from jax.sharding import Mesh, NamedSharding
    from jax.sharding import PartitionSpec as P

    from jcrowd.errors import JcrowdError

    if len(jax.devices()) == 1:
        return None
    mesh = Mesh(np.array(jax.devices()), ("agents",))
    by_hand = jax.tree.map(lambda x: jax.device_put(x, NamedSharding(mesh, P("agents"))), state)
    try:
        fn(by_hand, sim.view_at(0.0), sim.dt)
    except JcrowdError as e:
        return str(e)
    return None


def _prepared(caps: Sequence[int] = ()) -> tuple[Any, Any]:
    """The scenario on stdin prepared with the step's test model (``helpers.step_model``: three
    of the shipped model's levels; ``caps``: LOD capacities, one per level)."""
    from helpers import step_model

    from jcrowd.crowd import prepare
    from jcrowd.scenario import parse_scenario

    sim, state = prepare(parse_scenario(sys.stdin.read(), "t.toml"), step_model())
    if caps:
        sim = dataclasses.replace(sim, config=dataclasses.replace(sim.config, capacities=caps))
    return sim, state


def crowd_task(steps: str) -> dict[str, Any]:
    """The crowd step of the scenario on stdin, ``steps`` steps (``all``: the scenario's), split
    over every device (``shard_state``, ``Simulation.compiled()``) and whole on one device.

    Returns ``devices``; ``refused`` (:func:`_refused`); and per side (``split``, ``one``) the
    per-agent ``x z position tau agent alive`` in agent order and ``shards`` (devices holding
    the final state).
    """
    import jax

    from jcrowd.crowd import in_agent_order, shard_state

    sim, state = _prepared()
    n = sim.steps if steps == "all" else int(steps)

    def record(state: Any) -> dict[str, Any]:
        keys = ("x", "z", "position", "tau", "agent", "alive")
        out = {k: in_agent_order(getattr(state, k), state).tolist() for k in keys}
        return {**out, "shards": len(state.x.sharding.device_set)}

    fn = sim.compiled()
    refused = _refused(fn, sim, state)
    split, _ = _steps(fn, sim, shard_state(state), n)
    with one_device():
        whole = dataclasses.replace(sim)  # a fresh Simulation: its cached views are built here
        one, _ = _steps(whole.compiled(), whole, state, n)
    return {
        "devices": len(jax.devices()),
        "refused": refused,
        "split": record(split),
        "one": record(one),
    }


def pedestrians_task(model: str) -> dict[str, Any]:
    """``split_pedestrian_step`` over every device and over the first alone, 200 steps of 40
    agents leaving a 6 m room through a 1 m corridor (``model``: ``plain``, the collision-free
    speed model; ``anticipating``, with velocities and body headings). Per side (``split``,
    ``one``): final positions, alive flags (and headings), the agents out at each step
    (``left``) and ``shards``."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import shapely

    from jcrowd.pedestrians import (
        AvoidanceParams,
        Pedestrians,
        build_world,
        split_pedestrian_step,
    )

    room = shapely.box(0.0, 0.0, 6.0, 6.0)
    area = shapely.union(room, shapely.box(2.5, 6.0 - 1e-9, 3.5, 9.0))
    world = build_world(area, [shapely.box(2.5, 8.5, 3.5, 9.0)])
    xs = np.arange(0.5, 5.5, 0.6)
    pts = np.stack(np.meshgrid(xs, np.arange(0.5, 5.0, 0.6)), -1).reshape(-1, 2)[:40]
    n = len(pts)
    anticipating = model == "anticipating"
    velocity = jnp.zeros((n, 2), jnp.float32) if anticipating else None
    start = Pedestrians(
        jnp.asarray(pts, jnp.float32),
        jnp.zeros(n, jnp.int32),
        jnp.full(n, 1.34, jnp.float32),
        jnp.full(n, 0.2, jnp.float32),
        jnp.ones(n, bool),
        velocity,
        # The anticipating bodies have a heading that binds their speed (back_share < 1), and
        # stand where desire and repulsion cancel (the standing rule on).
        heading=jnp.linspace(-3.0, 3.0, n, dtype=jnp.float32) if anticipating else None,
    )
    params = AvoidanceParams(back_share=0.5, stand_drive=0.7) if anticipating else AvoidanceParams()
    out: dict[str, Any] = {"devices": len(jax.devices()), "refused": None}
    for side, devices in (("split", jax.devices()), ("one", jax.devices()[:1])):
        step, peds, left = split_pedestrian_step(devices), start, []
        for _ in range(200):
            peds, info = step(params, world, peds, jnp.float32(1 / 30))
            left.append(int(np.sum(np.asarray(info.arrived))))
        out[side] = {
            "pos": np.asarray(peds.position).tolist(),
            "alive": np.asarray(peds.alive).tolist(),
            "left": left,
            "shards": len(peds.position.sharding.device_set),
        }
        if peds.heading is not None:
            out[side]["heading"] = np.asarray(peds.heading).tolist()
    return out


def per_device_task(reference: str, caps: str) -> dict[str, Any]:
    """6 steps of the scenario on stdin split over 2 devices and, as ``reference`` says, on one
    device: ``whole`` (the whole crowd) or ``blocks`` (each device's block of agents alone with
    :func:`~jcrowd.crowd.devices.per_device_config`'s share of the budget, the blocks' records
    joined: per-agent values by agent id, the counters summed). ``caps`` (JSON list, ``[]``:
    the scenario's): LOD capacities.

    Each record: per-agent ``x tau level dots`` in agent order, ``overflow``, ``deferred``, and
    ``points`` (agent id → [level, drawn points]). Also ``devices`` and ``shards``.
    """
    import jax
    import numpy as np

    from jcrowd.crowd import in_agent_order, per_device_config, shard_state

    sim, state = _prepared(tuple(json.loads(caps)))
    n, steps, per_agent = state.num_agents, 6, ("x", "tau", "level", "dots")

    def record(state: Any, frame: Any, ids: np.ndarray, n_total: int) -> dict[str, Any]:
        # Per-agent arrays in agent order (ids[i]: the agent at row i), points keyed by agent id.
        pts = {}
        for lv, (s, ok, p) in enumerate(zip(frame.slots, frame.valid, frame.points, strict=True)):
            s, ok, p = np.asarray(s), np.asarray(ok), np.asarray(p)
            assert (s[~ok] == n_total).all()
            for i in np.flatnonzero(ok):
                pts[str(int(ids[int(s[i])]))] = [lv, p[i].tolist()]
        per = {"x": state.x, "tau": state.tau, "level": frame.level, "dots": frame.dots}
        return {
            **{k: in_agent_order(v, state).tolist() for k, v in per.items()},
            "overflow": int(frame.overflow),
            "deferred": int(frame.deferred),
            "points": pts,
        }

    everyone = np.arange(n)
    split_state, frame = _steps(sim.compiled(), sim, shard_state(state), steps)
    out = {
        "devices": len(jax.devices()),
        "shards": len(split_state.x.sharding.device_set),
        "split": record(split_state, frame, everyone, n),
    }
    with one_device():
        if reference == "whole":
            whole = dataclasses.replace(sim)  # a fresh Simulation: its views are built here
            out["reference"] = record(*_steps(whole.compiled(), whole, state, steps), everyone, n)
            return out
        assert reference == "blocks", reference
        sim_b = dataclasses.replace(sim, config=per_device_config(sim.config, 2))
        fn = sim_b.compiled()
        joined: dict[str, Any] = {k: [None] * n for k in per_agent}
        joined.update(overflow=0, deferred=0, points={})
        for b in range(2):
            ids = everyone[b::2]  # agents b, b + 2, ... (agent_order)
            block = jax.tree.map(lambda x: x[ids], state)  # noqa: B023 (used at once)
            part = record(*_steps(fn, sim_b, block, steps), ids, n // 2)
            for k in per_agent:
                for i, v in zip(ids, part[k], strict=True):
                    joined[k][i] = v
            joined["overflow"] += part["overflow"]
            joined["deferred"] += part["deferred"]
            joined["points"].update(part["points"])
        out["reference"] = joined
    return out


def _kept(state: Any, view: Any, frame: Any) -> dict[str, Any]:
    """What the K-step tests record of a frame: a field of the state at the frame's start, the
    camera, and every array of the frame."""
    return {"x": state.x, "eye": view.eye, "frame": frame}


def single_and_k_steps(sim: Any, state: Any, steps: int, chunk: int) -> dict[str, Any]:
    """``steps`` frames of ``sim`` from ``state`` (as placed: one device or split) by single
    compiled steps and by :meth:`~jcrowd.crowd.simulate.Simulation.compiled_steps` with
    ``chunk`` frames per call (a last call with fewer). Returns both sides' per-frame records
    (:func:`_kept`, host arrays stacked over frames) and final states, and the K-step
    function's compilations and the devices holding its final state (``k_shards``)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jcrowd.crowd.devices import on_all_devices

    single = sim.compiled()
    s, rows = jax.tree.map(jnp.copy, state), []
    for i in range(steps):
        view = sim.view_at(i * sim.dt)
        before = jax.device_get(s.x)  # the step donates ``s``
        s, frame = single(s, view, sim.dt_array)
        rows.append({"x": before, **jax.device_get({"eye": view.eye, "frame": frame})})
    one = {k: np.stack([r[k] for r in rows]) for k in ("x", "eye")}
    one["frame"] = jax.tree.map(lambda *a: np.stack(a), *[r["frame"] for r in rows])
    many = sim.compiled_steps(chunk, _kept)
    k, parts = jax.tree.map(jnp.copy, state), []
    for start in range(0, steps, chunk):
        n = min(chunk, steps - start)
        count = on_all_devices(jnp.asarray(n, jnp.int32))
        k, rec = many(k, sim.views(start, chunk), sim.dt_array, count)
        parts.append(jax.tree.map(lambda a, n=n: np.asarray(a)[:n], jax.device_get(rec)))
    k_rec = jax.tree.map(lambda *a: np.concatenate(a), *parts)
    return {
        "single": (one, jax.device_get(s)),
        "k": (k_rec, jax.device_get(k)),
        "k_shards": len(k.x.sharding.device_set),
        "compilations": int(many._cache_size()),
    }


def _same(a: Any, b: Any) -> bool:
    """Two pytrees of host arrays equal bit for bit (NaN equal to NaN)."""
    import jax
    import numpy as np

    pairs = zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    return all(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True) for x, y in pairs)


def steps_task(steps: str, chunk: str) -> dict[str, Any]:
    """The scenario on stdin split over every device: ``steps`` frames by single steps and by
    K-step calls of ``chunk`` frames (:func:`single_and_k_steps`). Returns ``devices``,
    ``shards`` (devices holding the K-step state), whether the records and the final states
    are equal bit for bit, and the K-step function's compilations."""
    import jax

    from jcrowd.crowd import shard_state

    sim, state = _prepared()
    out = single_and_k_steps(sim, shard_state(state), int(steps), int(chunk))
    (rec1, state1), (reck, statek) = out["single"], out["k"]
    return {
        "devices": len(jax.devices()),
        "shards": out["k_shards"],
        "records_equal": _same(rec1, reck),
        "states_equal": _same(state1, statek),
        "compilations": out["compilations"],
    }


CHILD_TASKS = {
    "crowd": crowd_task,
    "pedestrians": pedestrians_task,
    "per_device": per_device_task,
    "steps": steps_task,
}
