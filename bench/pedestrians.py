"""Crowd dynamics against real pedestrian experiments and JuPedSim, side by side (issue 18).

Every scene runs twice in this process, on the same geometry, start positions and entry times:
with jcrowd's pedestrian step (:func:`jcrowd.crowd.pedestrian_step`, the collision-free speed
model) and with JuPedSim's ``CollisionFreeSpeedModel`` (defaults, the same model family). Both
sides are measured with PedPy exactly as the experiments are (``../shared/data/pedestrians``).

Needs the bench extra: ``pip install -e '.[dev,bench]'`` (JuPedSim and PedPy).

Sections (``--sections``, default all):

- ``bottleneck``: 150 agents in a 10 m × 10 m room leave through a 4 m corridor of width
  0.8 … 2.4 m; flow = crossings of the corridor entrance per second over the middle 80 % of
  them; the linear fit's r² over widths.
- ``entrance``: the Wuppertal 2018 entrance run (75 people, 0.5 m gap) from the measured start
  positions; flow through the gap (middle 80 % of crossings), first-to-last crossing time,
  Voronoi density in front of the gap.
- ``fd``: each HERMES run (``--hermes DIR``; file names ``uo-<entrance>-<corridor>-<exit>`` in
  cm) re-simulated: each person is fed in at the corridor's entrance — at ``y = 3.8`` m, 0.2 m
  inside it — when and where the measurement sees them cross that line (so the run's entrance
  width is in the measured crossing points, and the measured entrance flow is the input); the
  exit opening is a gap of the run's width in a 0.2 m wall at the corridor's end; Voronoi
  density and speed in the measurement area over the run's steady state; Weidmann's curve as a
  second reference. (The reading taken: "fed in at the entrance" is the entrance line.
  Feeding people in where the camera first sees them, 3.8 m further up in the holding area,
  makes the model's merge into the corridor the bottleneck instead: both models then carry
  about 2 /s through the 1.8 m entrance where 2.9 /s were measured — row 2026-12-01, code
  c092641.)
- ``speed``: median ms per step of the dynamics alone at 0.5 agents/m² walking across a square
  with 2 m pillars every 25 m (the issue's "open area with obstacles"; JuPedSim's step cost
  grows with the obstacles) and across the same square without them, jcrowd vs JuPedSim (one
  core). ``--cpu-devices K`` splits jcrowd's step over K CPU devices
  (:func:`jcrowd.crowd.split_pedestrian_step`; default 1); the row says how many.

- ``counterflow``: the plaza's two head-on groups (1,500 people, 70 m fronts) on an open
  square, pure dynamics: the share that is through the other group after 40 s with jcrowd's two
  avoidance models and JuPedSim's collision-free speed and anticipation velocity models, from
  the same start.

- ``bidirectional``: ``examples/bidirectional.toml`` (a corridor 4 m × 20 m fed with about
  2 /s from each end for two minutes) run as ``jcrowd run`` runs it: people out, stuck,
  ``spawn_late``, the time from the last one entering the corridor to the last one leaving it,
  the share through within 30 s of that, density and speed in its middle 4 m.

- ``plaza``: ``examples/plaza.toml`` with avoidance in the animated crowd step (its groups cross
  head-on and at right angles), for three times its longest free-walking route, with each
  avoidance model: safety, and each agent's arrival time ÷ its free-walking time.

``--model`` (``anticipation`` or ``collision-free-speed``, default ``collision-free-speed``):
jcrowd's model in the bottleneck, entrance and fd sections, whose agents have a body heading
(:mod:`jcrowd.pedestrians.heading`; ``--no-heading``: without). The entrance section also
reports the queue's motion in front of the gap (``entrance_queue``, ``bench/follow.py``'s
``queue_motion``, beside the same measure of the measured run), ``standing_facing_deg`` (p90
of a standing body's heading against its desired direction) and ``heading_turn_rate_deg_s``
(p99), and runs jcrowd a second time with the opt-in standing rule (``stand_drive`` 0.7,
:mod:`jcrowd.pedestrians.avoidance`): ``entrance_standing`` (flow, first to last, queue,
safety, the two heading measures). The speed section always compares
the collision-free speed model with JuPedSim's (the same model on both sides).

Safety over every jcrowd scene: ``min_gap_ratio`` (smallest centre distance ÷ (r_i + r_j)),
``inside_obstacle`` (agent-frames whose centre is outside the walkable area), ``nan``, and
``stuck``: agents still in the scene when the run ends, a run lasting three times the longer of
the reference's time to empty the scene (the experiment, else JuPedSim in the same run) and the
farthest agent's free-walking time.

``python bench/pedestrians.py [--sections ...] [--hermes DIR] [--json]``; appends a row to
bench/RESULTS.md and writes ``docs/pedestrians_fd.png`` and ``docs/pedestrians_bottleneck.png``.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import jupedsim as jps
import numpy as np
import pandas as pd
import pedpy
import shapely
from common import ROOT, machine, report
from follow import measured_entrance, queue_motion, simulated_paths

from jcrowd.cli.run import use_cpu_devices
from jcrowd.pedestrians import (
    AvoidanceParams,
    Pedestrians,
    build_world,
    desired_directions,
    pedestrian_step,
    split_pedestrian_step,
)
from jcrowd.rollouts.windows import corridor_scene

DATA = ROOT.parent / "shared" / "data" / "pedestrians"
DT = 1.0 / 30.0
RADIUS = 0.2  # JuPedSim's default radius, used on both sides
SPEED = 1.34  # free walking speed (Weidmann 1993)
ENTRANCE_RADIUS = 0.13
STANDING_DRIVE = 0.7  # the entrance's second jcrowd run: the standing rule on at this c
ENTRANCE_FPS = 25.0  # the Wuppertal entrance run's frame rate
SPAWN_GAP = 2.05  # an entering agent waits until nobody is within 2.05 radii of its spot


# ------------------------------------------------------------------------------ two simulators


MODEL = "collision-free-speed"
"""jcrowd's avoidance model in the bottleneck, entrance and fd sections (``--model``)."""

HEADING = True
"""Whether jcrowd's agents have a body heading in those sections (``--no-heading``: not)."""


