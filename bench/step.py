"""Benchmark of the crowd step (issue 7; paper 000 §5, paper 003 §6): ms per step vs agents.

Plaza made in code: N agents uniformly in a square at 1 agent per 10 m², each walking to a
random point of the square, camera at the near edge 1.7 m high looking across, 60° vertical
fov, 1280×720, the shipped default model and the default LOD budget. Columns: compile s,
ms/step (median over steps after warm-up, ``block_until_ready``), the same in K-step calls
(``Simulation.compiled_steps``, ``--chunk`` frames per call, default 30, recording every
frame whole, as the single step returns it; a call's time ÷ its frames, median over
calls alternated with as many single steps, and its ratio to the single step),
``kernels_per_step`` (top-level operations of the compiled single step's optimized HLO on this
device kind: :func:`kernels_per_step`), agent-steps/s, the mean level histogram (last = culled),
bytes of state per agent.

In the same run, on the same agents:

- **naive interpolation** (paper 000's comparison): every agent-frame blends all S aligned
  samples with its kriging weights (the samples as stored full-size ``(S, T, P)`` pose vectors,
  reconstructed from the model), full skeleton FK, no tensor, no LOD;
- **full detail**: the level-0 decode + FK for every agent (agent-frames/s), in the chunks the
  step would use for a level of that many slots;
- **roof**: bytes the step must move divided by the bandwidth of a large copy measured in this
  process: every agent's per-step fields read and written (all of the state but the clips'
  mixing vectors, the waypoint lists and the cached coarsest-level cores, of which only the
  rows a step uses are read), plus, per synthesized slot,
  its two mixing vectors read and its drawn points written, plus the next-clip rows written.
  (With the state donated, untouched buffers are not copied: the count is what a step needs.)

Detail culling (``lod.min_pixels``, default 3 px) makes agents too small to show limbs dots
(root only), and agents beyond the last level's capacity (16,384 by default) are dots too; a
second 100k row with ``min_pixels = 0`` and a last capacity of N synthesizes every agent in view
(the step before detail culling).

The step runs split over ``--cpu-devices K`` CPU devices (default: one per core, as
``jcrowd run --cpu-devices``; the row says how many): XLA:CPU runs one step's kernels nearly one
after another, so one device uses about one core. The full-detail rate is measured on the same
devices (each decodes its share of the agents); the naive baseline is one program, which XLA
parallelizes over the cores inside each kernel.

With ``--avoid`` the plaza has ``[dynamics] avoid = true``: every agent's root is moved by the
avoidance model (``--model``, default ``anticipation``) among its neighbours
(:mod:`jcrowd.crowd.steering`) — the whole step with crowd dynamics; the row says so.

``python bench/step.py [--agents 1000,100000] [--cpu-devices K] [--avoid] [--chunk 30]
[--json]``; appends a row to bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from dataclasses import replace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from common import machine, report

from jcrowd import load_default_model
from jcrowd.cli.run import use_cpu_devices
from jcrowd.crowd import (
    agent_mesh,
    bucket_chunk,
    decode_bucket,
    decode_coeffs,
    level_points,
    pose_from_coeffs,
    prepare,
    shard_state,
)
from jcrowd.crowd.devices import on_all_devices
from jcrowd.model import MotionModel, PoseLayout
from jcrowd.motion import forward_kinematics, quat_from_expmap, quat_mul, yaw_quat
from jcrowd.scenario import parse_scenario

PLAZA = """
model = "default"
seed = 1
duration = 60.0
[ground]
center = [0, 0]
size = [{side}, {side}]
[camera]
eye = [0, 1.7, {eye_z}]
target = [0, 1.0, 0]
fov = 60
width = 1280
height = 720
[[groups]]
name = "plaza"
count = {n}
spawn = {{ shape = "rect", center = [0, 0], size = [{inner}, {inner}] }}
goal = {{ shape = "rect", center = [0, 0], size = [{inner}, {inner}] }}
"""


def _median_ms(fn: Any, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times))


def bandwidth_gbs() -> float:
    """GB/s of ``x + 1`` over 256 MB (reads and writes counted)."""
    x = jnp.ones(64 * 2**20, jnp.float32)
    f = jax.jit(lambda x: x + 1)
    jax.block_until_ready(f(x))
    ms = _median_ms(lambda: f(x), 5)
    return 2 * x.nbytes / (ms * 1e-3) / 1e9


def _naive_kernel(model: MotionModel, samples: jax.Array, layout: PoseLayout) -> Any:
    """One agent-frame of naive interpolation: Σ b_i Y_i(τ), full FK."""
    skel = model.skeleton
    ref = jnp.asarray(layout.reference[1:], jnp.float32)
    t_last = samples.shape[1] - 1
    joints = layout.num_joints

    def one(b: jax.Array, tau: jax.Array, xz: jax.Array, heading: jax.Array) -> jax.Array:
        i0 = jnp.minimum(jnp.floor(tau), t_last - 1)
        frac = tau - i0
        rows = jax.lax.dynamic_slice_in_dim(samples, i0.astype(jnp.int32), 2, axis=1)
        y2 = jnp.einsum("s,stp->tp", b, rows)
        y = y2[0] + frac * (y2[1] - y2[0])
        root = quat_mul(yaw_quat(heading), quat_from_expmap(y[4:7]))
        e = y[7 : 7 + 3 * (joints - 1)].reshape(joints - 1, 3)
        local = jnp.concatenate([root[None], quat_mul(ref, quat_from_expmap(e))], axis=0)
        base = jnp.stack([xz[0], y[0] * 1.7, xz[1]])
        _, pos = forward_kinematics(skel.scaled(1.7), local, base)
        return pos

    return jax.jit(jax.vmap(one))


def naive_ms(model: MotionModel, n: int, repeats: int) -> float:
    lv = model.levels[0]
    k = lv.kriging
    cores = np.asarray(k.residuals) + np.concatenate(
        [np.ones((k.num_samples, 1)), np.asarray(k.controls - k.control_mean) / k.control_scale],
        axis=1,
    ) @ np.asarray(k.trend)
    cores = cores.reshape(k.num_samples, *lv.u_pose.shape[1:], lv.u_time.shape[1])
    y = np.einsum("pr,srt,Tt->sTp", lv.u_pose, cores, lv.u_time) * model.layout.scale
    samples = jnp.asarray(y, jnp.float32)  # (S, T, P): the full-size aligned samples
    rng = np.random.default_rng(0)
    b = rng.dirichlet(np.ones(k.num_samples), n).astype(np.float32)
    tau = jnp.asarray(rng.uniform(0, 98, n), jnp.float32)
    xz = jnp.asarray(rng.uniform(-50, 50, (n, 2)), jnp.float32)
    heading = jnp.asarray(rng.uniform(-3, 3, n), jnp.float32)
    f = _naive_kernel(model, samples, model.layout)
    b = jnp.asarray(b)
    # Chunks of 100k agents: the gathered sample rows of 1M agents at once would take 36 GB.
    chunk = min(n, 100_000)
    parts = [
        (b[i : i + chunk], tau[i : i + chunk], xz[i : i + chunk], heading[i : i + chunk])
        for i in range(0, n, chunk)
    ]
    jax.block_until_ready(f(*parts[0]))
    return _median_ms(lambda: [jax.block_until_ready(f(*p)) for p in parts], repeats)


def full_detail_rate(sim: Any, state: Any, n: int, repeats: int) -> float:
    """Agent-frames/s of level-0 decode + FK for ``n`` agents (every agent at full detail),
    decoded as the step decodes a bucket: in chunks (:func:`jcrowd.crowd.stepping.decode_bucket`;
    one vmap over 100k agents materializes 480 MB of cores and runs memory-bound), each device its
    own share of the agents as in the split step."""
    from jax import shard_map
    from jax.sharding import NamedSharding
    from jax.sharding import PartitionSpec as P

    lv = sim.crowd.decoders.levels[0]
    host = [np.asarray(a)[:n] for a in (state.clip()[1], state.tau, state.x, state.z)]
    host += [np.asarray(state.heading)[:n], np.asarray(state.height)[:n]]

    def decode(mix: Any, tau: Any, x: Any, z: Any, hd: Any, h: Any) -> Any:
        m = tau.shape[0]

        def one(i: jax.Array) -> Any:
            y = pose_from_coeffs(lv, decode_coeffs(lv, mix[i], tau[i]))
            return level_points(lv, y, jnp.stack([x[i], z[i]]), hd[i], h[i])

        chunk = bucket_chunk(m, sim.config.chunk, lv.cores.shape[1])  # as the step would
        ids = jnp.arange(m, dtype=jnp.int32)
        return decode_bucket(jax.vmap(one), ids, jnp.int32(m), chunk)

    devices = jax.devices()
    if len(devices) > 1:
        mesh = agent_mesh()
        agents = P("agents")
        args = [jax.device_put(a, NamedSharding(mesh, agents)) for a in host]
        f = jax.jit(
            shard_map(decode, mesh=mesh, in_specs=agents, out_specs=agents, check_vma=False)
        )
    else:
        args = [jnp.asarray(a) for a in host]
        f = jax.jit(decode)
    jax.block_until_ready(f(*args))
    return n / (_median_ms(lambda: f(*args), repeats) * 1e-3)


def _counted(state: Any, view: Any, frame: Any) -> Any:
    """What the K-step calls keep of each frame: the whole frame, as the single step returns
    it (kept to the last array: XLA would skip computing what nothing reads, e.g. the
    coarse levels' points)."""
    return frame


HLO_PLUMBING = frozenset(("parameter", "constant", "tuple", "get-tuple-element", "bitcast"))
"""HLO instructions that launch no work: not counted as kernels."""


def kernels_per_step(hlo: str) -> int:
    """Top-level operations of a compiled step's optimized HLO (``compile().as_text()``): the
    instructions of the entry computation and of the computations it runs as control flow
    (``while`` bodies and conditions, ``conditional`` branches), fusions counted once and the
    computations inside fusions, reductions and sorts not at all; :data:`HLO_PLUMBING` left
    out. Each is a kernel the device launches (a while body's once per iteration; counted
    once here)."""
    computations: dict[str, list[str]] = {}
    entry, name = "", None
    for line in hlo.splitlines():
        head = re.match(r"^(ENTRY )?%?([\w.\-]+) .*\{$", line)
        if head:
            name = head.group(2)
            computations[name] = []
            entry = name if head.group(1) else entry
        elif line == "}":
            name = None
        elif name is not None:
            computations[name].append(line)
    control: set[str] = set()
    for lines in computations.values():
        for line in lines:
            if " while(" in line:
                control.update(re.findall(r"(?:body|condition)=%?([\w.\-]+)", line))
            branches = re.search(r"branch_computations=\{([^}]*)\}", line)
            if branches:
                control.update(b.strip().lstrip("%") for b in branches.group(1).split(","))
            control.update(re.findall(r"(?:true|false)_computation=%?([\w.\-]+)", line))
    count = 0
    for comp in [entry, *sorted(control)]:
        for line in computations.get(comp, []):
            op = re.match(r"\s*(?:ROOT )?%?[\w.\-]+ = .*? ([a-z][\w\-]*)\(", line)
            count += bool(op) and op.group(1) not in HLO_PLUMBING  # type: ignore[union-attr]
    return count


def roof_bytes(state: Any, frame: Any, refresh: int) -> int:
    """Bytes a step must read and write (module doc)."""
    n = state.num_agents
    rowwise = ("mix", "waypoints", "far_core")  # touched only in the rows a step uses
    arrays = {k: x for k, x in vars(state).items() if isinstance(x, jax.Array)}
    per_step = sum(x.nbytes for k, x in arrays.items() if k not in rowwise)
    mix_row = state.mix.nbytes // n  # both clip slots of one agent
    slots = sum(int(p.shape[0]) for p in frame.points)
    points = sum(int(np.prod(p.shape)) * 4 for p in frame.points)
    far = int(frame.points[-1].shape[0]) * (state.far_core.nbytes // n)  # cached cores read
    return 2 * per_step + n * 8 + slots * mix_row + points + refresh * mix_row // 2 + far


def run_count(
    model: MotionModel,
    n: int,
    steps: int,
    bw: float,
    min_pixels: float | None = None,
    avoid: bool = False,
    far_every: int = 1,
    dynamics_model: str = "anticipation",
    full_detail: bool = False,
    chunk: int = 30,
) -> dict[str, Any]:
    """One plaza of ``n`` walkers; ``full_detail`` turns the LOD off: every agent in view is
    synthesized at level 0 (one bucket holding all, thresholds out of reach, no dots), the
    scene, step and schedule otherwise the same (paper 000's with/without-LOD comparison)."""
    side = float(np.sqrt(10.0 * n))
    text = PLAZA.format(side=side + 2, inner=side, eye_z=-side / 2 - 0.5, n=n)
    if avoid:
        text += f'\n[dynamics]\navoid = true\nfar_every = {far_every}\nmodel = "{dynamics_model}"\n'
    sim, state = prepare(parse_scenario(text, "bench-plaza.toml"), model)
    state = shard_state(state)  # one block of agents per device (unchanged on one device)
    if min_pixels is not None:  # every agent in view synthesized: no dots at all
        caps = (*sim.config.capacities[:-1], n)
        sim = replace(sim, config=replace(sim.config, min_pixels=min_pixels, capacities=caps))
    if full_detail:
        levels = len(sim.config.capacities)
        cfg = replace(
            sim.config,
            min_pixels=0.0,
            capacities=(n, *(1,) * (levels - 1)),
            thresholds=(1e9,) * (levels - 1),
        )
        sim = replace(sim, config=cfg)
    fn = sim.compiled()
    view, dt = sim.view_at(0.0), sim.dt_array
    t = time.perf_counter()
    jax.block_until_ready(fn(jax.tree.map(jnp.copy, state), view, dt))  # state is donated
    compile_s = time.perf_counter() - t
    kernels = kernels_per_step(fn.lower(state, view, dt).compile().as_text())
    many = sim.compiled_steps(chunk, _counted)
    views, count = sim.views(0, chunk), on_all_devices(jnp.asarray(chunk, jnp.int32))
    k_state = jax.tree.map(jnp.copy, state)
    k_state, _ = jax.block_until_ready(many(k_state, views, dt, count))  # compiles
    for _ in range(3):  # warm-up: past the first clip choices
        state, frame = fn(state, view, dt)
    times, k_times, hist, dots = [], [], np.zeros(len(sim.config.capacities) + 1), 0
    for _ in range(max(3, -(-steps // chunk))):  # alternated: `chunk` single steps, one K-step call
        for _ in range(chunk):
            t = time.perf_counter()
            state, frame = fn(state, view, dt)
            jax.block_until_ready(state)
            times.append(time.perf_counter() - t)
            hist += np.bincount(np.asarray(frame.level), minlength=len(hist))
            dots += int(np.asarray(frame.dots).sum())
        t = time.perf_counter()
        k_state, _ = many(k_state, views, dt, count)
        jax.block_until_ready(k_state)
        k_times.append((time.perf_counter() - t) / chunk)
    steps = len(times)
    ms = 1e3 * float(np.median(times))
    steps_s = 150 if n <= 100_000 else 30
    safety = _safety(fn, jax.tree.map(jnp.copy, state), view, dt, steps_s) if avoid else {}
    state_bytes = sum(x.nbytes for x in jax.tree.leaves(state))
    refresh = sim.config.refresh or n // 32 + 64
    roof_ms = roof_bytes(state, frame, min(refresh, n)) / (bw * 1e9) * 1e3
    return {
        "agents": n,
        "min_pixels": sim.config.min_pixels,
        "dots": round(dots / steps, 1),
        "compile_s": compile_s,
        "ms_per_step": ms,
        "k_steps": chunk,
        "ms_per_step_k": 1e3 * float(np.median(k_times)),
        "k_step_ratio": float(np.median(k_times)) / float(np.median(times)),
        "kernels_per_step": kernels,
        "agent_steps_per_s": n / (ms * 1e-3),
        "level_histogram": (hist / steps).round(1).tolist(),  # last: not synthesized
        "state_bytes_per_agent": state_bytes / n,
        "roof_ms_per_step": roof_ms,
        "recompiles": fn._cache_size() - 1,
        "crowding": int(frame.crowding),
        **safety,
        "_sim": (sim, state),
    }


def _safety(fn: Any, state: Any, view: Any, dt: Any, steps: int) -> dict[str, Any]:
    """Over ``steps`` more steps, every alive agent at every step: the smallest centre distance
    ÷ (rᵢ + rⱼ) to its nearest neighbour (a k-d tree, SciPy) and the non-finite roots."""
    from scipy.spatial import cKDTree

    worst, nan = np.inf, 0
    for _ in range(steps):
        state, _ = fn(state, view, dt)
        alive = np.asarray(state.alive)
        p = np.stack([np.asarray(state.x), np.asarray(state.z)], 1)[alive]
        finite = np.isfinite(p).all(axis=1)
        nan += int((~finite).sum())
        p, r = p[finite], np.asarray(state.radius)[alive][finite]
        d, j = cKDTree(p).query(p, k=2)
        worst = min(worst, float(np.min(d[:, 1] / (r + r[j[:, 1]]))))
    return {"min_gap_ratio": round(worst, 3), "nan": nan, "safety_steps": steps}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", default="1000,10000,100000,1000000")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--chunk", type=int, default=30, help="frames per K-step call")
    ap.add_argument("--no-record", action="store_true")
    ap.add_argument("--cpu-devices", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--avoid", action="store_true", help="crowd dynamics on ([dynamics] avoid)")
    ap.add_argument(
        "--far-every", type=int, default=1, help="with --avoid: [dynamics] far_every (sim LOD)"
    )
    ap.add_argument(
        "--model",
        default="anticipation",
        choices=("anticipation", "collision-free-speed"),
        help="with --avoid: [dynamics] model",
    )
    args = ap.parse_args()
    use_cpu_devices(args.cpu_devices)  # before JAX starts its backend
    counts = [int(v) for v in args.agents.split(",")]
    model = load_default_model()
    bw = bandwidth_gbs()
    rows, naive, speedup = [], {}, {}
    full_rate = 0.0
    for n in counts:
        steps = args.steps if n < 1_000_000 else max(3, args.steps // 4)
        opts = {
            "avoid": args.avoid,
            "far_every": args.far_every,
            "dynamics_model": args.model,
            "chunk": args.chunk,
        }
        row = run_count(model, n, steps, bw, **opts)
        sim, state = row.pop("_sim")
        naive[str(n)] = naive_ms(model, n, 3)
        speedup[str(n)] = naive[str(n)] / row["ms_per_step"]
        if n == min(max(counts), 100_000) or n == max(counts):
            full_rate = max(full_rate, full_detail_rate(sim, state, min(n, 100_000), 3))
        rows.append(row)
        print(f"{n:,} agents: {row['ms_per_step']:.1f} ms/step", file=sys.stderr)
        if n == 100_000:  # the same plaza with every agent in view synthesized
            every = run_count(model, n, steps, bw, min_pixels=0.0, **opts)
            every.pop("_sim")
            rows.append(every)
    out = {
        "rows": rows,
        "naive_ms_per_step": naive,
        "speedup_vs_naive": speedup,
        "full_detail_agent_frames_per_s": full_rate,
        "roof_ms_per_step": {str(r["agents"]): r["roof_ms_per_step"] for r in rows},
        "state_bytes_per_agent": rows[-1]["state_bytes_per_agent"],
        "bandwidth_gbs": bw,
        "device": str(jax.devices()[0].platform),
        "devices": len(jax.devices()),
        "avoid": args.avoid,
        "far_every": args.far_every,
        "dynamics_model": args.model if args.avoid else None,
        "machine": machine(),
        "jax": jax.__version__,
    }
    text = _table(out)
    report(
        "step",
        f"{out['machine']}, jax {out['jax']}, {out['device']} × {out['devices']}"
        + (f", avoidance on ({args.model})" if args.avoid else "")
        + (f", far agents every {args.far_every} steps" if args.far_every > 1 else ""),
        out,
        text,
        args.json,
        not args.no_record,
    )


def _table(out: dict[str, Any]) -> str:
    lines = [
        "| agents | min px | compile s | ms/step | ms/step in K-step calls (× single) | kernels "
        "per step | agent-steps/s | levels 0…5, not synthesized (mean) | of which dots | state "
        "B/agent | roof ms | naive ms | speed-up vs naive |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    safety = [r for r in out["rows"] if "min_gap_ratio" in r]
    for r in out["rows"]:
        n = str(r["agents"])
        hist = " / ".join(f"{v:g}" for v in r["level_histogram"])
        lines.append(
            f"| {r['agents']:,} | {r['min_pixels']:g} | {r['compile_s']:.1f} | "
            f"{r['ms_per_step']:.2f} | {r['ms_per_step_k']:.2f} ({r['k_step_ratio']:.2f}×) | "
            f"{r['kernels_per_step']} | {r['agent_steps_per_s']:.3g} | {hist} | {r['dots']:g} | "
            f"{r['state_bytes_per_agent']:.0f} | "
            f"{r['roof_ms_per_step']:.2f} | {out['naive_ms_per_step'][n]:.1f} | "
            f"{out['naive_ms_per_step'][n] / r['ms_per_step']:.1f}× |"
        )
    lines += [
        "",
        f"full detail (level-0 decode + FK, every agent): "
        f"{out['full_detail_agent_frames_per_s']:.3g} agent-frames/s; "
        f"copy bandwidth {out['bandwidth_gbs']:.1f} GB/s; K-step calls of "
        f"{out['rows'][0]['k_steps']} frames",
    ]
    if safety:
        lines += [
            "",
            "safety over the next steps, every alive agent (closest centre distance ÷ (rᵢ + rⱼ);"
            " non-finite roots): "
            + "; ".join(
                f"{r['agents']:,} (min px {r['min_pixels']:g}): {r['min_gap_ratio']:.3f} over "
                f"{r['safety_steps']} steps, nan {r['nan']}"
                for r in safety
            ),
        ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
