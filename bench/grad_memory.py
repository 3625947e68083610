"""Memory and time of a differentiable rollout's gradient (issue 22, item 1).

The scene: a corridor 5 m wide and 250 m long with a door 4.4 m wide (two 0.3 m jambs) 210 m
along it, the target at its far end. ``--agents`` people (default 1,000) stand on a jittered
grid at about 1 /m² behind the door; the rearmost fifth are a source, let go front to back at
10 /s. Desired speeds vary from 1.2 to 1.5 m/s, so people catch up and follow. Over
``--steps`` steps of 1/30 s (default 600, 20 s) the front passes the door and an exit line 1 m
past it. A unidirectional flow at this density does not jam (see the note in
:mod:`jcrowd.rollouts.rollout`: in a jam the pathwise gradient grows about 1.5× per step).

Measured: the gradient of ``soft count through the line at T + mean travel time`` with respect
to every parameter kind of :class:`~jcrowd.rollouts.rollout.RolloutParams` (float32),

- ``peak_bytes``: the compiled gradient's arguments + outputs + temporaries − aliased buffers
  (XLA's buffer assignment, ``compiled.memory_analysis()``): the memory the gradient itself
  needs;
- ``rss_peak_bytes``: the process's peak resident set up to the end of the gradient runs
  (Python, JAX, XLA's compiler, the scene, every buffer; ``getrusage``), an upper bound;
  ``rss_run_peak_bytes``: the largest resident set seen while the gradients ran (sampled every
  5 ms from ``/proc/self/statm``; it includes what the compiler's heap kept);
- ``compile_s`` (trace + compile) and ``grad_s`` (median of ``--repeats`` runs) apart;
- the same gradient without checkpointing, compiled only (``plain_peak_bytes``; skip with
  ``--no-plain``), to show what the checkpoints save.

``python bench/grad_memory.py [--agents 1000] [--steps 600] [--json] [--no-record]``; appends a
row to bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import threading
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import shapely
from common import machine, report

from jcrowd.pedestrians import AvoidanceParams, Pedestrians, build_world
from jcrowd.rollouts.doors import find_door
from jcrowd.rollouts.rollout import (
    RolloutSetup,
    initial_params,
    mean_travel_time,
    rollout,
    soft_exit_count,
)

WIDTH, LENGTH, DOOR_AT, DOOR = 5.0, 250.0, 210.0, 4.4
LINE = ((DOOR_AT + 1.0, 0.0), (1.0, 0.0))  # 1 m past the door, normal along the corridor
RATE = 10.0
DT = 1.0 / 30.0


def scene(agents: int, steps: int, checkpoint: bool = True) -> RolloutSetup:
    """The corridor, its door and the crowd behind it (module docstring)."""
    jamb = (WIDTH - DOOR) / 2
    walk = shapely.difference(
        shapely.box(0.0, 0.0, LENGTH, WIDTH),
        shapely.union(
            shapely.box(DOOR_AT, 0.0, DOOR_AT + 0.2, jamb),
            shapely.box(DOOR_AT, WIDTH - jamb, DOOR_AT + 0.2, WIDTH),
        ),
    )
    world = build_world(walk, [shapely.box(LENGTH - 1.0, 0.0, LENGTH, WIDTH)])
    walls = np.asarray(world.walls)
    # The jambs' tips move; their bases stay on the corridor's walls.
    door = find_door(
        walls,
        [(DOOR_AT, jamb), (DOOR_AT + 0.2, jamb)],
        [(DOOR_AT, WIDTH - jamb), (DOOR_AT + 0.2, WIDTH - jamb)],
        tol=1e-4,
    )
    rng = np.random.default_rng(0)
    rows = np.arange(0.5, WIDTH - 0.4, 0.8)  # 6 across, then a column every 1.2 m: 1 /m²
    cols = DOOR_AT - 1.0 - np.arange(-(-agents // len(rows))) * 1.2
    xz = np.stack(np.meshgrid(cols, rows, indexing="ij"), -1).reshape(-1, 2)[:agents]
    xz = xz + rng.uniform(-0.1, 0.1, xz.shape)
    n = len(xz)
    source = n - n // 5
    rank = np.concatenate([np.full(source, -1e3), np.arange(n - source, dtype=float)])
    peds = Pedestrians(
        jnp.asarray(xz, jnp.float32),
        jnp.zeros(n, jnp.int32),
        jnp.asarray(rng.uniform(1.2, 1.5, n), jnp.float32),
        jnp.full(n, 0.2, jnp.float32),
        jnp.ones(n, bool),
        jnp.zeros((n, 2), jnp.float32),
        False,
    )
    return RolloutSetup(
        world,
        peds,
        jnp.asarray(rank, jnp.float32),
        steps=steps,
        dt=DT,
        doors=(door,),
        checkpoint=checkpoint,
    )


def loss(params: Any, setup: RolloutSetup) -> jax.Array:
    traj = rollout(params, setup)
    return soft_exit_count(traj, *LINE) + mean_travel_time(traj, *LINE)


def _peak(compiled: Any) -> int | None:
    stats = compiled.memory_analysis()
    if stats is None:
        return None
    return int(
        stats.argument_size_in_bytes
        + stats.output_size_in_bytes
        + stats.temp_size_in_bytes
        - stats.alias_size_in_bytes
    )


def _rss_bytes() -> int:
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # KiB on Linux


class _RssSampler(threading.Thread):
    """The largest current resident set (``/proc/self/statm``) seen while it runs."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.peak: int | None = None
        self.done = threading.Event()

    def run(self) -> None:
        page = os.sysconf("SC_PAGE_SIZE")
        while not self.done.is_set():
            try:
                with open("/proc/self/statm") as f:
                    now = int(f.read().split()[1]) * page
            except OSError:
                return
            self.peak = now if self.peak is None else max(self.peak, now)
            self.done.wait(0.005)