def run_jcrowd(
    area,
    target,
    spawn_xy,
    spawn_t,
    t_max,
    speed=SPEED,
    radius=RADIUS,
    gap=SPAWN_GAP,
    params=None,
    headings=None,
):
    """jcrowd's dynamics; agents appear at ``spawn_t`` once their spot is free. ``params``:
    the avoidance model's (default: its defaults). ``headings``: a list that receives the
    bodies' headings ``(F, N)`` and desired directions ``(F, N, 2)`` (with ``HEADING``).

    Returns ``(positions (F, N, 2), alive (F, N))`` at every step and the seconds per step.
    """
    world = build_world(area, [target])
    n = len(spawn_xy)
    xy = jnp.asarray(spawn_xy, jnp.float32)
    start = jnp.asarray(spawn_t, jnp.float32)
    params = AvoidanceParams() if params is None else params
    target_ids = jnp.zeros(n, jnp.int32)
    # Bodies face down their field where they appear (HEADING; None: the model without a body).
    face = desired_directions(world.nav, target_ids, xy) if HEADING else None
    heading0 = None if face is None else jnp.arctan2(face[:, 0], face[:, 1])
    peds = Pedestrians(
        xy,
        target_ids,
        jnp.full(n, speed, jnp.float32),
        jnp.full(n, radius, jnp.float32),
        jnp.zeros(n, bool),
        jnp.zeros((n, 2), jnp.float32),
        MODEL == "anticipation",
        heading=heading0,
    )

    def one(carry, t):
        peds, pending = carry
        p = peds.position
        d2 = jnp.sum((xy[:, None] - p[None]) ** 2, axis=-1)
        blocked = jnp.any(peds.alive[None] & (d2 < (gap * radius) ** 2), axis=1)
        appear = pending & (start <= t) & ~blocked
        # One agent per step and spot: among those appearing, drop any within 2r of a lower id.
        close = (jnp.sum((xy[:, None] - xy[None]) ** 2, -1) < (2 * radius) ** 2) & jnp.tri(
            n, k=-1, dtype=bool
        )
        appear = appear & ~jnp.any(close & appear[None], axis=1)
        velocity = None if peds.velocity is None else jnp.where(appear[:, None], 0.0, peds.velocity)
        heading = None
        if heading0 is not None and peds.heading is not None:
            heading = jnp.where(appear, heading0, peds.heading)
        peds = Pedestrians(
            jnp.where(appear[:, None], xy, p),
            peds.target,
            peds.speed,
            peds.radius,
            peds.alive | appear,
            velocity,
            peds.anticipate,
            heading=heading,
        )
        peds, _ = pedestrian_step(params, world, peds, DT)
        face = jnp.zeros(n) if peds.heading is None else peds.heading
        desired = desired_directions(world.nav, peds.target, peds.position)
        return (peds, pending & ~appear), (peds.position, peds.alive, face, desired)

    @jax.jit
    def chunk(carry, ts):
        return jax.lax.scan(one, carry, ts)

    carry = (peds, jnp.ones(n, bool))
    steps = math.ceil(t_max / DT)
    out_p, out_a, out_h, out_d = [], [], [], []
    t0 = time.perf_counter()
    for k0 in range(0, steps, 300):
        ts = jnp.arange(k0, min(k0 + 300, steps), dtype=jnp.float32) * DT
        carry, (pos, alive, face, desired) = chunk(carry, ts)
        out_p.append(np.asarray(pos))
        out_a.append(np.asarray(alive))
        if headings is not None:
            out_h.append(np.asarray(face))
            out_d.append(np.asarray(desired))
        if not bool(carry[0].alive.any()) and not bool(carry[1].any()):
            break
    seconds = time.perf_counter() - t0
    pos, alive = np.concatenate(out_p), np.concatenate(out_a)
    if headings is not None:
        headings.extend([np.concatenate(out_h), np.concatenate(out_d)])
    return pos, alive, seconds / len(pos)


def run_jupedsim(area, target, spawn_xy, spawn_t, t_max, speed=SPEED, radius=RADIUS, gap=SPAWN_GAP):
    """JuPedSim's collision-free speed model on the same scene (agents added at ``spawn_t``
    when no agent is within 2r of the spot). Same outputs as :func:`run_jcrowd`."""
    sim = jps.Simulation(model=jps.CollisionFreeSpeedModel(), geometry=area, dt=DT)
    exit_id = sim.add_exit_stage(target)
    journey = sim.add_journey(jps.JourneyDescription([exit_id]))
    n = len(spawn_xy)
    ids = np.full(n, -1)
    order = np.argsort(spawn_t, kind="stable")
    steps = math.ceil(t_max / DT)
    pos = np.full((steps, n, 2), np.nan, np.float32)
    alive = np.zeros((steps, n), bool)
    next_k = 0
    t0 = time.perf_counter()
    k = 0
    for k in range(steps):
        t = k * DT
        here = [a.position for a in sim.agents()]  # agents added now show after iterate()
        while next_k < n and spawn_t[order[next_k]] <= t:
            i = order[next_k]
            if (
                here
                and np.min(np.linalg.norm(np.asarray(here) - spawn_xy[i], axis=1)) < gap * radius
            ):
                break
            try:  # JuPedSim checks against positions newer than sim.agents() shows
                ids[i] = sim.add_agent(
                    jps.CollisionFreeSpeedModelAgentParameters(
                        journey_id=journey,
                        stage_id=exit_id,
                        position=tuple(map(float, spawn_xy[i])),
                        desired_speed=speed,
                        radius=radius,
                    )
                )
            except RuntimeError:
                break  # the spot is taken: try again next step
            here.append(tuple(spawn_xy[i]))
            next_k += 1
        sim.iterate()
        where = {a.id: a.position for a in sim.agents()}
        for i in range(n):
            if ids[i] >= 0 and ids[i] in where:
                pos[k, i] = where[ids[i]]
                alive[k, i] = True
        if next_k == n and sim.agent_count() == 0:
            break
    seconds = time.perf_counter() - t0
    return pos[: k + 1], alive[: k + 1], seconds / (k + 1)


# ------------------------------------------------------------------------------ measurements


def crossings(pos, alive, axis, level, sign=-1.0):
    """Time (s) each agent first crosses ``pos[..., axis] = level`` moving in ``sign``."""
    side = np.where(alive, sign * (pos[..., axis] - level) > 0, False)
    first = np.argmax(side, axis=0)
    return np.where(side.any(axis=0), (first + 1) * DT, np.nan)


def middle_flow(times):
    t = np.sort(times[np.isfinite(times)])
    if len(t) < 5:
        return 0.0
    k0, k1 = int(0.1 * len(t)), int(0.9 * len(t)) - 1
    return (k1 - k0) / max(t[k1] - t[k0], 1e-9)


def safety(pos, alive, area, radius=RADIUS):
    gaps = []
    for f in range(0, len(pos), 3):
        p = pos[f][alive[f]]
        if len(p) > 1:
            d = np.linalg.norm(p[:, None] - p[None], axis=-1) + 1e9 * np.eye(len(p))
            gaps.append(d.min() / (2 * radius))
    p = pos[alive]
    inside = shapely.contains_xy(shapely.buffer(area, 1e-3), p[:, 0], p[:, 1])
    return {
        "min_gap_ratio": float(min(gaps)) if gaps else float("nan"),
        "inside_obstacle": int((~inside).sum()),
        "nan": int((~np.isfinite(p)).sum()),
        "stuck": int(alive[-1].sum()),
    }


def trajectory(pos, alive, fps):
    f, i = np.nonzero(alive)
    df = pd.DataFrame({"id": i, "frame": f, "x": pos[f, i, 0], "y": pos[f, i, 1]})
    return pedpy.TrajectoryData(data=df, frame_rate=fps)


