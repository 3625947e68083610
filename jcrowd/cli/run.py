"""``jcrowd run SCENARIO.toml``: simulate a crowd; record roots, visible joints or everything.

The steps are compiled once (``compile_s``), then run ``--steps`` times (or ``--seconds``;
default: the scenario's duration), ``frames_per_call`` (30, fewer for large records) per call
of :class:`jcrowd.cli.runloop.RunLoop`; ``ms_per_step_median`` is a call's time ÷ its frames.
``recompiles`` counts compilations after the first (0 is the contract); ``crowding_max`` the
most agents the crowd dynamics' neighbour grid could not hold in any step (0 without
``[dynamics] avoid``); ``unblended_changes`` the level changes shown at once because the
step's blend buckets were full (:mod:`jcrowd.crowd.level_blend`); ``spawned``, ``exited``
(reached a goal or the end of an open path and left) and ``alive_end`` count agents;
``agents`` is the number of slots (with ``[[sources]]``: the pool, :mod:`jcrowd.crowd.pool`),
and ``spawn_late`` the source agents due by the end that still wait for a free slot.

Recording (``--out run.npz``, written atomically):

- ``roots`` (default): per step and agent the root ``position (x, z)``, ``heading``, ``level``
  (``L`` = not synthesized: culled, or a dot), ``dots`` (in view but below ``lod.min_pixels``
  or beyond the budget: drawn at the root) and ``alive``; with ``[[sources]]`` the arrays are
  per slot, and ``agent`` says which agent each slot holds at each step (−1: none yet).
- ``visible``: also, per level, the slots' agent ids and joint/End Site positions
  (``points_l``: steps × capacity × points × 3).
- ``all``: also each agent's clip state (phase, controls of the current and next clip, whether
  a next clip is chosen) so ``jcrowd export`` can re-synthesize any agent at full detail.

``--cpu-devices K`` splits the crowd over K CPU devices (one per core is fastest; the agent
count must divide by K): each steps its own block of agents with 1/K of every LOD budget.

Several processes (``--coordinator HOST:PORT --num-processes N --process-id I``, one command
per process): JAX's multi-process runtime (``jax.distributed``; gloo collectives on CPU) joins
every process's devices into one mesh, the agent axis is split over it, each process feeds its
own block of agents, and process 0 writes the recording. Each process prints its own JSON.

Arrays are named ``position``, ``heading``, ``level``, ``dots``, ``alive``, ``slots_l``,
``valid_l``, ``points_l``, ``tau``, ``control``, ``control_next``, ``has_next``, ``stands``
(with the dynamics on: standing at a double-support phase), ``stride`` (the planted feet's
stride warp, :func:`jcrowd.motion.planting.warp_stride`) plus ``height``, ``group``, ``color``,
``parents`` (bones to draw), ``obstacles`` (scenarios with walls: their
prisms, :func:`jcrowd.render.meshes.prism_mesh`), ``eye``/``target`` per step and ``lens``
(fov, near, far) of the camera, ``fps`` and ``model`` (the model file used)."""

from __future__ import annotations

import argparse
import io
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "run", help="simulate a crowd scenario", description=__doc__
    )
    p.add_argument("scenario", help="a scenario file (TOML)")
    p.add_argument("--model", help="a model file (default: the scenario's, else the shipped one)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--steps", type=int, help="steps to run (default: the scenario's duration)")
    g.add_argument("--seconds", type=float, help="scenario seconds to run")
    p.add_argument("--record", choices=("roots", "visible", "all"), default="roots")
    p.add_argument("--out", help="write the recording here (.npz)")
    p.add_argument(
        "--cpu-devices",
        type=int,
        default=1,
        help="split the crowd over this many CPU devices, e.g. one per core (the agent count "
        "must divide by it; each device gets its share of the LOD budget)",
    )
    p.add_argument("--coordinator", help="HOST:PORT of process 0, for a run over several hosts")
    p.add_argument("--num-processes", type=int, default=1)
    p.add_argument("--process-id", type=int, default=0)
    return p


def init_distributed(coordinator: str, processes: int, process_id: int) -> None:
    """Join JAX's multi-process runtime (before any array exists); gloo collectives on CPU."""
    import jax

    from jcrowd.errors import JcrowdError

    if not 0 <= process_id < processes:
        raise JcrowdError(
            f"--process-id: expected 0..{processes - 1} for --num-processes {processes}, "
            f"found {process_id}"
        )
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(coordinator, processes, process_id)


def use_cpu_devices(count: int) -> None:
    """Ask XLA for ``count`` CPU devices (before JAX starts its backend; 1: leave as is).

    The crowd step runs one device's share of the agents per device
    (:func:`jcrowd.crowd.simulate.Simulation.compiled`); on CPU, XLA runs one step's kernels nearly
    one after the other, so a second device is what puts a second core to work
    (``bench/step.py --cpu-devices K`` times the step on K devices).
    """
    from jcrowd.errors import JcrowdError

    if count < 1:
        raise JcrowdError(f"--cpu-devices: expected a positive integer, found {count}")
    if count > 1:
        flag = f"--xla_force_host_platform_device_count={count}"
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {flag}".strip()