def measure(agents: int, steps: int, repeats: int, plain: bool) -> dict[str, Any]:
    setup = scene(agents, steps)
    params = initial_params(setup, AvoidanceParams(), rate=RATE)
    rss_before = _rss_bytes()
    t = time.perf_counter()
    compiled = jax.jit(jax.value_and_grad(loss)).lower(params, setup).compile()
    compile_s = time.perf_counter() - t
    rss_compiled = _rss_bytes()
    times, value, grad = [], None, None
    sampler = _RssSampler()
    sampler.start()
    for _ in range(repeats):
        t = time.perf_counter()
        value, grad = jax.block_until_ready(compiled(params, setup))
        times.append(time.perf_counter() - t)
    sampler.done.set()
    sampler.join()
    rss_peak = _rss_bytes()  # before the forward rollout below compiles
    leaves = [np.asarray(g) for g in jax.tree.leaves(grad)]
    traj = jax.jit(rollout)(params, setup)
    out: dict[str, Any] = {
        "agents": agents,
        "steps": steps,
        "block": setup.block or int(np.ceil(np.sqrt(steps))),
        "peak_bytes": _peak(compiled),
        "rss_before_compile_bytes": rss_before,
        "rss_after_compile_bytes": rss_compiled,
        "rss_run_peak_bytes": sampler.peak,
        "rss_peak_bytes": rss_peak,
        "compile_s": round(compile_s, 2),
        "grad_s": round(float(np.median(times)), 3),
        "loss": float(value),  # type: ignore[arg-type]
        "grad_finite": bool(all(np.isfinite(g).all() for g in leaves)),
        "grad_max_abs": float(max(np.abs(g).max() for g in leaves)),
        "through_line": round(float(soft_exit_count(traj, *LINE)), 2),
        "overflow": int(traj.overflow),
    }
    out["peak_gb"] = None if out["peak_bytes"] is None else round(out["peak_bytes"] / 1e9, 4)
    if plain:
        t = time.perf_counter()
        plain_c = jax.jit(jax.value_and_grad(loss)).lower(params, scene(agents, steps, False))
        out["plain_peak_bytes"] = _peak(plain_c.compile())
        out["plain_compile_s"] = round(time.perf_counter() - t, 2)
    return out


def _table(out: dict[str, Any]) -> str:
    def gb(x: int | None) -> str:
        return "n/a" if x is None else f"{x / 1e9:.3f}"

    lines = [
        "| agents | steps | block | compile s | grad s | peak GB (XLA) | RSS GB: before compile "
        "/ after / while running / peak | without checkpoints GB (XLA) | gradient finite | "
        "max abs gradient | through line |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        f"| {out['agents']:,} | {out['steps']} | {out['block']} | {out['compile_s']:.1f} | "
        f"{out['grad_s']:.2f} | {gb(out['peak_bytes'])} | {gb(out['rss_before_compile_bytes'])} "
        f"/ {gb(out['rss_after_compile_bytes'])} / {gb(out['rss_run_peak_bytes'])} / "
        f"{gb(out['rss_peak_bytes'])} | {gb(out.get('plain_peak_bytes'))} | "
        f"{out['grad_finite']} | {out['grad_max_abs']:.3g} | {out['through_line']:.1f} |",
    ]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-plain", action="store_true", help="skip the uncheckpointed compile")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    out = measure(args.agents, args.steps, args.repeats, not args.no_plain)
    out["machine"] = machine()
    out["jax"] = jax.__version__
    out["device"] = str(jax.devices()[0].platform)
    print(
        f"{out['agents']} agents × {out['steps']} steps: {out['grad_s']:.2f} s per gradient",
        file=sys.stderr,
    )
    report(
        "grad_memory",
        f"{out['machine']}, jax {out['jax']}, {out['device']}, float32",
        out,
        _table(out),
        args.json,
        not args.no_record,
    )


if __name__ == "__main__":
    main()