# ------------------------------------------------------------------------------ bottleneck


def bottleneck_scene(width):
    room = shapely.box(0.0, 0.0, 10.0, 10.0)
    corridor = shapely.box(5.0 - width / 2, 10.0 - 1e-9, 5.0 + width / 2, 14.0)
    return shapely.union(room, corridor), shapely.box(5 - width / 2, 13.5, 5 + width / 2, 14)


def bottleneck(widths, out):
    starts = np.array(
        jps.distributions.distribute_by_number(
            polygon=shapely.box(0.5, 0.5, 9.5, 9.5),
            number_of_agents=150,
            distance_to_agents=0.45,
            distance_to_polygon=0.3,
            seed=1,
        )
    )
    ours, theirs, safe = [], [], []
    for w in widths:
        area, exit_ = bottleneck_scene(w)
        jp, ja, _ = run_jupedsim(area, exit_, starts, np.zeros(150), 400.0)
        t_ref = len(jp) * DT
        p, a, _ = run_jcrowd(area, exit_, starts, np.zeros(150), 3 * t_ref)
        ours.append(middle_flow(crossings(p, a, 1, 10.0, +1.0)))
        theirs.append(middle_flow(crossings(jp, ja, 1, 10.0, +1.0)))
        safe.append(safety(p, a, area))
        print(
            f"bottleneck {w} m: jcrowd {ours[-1]:.2f} /s, JuPedSim {theirs[-1]:.2f} /s",
            file=sys.stderr,
            flush=True,
        )
    fit = np.polyfit(widths, ours, 1)
    pred = np.polyval(fit, widths)
    r2 = 1 - np.sum((np.array(ours) - pred) ** 2) / np.sum((ours - np.mean(ours)) ** 2)
    out["bottleneck_widths_m"] = list(widths)
    out["bottleneck_flow_per_s"] = [round(x, 3) for x in ours]
    out["jupedsim_bottleneck_flow_per_s"] = [round(x, 3) for x in theirs]
    out["bottleneck_r2"] = round(float(r2), 4)
    out["safety"]["bottleneck"] = _worst(safe)


def _worst(items):
    return {
        "min_gap_ratio": min(s["min_gap_ratio"] for s in items),
        "inside_obstacle": sum(s["inside_obstacle"] for s in items),
        "nan": sum(s["nan"] for s in items),
        "stuck": sum(s["stuck"] for s in items),
    }


# ------------------------------------------------------------------------------ entrance


def entrance(out):
    left = shapely.Polygon(
        [
            (-0.7, -1.1),
            (-0.25, -1.1),
            (-0.25, -0.15),
            (-0.4, 0),
            (-2.8, 0),
            (-2.8, 6.7),
            (-3.05, 6.7),
            (-3.05, -0.3),
            (-0.7, -0.3),
            (-0.7, -1.0),
        ]
    )
    right = shapely.Polygon(
        [
            (0.25, -1.1),
            (0.7, -1.1),
            (0.7, -0.3),
            (3.05, -0.3),
            (3.05, 6.7),
            (2.8, 6.7),
            (2.8, 0),
            (0.4, 0),
            (0.25, -0.15),
            (0.25, -1.1),
        ]
    )
    area = shapely.box(-3.5, -2.0, 3.5, 8.0).difference(shapely.union(left, right))
    exit_ = shapely.box(-3.5, -2.0, 3.5, -1.6)
    d = np.loadtxt(DATA / "bottleneck_entrance" / "040_c_56_h-.txt", comments="#")
    first = d[d[:, 1] == d[:, 1].min()]
    starts = first[:, 2:4]
    n = len(starts)
    measured_total = 64.5
    # The measured crowd stands closer than 0.4 m centre to centre (0.27 m at the start): a
    # 0.2 m disc cannot hold it, so both simulators get 0.13 m discs here.
    r = ENTRANCE_RADIUS
    run = {"radius": r, "gap": 2.0}  # everyone stands where measured at t = 0
    faces: list[np.ndarray] = []
    p, a, _ = run_jcrowd(
        area, exit_, starts, np.zeros(n), 3 * measured_total, **run, headings=faces
    )
    jp, ja, _ = run_jupedsim(area, exit_, starts, np.zeros(n), 3 * measured_total, **run)
    res = {}
    for name, (pp, aa) in (("jcrowd", (p, a)), ("jupedsim", (jp, ja))):
        t = crossings(pp, aa, 1, 0.0)
        t = t[np.isfinite(t)]
        res[name] = {
            "flow": middle_flow(t),
            "total": float(t.max() - t.min()) if len(t) > 1 else float("nan"),
            "crossed": len(t),
            "density": _entrance_density(pp, aa, area, t),
        }
    out["entrance_flow_per_s"] = round(res["jcrowd"]["flow"], 3)
    out["entrance_total_s"] = round(res["jcrowd"]["total"], 2)
    out["entrance_density_per_m2"] = round(res["jcrowd"]["density"], 2)
    out["jupedsim_entrance"] = {k: round(v, 3) for k, v in res["jupedsim"].items()}
    out["entrance_measured"] = {"flow": 1.16, "total": 64.5, "density": 5.9}
    out["safety"]["entrance"] = safety(p, a, area, r)
    fps = 1.0 / DT
    out["entrance_queue"] = queue_motion(simulated_paths(p, a), fps)
    out["entrance_queue_measured"] = queue_motion(measured_entrance(), ENTRANCE_FPS)
    # The opt-in standing rule (jcrowd.pedestrians.avoidance), same scene.
    calm = AvoidanceParams(stand_drive=STANDING_DRIVE)
    calm_faces: list[np.ndarray] = []
    sp, sa, _ = run_jcrowd(
        area,
        exit_,
        starts,
        np.zeros(n),
        3 * measured_total,
        **run,
        params=calm,
        headings=calm_faces,
    )
    st = crossings(sp, sa, 1, 0.0)
    st = st[np.isfinite(st)]
    out["entrance_standing"] = {
        "stand_drive": STANDING_DRIVE,
        "flow_per_s": round(middle_flow(st), 3),
        "total_s": round(float(st.max() - st.min()), 2) if len(st) > 1 else float("nan"),
        "queue": queue_motion(simulated_paths(sp, sa), fps),
        "safety": safety(sp, sa, area, r),
    }
    if HEADING:
        out["entrance_standing"].update(heading_measures(sp, sa, *calm_faces))
    if HEADING:
        out.update(heading_measures(p, a, *faces))
    print(f"entrance: {res}", file=sys.stderr, flush=True)