def run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.output import emit

    use_cpu_devices(args.cpu_devices)
    if args.coordinator:
        # Gloo logs its connections on the C-level stdout: fd 1 goes to stderr during the run,
        # so stdout still carries one JSON object.
        sys.stdout.flush()
        saved = os.dup(1)
        os.dup2(2, 1)
        try:
            init_distributed(args.coordinator, args.num_processes, args.process_id)
            result = _run(args)
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
    else:
        result = _run(args)
    emit(result, args.json, _print)
    return result


def _run(args: argparse.Namespace) -> dict[str, Any]:
    from jcrowd.cli.runloop import load_model
    from jcrowd.crowd.devices import shard_state
    from jcrowd.crowd.simulate import prepare
    from jcrowd.errors import JcrowdError
    from jcrowd.scenario.parse import load_scenario

    scenario = load_scenario(args.scenario)
    model, model_path = load_model(scenario, args.model)
    check_cpu_devices(args.cpu_devices)
    sim, state = prepare(scenario, model)
    state = shard_state(state)
    steps = sim.steps
    if args.steps is not None:
        steps = args.steps
    elif args.seconds is not None:
        steps = round(args.seconds * scenario.fps)
    if steps < 1:
        raise JcrowdError(f"run: expected at least one step, found {steps}")
    result, recording = simulate(sim, state, steps, args.record)
    result.update(scenario=str(args.scenario), model=model_path, record=args.record, out=None)
    result["devices"] = jax_device_count()
    if args.out:
        from jcrowd.crowd.synthesis import point_parents

        recording["model"] = np.asarray(model_path)
        recording["parents"] = np.asarray(point_parents(model), np.int32)
        if jax_process_index() == 0:  # one writer when several processes run one crowd
            result["out"] = str(save_recording(args.out, recording))
    return result


def check_cpu_devices(count: int) -> None:
    """``--cpu-devices`` took effect: JAX on CPU sees that many devices in this process (it does
    not when the backend had started before :func:`use_cpu_devices`, e.g. in a host program
    that used JAX first)."""
    import jax

    from jcrowd.errors import JcrowdError

    if count > 1 and jax.default_backend() == "cpu" and len(jax.local_devices()) != count:
        raise JcrowdError(
            f"--cpu-devices: expected {count} CPU devices, found {len(jax.local_devices())} (JAX "
            f"started before the option was read; set XLA_FLAGS="
            f"--xla_force_host_platform_device_count={count} before starting Python)"
        )


def jax_device_count() -> int:
    import jax

    return len(jax.devices())


def jax_process_index() -> int:
    import jax

    return jax.process_index()


def save_recording(path: str | Path, recording: dict[str, np.ndarray]) -> Path:
    """Write a recording as one ``.npz`` file, atomically."""
    from jcrowd.io.atomic import write_atomic

    buffer = io.BytesIO()
    np.savez_compressed(buffer, **recording)  # type: ignore[arg-type]  # numpy's stub: **kwds
    write_atomic(path, buffer.getvalue())
    return Path(path)


PER_AGENT = frozenset(
    (
        "position",
        "heading",
        "alive",
        "agent",
        "tau",
        "control",
        "control_next",
        "has_next",
        "stands",
        "stride",
        "level",
        "dots",
    )
)
"""Recorded arrays with one row per agent (the others are per camera or per bucket slot)."""


def _record_keys(sim: Any, record: str) -> list[str]:
    """The arrays recorded per step for ``--record``."""
    keys = ["position", "heading", "level", "dots", "alive", "eye", "target"]
    if record in ("visible", "all"):
        keys += [f"{k}_{lv}" for lv in range(len(sim.config.capacities)) for k in FRAME_KEYS]
    if record == "all":
        keys += ["tau", "control", "control_next", "has_next", "stands", "stride"]
    if sim.pool is not None:
        keys.append("agent")
    return keys


FRAME_KEYS = ("slots", "valid", "points")
"""A frame's per-level arrays, recorded with ``--record visible`` and ``all``."""


def _snapshot(sim: Any, record: str, state: Any, view: Any) -> dict[str, Any]:
    """What is recorded of the state at a step's start (traced, in the compiled steps)."""
    snapshot: dict[str, Any] = {
        "position": state.position,
        "heading": state.heading,
        "alive": state.alive,
        "eye": view.eye,
        "target": view.target,
    }
    if sim.pool is not None:
        snapshot["agent"] = state.agent
    if record == "all":
        control, _, _ = state.clip("current")
        control_next, _, _ = state.clip("next")
        snapshot.update(
            tau=state.tau,
            control=control,
            control_next=control_next,
            has_next=state.has_next,
            stands=state.stands,
            stride=state.stride,
        )
    return snapshot


