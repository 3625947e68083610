"""How closely drawn walkers follow the simulated crowd (issue 19): root and heading, foot
skate, standing, level-change pops.

Runs ``examples/entrance.toml`` (slow and dense: 75 people through a 0.5 m gap),
``examples/counterflow.toml`` (two groups passing head-on) and the first minute of
``examples/station.toml`` (people coming up from two platforms, ``WINDOW_S``) with the crowd
dynamics on, recording everything (``jcrowd run --record all``), and measures from the
recording (skate and pops over each agent slot's first life, :func:`alive_span`):

- ``root_deviation_cm`` (p50, p99, max): the drawn root joint vs the simulated position, over
  drawn agent-frames.
- ``heading_deviation_deg`` (p99): the drawn heading vs the direction of the simulated velocity
  (from the simulated positions, ``(x_{f+1} − x_f)·fps``) over agent-frames moving faster than
  ``SLOW_M_S``: a standing person's velocity has no direction.
- ``skate_cm_per_frame``: every agent re-synthesized at level 0 over its time in the scene with
  the root where the run put it (:func:`jcrowd.crowd.agent_motion`), its feet planted as the
  step plants a near agent's (:func:`jcrowd.motion.planting.plant_sequence`, where the scene's
  dynamics and foot lock are on), foot skate as :func:`jcrowd.model.foot_skate`
  (``bench/skate.py``'s measure) on those joints; ``skate_captures_cm_per_frame`` the same on
  the ``cmu16`` captures (the default model's data, 30 fps), ``skate_ratio`` the two;
  ``skate_drawn_level0_cm_per_frame`` (and ``_ratio``) the same measure on the drawn joints of
  stretches of at least ``LEVEL0_RUN`` frames drawn at level 0.
  The jumps below compare the drawn joints with this planted level-0 walker.
- ``slow_share``: agent-frames whose simulated speed is below ``SLOW_M_S``;
  ``standing_share``: alive agent-frames standing (the step's ``stands``: the phase waiting at
  a double-support phase; ``0`` before the step had it);
  ``standing_skate_cm_per_frame``: the drawn feet of standing agent-frames (of slow ones in
  recordings without ``stands``), each foot's lower joint (ankle or toe) moving horizontally
  per frame, mean over both feet; ``None`` ("—") when nobody stood two frames running (rows
  of 2026-12-03 and earlier measured slow walkers' feet there instead);
  ``walking_in_place_share``: of the slow agent-frames, those whose gait phase advances at
  half the model's cadence or more (a walk at walking cadence while hardly moving).
- ``pop_cm`` (p99) and ``pop_ratio`` (p99): at each level change of a drawn agent, the largest
  joint jump beyond what the same agent re-synthesized at level 0 moves in the same frame
  (``max_j |Δp_j − Δp⁰_j|``, cm), over the frame of the change and the frames the step eases
  the change over (:data:`~jcrowd.crowd.level_blend.BLEND_SECONDS`; until the next change),
  and that ÷ the agent's median per-frame joint motion (``median_f max_j |Δp_j|``); ``None``
  ("—") where no drawn agent changed level;
  ``steady_jump_cm`` (p99) the same jump in drawn frames with no level change near: what the
  coarser levels move beyond level 0 on their own. Frames where the phase wraps (the cycle
  hands over to the next clip) are left out of both and measured apart, ``wrap_jump_cm``
  (p99; any drawn level, so a coarse level's own deviation counts) and ``wrap_jump_level0_cm``
  (p99; drawn at level 0 on both frames): the jump a hand-over makes beyond the re-synthesized
  walker's (the step closes each cycle, :func:`jcrowd.model.posevec.cycle_closing`; the
  offline re-synthesis too).
  Our reading of the issue's "largest joint jump": the raw largest joint motion in a frame is
  several cm for any swinging foot, so the jump is taken beyond the motion a full-detail
  walker makes in the same frame.

- ``lower_body_deviation_deg`` (p95, p99): the drawn pelvis's forward direction
  (perpendicular to the hip-to-hip vector, the hips being the feet's grandparent joints, its
  sign from the rest pose's toes) against the direction travelled over ``TRAVEL_S`` (centred),
  agent-frames faster than ``FAST_M_S`` over it; ``body_turn_rate_deg_s`` (p99): how fast that
  forward turns between drawn frames; ``standing_facing_deg`` (p90): of agent-frames slower
  than ``STAND_M_S``, that forward against the direction the agent walks off in next (from
  where it stands to where it is first ``NEXT_M`` away; our reading of "facing where it wants
  to go", as the recording holds no desired direction); ``pop_px`` and ``steady_px`` (p99):
  ``pop_cm`` and ``steady_jump_cm``'s jumps with every joint projected through the scene's
  camera of that frame into a ``PIXELS`` image, over the joints on screen (in front of the
  camera and inside the image: a jump nobody can see is not counted).
- ``queue_motion`` (entrance only), the simulated queue beside the measured one (the Wuppertal
  run ``040_c_56_h-``, ``../shared/data/pedestrians``), the same measure on both: in front of the
  gap (``0.3 < z < 4`` m), the direction of travel over a 0.4 s window (``QUEUE_WINDOW_S``;
  shorter windows measure the trackers' head sway), ``moving_share`` the frames faster than
  ``SLOW_M_S``, and of those the shares more than 60° and 90° from the direction to the gap;
  ``smooth_heading_p99_deg`` how far the per-frame velocity sits from the best heading that
  turns smoothly (the direction walked over a centred 1 s window, chosen with hindsight), p99
  over frames faster than ``SLOW_M_S``. Why it is here: ``heading_deviation_deg`` compares the
  drawn heading with the velocity's direction, and people in a queue step aside and back while
  they face the gap — the measured crowd's own velocities sit p99 tens of degrees from any
  smooth heading, so that bar measures how much the crowd sidesteps as well as how the walkers
  follow.

``python bench/follow.py [--json] [--no-record] [--no-plant-feet]``; appends a row to
bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from common import ROOT, data_root, machine, report

from jcrowd import load_default_model
from jcrowd.cli.run import simulate
from jcrowd.crowd import prepare
from jcrowd.crowd.level_blend import BLEND_SECONDS
from jcrowd.io import load_dataset
from jcrowd.model import agent_motion, foot_skate
from jcrowd.motion.clip import joint_positions
from jcrowd.motion.footlock import slides_of_points
from jcrowd.motion.gait import find_feet
from jcrowd.motion.planting import plant_sequence, warp_stride
from jcrowd.motion.skeleton import rest_positions
from jcrowd.render.camera import View, project
from jcrowd.scenario import load_scenario

SCENES = ("entrance", "counterflow", "station")
WINDOW_S = {"station": 60.0}
"""Scenes measured over their first seconds only: the station's 480 s with its pool of 632
slots recorded in full (every drawn joint, every frame) would not fit in memory."""
SLOW_M_S = 0.2
"""Agent-frames slower than this count as slow (the issue's bound for walking in place)."""

QUEUE_WINDOW_S = 0.4
"""s: the window the queue's direction of travel is taken over (``queue_motion``)."""
ENTRANCE_DATA = Path("pedestrians") / "bottleneck_entrance" / "040_c_56_h-.txt"

PER_FRAME = ("position", "heading", "tau", "control", "control_next", "has_next")


def _or_dash(value: object) -> str:
    """A table cell: the value, or "—" for None (nothing to measure)."""
    return "—" if value is None else str(value)


def drawn_points(rec: dict, n: int) -> np.ndarray:
    """Every agent's drawn points per frame ``(F, N, P, 3)`` (NaN where it is not drawn)."""
    frames = rec["position"].shape[0]
    p = rec["points_0"].shape[2]
    out = np.full((frames, n, p, 3), np.nan, np.float32)
    for lv in range(int(rec["levels"])):
        slots, valid, pts = rec[f"slots_{lv}"], rec[f"valid_{lv}"], rec[f"points_{lv}"]
        f, k = np.nonzero(valid)
        out[f, slots[f, k]] = pts[f, k]
    return out


def alive_span(alive: np.ndarray) -> tuple[int, int] | None:
    """The first run of frames an agent is alive, ``[start, stop)``."""
    idx = np.flatnonzero(alive)
    if idx.size < 3:
        return None
    start = idx[0]
    gaps = np.flatnonzero(np.diff(idx) > 1)
    stop = idx[gaps[0]] + 1 if gaps.size else idx[-1] + 1
    return int(start), int(stop)


def level0_joints(model, rec: dict, agent: int, span: tuple[int, int], cm=None):
    """The agent re-synthesized at level 0 over ``span``: its Motion, its joints ``(F, J, 3)``
    and, when ``cm`` (the crowd model) is given, those joints with the feet planted as the step
    plants a near agent's (:func:`jcrowd.motion.planting.plant_sequence`; else ``None``)."""
    a, b = span
    sub = {k: rec[k][a:b] for k in PER_FRAME}
    sub["height"], sub["fps"] = rec["height"], rec["fps"]
    motion = agent_motion(model, sub, agent)
    joints = np.asarray(joint_positions(motion))
    if cm is None or not cm.legs:
        return motion, joints, None
    return motion, joints, _planted(model, cm, rec, agent, joints, a, b)


def _planted(model, cm, rec: dict, agent: int, joints: np.ndarray, a: int, b: int) -> np.ndarray:
    """``joints (F, J, 3)``, the agent's frames ``a`` to ``b``, with the feet planted from fresh
    pins at the first frame, with the stride warp the step drew them with."""
    j = joints.shape[1]
    size = max(max(leg[4]) for leg in cm.legs) + 1  # the legs' End Sites follow the joints
    pts = np.concatenate([joints, np.zeros((len(joints), max(size - j, 0), 3), joints.dtype)], 1)
    scale = float(rec["height"][agent]) / model.body_height
    planted = plant_sequence(
        cm.legs,
        (float(cm.double_support[0]), float(cm.double_support[1])),
        float(cm.frames - 1),
        jnp.asarray(pts),
        jnp.asarray(rec["tau"][a:b, agent], jnp.float32),
        jnp.float32(scale),
        jnp.asarray(rec["heading"][a:b, agent], jnp.float32) if "stride" in rec else None,
        jnp.asarray(rec["stride"][a:b, agent], jnp.float32) if "stride" in rec else None,
    )
    return np.asarray(planted)[:, :j]


def _warped(cm, rec: dict, agent: int, span: tuple[int, int], joints: np.ndarray) -> np.ndarray:
    """``joints (F, J, 3)`` with the stride warp the step drew every level with
    (:func:`jcrowd.motion.planting.warp_stride`; unchanged for recordings without it)."""
    if "stride" not in rec:
        return joints.copy()
    a, b = span
    j = joints.shape[1]
    size = max(max(leg[4]) for leg in cm.legs) + 1  # the legs' End Sites follow the joints
    pts = np.concatenate([joints, np.zeros((len(joints), max(size - j, 0), 3), joints.dtype)], 1)
    warp = jax.vmap(lambda p, h, k: warp_stride(cm.legs, p, h, k))
    heading, stride = rec["heading"][a:b, agent], rec["stride"][a:b, agent]
    out = warp(jnp.asarray(pts), jnp.asarray(heading, jnp.float32), jnp.asarray(stride))
    return np.array(out)[:, :j]


def planted_in_runs(model, cm, rec, agent, span, loose, near) -> np.ndarray:
    """The level-0 joints ``loose`` planted as the step plants this agent: from fresh pins at
    the start of each run of frames it is drawn near (``near (F,)``), as the step's pins start
    when an agent comes near; ``loose`` elsewhere."""
    out = _warped(cm, rec, agent, span, loose)
    edges = np.diff(np.concatenate([[0], near.astype(int), [0]]))
    for r0, r1 in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        a, b = span[0] + r0, span[0] + r1
        out[r0:r1] = _planted(model, cm, rec, agent, loose[r0:r1], a, b)
    return out


NO_PLANT = False
"""``--no-plant-feet``: the scenes run without planted feet
(:attr:`~jcrowd.crowd.state.StepConfig.plant_feet` off)."""

LEVEL0_RUN = 30
"""Frames: a drawn level-0 stretch this long or longer counts towards the drawn skate."""


def level0_runs(level: np.ndarray) -> list[tuple[int, int]]:
    """The ``[start, stop)`` stretches of frames drawn at level 0, at least :data:`LEVEL0_RUN`
    long."""
    edges = np.diff(np.concatenate([[0], (level == 0).astype(int), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if b - a >= LEVEL0_RUN]


def queue_motion(tracks: list[np.ndarray], fps: float) -> dict:
    """In front of the entrance's gap (at the origin, people walking towards −z): how often and
    which way people move (module docstring). ``tracks``: one ``(F, 2)`` path per person."""
    w = max(1, round(QUEUE_WINDOW_S * fps))
    half = max(1, round(0.5 * fps))
    speeds, away, off = [], [], []
    for p in tracks:
        if len(p) <= max(w, 2 * half + 1):
            continue
        step = p[w:] - p[:-w]
        mid = 0.5 * (p[w:] + p[:-w])
        sp = np.linalg.norm(step, axis=1) / QUEUE_WINDOW_S
        front = (mid[:, 1] > 0.3) & (mid[:, 1] < 4.0)
        go = front & (sp > SLOW_M_S)
        bearing = np.arctan2(step[go, 0], step[go, 1]) - np.arctan2(-mid[go, 0], -mid[go, 1])
        away.append(np.abs(np.remainder(bearing + np.pi, 2 * np.pi) - np.pi))
        speeds.append(sp[front])
        # The per-frame velocity against the direction walked over the centred second.
        v = (p[1:] - p[:-1])[half:-half] * fps
        span = p[2 * half + 1 :] - p[: -2 * half - 1]
        ok = (np.linalg.norm(v, axis=1) > SLOW_M_S) & (np.linalg.norm(span, axis=1) > 1e-3)
        turn = np.arctan2(v[ok, 0], v[ok, 1]) - np.arctan2(span[ok, 0], span[ok, 1])
        off.append(np.abs(np.remainder(turn + np.pi, 2 * np.pi) - np.pi))
    sp, ang, dev = np.concatenate(speeds), np.concatenate(away), np.degrees(np.concatenate(off))
    return {
        "moving_share": round(float(np.mean(sp > SLOW_M_S)), 3),
        "away_over_60_share": round(float(np.mean(ang > np.pi / 3)), 3),
        "away_over_90_share": round(float(np.mean(ang > np.pi / 2)), 3),
        "smooth_heading_p99_deg": round(float(np.percentile(dev, 99)), 1),
    }


def measured_entrance() -> list[np.ndarray]:
    """The Wuppertal entrance run's head paths ``(F, 2)`` (x across, y along; 25 fps)."""
    raw = np.loadtxt(data_root() / ENTRANCE_DATA, comments="#")
    out = []
    for pid in np.unique(raw[:, 0]):
        r = raw[raw[:, 0] == pid]
        out.append(r[np.argsort(r[:, 1]), 2:4])
    return out


def simulated_paths(pos: np.ndarray, alive: np.ndarray) -> list[np.ndarray]:
    """Each agent's positions over its first run of alive frames."""
    spans = (alive_span(alive[:, a]) for a in range(pos.shape[1]))
    return [pos[s[0] : s[1], a] for a, s in enumerate(spans) if s is not None]


PIXELS = (1280, 720)  # the image the pops are projected into
TRAVEL_S = 0.5  # s: the window the lower body is compared with the direction travelled over
FAST_M_S = 0.3  # m/s: agents slower than this over that window are not compared
STAND_M_S = 0.1  # m/s: standing, for standing_facing_deg (bench/pedestrians.py's bound)
NEXT_M = 0.5  # m: how far a standing agent walks off before its direction counts


def hips(skeleton) -> tuple[int, int, float]:
    """The left and right hip joints (the feet's grandparents) and the sign that turns
    ``perp(left − right)`` into the body's forward, fixed by the rest pose's toes."""
    feet = find_feet(skeleton)
    par = skeleton.parents
    left, right = par[par[feet.left_ankle]], par[par[feet.right_ankle]]
    rest, _ = rest_positions(skeleton)
    fwd = _perp(rest[left] - rest[right])
    toes = rest[[feet.left_toe, feet.right_toe]] - rest[[feet.left_ankle, feet.right_ankle]]
    return int(left), int(right), float(np.sign(np.sum(fwd * toes.mean(0)[[0, 2]])) or 1.0)


def _perp(hip_to_hip: np.ndarray) -> np.ndarray:
    """``(x, z)`` perpendicular to the horizontal part of a left-minus-right hip vector."""
    return np.stack([-hip_to_hip[..., 2], hip_to_hip[..., 0]], axis=-1)


def body_measures(pts, pos, alive, skeleton, fps) -> dict:
    """``lower_body_deviation_deg`` (p95, p99): the drawn pelvis's forward (perpendicular to
    the hip-to-hip vector) against the direction travelled over ``TRAVEL_S`` (centred), agents
    faster than ``FAST_M_S`` over it; ``body_turn_rate_deg_s`` (p99): how fast that forward
    turns between drawn frames."""
    left, right, sign = hips(skeleton)
    fwd = sign * _perp(pts[:, :, left] - pts[:, :, right])
    ang = np.arctan2(fwd[..., 0], fwd[..., 1])
    half = max(1, round(TRAVEL_S * fps / 2))
    travel = np.full_like(pos, np.nan)
    travel[half:-half] = pos[2 * half :] - pos[: -2 * half]
    ok_t = np.zeros_like(alive)
    ok_t[half:-half] = alive[2 * half :] & alive[: -2 * half] & alive[half:-half]
    fast = ok_t & (np.linalg.norm(travel, axis=-1) / (2 * half / fps) > FAST_M_S)
    fast &= np.isfinite(ang)
    off = np.remainder(ang - np.arctan2(travel[..., 0], travel[..., 1]) + np.pi, 2 * np.pi)
    dev = np.degrees(np.abs(off - np.pi))[fast]
    both = np.isfinite(ang[1:]) & np.isfinite(ang[:-1]) & alive[1:] & alive[:-1]
    turn = np.abs(np.remainder(ang[1:] - ang[:-1] + np.pi, 2 * np.pi) - np.pi)
    rate = np.degrees(turn[both]) * fps
    facing = standing_facing(ang, pos, alive, fps)

    def pct(v, q):
        return round(float(np.percentile(v, q)), 1) if len(v) else None

    return {
        "lower_body_deviation_deg": {"p95": pct(dev, 95), "p99": pct(dev, 99)},
        "body_turn_rate_deg_s": pct(rate, 99),
        "standing_facing_deg": pct(facing, 90),
    }


def standing_facing(ang, pos, alive, fps) -> np.ndarray:
    """Per standing agent-frame (slower than ``STAND_M_S``, drawn), the angle (°) between the
    drawn pelvis's forward ``ang`` and the direction the agent walks off in next: from where it
    stands to where it first is ``NEXT_M`` away (frames with no such later place are left
    out)."""
    speed = np.full(alive.shape, np.inf)
    speed[:-1] = np.linalg.norm(pos[1:] - pos[:-1], axis=-1) * fps
    speed[:-1] = np.where(alive[1:] & alive[:-1], speed[:-1], np.inf)
    out = []
    for agent in range(pos.shape[1]):
        frames = np.flatnonzero((speed[:, agent] < STAND_M_S) & np.isfinite(ang[:, agent]))
        if not len(frames):
            continue
        life = np.flatnonzero(alive[:, agent])
        path = pos[life, agent]
        at = np.searchsorted(life, frames)
        away = np.linalg.norm(path[None, :] - path[at][:, None], axis=-1) >= NEXT_M
        away &= np.arange(len(life))[None, :] > at[:, None]
        life_of = np.cumsum(np.diff(life, prepend=life[0]) > 1)  # a pool's slot has several
        away &= life_of[None, :] == life_of[at][:, None]
        found = away.any(axis=1)
        nxt = path[np.argmax(away, axis=1)] - path[at]
        want = np.arctan2(nxt[:, 0], nxt[:, 1])
        off = np.remainder(ang[frames, agent] - want + np.pi, 2 * np.pi) - np.pi
        out.append(np.degrees(np.abs(off[found])))
    return np.concatenate(out) if out else np.zeros(0)


def pixel_jumps(own, r0, r1, view_ids, views) -> np.ndarray:
    """``max_j |Δq_j − Δq⁰_j|`` in pixels per frame step: the drawn joints ``own (F, J, 3)``
    and the level-0 ones of each step ``r0, r1 (F − 1, J, 3)`` (the earlier and the later
    frame's), projected with the view of the step's later frame
    (``views[view_ids[f]]``; one projection per distinct view: a fixed camera projects every
    frame at once). Only joints on screen count: beyond the near plane in all four and, drawn
    in the later frame, inside the image (a point behind the camera projects to meaningless
    pixels, :func:`~jcrowd.render.camera.project`); NaN where none is."""
    pairs = np.stack([own[:-1], own[1:], r0, r1], axis=1)  # (F−1, 4, J, 3)
    out = np.full(len(own) - 1, np.nan)
    later = view_ids[1:]
    size = np.array(PIXELS, np.float64)
    for k in np.unique(later):
        sel = later == k
        q, front = project(pairs[sel], views[k], *PIXELS)
        shown = front.all(axis=1) & ((q[:, 1] >= 0) & (q[:, 1] < size)).all(axis=-1)
        d = np.linalg.norm((q[:, 1] - q[:, 0]) - (q[:, 3] - q[:, 2]), axis=-1)
        d = np.where(shown, d, -np.inf).max(axis=-1)
        out[sel] = np.where(np.isfinite(d), d, np.nan)
    return out


def measure(model, name: str, steps: int | None) -> dict:
    sim, state = prepare(load_scenario(Path(ROOT) / "examples" / f"{name}.toml"), model)
    if NO_PLANT:
        sim = dataclasses.replace(sim, config=dataclasses.replace(sim.config, plant_feet=False))
    seconds = min(sim.scenario.duration_s, WINDOW_S.get(name, np.inf))
    steps = steps or round(seconds * sim.scenario.fps)
    _, rec = simulate(sim, state, steps, "all")
    fps = float(rec["fps"])
    n = rec["position"].shape[1]
    pts = drawn_points(rec, n)
    pos, alive, level = rec["position"], rec["alive"], rec["level"]
    nlev = int(rec["levels"])
    j = model.skeleton.num_joints
    feet = find_feet(model.skeleton)
    foot_pairs = ((feet.left_ankle, feet.left_toe), (feet.right_ankle, feet.right_toe))

    drawn = alive & np.isfinite(pts[:, :, 0, 0])
    root_dev = 100 * np.linalg.norm(pts[:, :, 0, [0, 2]] - pos, axis=-1)[drawn]

    both = alive[:-1] & alive[1:]
    vel = (pos[1:] - pos[:-1]) * fps
    speed = np.linalg.norm(vel, axis=-1)
    moving = both & (speed > SLOW_M_S)
    want = np.arctan2(vel[..., 0], vel[..., 1])
    dev = np.remainder(rec["heading"][:-1] - want + np.pi, 2 * np.pi) - np.pi
    head_dev = np.degrees(np.abs(dev[moving]))

    slow = both & (speed < SLOW_M_S)
    standing = alive & rec["stands"] if "stands" in rec else np.zeros_like(alive)
    last = float(sim.crowd.frames - 1)
    dtau = np.remainder(rec["tau"][1:] - rec["tau"][:-1], last)
    cadence = dtau * fps / last  # cycles per second
    walking_cadence = 0.5 / sim.crowd.cycle_seconds
    in_place = slow & (cadence >= walking_cadence)

    # Drawn feet of slow agent-frames: each foot's lower joint, horizontal motion per frame.
    step_feet = []
    d0, d1 = pts[:-1], pts[1:]
    # Recordings from before the step could stand have no "stands": their slow frames stand in.
    still = (standing[:-1] & standing[1:]) if "stands" in rec else slow
    ok = still & drawn[:-1] & drawn[1:]
    for ankle, toe in foot_pairs:
        low = np.where(d0[..., ankle, 1] <= d0[..., toe, 1], ankle, toe)
        a = np.take_along_axis(d0, low[..., None, None], axis=2)[..., 0, :]
        b = np.take_along_axis(d1, low[..., None, None], axis=2)[..., 0, :]
        step_feet.append(100 * np.linalg.norm((b - a)[..., [0, 2]], axis=-1)[ok])
    # None: nobody stood in two frames running (nothing to measure).
    standing_skate = float(np.mean(np.concatenate(step_feet))) if ok.any() else None

    skates, pops, ratios, steady, wraps, wraps0 = [], [], [], [], [], []
    drawn_slides: list[np.ndarray] = []
    pops_px, steady_px = [], []
    cam = sim.scenario.camera
    eyes, view_ids = np.unique(
        np.concatenate([rec["eye"], rec["target"]], axis=1), axis=0, return_inverse=True
    )
    views = [
        View(
            tuple(map(float, e[:3])),
            tuple(map(float, e[3:])),
            fov_deg=cam.fov_deg,
            near=cam.near,
            far=cam.far,
        )
        for e in eyes
    ]
    view_ids = view_ids.reshape(-1)
    # The step plants near agents' feet with the dynamics on; the level-0 walker is planted alike.
    config = sim.config
    planting = sim.crowd if config.avoid and config.foot_lock and config.plant_feet else None
    near_max = config.blend_max_level
    ease = int(np.ceil(BLEND_SECONDS * fps)) + 1  # frames a level change moves the pose over
    for agent in range(n):
        span = alive_span(alive[:, agent])
        if span is None:
            continue
        _, loose, planted = level0_joints(model, rec, agent, span, planting)
        ref = loose if planted is None else planted  # a near agent's, as the step draws it
        scale = float(rec["height"][agent]) / model.body_height
        slid = slides_of_points(ref.astype(np.float64), model.skeleton.scaled(scale), fps)
        every = np.concatenate([np.linalg.norm(step, axis=1) for _, step in slid])
        skates.append(100 * float(every.mean()) if every.size else 0.0)
        a, b = span
        own = pts[a:b, agent, :j]
        lv = level[a:b, agent]
        move = np.diff(own, axis=0)
        # Each frame step is compared with the level-0 walker drawn as this one is: planted
        # where both frames are at a near level (when the step plants, from fresh pins each
        # time the agent comes near, as the step's), else not.
        if planted is not None:
            drawn_ref = planted_in_runs(model, planting, rec, agent, span, loose, lv <= near_max)
        else:
            drawn_ref = loose
        both_near = ((lv[1:] <= near_max) & (lv[:-1] <= near_max))[:, None, None]
        r0 = np.where(both_near, drawn_ref[:-1], loose[:-1])
        r1 = np.where(both_near, drawn_ref[1:], loose[1:])
        extra = np.linalg.norm(move - (r1 - r0), axis=-1).max(axis=1)
        extra_px = np.where(
            np.isfinite(extra), pixel_jumps(own, r0, r1, view_ids[a:b], views), np.nan
        )
        raw = np.linalg.norm(move, axis=-1).max(axis=1)
        change = (lv[1:] != lv[:-1]) & (lv[1:] < nlev) & (lv[:-1] < nlev)
        normal = np.nanmedian(raw) if np.isfinite(raw).any() else np.nan
        # The cycle hand-over (the phase wraps): the model's own jump, measured apart.
        wrap = np.diff(rec["tau"][a:b, agent]) < 0
        drawn_both = (lv[1:] < nlev) & (lv[:-1] < nlev)
        wraps.extend(100 * extra[wrap & drawn_both & np.isfinite(extra)])
        fine = (lv[1:] == 0) & (lv[:-1] == 0)
        wraps0.extend(100 * extra[wrap & fine & np.isfinite(extra)])
        calm = np.isfinite(extra) & ~wrap
        starts = np.flatnonzero(change)
        stops = [*starts[1:], len(extra)][: len(starts)]
        for f, stop in zip(starts, stops, strict=True):
            window = np.where(wrap, np.nan, extra)[f : min(stop, f + ease)]
            calm[f : min(stop, f + ease)] = False
            if np.isfinite(window).any():
                pops.append(100 * np.nanmax(window))
                ratios.append(np.nanmax(window) / normal)
                seen = np.where(wrap, np.nan, extra_px)[f : min(stop, f + ease)]
                if np.isfinite(seen).any():
                    pops_px.append(np.nanmax(seen))
        steady.extend(100 * extra[calm & drawn_both])
        for r0, r1 in level0_runs(lv):
            slid = slides_of_points(
                own[r0:r1].astype(np.float64), model.skeleton.scaled(scale), fps
            )
            drawn_slides.extend(100 * np.linalg.norm(step, axis=1) for _, step in slid)
        steady_px.extend(extra_px[calm & drawn_both & np.isfinite(extra_px)])
    print(f"{name}: {steps} steps, {n} agents, {len(pops)} level changes", file=sys.stderr)

    def pct(v, q):
        return round(float(np.percentile(v, q)), 3) if len(v) else None

    queue = {}
    if name == "entrance":
        queue["queue_motion"] = {
            "simulated": queue_motion(simulated_paths(pos, alive), fps),
            "measured": queue_motion(measured_entrance(), 25.0),
        }
    return {
        **queue,
        "steps": steps,
        "agents": n,
        "root_deviation_cm": {
            "p50": pct(root_dev, 50),
            "p99": pct(root_dev, 99),
            "max": round(float(root_dev.max()), 3) if root_dev.size else None,
        },
        "heading_deviation_deg": {"p50": pct(head_dev, 50), "p99": pct(head_dev, 99)},
        "skate_cm_per_frame": round(float(np.mean(skates)), 3),
        "skate_drawn_level0_cm_per_frame": (
            round(float(np.mean(np.concatenate(drawn_slides))), 3) if drawn_slides else None
        ),
        "slow_share": round(float(slow.sum() / max(both.sum(), 1)), 4),
        "standing_share": round(float(standing.sum() / max(alive.sum(), 1)), 4),
        "standing_skate_cm_per_frame": (
            None if standing_skate is None else round(standing_skate, 3)
        ),
        "walking_in_place_share": round(float(in_place.sum() / max(slow.sum(), 1)), 4),
        "level_changes": len(pops),
        "pop_cm": pct(pops, 99),
        "pop_ratio": pct(ratios, 99),
        "steady_jump_cm": pct(steady, 99),
        "wrap_jump_cm": pct(wraps, 99),
        "wrap_jump_level0_cm": pct(wraps0, 99),
        "pop_px": pct(pops_px, 99),
        "steady_px": pct(steady_px, 99),
        **body_measures(pts, pos, alive, model.skeleton, fps),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--steps", type=int, default=0, help="steps per scene (0: its duration)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    ap.add_argument("--no-plant-feet", action="store_true", help="near agents' feet unplanted")
    args = ap.parse_args()
    global NO_PLANT
    NO_PLANT = args.no_plant_feet
    model = load_default_model()
    captures = [100 * foot_skate(c.motion) for c in load_dataset(data_root() / "cmu16")]
    ref = float(np.mean(captures))
    out: dict = {"skate_captures_cm_per_frame": round(ref, 3)}
    for name in args.scenes.split(","):
        res = measure(model, name, args.steps or None)
        res["skate_ratio"] = round(res["skate_cm_per_frame"] / ref, 2)
        drawn = res["skate_drawn_level0_cm_per_frame"]
        res["skate_drawn_level0_ratio"] = None if drawn is None else round(drawn / ref, 2)
        out[name] = res
    out.update(machine=machine(), jax=jax.__version__)
    rows = [
        "| scene | root dev cm p50 / p99 / max | heading dev ° p99 | skate cm/frame (× captures) "
        "| slow share | standing share | standing skate cm/frame | walking in place | "
        "level changes | pop cm p99 | pop ÷ motion p99 | steady jump cm p99 | "
        "cycle hand-over jump cm p99 (all levels / level 0) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in args.scenes.split(","):
        r = out[name]
        rd = r["root_deviation_cm"]
        rows.append(
            f"| {name} | {rd['p50']} / {rd['p99']} / {rd['max']} | "
            f"{r['heading_deviation_deg']['p99']} | {r['skate_cm_per_frame']} "
            f"({r['skate_ratio']}×) | {r['slow_share']} | {r['standing_share']} | "
            f"{_or_dash(r['standing_skate_cm_per_frame'])} | {r['walking_in_place_share']} | "
            f"{r['level_changes']} | {_or_dash(r['pop_cm'])} | {_or_dash(r['pop_ratio'])} | "
            f"{r['steady_jump_cm']} | "
            f"{r['wrap_jump_cm']} / {r['wrap_jump_level0_cm']} |"
        )
    text = "\n".join(rows) + f"\n\ncmu16 captures' own skate: {ref:.3f} cm/frame"
    text += (
        f"\n\n| scene | drawn level-0 skate cm/frame (× captures) | lower body vs travel ° "
        f"p95 / p99 | drawn body turn °/s p99 | standing facing ° p90 | pop px p99 | "
        f"steady px p99 ({PIXELS[0]}×{PIXELS[1]}) |\n|---|---|---|---|---|---|---|\n"
    )
    for name in args.scenes.split(","):
        r = out[name]
        lb = r["lower_body_deviation_deg"]
        text += (
            f"| {name} | {_or_dash(r['skate_drawn_level0_cm_per_frame'])} "
            f"({_or_dash(r['skate_drawn_level0_ratio'])}×) | {lb['p95']} / {lb['p99']} | "
            f"{r['body_turn_rate_deg_s']} | "
            f"{_or_dash(r['standing_facing_deg'])} | {_or_dash(r['pop_px'])} | {r['steady_px']} |\n"
        )
    if "entrance" in out:
        q = out["entrance"]["queue_motion"]
        text += (
            "\n\nIn front of the entrance's gap | moving share | of those > 60° / > 90° from the "
            "gap | velocity vs best smooth heading p99 °\n|---|---|---|---|\n"
        )
        for who in ("simulated", "measured"):
            m = q[who]
            text += (
                f"| {who} | {m['moving_share']} | {m['away_over_60_share']} / "
                f"{m['away_over_90_share']} | {m['smooth_heading_p99_deg']} |\n"
            )
    feet = "feet unplanted" if NO_PLANT else "feet planted"
    details = f"{out['machine']}, jax {out['jax']}, {feet}"
    report("follow", details, out, text, args.json, not args.no_record)


if __name__ == "__main__":
    main()