def heading_measures(pos, alive, heading, desired, stand=0.1):
    """``standing_facing_deg``: the p90 angle between a standing body's heading and its
    desired direction (agent-frames slower than ``stand`` m/s, alive on both sides of the
    step); ``heading_turn_rate_deg_s``: the p99 of how fast headings turn (°/s)."""
    both = alive[1:] & alive[:-1]
    speed = np.linalg.norm(pos[1:] - pos[:-1], axis=-1) / DT
    want = np.arctan2(desired[1:, ..., 0], desired[1:, ..., 1])
    off = np.abs(np.remainder(heading[1:] - want + np.pi, 2 * np.pi) - np.pi)
    standing = both & (speed < stand)
    turn = np.abs(np.remainder(heading[1:] - heading[:-1] + np.pi, 2 * np.pi) - np.pi) / DT
    return {
        "standing_facing_deg": round(float(np.degrees(np.percentile(off[standing], 90))), 1)
        if standing.any()
        else float("nan"),
        "heading_turn_rate_deg_s": round(float(np.degrees(np.percentile(turn[both], 99))), 1),
    }


def _entrance_density(pos, alive, area, times):
    if len(times) < 2:
        return float("nan")
    traj = trajectory(pos, alive, 1 / DT)
    walk = pedpy.WalkableArea(area)
    ma = pedpy.MeasurementArea([(-0.4, 0.5), (0.4, 0.5), (0.4, 1.3), (-0.4, 1.3)])
    vor = pedpy.compute_individual_voronoi_polygons(traj_data=traj, walkable_area=walk)
    dens, _ = pedpy.compute_voronoi_density(individual_voronoi_data=vor, measurement_area=ma)
    f0, f1 = int(times.min() / DT), int(times.max() / DT)
    sel = dens[(dens.index >= f0) & (dens.index <= f1)] if "frame" not in dens else dens
    if "frame" in dens:
        sel = dens[(dens.frame >= f0) & (dens.frame <= f1)]
    return float(sel["density"].mean())


# ------------------------------------------------------------------------------ HERMES


HERMES_AREA = corridor_scene(1.8, 1.8)[0]
"""The HERMES corridor (1.8 m) with its rooms: jcrowd.rollouts.calibrate's scene, no exit wall."""
HERMES_FPS = 16.0


def hermes_scene(exit_cm):
    """The run's walkable area (an exit ``exit_cm`` wide in a wall at y = −4) and its target."""
    area, target, _ = corridor_scene(1.8, exit_cm / 100.0)
    return area, target


FEED_Y = 3.8  # m: people enter the simulation 0.2 m inside the corridor's entrance (y = 4)


def hermes_feed(d):
    """Where and when each person of a HERMES run (rows ``id frame x y`` in metres) enters:
    their first frame below ``FEED_Y`` (their first frame if none is), ``x`` kept a radius (and
    2 cm: JuPedSim refuses agents touching a wall) inside the 1.8 m corridor. The run's entrance
    width is in where the measured people cross the line."""
    ids = np.unique(d[:, 0])
    xy, t = np.zeros((len(ids), 2)), np.zeros(len(ids))
    for k, i in enumerate(ids):
        rows = d[d[:, 0] == i]
        below = rows[:, 3] < FEED_Y
        row = rows[np.argmax(below)] if below.any() else rows[0]
        xy[k], t[k] = (row[2], min(row[3], FEED_Y)), row[1] / HERMES_FPS
    xy[:, 0] = np.clip(xy[:, 0], RADIUS + 0.02, 1.8 - RADIUS - 0.02)
    return xy, t


def weidmann(rho):
    return 1.34 * (1 - np.exp(-1.913 * (1 / np.maximum(rho, 1e-3) - 1 / 5.4)))


def fd(folder, out):
    steady = pd.read_csv(folder / "steady_state.csv").set_index("run")
    rows = []
    for f in sorted(folder.glob("uo-*.txt")):
        m = re.match(r"uo-(\d+)-(\d+)-(\d+)", f.stem)
        if not m or f.stem not in steady.index:
            continue
        d = np.loadtxt(f, comments="#")
        d[:, 2:4] /= 100.0  # cm -> m
        spawn_xy, spawn_t = hermes_feed(d)
        area, target = hermes_scene(float(m.group(3)))
        t_ref = d[:, 1].max() / HERMES_FPS
        measured = _fd_measure(d, HERMES_FPS, steady.loc[f.stem], HERMES_AREA)
        p, a, _ = run_jcrowd(area, target, spawn_xy, spawn_t, 3 * t_ref)
        jp, ja, _ = run_jupedsim(area, target, spawn_xy, spawn_t, 3 * t_ref)
        sim = _fd_measure_sim(p, a, steady.loc[f.stem], area)
        jsim = _fd_measure_sim(jp, ja, steady.loc[f.stem], area)
        rows.append(
            {
                "run": f.stem,
                "measured_density": round(measured[0], 3),
                "measured_speed": round(measured[1], 3),
                "density": round(sim[0], 3),
                "speed": round(sim[1], 3),
                "jupedsim_density": round(jsim[0], 3),
                "jupedsim_speed": round(jsim[1], 3),
                "safety": safety(p, a, area),
            }
        )
        print(f"fd {rows[-1]}", file=sys.stderr, flush=True)
    ms = np.array([r["measured_speed"] for r in rows])
    out["fd"] = rows
    out["fd_speed_rmse_m_s"] = round(
        float(np.sqrt(np.mean((np.array([r["speed"] for r in rows]) - ms) ** 2))), 3
    )
    out["jupedsim_fd_speed_rmse_m_s"] = round(
        float(np.sqrt(np.mean((np.array([r["jupedsim_speed"] for r in rows]) - ms) ** 2))), 3
    )
    out["fd_density_rel_error"] = [round(r["density"] / r["measured_density"] - 1, 3) for r in rows]
    out["weidmann_speed_rmse_m_s"] = round(
        float(
            np.sqrt(np.mean((weidmann(np.array([r["measured_density"] for r in rows])) - ms) ** 2))
        ),
        3,
    )
    out["safety"]["fd"] = _worst([r.pop("safety") for r in rows])


_MA = pedpy.MeasurementArea([(0, -2), (1.8, -2), (1.8, 0), (0, 0)])


def _fd_from_traj(traj, walk, f0, f1, frame_step):
    vor = pedpy.compute_individual_voronoi_polygons(traj_data=traj, walkable_area=walk)
    dens, inter = pedpy.compute_voronoi_density(individual_voronoi_data=vor, measurement_area=_MA)
    speed = pedpy.compute_individual_speed(
        traj_data=traj,
        frame_step=frame_step,
        speed_calculation=pedpy.SpeedCalculation.BORDER_SINGLE_SIDED,
    )
    vs = pedpy.compute_voronoi_speed(
        traj_data=traj,
        individual_speed=speed,
        individual_voronoi_intersection=inter,
        measurement_area=_MA,
    )
    fd_ = dens.reset_index() if "frame" not in dens.columns else dens
    vs_ = vs.reset_index() if "frame" not in vs.columns else vs
    dsel = fd_[(fd_.frame >= f0) & (fd_.frame <= f1)]["density"].mean()
    vsel = vs_[(vs_.frame >= f0) & (vs_.frame <= f1)]["speed"].mean()
    return float(dsel), float(vsel)