def _frame_parts(frame: Any, record: str, nlev: int) -> dict[str, Any]:
    """What is recorded or counted of a step's frame."""
    parts = {
        "level": frame.level,
        "dots": frame.dots,
        "overflow": frame.overflow,
        "deferred": frame.deferred,
        "crowding": frame.crowding,
        "unblended": frame.unblended,
    }
    if record != "roots":
        parts.update(
            {f"{name}_{lv}": getattr(frame, name)[lv] for lv in range(nlev) for name in FRAME_KEYS}
        )
    return parts


def simulate(sim: Any, state: Any, steps: int, record: str) -> tuple[dict[str, Any], dict]:
    """Run ``steps`` steps with a progress bar; return the JSON summary and the recording."""
    from jcrowd.cli.runloop import RunLoop
    from jcrowd.crowd.devices import in_agent_order

    nlev = len(sim.config.capacities)

    def keep(state: Any, view: Any, frame: Any) -> dict[str, Any]:
        return {**_snapshot(sim, record, state, view), **_frame_parts(frame, record, nlev)}

    loop = RunLoop(sim, state, keep)
    rec: dict[str, list] = {k: [] for k in _record_keys(sim, record)}
    hist = np.zeros(nlev + 1, np.int64)
    counts = dict.fromkeys(("overflow", "deferred", "crowding", "unblended", "dots"), 0)
    for _, host in loop.frames(steps, f"{sim.num_agents:,} agents"):
        for key in PER_AGENT.intersection(host):  # agents may be interleaved over devices
            host[key] = in_agent_order(host[key], loop.state)
        for key in ("overflow", "deferred", "unblended"):
            counts[key] += int(host.pop(key))
        counts["crowding"] = max(counts["crowding"], int(host.pop("crowding")))
        for key, value in host.items():
            rec[key].append(value)
        hist += np.bincount(np.asarray(host["level"]), minlength=nlev + 1)
        counts["dots"] += int(np.sum(host["dots"]))
    recording = {k: np.stack(v) for k, v in rec.items()}
    recording.update(_run_constants(sim, nlev))
    return _summary(sim, loop, steps, hist, counts), recording


def _run_constants(sim: Any, nlev: int) -> dict[str, np.ndarray]:
    """What a recording holds once: agents' heights, groups and colours, the rate, the lens,
    the level count, whether near agents' feet were planted (``planted``: ``jcrowd export``
    plants them alike) and, with a layout, the obstacles' prisms (drawn by ``jcrowd render``)."""
    from jcrowd.cli.runloop import scenario_obstacles
    from jcrowd.crowd.feet import plants_feet

    cam = sim.scenario.camera
    out = {
        "height": np.asarray(sim.spawn.height, np.float32),
        "group": np.asarray(sim.spawn.group, np.int32),
        "color": np.asarray(sim.spawn.color, np.float32),
        "fps": np.asarray(sim.scenario.fps),
        "lens": np.asarray([cam.fov_deg, cam.near, cam.far], np.float64),
        "levels": np.asarray(nlev),
        "planted": np.asarray(plants_feet(sim.crowd, sim.config)),
    }
    if not sim.scenario.layout.empty:
        out["obstacles"] = scenario_obstacles(sim.scenario)
    return out


def _summary(
    sim: Any, loop: Any, steps: int, hist: np.ndarray, counts: dict[str, int]
) -> dict[str, Any]:
    """The run's JSON summary (the module docstring names the keys)."""
    from jcrowd.cli.runloop import fetch

    result = {
        "agents": sim.num_agents,
        "steps": steps,
        "ms_per_step_median": 1e3 * float(np.median(loop.step_seconds)),
        "compile_s": loop.compile_s,
        "frames_per_call": loop.chunk,
        "level_histogram": (hist / steps).round(1).tolist(),
        "dots_per_step": counts["dots"] / steps,
        "recompiles": loop.recompiles,
        "overflow_per_step": counts["overflow"] / steps,
        "deferred_clips": counts["deferred"],
        "crowding_max": counts["crowding"],
        "unblended_changes": counts["unblended"],
        "alive_end": int(np.sum(fetch(loop.state.alive))),
    }
    # Agents placed at t = 0 plus those [[sources]] added (each slot counts the agents it has
    # taken); an agent no longer alive has left through its goal or at its path's end.
    result["spawned"] = sim.scenario.num_agents + int(np.sum(fetch(loop.state.next_row)))
    result["exited"] = result["spawned"] - result["alive_end"]
    if sim.pool is not None:
        due = int(np.sum(np.asarray(sim.pool.times) < steps * sim.dt))
        result["spawn_late"] = sim.scenario.num_agents + due - result["spawned"]
    return result


def _print(result: dict[str, Any]) -> None:
    hist = ", ".join(f"{v:g}" for v in result["level_histogram"])
    sys.stdout.write(
        f"{result['agents']:,} agents × {result['steps']} steps: "
        f"{result['ms_per_step_median']:.2f} ms/step (median), "
        f"compile {result['compile_s']:.1f} s, {result['recompiles']} recompiles\n"
        f"mean agents per level (last = not synthesized): [{hist}], "
        f"{result['dots_per_step']:g} of them drawn as dots\n"
        + (f"recording: {result['out']}\n" if result["out"] else "")
    )