def _fd_measure(d, fps, window, area):
    df = pd.DataFrame(
        {"id": d[:, 0].astype(int), "frame": d[:, 1].astype(int), "x": d[:, 2], "y": d[:, 3]}
    )
    traj = pedpy.TrajectoryData(data=df, frame_rate=fps)
    return _fd_from_traj(traj, pedpy.WalkableArea(area), window.first_frame, window.last_frame, 5)


def _fd_measure_sim(pos, alive, window, area):
    traj = trajectory(pos, alive, 1 / DT)
    scale = (1 / DT) / HERMES_FPS
    f0, f1 = int(window.first_frame * scale), int(window.last_frame * scale)
    return _fd_from_traj(traj, pedpy.WalkableArea(HERMES_AREA), f0, f1, round(5 * scale))


# ------------------------------------------------------------------------------ plaza


def plaza(out, model="anticipation"):
    """Safety of the counter-flow plaza (``examples/plaza.toml`` with ``[dynamics] avoid =
    true`` and ``model``) in the animated crowd step, one device: every step, the closest pair
    ÷ (rᵢ + rⱼ) (SciPy k-d tree) and non-finite roots over the agents in the scene; at the end,
    ``stuck``: agents with an end (not looping) still in the scene and farther than the
    waypoint reach from their last waypoint, after three times the longest free-walking time
    of the routes. How well the groups pass each other: ``plaza_arrival_ratio`` (p50, p90 over
    the agents with an end) of the time an agent took to arrive (leave, or come within the
    reach of its last waypoint) ÷ its route's length at its free speed (1: never slowed)."""
    from scipy.spatial import cKDTree

    from jcrowd import load_default_model
    from jcrowd.crowd import prepare
    from jcrowd.scenario import parse_scenario

    text = (ROOT / "examples" / "plaza.toml").read_text()
    text = text.split("[dynamics]")[0] + f'\n[dynamics]\navoid = true\nmodel = "{model}"\n'
    sim, state = prepare(parse_scenario(text, "plaza.toml"), load_default_model())
    sp = sim.spawn
    ends = sp.waypoints[np.arange(len(sp.speed)), sp.num_waypoints - 1]
    legs = np.concatenate([sp.position[:, None], sp.waypoints], axis=1)
    route = np.linalg.norm(np.diff(legs, axis=1), axis=2).sum(axis=1)
    finite = ~sp.loop
    t_run = 3.0 * float(np.max(route[finite] / sp.speed[finite]))
    fn, view, dt = sim.compiled(), sim.view_at(0.0), sim.dt_array
    worst, nan = np.inf, 0
    steps = math.ceil(t_run / sim.dt)
    arrived = np.full(len(finite), np.inf)
    for k in range(steps):
        state, _ = fn(state, view, dt)
        alive = np.asarray(state.alive)
        p = np.stack([np.asarray(state.x), np.asarray(state.z)], axis=1)
        there = ~alive | (np.linalg.norm(p - ends, axis=1) <= sim.config.reach)
        arrived = np.where(np.isinf(arrived) & there, (k + 1) * sim.dt, arrived)
        ok = alive & np.isfinite(p).all(axis=1)
        nan += int((alive & ~ok).sum())
        if ok.sum() > 1:
            r = np.asarray(state.radius)[ok]
            d, j = cKDTree(p[ok]).query(p[ok], k=2)
            worst = min(worst, float(np.min(d[:, 1] / (r + r[j[:, 1]]))))
    far = np.linalg.norm(p - ends, axis=1) > sim.config.reach
    stuck = int((finite & alive & far).sum())
    key = "plaza" if model == "anticipation" else f"plaza_{model}"
    out["safety"][key] = {
        "min_gap_ratio": round(worst, 3),
        "inside_obstacle": 0,  # the plaza has no obstacles
        "nan": nan,
        "stuck": stuck,
    }
    ratio = arrived[finite] / (route[finite] / sp.speed[finite])
    out.setdefault("plaza_arrival_ratio", {})[model] = {
        "p50": round(float(np.percentile(ratio, 50)), 2),
        "p90": round(float(np.percentile(ratio, 90)), 2),
    }
    out["plaza_seconds"] = round(t_run, 1)
    out["plaza_agents_with_an_end"] = int(finite.sum())
    print(
        f"plaza ({model}): {out['safety'][key]}, arrival ÷ free time "
        f"{out['plaza_arrival_ratio'][model]} after {t_run:.0f} s",
        file=sys.stderr,
        flush=True,
    )


# ------------------------------------------------------------------------------ counterflow

COUNTERFLOW_S = 40.0
"""How long the counter-flow scene runs (s)."""


def counterflow(out):
    """The plaza's two head-on groups (``examples/plaza.toml``: 800 walking north from
    ``z ≈ −46``, 700 south from ``z ≈ −22``, 70 m wide fronts, 0.6 /m²; same start positions and
    free speeds on every side) on an open 120 m square, each group leaving through a strip
    beyond the other, for :data:`COUNTERFLOW_S` s: jcrowd's dynamics with both avoidance models
    and JuPedSim's collision-free speed and anticipation velocity models (defaults).

    ``counterflow_through``: the share of people beyond the far edge of where the other group
    started (or gone); walking free, everyone is through by 32 s.
    ``docs/pedestrians_counterflow.png``: the two groups seen from above at 10 and 20 s.
    JuPedSim walks an agent towards a point of its exit, so each of its agents gets a waypoint
    straight ahead of its start first (else its groups narrow towards the exits' centres and
    meet denser)."""
    from jcrowd import load_default_model
    from jcrowd.crowd import prepare
    from jcrowd.scenario import parse_scenario

    scenario = parse_scenario((ROOT / "examples" / "plaza.toml").read_text(), "plaza.toml")
    sim, _ = prepare(scenario, load_default_model())
    group = np.repeat(np.arange(len(scenario.groups)), [g.count for g in scenario.groups])
    head_on = group < 2  # northbound, southbound
    xy = sim.spawn.position[head_on].astype(np.float32)
    v0 = sim.spawn.speed[head_on].astype(np.float32)
    g = group[head_on]
    exits = [shapely.box(-35, 46, 35, 54), shapely.box(-30, -60, 40, -56)]
    area = shapely.box(-60, -60, 60, 60)
    steps = round(COUNTERFLOW_S / DT)
    shots = (round(10 / DT), round(20 / DT))
    n = len(xy)
    snaps, through = {}, {}
    # Through: beyond the far edge of where the other group started (or left).
    north_line = float(xy[g == 1, 1].max())
    south_line = float(xy[g == 0, 1].min())

    def share_through(p, a):
        past = np.where(g == 0, p[:, 1] > north_line, p[:, 1] < south_line)
        return round(float(np.mean(~a | past)), 3)

    world = build_world(area, exits, nav_cell=0.25)
    step = jax.jit(pedestrian_step)
    for model in ("anticipation", "collision-free-speed"):
        e0 = np.where(g[:, None] == 0, [0.0, 1.0], [0.0, -1.0]).astype(np.float32)
        peds = Pedestrians(
            jnp.asarray(xy),
            jnp.asarray(g, jnp.int32),
            jnp.asarray(v0),
            jnp.full(n, RADIUS, jnp.float32),
            jnp.ones(n, bool),
            jnp.asarray(e0 * v0[:, None]),
            model == "anticipation",
        )
        name = f"jcrowd {model}"
        for k in range(1, steps + 1):
            peds, _ = step(AvoidanceParams(), world, peds, jnp.float32(DT))
            if k in shots:
                snaps[name, k] = (np.asarray(peds.position), np.asarray(peds.alive))
        through[name] = share_through(np.asarray(peds.position), np.asarray(peds.alive))
    for model in ("CollisionFreeSpeedModel", "AnticipationVelocityModel"):
        sim_j = jps.Simulation(model=getattr(jps, model)(), geometry=area, dt=DT)
        stages = [sim_j.add_exit_stage(e) for e in exits]
        params = getattr(jps, f"{model}AgentParameters")
        row = {}
        for i in range(n):
            # JuPedSim routes to a point of the exit: a waypoint straight ahead, beyond the
            # other group, keeps its agents on the straight paths jcrowd's fields give.
            ahead = sim_j.add_waypoint_stage((float(xy[i, 0]), 40.0 if g[i] == 0 else -52.0), 1.0)
            journey = jps.JourneyDescription([ahead, stages[g[i]]])
            journey.set_transition_for_stage(
                ahead, jps.Transition.create_fixed_transition(stages[g[i]])
            )
            agent = params(
                journey_id=sim_j.add_journey(journey),
                stage_id=ahead,
                position=tuple(map(float, xy[i])),
                desired_speed=float(v0[i]),
                radius=RADIUS,
            )
            row[sim_j.add_agent(agent)] = i
        name = f"JuPedSim {model}"
        for k in range(1, steps + 1):
            sim_j.iterate()
            if k in shots or k == steps:
                p, a = np.full((n, 2), np.nan), np.zeros(n, bool)
                for agent in sim_j.agents():
                    p[row[agent.id]], a[row[agent.id]] = agent.position, True
                snaps[name, k] = (p, a)
        through[name] = share_through(*snaps.pop((name, steps)))
    out["counterflow_through"] = through
    out["counterflow_seconds"] = COUNTERFLOW_S
    print(
        f"counterflow: through after {COUNTERFLOW_S:.0f} s {through}", file=sys.stderr, flush=True
    )
    if MODEL == "collision-free-speed":
        _plot_counterflow(snaps, g, shots)


BIDIRECTIONAL_MOUTH_Z = 10.0  # m: the corridor of examples/bidirectional.toml is |z| < 10
BIDIRECTIONAL_WIDTH = 4.0


def bidirectional(out):
    """``examples/bidirectional.toml`` as a user runs it (``jcrowd run --json``, the animated
    crowd step, one device), measured from its recording: people out of the scene and
    ``spawn_late`` (the run's own counts); ``stuck``, still in the scene at the end; entering
    and leaving the corridor (crossing its near and far mouth in one's walking direction):
    ``clear_s``, from the last one entering to the last one leaving it, and ``out_within_30s``,
    the share of all people through the corridor within 30 s of the last one entering;
    ``density_per_m2`` and ``speed_m_s`` in the corridor's middle 4 m (``|z| < 2``) over the
    frames with somebody there; ``min_gap_ratio`` (closest pair ÷ (rᵢ + rⱼ), every tenth
    frame)."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        rec_path = Path(tmp) / "run.npz"
        cmd = [
            sys.executable,
            "-m",
            "jcrowd.cli",
            "run",
            str(ROOT / "examples" / "bidirectional.toml"),
        ]
        run = subprocess.run(
            [*cmd, "--json", "--out", str(rec_path)], capture_output=True, text=True
        )
        if run.returncode:
            raise RuntimeError(run.stderr[-2000:])
        summary = json.loads(run.stdout)
        rec = dict(np.load(rec_path))
    pos, alive, agent = rec["position"], rec["alive"], rec["agent"]
    fps = float(rec["fps"])
    north = rec["group"] == 0  # walking towards +z
    z = np.where(north[None], pos[..., 1], -pos[..., 1])  # along one's own way
    both = alive[1:] & alive[:-1]
    entered, left = {}, {}
    for mouth, seen in ((-BIDIRECTIONAL_MOUTH_Z, entered), (BIDIRECTIONAL_MOUTH_Z, left)):
        f, s = np.nonzero(both & (z[:-1] < mouth) & (z[1:] >= mouth))
        for fi, si in zip(f, s, strict=True):
            seen[int(agent[fi + 1, si])] = (fi + 1) / fps
    last_in = max(entered.values())
    mid = alive & (np.abs(pos[..., 1]) < 2.0)
    busy = mid.any(axis=1)
    speed = np.linalg.norm(pos[1:] - pos[:-1], axis=-1) * fps
    gaps = []
    for f in range(0, len(pos), 10):
        p = pos[f, alive[f]]
        if len(p) > 1:
            d = np.linalg.norm(p[:, None] - p[None], axis=-1) + 1e9 * np.eye(len(p))
            gaps.append(d.min() / (2 * RADIUS))
    people = summary["spawned"]
    out["bidirectional"] = {
        "people": people,
        "out": summary["exited"],
        "spawn_late": summary["spawn_late"],
        "stuck": summary["alive_end"],
        "clear_s": round(max(left.values()) - last_in, 1),
        "out_within_30s": round(sum(t <= last_in + 30.0 for t in left.values()) / people, 3),
        "density_per_m2": round(
            float(mid[busy].sum(axis=1).mean() / (4.0 * BIDIRECTIONAL_WIDTH)), 2
        ),
        "speed_m_s": round(float(speed[(mid[1:] & mid[:-1])].mean()), 2),
        "min_gap_ratio": round(float(min(gaps)), 3),
    }
    print(f"bidirectional: {out['bidirectional']}", file=sys.stderr, flush=True)


def _plot_counterflow(snaps, g, shots):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(name for name, _ in snaps))
    fig, axes = plt.subplots(
        len(shots), len(names), figsize=(3.2 * len(names), 5.6), sharex=True, sharey=True
    )
    for c, name in enumerate(names):
        for r, k in enumerate(shots):
            p, a = snaps[name, k]
            ax = axes[r, c]
            for gg, colour in ((0, "tab:red"), (1, "tab:blue")):
                m = a & (g == gg)
                ax.scatter(p[m, 0], p[m, 1], s=0.6, c=colour)
            ax.set_title(f"{name.replace('Model', '')}, {k * DT:.0f} s", fontsize=8)
            ax.set_aspect("equal")
            ax.set_xlim(-40, 45)
            ax.set_ylim(-60, 0)
    fig.suptitle("Counter-flow: north (red) and south (blue) from the same start", fontsize=9)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "pedestrians_counterflow.png")
    plt.close(fig)


# ------------------------------------------------------------------------------ speed


def speed(sizes, out, pillars=True):
    """Median ms per step of both on a square at 0.5 agents/m² walking to one side, with 2 m
    pillars every 25 m (``pillars``) or open."""
    ours, theirs = {}, {}
    for size in sizes:
        side = 1.15 * math.sqrt(size / 0.5)  # room for the pillars and the margins
        blocks = [
            shapely.box(x, z, x + 2, z + 2)
            for x in np.arange(10, side - 10, 25)
            for z in np.arange(10, side - 10, 25)
        ]
        area = shapely.box(0, 0, side, side)
        if pillars:
            area = area.difference(shapely.unary_union(blocks))
        target = shapely.box(side - 2, 0, side, side)
        # A jittered lattice at 0.5 /m² (spacing 1.41 m, jitter ±0.3 m: no two closer than
        # 0.8 m), the cells inside pillars left out.
        rng = np.random.default_rng(0)
        k = np.arange(1.0, side - 3.0, math.sqrt(2.0))
        pts = np.stack(np.meshgrid(k, k), -1).reshape(-1, 2)
        pts = pts + rng.uniform(-0.3, 0.3, pts.shape)
        pts = pts[shapely.contains_xy(area.buffer(-0.3), pts[:, 0], pts[:, 1])][:size]
        n = len(pts)
        assert n == size, (n, size)
        world = build_world(area, [target], grid_cell=1.0)
        peds = Pedestrians(
            jnp.asarray(pts, jnp.float32),
            jnp.zeros(n, jnp.int32),
            jnp.full(n, SPEED, jnp.float32),
            jnp.full(n, RADIUS, jnp.float32),
            jnp.ones(n, bool),
            jnp.zeros((n, 2), jnp.float32),
            False,
        )
        # Split over the CPU devices (--cpu-devices; JuPedSim runs on one core either way).
        step = split_pedestrian_step() if jax.device_count() > 1 else jax.jit(pedestrian_step)
        params = AvoidanceParams()
        peds, _ = step(params, world, peds, jnp.float32(DT))
        jax.block_until_ready(peds)
        ts = []
        for _ in range(10):
            t0 = time.perf_counter()
            peds, _ = step(params, world, peds, jnp.float32(DT))
            jax.block_until_ready(peds)
            ts.append(time.perf_counter() - t0)
        ours[size] = float(np.median(ts))
        sim = jps.Simulation(model=jps.CollisionFreeSpeedModel(), geometry=area, dt=DT)
        ex = sim.add_exit_stage(target)
        j = sim.add_journey(jps.JourneyDescription([ex]))
        for p in pts:
            sim.add_agent(
                jps.CollisionFreeSpeedModelAgentParameters(
                    journey_id=j,
                    stage_id=ex,
                    position=tuple(map(float, p)),
                    desired_speed=SPEED,
                    radius=RADIUS,
                )
            )
        sim.iterate()
        ts = []
        for _ in range(5 if size >= 50000 else 10):
            t0 = time.perf_counter()
            sim.iterate()
            ts.append(time.perf_counter() - t0)
        theirs[size] = float(np.median(ts))
        print(
            f"speed {size}: jcrowd {1e3 * ours[size]:.1f} ms, JuPedSim {1e3 * theirs[size]:.1f} ms",
            file=sys.stderr,
            flush=True,
        )
    tag = "" if pillars else "_open"
    out[f"dynamics_ms{tag}"] = {str(n): round(1e3 * ours[n], 2) for n in sizes}
    out[f"jupedsim_ms{tag}"] = {str(n): round(1e3 * theirs[n], 2) for n in sizes}
    out[f"speedup_vs_jupedsim{tag}"] = {str(n): round(theirs[n] / ours[n], 2) for n in sizes}


# ------------------------------------------------------------------------------ plots


def plot(out):
    """``docs/pedestrians_fd.png`` and ``docs/pedestrians_bottleneck.png`` from the results."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    docs = ROOT / "docs"
    if "fd" in out:
        fig, ax = plt.subplots(figsize=(6, 4), dpi=120)
        rho = np.linspace(0.3, 4.0, 200)
        ax.plot(rho, weidmann(rho), "k--", lw=1, label="Weidmann 1993")
        for key, mark, label in (
            ("measured_", "o", "HERMES (measured)"),
            ("", "s", "jcrowd"),
            ("jupedsim_", "^", "JuPedSim"),
        ):
            d = [r[f"{key}density"] for r in out["fd"]]
            v = [r[f"{key}speed"] for r in out["fd"]]
            ax.scatter(d, v, marker=mark, label=label, zorder=3)
        ax.set(xlabel="Voronoi density (1/m²)", ylabel="Voronoi speed (m/s)", xlim=(0, 4))
        ax.set_title("Fundamental diagram, HERMES corridor runs (PedPy on both)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(docs / "pedestrians_fd.png")
        plt.close(fig)
    if "bottleneck_flow_per_s" in out:
        fig, ax = plt.subplots(figsize=(6, 4), dpi=120)
        w = out["bottleneck_widths_m"]
        ax.plot(w, out["bottleneck_flow_per_s"], "s-", label="jcrowd")
        ax.plot(w, out["jupedsim_bottleneck_flow_per_s"], "^-", label="JuPedSim")
        ax.set(xlabel="bottleneck width (m)", ylabel="flow (1/s)")
        ax.set_title("150 agents through a 4 m corridor")
        ax.legend()
        fig.tight_layout()
        fig.savefig(docs / "pedestrians_bottleneck.png")
        plt.close(fig)


# ------------------------------------------------------------------------------ main


def _text(out):
    lines = []
    if "bottleneck_flow_per_s" in out:
        lines += [
            "| bottleneck width m | "
            + " | ".join(f"{w:g}" for w in out["bottleneck_widths_m"])
            + " |",
            "|---|" + "---|" * len(out["bottleneck_widths_m"]),
            "| jcrowd flow /s | "
            + " | ".join(f"{x:.2f}" for x in out["bottleneck_flow_per_s"])
            + " |",
            "| JuPedSim flow /s | "
            + " | ".join(f"{x:.2f}" for x in out["jupedsim_bottleneck_flow_per_s"])
            + " |",
            "",
            f"bottleneck r² {out['bottleneck_r2']}",
        ]
    if "entrance_flow_per_s" in out:
        j = out["jupedsim_entrance"]
        lines += [
            "",
            "entrance (measured 1.16 /s, 64.5 s, 5.9 /m²): "
            f"jcrowd {out['entrance_flow_per_s']} /s, {out['entrance_total_s']} s, "
            f"{out['entrance_density_per_m2']} /m²; JuPedSim "
            f"{j['flow']} /s, {j['total']} s, {j['density']} /m²",
            "",
            "| entrance queue | moving share | away > 60° | away > 90° | velocity vs smooth "
            "heading p99 ° |",
            "|---|---|---|---|---|",
        ]
        queues = [("jcrowd", out["entrance_queue"])]
        if "entrance_standing" in out:
            calm = out["entrance_standing"]
            queues.append((f"jcrowd, stand_drive {calm['stand_drive']}", calm["queue"]))
        queues.append(("measured", out["entrance_queue_measured"]))
        for name, q in queues:
            lines.append(
                f"| {name} | {q['moving_share']} | {q['away_over_60_share']} | "
                f"{q['away_over_90_share']} | {q['smooth_heading_p99_deg']} |"
            )
        if "entrance_standing" in out:
            calm = out["entrance_standing"]
            lines += [
                "",
                f"standing rule on (stand_drive {calm['stand_drive']}): {calm['flow_per_s']} /s, "
                f"{calm['total_s']} s, stuck {calm['safety']['stuck']}, min gap "
                f"{round(calm['safety']['min_gap_ratio'], 3)}"
                + (
                    f"; standing facing p90 {calm['standing_facing_deg']}°, turn rate p99 "
                    f"{calm['heading_turn_rate_deg_s']}°/s"
                    if "standing_facing_deg" in calm
                    else ""
                ),
            ]
        if "standing_facing_deg" in out:
            lines += [
                "",
                f"bodies: standing facing p90 {out['standing_facing_deg']}°, "
                f"turn rate p99 {out['heading_turn_rate_deg_s']}°/s",
            ]
    if "bidirectional" in out:
        b = out["bidirectional"]
        lines += [
            "",
            "| bidirectional corridor | people | out | stuck | spawn_late | last in → last out s "
            "| out within 30 s | middle ρ /m² | v m/s | min gap |",
            "|---|---|---|---|---|---|---|---|---|---|",
            f"| jcrowd (anticipation) | {b['people']} | {b['out']} | {b['stuck']} | "
            f"{b['spawn_late']} | {b['clear_s']} | {b['out_within_30s']} | {b['density_per_m2']} "
            f"| {b['speed_m_s']} | {b['min_gap_ratio']} |",
        ]
    if "fd" in out:
        lines += [
            "",
            "| HERMES run | measured ρ /m² | v m/s | jcrowd ρ | v | JuPedSim ρ | v |",
            "|---|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {r['run']} | {r['measured_density']:.2f} | {r['measured_speed']:.2f} | "
            f"{r['density']:.2f} | {r['speed']:.2f} | {r['jupedsim_density']:.2f} | "
            f"{r['jupedsim_speed']:.2f} |"
            for r in out["fd"]
        ]
        lines += [
            "",
            f"speed RMSE: jcrowd {out['fd_speed_rmse_m_s']} m/s, JuPedSim "
            f"{out['jupedsim_fd_speed_rmse_m_s']} m/s, "
            f"Weidmann {out['weidmann_speed_rmse_m_s']} m/s",
        ]
    for tag, what in (("", "with pillars"), ("_open", "open square")):
        if f"speedup_vs_jupedsim{tag}" not in out:
            continue
        sizes = list(out[f"dynamics_ms{tag}"])
        lines += [
            "",
            f"| agents ({what}) | " + " | ".join(sizes) + " |",
            "|---|" + "---|" * len(sizes),
            "| jcrowd dynamics ms/step | "
            + " | ".join(str(out[f"dynamics_ms{tag}"][s]) for s in sizes)
            + " |",
            "| JuPedSim ms/step | "
            + " | ".join(str(out[f"jupedsim_ms{tag}"][s]) for s in sizes)
            + " |",
            "| speed-up | "
            + " | ".join(f"{out[f'speedup_vs_jupedsim{tag}'][s]}×" for s in sizes)
            + " |",
        ]
    if out["safety"]:
        lines += ["", f"safety: {out['safety']}"]
    if "counterflow_through" in out:
        lines += [
            "",
            f"| counter-flow, through after {out['counterflow_seconds']:.0f} s | share |",
            "|---|---|",
            *(f"| {k} | {v} |" for k, v in out["counterflow_through"].items()),
        ]
    if "plaza_seconds" in out:
        lines += [
            "",
            f"plaza: {out['plaza_seconds']} s simulated, {out['plaza_agents_with_an_end']} "
            "agents with an end (stuck: farther than the reach from it at the end)",
            "",
            "| plaza model | arrival ÷ free time p50 | p90 |",
            "|---|---|---|",
            *(f"| {m} | {r['p50']} | {r['p90']} |" for m, r in out["plaza_arrival_ratio"].items()),
        ]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--sections", default="bidirectional,bottleneck,counterflow,entrance,fd,plaza,speed"
    )
    ap.add_argument("--hermes", type=Path, default=DATA / "hermes_uo")
    ap.add_argument("--widths", default="0.8,1.2,1.6,2.0,2.4")
    ap.add_argument("--sizes", default="1000,10000,50000,100000")
    ap.add_argument("--json", action="store_true")
    ap.add_argument(
        "--model", default="collision-free-speed", choices=("collision-free-speed", "anticipation")
    )
    ap.add_argument("--no-record", action="store_true")
    ap.add_argument("--no-heading", action="store_true", help="jcrowd's agents without a body")
    ap.add_argument("--cpu-devices", type=int, default=1, help="split jcrowd's speed runs")
    args = ap.parse_args()
    use_cpu_devices(args.cpu_devices)  # before JAX starts its backend
    sections = set(args.sections.split(","))
    global MODEL, HEADING
    MODEL, HEADING = args.model, not args.no_heading
    out: dict = {
        "model": MODEL,
        "heading": HEADING,
        "safety": {},
        "machine": machine(),
        "jax": jax.__version__,
        "jupedsim": jps.__version__,
        "cpu_devices": jax.device_count(),
    }
    if "bottleneck" in sections:
        bottleneck([float(w) for w in args.widths.split(",")], out)
    if "entrance" in sections:
        entrance(out)
    if "fd" in sections:
        fd(args.hermes, out)
    if "counterflow" in sections:
        counterflow(out)
    if "bidirectional" in sections:
        bidirectional(out)
    if "plaza" in sections:
        for model in ("anticipation", "collision-free-speed"):
            plaza(out, model)
    if "speed" in sections:
        speed([int(n) for n in args.sizes.split(",")], out)
        speed([int(n) for n in args.sizes.split(",")], out, pillars=False)
    details = (
        f"{out['machine']}, jax {out['jax']}, JuPedSim {out['jupedsim']}, dt 1/30 s, "
        f"sections {args.sections}, model {MODEL}, cpu × {jax.device_count()}"
        + ("" if HEADING else ", no heading")
    )
    if MODEL == "collision-free-speed":  # the plots show the model JuPedSim runs too
        plot(out)
    report("pedestrians", details, out, _text(out), args.json, not args.no_record)


if __name__ == "__main__":
    main()
